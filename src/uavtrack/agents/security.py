"""Who may speak in a swarm: keys, message authentication and replay windows.

Every message of the agent form passes through a `Gate` before anything reads it. The
gate checks that it came from the program it names, to the program that reads it, and
that it was not seen before; what fails is dropped and counted by reason, never acted on.

Trust model. The world program is the root of trust. For each run it makes

* an Ed25519 signing key of its own, whose public half every program is given at launch
  (spawned programs through their standard input, programs on other machines in a key
  file the user copies, `Credential`): it signs the run's `Hello`, and only the world can;
* one X25519 key pair per program (UAVs 0 .. N-1, the central node N, the world): each
  program is handed its own private key with the world's public signing key, and learns
  every program's public key from the signed Hello.

Two programs s and r derive a key of their own, for messages from s to r, from their
X25519 agreement (HKDF-SHA256 over the run, s and r). Each message carries (sender,
receiver, sequence number) and a BLAKE2b tag under that key over them and the message,
so only s (and r itself) can make a message that r accepts as s's: a third member cannot
speak as s, and a stranger cannot speak at all. The sequence number of a sender only
grows; a receiver keeps a window of the last `WINDOW` numbers per sender and drops a
number seen before (a replay) or older than the window. Messages to different receivers
are separate messages (the radio delivers to each receiver what it can hear), so pairwise
keys cost one keyed hash per message instead of a public-key signature (about 2 us
against 130 us to verify Ed25519 on the 2-core machine; see the docs, the agent form,
Trust).

A swarm that does not authenticate (``--no-sign``) tags each envelope with an unkeyed
BLAKE2b checksum of the same bytes instead: it catches a corrupted message (dropped as
malformed), not a forged one, and keeps every frame the size `radio.TAG_BYTES` counts.
Sequence numbers start above `radio.SEQ_START` for the same reason.

What this does not do: hide the messages from the network (use TLS, `--tls-*`: mutual
TLS lets only holders of a certificate of the swarm's CA connect at all), or keep a
program whose key is stolen from speaking as itself. A key file is refused when others
than its owner may read it (as ssh refuses a private key), since a key file that others
can read is a key that may have been stolen.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import stat
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import msgspec

from ..radio import SEQ_START, TAG_BYTES

if TYPE_CHECKING:  # cryptography is loaded on first use (`_crypto`)
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

WORLD = -1
"""The world program's number on the wire."""
EVERYONE = -2
"""The receiver of a broadcast (the world's Hello)."""
WINDOW = 4096
"""Sequence numbers a receiver remembers per sender; an older one is dropped."""
_PERSON = b"uavtrack-mac-v1"
_SIGNED = b"uavtrack-hello-v1|"


class Envelope(msgspec.Struct, array_like=True, frozen=True, kw_only=True):
    """A message on the wire: who sent it to whom, its sequence number, the encoded
    message (`messages`), and its tag (keyed hash, Ed25519 signature for the world's
    Hello to all). A radio frame to several receivers (``radio.frames = "broadcast"``)
    names a list of receivers and holds a list of tags, one per receiver, each the tag
    that receiver would check alone (`Gate.seal_for`)."""

    sender: int
    receiver: int | list[int]
    seq: int
    body: bytes
    tag: bytes | list[bytes]


_encode = msgspec.msgpack.Encoder().encode
_decode = msgspec.msgpack.Decoder(Envelope).decode


def peek_sender(payload: bytes) -> int | None:
    """The sender an envelope names, unverified (None: not an envelope)."""
    try:
        return _decode(payload).sender
    except (msgspec.DecodeError, msgspec.ValidationError, TypeError, ValueError):
        return None


def tag_of(key: bytes, run: str, sender: int, receiver: int, seq: int, body: bytes) -> bytes:
    """An envelope's tag: BLAKE2b under `key` over the run, sender, receiver, sequence
    number and body; with no key (b""), the checksum of a swarm that does not
    authenticate, which anyone can make."""
    head = f"{run}|{sender}|{receiver}|{seq}|".encode()
    return hashlib.blake2b(head + body, key=key, digest_size=TAG_BYTES, person=_PERSON).digest()


def _crypto():
    try:
        from cryptography.hazmat.primitives import hashes
        from cryptography.hazmat.primitives.asymmetric import ed25519, x25519
        from cryptography.hazmat.primitives.kdf.hkdf import HKDF
    except ImportError as exc:  # pragma: no cover - a dependency of the package
        raise ImportError(
            "authenticated swarms need cryptography: pip install cryptography"
        ) from exc
    return hashes, ed25519, x25519, HKDF


def check_private(path: Path | str, mode: int) -> None:
    """ValueError when a secret file of permission bits `mode` is open to its group or to
    others (as ssh refuses such a private key), naming the file and the fix."""
    if os.name == "posix" and mode & 0o077:
        raise ValueError(
            f"{path}: permissions {stat.S_IMODE(mode):04o} are too open (a key must be "
            f"private to its owner); chmod 600 {path}"
        )


def public_of(secret: bytes) -> bytes:
    """The X25519 public key (32 bytes) of the private key `secret` (32 bytes)."""
    from cryptography.hazmat.primitives import serialization

    _, _, x25519, _ = _crypto()
    key = x25519.X25519PrivateKey.from_private_bytes(secret).public_key()
    return key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)


@dataclass(frozen=True)
class Credential:
    """What one program needs to join a run: the run, its number, its X25519 private
    key (32 bytes) and the world's Ed25519 public key (32 bytes)."""

    run: str
    program: int
    secret: bytes
    world: bytes

    def to_json(self) -> str:
        return json.dumps(
            {
                "uavtrack_credential": 1,
                "run": self.run,
                "program": self.program,
                "secret": self.secret.hex(),
                "world": self.world.hex(),
            }
        )

    @classmethod
    def from_json(cls, text: str) -> Credential:
        """The credential in `text`; ValueError naming what is wrong."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError:
            raise ValueError("not a uavtrack key file (not JSON)") from None
        if not isinstance(data, dict) or data.get("uavtrack_credential") != 1:
            raise ValueError("not a uavtrack key file")
        try:
            out = cls(
                str(data["run"]),
                int(data["program"]),
                bytes.fromhex(data["secret"]),
                bytes.fromhex(data["world"]),
            )
        except (KeyError, TypeError, ValueError):
            raise ValueError("a uavtrack key file with a missing or malformed field") from None
        if len(out.secret) != 32 or len(out.world) != 32 or out.program < 0:
            raise ValueError("a uavtrack key file with a malformed key")
        return out

    def write(self, path: Path) -> None:
        """Write to `path`, readable and writable by the owner only (mode 0600 whatever
        the umask); never through a link, never over an existing file."""
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
        fd = os.open(path, flags, 0o600)
        with os.fdopen(fd, "w", encoding="ascii") as handle:
            if os.name == "posix":  # a umask takes bits away: with 0o277 it would be 0400
                os.fchmod(handle.fileno(), 0o600)
            handle.write(self.to_json() + "\n")

    def public(self) -> bytes:
        """This program's X25519 public key, as the world's Hello names it."""
        return public_of(self.secret)

    @classmethod
    def read(cls, path: Path) -> Credential:
        """The credential in the file `path`; ValueError naming what is wrong (also a
        file that its group or others may read: `check_private`)."""
        try:
            fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
        except OSError as exc:
            raise ValueError(f"cannot read {path}: {exc.strerror}") from None
        with os.fdopen(fd, encoding="ascii", errors="replace") as handle:
            mode = os.fstat(handle.fileno()).st_mode
            if not stat.S_ISREG(mode):
                raise ValueError(f"{path} is not a regular file")
            check_private(path, mode)
            text = handle.read(4096)
        try:
            return cls.from_json(text)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None


class Keyring:
    """The world's keys for one run of `programs` programs (see the module docstring)."""

    def __init__(self, run: str, programs: int) -> None:
        _, ed25519, x25519, _ = _crypto()
        self.run, self.programs = run, programs
        self.signing = ed25519.Ed25519PrivateKey.generate()
        self.secrets = [x25519.X25519PrivateKey.generate() for _ in range(programs + 1)]

    def _raw(self, key) -> bytes:
        from cryptography.hazmat.primitives import serialization

        if hasattr(key, "private_bytes"):
            return key.private_bytes(
                serialization.Encoding.Raw,
                serialization.PrivateFormat.Raw,
                serialization.NoEncryption(),
            )
        return key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)

    def credential(self, program: int) -> Credential:
        """Program `program`'s credential (the world's own is number `programs`)."""
        return Credential(
            self.run,
            program,
            self._raw(self.secrets[program]),
            self._raw(self.signing.public_key()),
        )

    def public(self) -> list[bytes]:
        """Every program's X25519 public key, the world's last."""
        return [self._raw(k.public_key()) for k in self.secrets]

    def gate(self) -> Gate:
        """The world's gate."""
        gate = Gate(
            run=self.run,
            me=WORLD,
            programs=self.programs,
            credential=self.credential(self.programs),
        )
        gate.learn(self.public())
        gate.signing = self.signing
        return gate


@dataclass
class Window:
    """The sequence numbers seen of one sender: the highest and a bitmap of the
    `WINDOW` below it."""

    top: int = 0
    seen: int = 0

    def fresh(self, seq: int) -> bool:
        """Whether `seq` is new; if so it is remembered."""
        if seq > self.top:
            shift = seq - self.top
            self.seen = ((self.seen << shift) | 1) & ((1 << WINDOW) - 1) if shift < WINDOW else 1
            self.top = seq
            return True
        back = self.top - seq
        if back >= WINDOW or (self.seen >> back) & 1:
            return False
        self.seen |= 1 << back
        return True


@dataclass(kw_only=True)
class Gate:
    """One program's side of authentication: it seals what the program sends and opens
    what it receives (see the module docstring).

    run: the run id; me: this program's number (`WORLD` for the world); programs: the
    run's programs (UAVs and central node), numbered 0 .. programs-1; credential: this
    program's (None: the swarm does not authenticate; every envelope is taken at its
    word). Until `learn` gives the programs' public keys (from the Hello), only the
    world's signed Hello can be opened.
    """

    run: str
    me: int
    programs: int
    credential: Credential | None
    signing: Ed25519PrivateKey | None = None  # the world's
    drops: dict[str, int] = field(default_factory=dict)
    _publics: list[bytes] | None = None
    _keys: dict[tuple[int, int], bytes] = field(default_factory=dict)
    _windows: dict[int, Window] = field(default_factory=dict)
    _seq: int = SEQ_START

    @property
    def authenticates(self) -> bool:
        return self.credential is not None

    @property
    def ready(self) -> bool:
        """Whether messages of the other programs can be opened."""
        return self.credential is None or self._publics is not None

    def learn(self, publics: Iterable[bytes]) -> None:
        """The programs' X25519 public keys, the world's last (from the signed Hello);
        `programs` must be set first."""
        publics = [bytes(p) for p in publics]
        if self.credential is not None and len(publics) != self.programs + 1:
            raise ValueError("the Hello names another number of programs")
        self._publics = publics

    def _index(self, program: int) -> int:
        return self.programs if program == WORLD else program

    def _key(self, sender: int, receiver: int) -> bytes:
        """The key of messages from `sender` to `receiver`, one of them this program."""
        key = self._keys.get((sender, receiver))
        if key is None:
            hashes, _, x25519, HKDF = _crypto()
            other = receiver if sender == self.me else sender
            # keys exist only in an authenticated run, once the Hello named the publics
            assert self.credential is not None and self._publics is not None
            mine = x25519.X25519PrivateKey.from_private_bytes(self.credential.secret)
            theirs = x25519.X25519PublicKey.from_public_bytes(self._publics[self._index(other)])
            info = f"uavtrack|{self.run}|{sender}>{receiver}".encode()
            key = HKDF(hashes.SHA256(), 32, None, info).derive(mine.exchange(theirs))
            self._keys[(sender, receiver)] = key
        return key

    def _mac(self, key: bytes, sender: int, receiver: int, seq: int, body: bytes) -> bytes:
        head = f"{self.run}|{sender}|{receiver}|{seq}|".encode()
        return hashlib.blake2b(head + body, key=key, digest_size=TAG_BYTES, person=_PERSON).digest()

    def seal(self, receiver: int, body: bytes) -> bytes:
        """The envelope of `body` (an encoded message) from this program to `receiver`."""
        self._seq += 1
        seq = self._seq
        tag = tag_of(b"", self.run, self.me, receiver, seq, body)  # without keys, a checksum
        if self.credential is not None:
            if receiver == EVERYONE:
                if self.signing is None:
                    raise ValueError("only the world, which holds the signing key, signs to all")
                tag = self.signing.sign(_SIGNED + f"{self.run}|{seq}|".encode() + body)
            else:
                tag = self._mac(self._key(self.me, receiver), self.me, receiver, seq, body)
        return _encode(Envelope(sender=self.me, receiver=receiver, seq=seq, body=body, tag=tag))

    def seal_for(self, receivers: list[int], body: bytes) -> bytes:
        """One envelope of `body` from this program to every program of `receivers`
        (two or more, distinct): one sequence number, a tag for each receiver under the
        key of that pair (a checksum without keys), so each receiver checks its own as
        it would a frame to it alone."""
        if len(receivers) < 2 or len(set(receivers)) != len(receivers):
            raise ValueError("a frame to several receivers names two or more, each once")
        self._seq += 1
        seq = self._seq
        tags = [
            tag_of(b"", self.run, self.me, r, seq, body)
            if self.credential is None
            else self._mac(self._key(self.me, r), self.me, r, seq, body)
            for r in receivers
        ]
        return _encode(
            Envelope(sender=self.me, receiver=list(receivers), seq=seq, body=body, tag=tags)
        )

    def open(self, payload: bytes) -> tuple[int, bytes] | str:
        """(sender, body) of an envelope meant for this program and authentic, or the
        reason it is not (also counted in `drops`)."""
        reason = self._open(payload)
        if isinstance(reason, str):
            self.drops[reason] = self.drops.get(reason, 0) + 1
        return reason

    def _open(self, payload: bytes) -> tuple[int, bytes] | str:
        try:
            envelope = _decode(payload)
        except (msgspec.DecodeError, msgspec.ValidationError, TypeError, ValueError):
            return "malformed"
        sender, seq, body = envelope.sender, envelope.seq, envelope.body
        if isinstance(envelope.receiver, int) and isinstance(envelope.tag, bytes):
            receiver, tag = envelope.receiver, envelope.tag
        else:  # a frame to several: this program's tag, read as a frame to it alone
            mine = self._mine(envelope.receiver, envelope.tag)
            if isinstance(mine, str):
                return mine
            receiver, tag = self.me, mine
        if receiver not in (self.me, EVERYONE):
            return "not for this program"
        if not (sender == WORLD or 0 <= sender < self.programs) or sender == self.me:
            return "unknown sender"
        if receiver == EVERYONE and sender != WORLD:
            return "unknown sender"
        if not 0 < seq < 2**62:
            return "malformed"
        if self.credential is None:
            checksum = tag_of(b"", self.run, sender, receiver, seq, body)
            if not hmac.compare_digest(tag, checksum):
                return "malformed"  # corrupted on the way
        elif not self._authentic(sender, receiver, seq, body, tag):
            return "not authentic"
        window = self._windows.setdefault(sender, Window())
        if not window.fresh(seq):
            return "replayed"
        return sender, body

    def _mine(self, receivers: int | list[int], tags: bytes | list[bytes]) -> bytes | str:
        """This program's tag in a frame to several receivers, or why there is none: the
        two lists of one length, two or more programs each named once (a list longer
        than the run has programs is malformed before it is read)."""
        if not isinstance(receivers, list) or not isinstance(tags, list):
            return "malformed"
        if not 2 <= len(receivers) <= self.programs + 1 or len(tags) != len(receivers):
            return "malformed"
        if len(set(receivers)) != len(receivers):
            return "malformed"
        if self.me not in receivers:
            return "not for this program"
        return tags[receivers.index(self.me)]

    def _authentic(self, sender: int, receiver: int, seq: int, body: bytes, tag: bytes) -> bool:
        if receiver == EVERYONE:  # the world's Hello: its Ed25519 signature
            _, ed25519, _, _ = _crypto()
            from cryptography.exceptions import InvalidSignature

            assert self.credential is not None  # only an authenticated run checks envelopes
            world = ed25519.Ed25519PublicKey.from_public_bytes(self.credential.world)
            try:
                world.verify(tag, _SIGNED + f"{self.run}|{seq}|".encode() + body)
            except InvalidSignature:
                return False
            return True
        if self._publics is None:
            return False
        expected = self._mac(self._key(sender, receiver), sender, receiver, seq, body)
        return hmac.compare_digest(tag, expected)
