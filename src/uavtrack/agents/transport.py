"""Transports: how the programs of a swarm reach each other, behind one interface.

* `MemoryTransport`: an in-process bus, for tests and for `uavtrack swarm --transport
  memory`: every program runs in a thread of one process; publishing calls the
  subscribers' handlers at once.
* `ZenohTransport`: Eclipse Zenoh in peer mode, one session per OS process, explicit
  endpoints, multicast scouting off, no router or daemon; optionally TLS (mutual: only
  holders of a certificate of the swarm's CA connect) and a Zenoh configuration file.

Keys live under ``uavtrack/<run id>/`` (`keys`), so two swarms never hear each other.
Each program has a key of its own (``to/<program>``) and reads nothing else but the
world's broadcast Hello: a radio message goes only to the programs that can hear it.

A `Link` is a program's way out (`send` seals a message for one receiver, `security`);
a `Mailbox` its way in: every payload passes the program's `security.Gate`, is decoded
and checked against the run (`messages.Spec`); what fails is dropped and counted by
reason. What is kept is bounded (a window of cycles, rounds up to the run's most), and a
waiting program is woken when what it waits for is complete, not per message.
"""

from __future__ import annotations

import json
import re
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .messages import (
    Hello,
    Lost,
    Message,
    Radio,
    Ready,
    Report,
    Sense,
    Spec,
    Tick,
    decode,
    encode,
)
from .security import EVERYONE, WORLD, Gate, peek_sender
from .stops import STOPS, Stops

ANY_HELLO = "uavtrack/*/hello"
"""Every world's Hello: a program listens to them to tell a world of another run."""
ANY_JOIN = "uavtrack/*/join"
"""Requests for a Hello, whatever the run: a world answers each with its own."""


def keys(run: str) -> dict[str, str]:
    """The key layout of a run: the world's Hello, requests for it, each program's
    inbox (``to`` + number, or ``world``) and liveliness tokens (``alive`` + number)."""
    root = f"uavtrack/{run}/"
    return {
        "root": root,
        "hello": root + "hello",
        "join": root + "join",
        "to": root + "to/",
        "alive": root + "alive/",
    }


def inbox_key(run: str, program: int) -> str:
    """The key a program (or the world, `WORLD`) reads."""
    return f"uavtrack/{run}/to/" + ("world" if program == WORLD else str(program))


class Transport:
    """Publish bytes under a key, subscribe to a key prefix, announce and watch liveness."""

    published = 0
    bytes = 0

    def publish(self, key: str, payload: bytes) -> None:
        raise NotImplementedError

    def subscribe(self, key: str, handler: Callable[[str, bytes], None]) -> None:
        """Call handler(key, payload) for every publication on `key`, or under it when
        `key` ends with a slash."""
        raise NotImplementedError

    def announce(self, key: str) -> None:
        """Declare this program alive under `key` until the transport closes."""

    def watch(self, key: str, on_gone: Callable[[str], None]) -> None:
        """Call on_gone(key) when a token announced as `key` (or under it, when it ends
        with a slash) is gone. Anyone on the network can make and drop a token: treat
        it as a hint, about a program already heard, and confirm with `alive`."""

    def alive(self, key: str) -> set[str]:
        """The keys announced now as `key` (or under it, when it ends with a slash)."""
        return set()

    def close(self) -> None:
        pass


def matches(subscription: str, key: str) -> bool:
    """Whether `key` is `subscription`, or under it when it ends with a slash; a chunk
    ``*`` of the subscription stands for any one chunk of the key (as in Zenoh)."""
    if "*" not in subscription:
        return key == subscription or (subscription.endswith("/") and key.startswith(subscription))
    want, have = subscription.split("/"), key.split("/")
    if subscription.endswith("/"):
        want, have = want[:-1], have[: len(want) - 1]
    return len(want) == len(have) and all(w in ("*", h) for w, h in zip(want, have, strict=True))


def expression(subscription: str) -> str:
    """A subscription as a Zenoh key expression."""
    return subscription + "**" if subscription.endswith("/") else subscription


class Bus:
    """The shared medium of in-process transports."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.subscribers: list[tuple[str, Callable[[str, bytes], None]]] = []
        self.watchers: list[tuple[str, Callable[[str], None]]] = []
        self.alive: list[str] = []  # one entry per token: the same key may be held twice
        self.published = 0
        self.bytes = 0

    def drop(self, key: str) -> None:
        """A token is gone (a program ended or crashed): its watchers are told."""
        with self.lock:
            if key in self.alive:
                self.alive.remove(key)
            watchers = [w for w in self.watchers if matches(w[0], key)]
        for _, on_gone in watchers:
            on_gone(key)


class MemoryTransport(Transport):
    """A program's handle on an in-process `Bus`."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self.announced: list[str] = []
        self.published = 0
        self.bytes = 0

    def publish(self, key: str, payload: bytes) -> None:
        self.published += 1
        self.bytes += len(payload)
        with self.bus.lock:
            self.bus.published += 1
            self.bus.bytes += len(payload)
            handlers = [h for sub, h in self.bus.subscribers if matches(sub, key)]
        for handler in handlers:
            handler(key, payload)

    def subscribe(self, key: str, handler: Callable[[str, bytes], None]) -> None:
        with self.bus.lock:
            self.bus.subscribers.append((key, handler))

    def announce(self, key: str) -> None:
        with self.bus.lock:
            self.bus.alive.append(key)
        self.announced.append(key)

    def watch(self, key: str, on_gone: Callable[[str], None]) -> None:
        with self.bus.lock:
            self.bus.watchers.append((key, on_gone))

    def alive(self, key: str) -> set[str]:
        with self.bus.lock:
            return {k for k in self.bus.alive if matches(key, k)}

    def close(self) -> None:
        for key in self.announced:
            self.bus.drop(key)
        self.announced = []


@dataclass(frozen=True)
class ZenohOptions:
    """How a Zenoh session is set up beyond its endpoints: a Zenoh configuration file
    (JSON5, Zenoh's own format) and TLS files (PEM: the CA that signs every member's
    certificate, this member's certificate and its private key)."""

    config: str | None = None
    tls_ca: str | None = None
    tls_cert: str | None = None
    tls_key: str | None = None

    @property
    def tls(self) -> bool:
        return self.tls_ca is not None

    def check(self, endpoints: list[str]) -> None:
        """ValueError naming what is wrong, before Zenoh starts: TLS files with an endpoint
        they do not secure (it would run in clear text), or TLS files of this host that its
        peers would refuse (`tls.check`)."""
        ca, cert, key = self.tls_ca, self.tls_cert, self.tls_key
        if ca is not None:
            if cert is None or key is None:
                raise ValueError("TLS needs all three of tls_ca, tls_cert and tls_key")
            from . import tls

            tls.refuse_clear(endpoints)
            tls.check(ca, cert, key)


LEASE = 10.0
"""Seconds a Zenoh session lasts without hearing its peer (its lease): a program out of
reach longer loses its session (the world counts it lost), and a world stopped longer
loses its programs' sessions, which they open again when it runs (`stops`)."""
SESSION = {
    "transport/link/tx/lease": int(1000 * LEASE),
    "transport/link/tx/keep_alive": 4,  # keep-alives per lease
    # a client whose session closed opens it again after 1 s, then every 2 s, then 4 s
    "connect/retry": {"period_init_ms": 1000, "period_max_ms": 4000, "period_increase_factor": 2},
}
"""The Zenoh session settings uavtrack's rules rest on, set unless a configuration file
sets them: the lease (`LEASE`), and how a client whose session closed connects again."""


def zenoh_config(
    listen: list[str],
    connect: list[str],
    connect_timeout: float = 5.0,
    options: ZenohOptions | None = None,
    mode: str = "peer",
) -> Any:
    """A Zenoh configuration: the file of `options` if any, then `mode`, no multicast
    scouting and the session's lease and reconnection (`SESSION`) where the file does not
    set them, the endpoints (to listen on: `listen`, none else), and TLS (mutual: every
    member shows a certificate of the CA) when its files are given."""
    import zenoh

    options = options or ZenohOptions()
    conf = zenoh.Config.from_file(options.config) if options.config else zenoh.Config()
    if conf.get_json("mode") == "null":
        conf.insert_json5("mode", json.dumps(mode))
    if conf.get_json("scouting/multicast/enabled") == "null":
        conf.insert_json5("scouting/multicast/enabled", "false")
    if conf.get_json("transport/shared_memory/enabled") == "null":
        conf.insert_json5("transport/shared_memory/enabled", "false")  # no SHM watchdogs
    default = zenoh.Config()
    for key, value in SESSION.items():  # uavtrack's rules rest on these, not on defaults
        if conf.get_json(key) in ("null", default.get_json(key)):  # unless the file sets them
            conf.insert_json5(key, json.dumps(value))
    # the endpoints are uavtrack's, whatever the file says: a program listens on nothing
    # (not Zenoh's default, every interface), the world where --listen says
    conf.insert_json5("listen/endpoints", json.dumps(listen))
    if connect:  # fail, rather than retry for ever, when nothing answers
        conf.insert_json5("connect/endpoints", json.dumps(connect))
        conf.insert_json5("connect/exit_on_failure", "true")
        conf.insert_json5("connect/timeout_ms", json.dumps(int(1000 * connect_timeout)))
    if options.tls:
        tls = "transport/link/tls/"
        conf.insert_json5(tls + "root_ca_certificate", json.dumps(options.tls_ca))
        for role in ("listen", "connect"):
            conf.insert_json5(f"{tls}{role}_certificate", json.dumps(options.tls_cert))
            conf.insert_json5(f"{tls}{role}_private_key", json.dumps(options.tls_key))
        conf.insert_json5(tls + "enable_mtls", "true")
    return conf


def zenoh_reason(exc: BaseException) -> str:
    """Zenoh's error message in words: without source locations, its debug wrappers
    and brackets."""
    text = " ".join(str(exc).split())
    quoted = re.search(r'msg: "([^"]*)"', text)  # a configuration error's message
    if quoted:
        text = quoted.group(1)
    text = re.sub(r" at /\S+", "", text)  # source locations
    text = re.sub(r"\bSingle\(([^)]*)\)", r"\1", text)
    text = re.sub(r"-->.*?\|\s*\d+\s*\|.*?= ", "", text)  # a JSON5 parser's drawing
    text = text.replace("[", "").replace("]", "").rstrip(".")
    return text[:200] or type(exc).__name__


ZENOH_LOG = "error,zenoh::net::routing::hat::client::token=off"
"""Zenoh's log level unless RUST_LOG says otherwise: errors, but not those of a client
hearing a token dropped that it had not heard declared (a program's watch on a token of
the world, declared before the watch), which is harmless and says so at every end."""


class ZenohTransport(Transport):
    """One Zenoh session of one OS process: the world's is a router (it listens, and
    relays between the programs, as the radio medium it emulates), a program's a client
    of it (it listens on nothing)."""

    def __init__(
        self,
        listen: list[str],
        connect: list[str],
        options: ZenohOptions | None = None,
        mode: str = "client",
    ) -> None:
        import zenoh

        zenoh.init_log_from_env_or(ZENOH_LOG)
        self.session = zenoh.open(zenoh_config(listen, connect, options=options, mode=mode))
        self.publishers: dict[str, Any] = {}
        self.keep: list[Any] = []  # subscribers and tokens live as long as the session
        self.published = 0
        self.bytes = 0

    def publish(self, key: str, payload: bytes) -> None:
        publisher = self.publishers.get(key)
        if publisher is None:  # block rather than drop when queues fill: a lost message
            import zenoh  # would cost its receivers a deadline; losses are the fault model's

            publisher = self.publishers[key] = self.session.declare_publisher(
                key,
                congestion_control=zenoh.CongestionControl.BLOCK,
                reliability=zenoh.Reliability.RELIABLE,
            )
        publisher.put(payload)
        self.published += 1
        self.bytes += len(payload)

    def subscribe(self, key: str, handler: Callable[[str, bytes], None]) -> None:
        def listener(sample) -> None:
            handler(str(sample.key_expr), sample.payload.to_bytes())

        self.keep.append(self.session.declare_subscriber(expression(key), listener))

    def announce(self, key: str) -> None:
        self.keep.append(self.session.liveliness().declare_token(key))

    def watch(self, key: str, on_gone: Callable[[str], None]) -> None:
        import zenoh

        def listener(sample) -> None:
            if sample.kind == zenoh.SampleKind.DELETE:
                on_gone(str(sample.key_expr))

        self.keep.append(
            self.session.liveliness().declare_subscriber(expression(key), listener, history=False)
        )

    def alive(self, key: str) -> set[str]:
        replies = self.session.liveliness().get(expression(key), timeout=2.0)
        return {str(reply.ok.key_expr) for reply in replies if reply.ok is not None}

    def close(self) -> None:
        for item in reversed(self.keep):
            try:
                item.undeclare()
            except Exception:  # already gone with its session
                pass
        self.keep = []
        try:
            self.session.close()
        except Exception:
            pass


class Link:
    """A program's way out: messages sealed by its gate, each to one receiver's key."""

    def __init__(self, transport: Transport, gate: Gate) -> None:
        self.transport, self.gate = transport, gate
        self.run = gate.run

    def send(self, receiver: int, message: Message) -> None:
        self.send_body(receiver, encode(message))

    def send_body(self, receiver: int, body: bytes) -> int:
        """An encoded message to `receiver` (a program, or `WORLD`); returns its bytes
        on the wire (the envelope's)."""
        payload = self.gate.seal(receiver, body)
        self.transport.publish(inbox_key(self.run, receiver), payload)
        return len(payload)

    def broadcast(self, receivers: list[int], body: bytes) -> int:
        """An encoded message to several programs as one frame (`Gate.seal_for`),
        published to each receiver's key; returns its bytes on the wire, counted once
        (the radio sends it once)."""
        payload = self.gate.seal_for(receivers, body)
        for receiver in receivers:
            self.transport.publish(inbox_key(self.run, receiver), payload)
        return len(payload)

    def hello(self, message: Hello) -> None:
        self.transport.publish(keys(self.run)["hello"], self.gate.seal(EVERYONE, encode(message)))


EARLY = 4
"""Payloads a program keeps per sender that arrive before it knows the run (from the
Hello): the latest; older ones are superseded (presence messages, sent again and again)."""
EARLY_SENDERS = 1024
"""Senders named by early payloads a program keeps at most."""
EARLY_BYTES = 64 * 1024
"""Bytes of early payloads a program keeps per sender named: an early message of the
protocol is a presence (a few bytes per program), so a larger one is not one of the run's."""
EARLY_TOTAL = 4 * 1024 * 1024
"""Bytes of early payloads a program keeps in all: unverified until the Hello, they may
all be a stranger's, who names any sender it likes."""
CONFIRM_EVERY = 0.5
"""Seconds between two checks of the tokens said gone: a stranger who makes and drops
tokens as fast as it can costs a program one liveliness query per half second."""
MEANWHILE = 1.0
"""Seconds between two calls of a wait's `meanwhile` (the world asking again, `world`)."""
REJOIN = LEASE
"""Seconds after this process ran again from a stop (`stops`) during which a token
confirmed gone is not believed yet: the sessions its peers closed while it was stopped
open again within a few seconds (`SESSION`), their tokens with them."""


class Mailbox:
    """What a program received, opened, checked and sorted, with waits that have
    deadlines.

    Radio parts are kept by (cycle, protocol, sender) -> {round: arrays}, with the round
    from which a sender's content is final; other messages by kind. `now` is the
    program's current cycle: radio messages of cycles outside `spec`'s window around it
    are dropped, as are those of forgotten cycles. Every drop is counted in `drops`, by
    reason. `received` counts the payloads delivered here.

    Liveliness is a hint, never a belief: anyone who reaches the network can make and
    drop a token in any name. A token that goes counts only for a program `heard` (an
    authentic message of it was opened here: it had made its own token before it said a
    word, and no one else can drop that token); it is a suspect until `transport`
    confirms it gone (asked twice), at most once per `CONFIRM_EVERY` seconds; then it is
    in `gone`. An authentic message of a program said gone takes it back: gone is "heard
    from, then its own token gone", never "a token went". Within `REJOIN` seconds of this
    process running again from a stop (`stops`), a token confirmed gone stays a suspect:
    its session may have closed because this process was silent, and opens again.
    """

    def __init__(
        self,
        gate: Gate,
        spec: Spec | None = None,
        transport: Transport | None = None,
        stops: Stops = STOPS,
    ) -> None:
        self.gate, self.spec, self.transport, self.stops = gate, spec, transport, stops
        self.run, self.me = gate.run, gate.me
        self.hello_key = keys(gate.run)["hello"]
        self.cond = threading.Condition()
        self.radio: dict[tuple[int, str, int], dict[int, Any]] = {}
        self.final: dict[tuple[int, str, int], int] = {}
        self.inbox: dict[tuple, Any] = {}
        self.drops: dict[str, int] = {}
        self.received = 0
        self.now = -1
        self.oldest = -(2**62)  # radio messages of earlier cycles are no longer needed
        self.heard: set[int] = set()
        self.gone: set[int] = set()
        self.suspects: set[int] = set()
        self.joins = 0
        self._early: dict[int, deque[bytes]] = {}
        self._early_bytes = 0
        self._confirmed = -float("inf")
        self._need: Callable[[], bool] | None = None

    @property
    def world_gone(self) -> bool:
        """Whether the world program is gone (heard, then its token confirmed gone)."""
        return WORLD in self.gone

    def is_gone(self, program: int) -> bool:
        """Whether program `program` is gone (heard, then its token confirmed gone)."""
        return program in self.gone

    @property
    def early_bytes(self) -> int:
        """Bytes of the payloads kept until the Hello."""
        return self._early_bytes

    @property
    def dropped(self) -> int:
        """Every payload dropped, whatever the reason (the gate's included)."""
        return sum(self.drops.values()) + sum(self.gate.drops.values())

    def reasons(self) -> dict[str, int]:
        """Drops by reason, the gate's and the checks'."""
        out = dict(self.gate.drops)
        for reason, count in self.drops.items():
            out[reason] = out.get(reason, 0) + count
        return out

    def _drop(self, reason: str) -> None:
        self.drops[reason] = self.drops.get(reason, 0) + 1

    def handler(self, key: str, payload: bytes) -> None:
        with self.cond:
            self.received += 1
            if self.spec is None and key != self.hello_key:
                self._keep_early(payload)
                return
            self._take(payload)
            if self._need is None or self._need():
                self.cond.notify_all()

    def _keep_early(self, payload: bytes) -> None:
        """Keep a payload that came before the Hello (it cannot be opened yet), within
        `EARLY` payloads and `EARLY_BYTES` per sender it names, `EARLY_SENDERS` senders
        and `EARLY_TOTAL` bytes: a sender's oldest go first; what does not fit is dropped
        by reason (a presence dropped here is said again after the Hello)."""
        sender = peek_sender(payload) if len(payload) <= EARLY_BYTES else None
        if len(payload) > EARLY_BYTES:  # not even decoded
            reason = "too large before the run's keys"
        elif sender is None:
            reason = "malformed"
        elif self._early_bytes + len(payload) > EARLY_TOTAL:
            reason = "over the buffer before the run's keys"
        elif sender not in self._early and len(self._early) >= EARLY_SENDERS:
            reason = "before the run's keys"
        else:
            queue = self._early.setdefault(sender, deque())
            queue.append(payload)
            self._early_bytes += len(payload)
            while len(queue) > EARLY or sum(map(len, queue)) > EARLY_BYTES:
                self._early_bytes -= len(queue.popleft())  # superseded by the newer
            return
        self._drop(reason)

    def joined(self, key: str, payload: bytes) -> None:
        """A program asks for the Hello (the world's side; the request is not read)."""
        with self.cond:
            self.joins += 1

    def learn(self, spec: Spec, publics: list[bytes]) -> None:
        """The run's spec and keys (from the Hello): open what came early."""
        with self.cond:
            self.gate.learn(publics)
            self.spec = spec
            early, self._early, self._early_bytes = self._early, {}, 0
            for payload in (p for queue in early.values() for p in queue):
                self._take(payload)
            self.cond.notify_all()

    def _take(self, payload: bytes) -> None:
        opened = self.gate.open(payload)
        if isinstance(opened, str):
            return
        sender, body = opened
        self.heard.add(sender)  # an authentic word: the sender is a member, and not gone
        self.gone.discard(sender)
        message = decode(body, self.run)
        if message is None:
            self._drop("malformed")
            return
        reason = self._store(sender, message)
        if reason is not None:
            self._drop(reason)

    def _store(self, sender: int, message: Message) -> str | None:
        """Keep `message` from `sender`, or say why not."""
        spec = self.spec
        if isinstance(message, Hello):
            if sender != WORLD:
                return "not from its sender"
            self.inbox[("hello",)] = message
            return None
        if spec is None:
            return "before the run's keys"
        if isinstance(message, Radio):
            if message.sender != sender:
                return "not from its sender"
            if self.me == WORLD and message.k == -1:  # a presence: the world needs only to
                return None  # have heard it (`heard`), whenever it comes
            if message.k < self.oldest:
                return "outside the window of cycles"
            parts = spec.radio(message, max(self.now, 0))
            if isinstance(parts, str):
                return parts
            for protocol, round_, final, content in parts:  # what is kept is not replaced
                slot = (message.k, protocol, sender)  # (but a presence, said again and again)
                rounds = self.radio.setdefault(slot, {})
                if round_ in rounds and protocol != "presence" or slot in self.final:
                    return "duplicate"
                if content is not None:
                    rounds[round_] = content
                if final >= 0:
                    self.final[slot] = final
            return None
        if isinstance(message, Sense | Tick):
            if sender != WORLD:
                return "not from its sender"
            if not self.now <= message.k <= self.now + spec.ahead + 1:
                return "outside the window of cycles"
            arrays = (
                spec.sense(message, self.me) if isinstance(message, Sense) else spec.tick(message)
            )
            if isinstance(arrays, str):
                return arrays
            kind = "sense" if isinstance(message, Sense) else "tick"
            if (kind, message.k) not in self.inbox:  # else the world asks again: one will do
                self.inbox[(kind, message.k)] = (message, arrays)
            return None
        if isinstance(message, Lost):
            if sender != WORLD or message.program != self.me:
                return "not from its sender"
            self.inbox[("lost",)] = message
            return None
        if isinstance(message, Ready):
            if message.program != sender or self.me != WORLD:
                return "not from its sender"
            self.inbox[("ready", sender)] = message
            return None
        if isinstance(message, Report):
            if message.uav != sender or self.me != WORLD:
                return "not from its sender"
            if message.k != self.now:
                return "outside the window of cycles"
            arrays = spec.report(message)
            if isinstance(arrays, str):
                return arrays
            if ("report", message.k, sender) in self.inbox:
                return "duplicate"
            self.inbox[("report", message.k, sender)] = (message, arrays)
            return None
        return "not from its sender"

    def lost(self, key: str) -> None:
        """A liveliness token went away: a hint, about a program heard only (see the
        class docstring), confirmed before use."""
        tail = key.rsplit("/", 1)[-1]
        program = WORLD if tail == "world" else int(tail) if tail.isdigit() else None
        with self.cond:
            if program is not None and program in self.heard:
                self.suspects.add(program)
                self.cond.notify_all()

    def content(self, k: int, protocol: str, sender: int, round_: int):
        """The content of a sender's round (or its final content), or None if not here."""
        slot = (k, protocol, sender)
        rounds = self.radio.get(slot)
        if rounds is None:
            return None
        if round_ in rounds:
            return rounds[round_]
        final = self.final.get(slot)
        if final is not None and round_ >= final:
            return rounds.get(final)
        return None

    def wait(
        self,
        ready: Callable[[], bool],
        deadline: float,
        meanwhile: Callable[[], None] | None = None,
    ) -> bool:
        """Wait until ready() holds (checked under the lock) or the deadline passes; the
        program is woken when ready() holds, when a token goes (confirmed with the
        transport, at most once per `CONFIRM_EVERY` s, before `gone` takes it), or every
        half second. Tokens that go, however many, never keep a wait past its deadline.
        `meanwhile`, if given, is called every `MEANWHILE` seconds (without the lock).

        Time this process spent stopped (SIGSTOP, a suspended machine) does not count
        against the deadline: when a half-second wait took much longer, the deadline
        moves by as much, so a program that was stopped does not blame the others."""
        with self.cond:
            self._need = ready
            called = time.monotonic()
            try:
                while not ready():
                    now = time.monotonic()
                    if meanwhile is not None and now >= called + MEANWHILE:
                        self.cond.release()
                        try:
                            meanwhile()
                        finally:
                            self.cond.acquire()
                        called = time.monotonic()
                        continue
                    due = self._confirmed + CONFIRM_EVERY
                    if self.suspects and now >= due:
                        self._confirm()
                        continue
                    left = deadline - now
                    if left <= 0:
                        return False
                    slice_ = min(left, 0.5)
                    if self.suspects:
                        slice_ = min(slice_, due - now)
                    if meanwhile is not None:
                        slice_ = max(0.0, min(slice_, called + MEANWHILE - now))
                    before = time.monotonic()
                    self.cond.wait(slice_)
                    stopped = time.monotonic() - before - slice_
                    if stopped > 1.0:
                        deadline += stopped
                return True
            finally:
                self._need = None

    def _token(self, program: int) -> str:
        return keys(self.run)["alive"] + ("world" if program == WORLD else str(program))

    def _confirm(self) -> None:
        """Move the suspects whose tokens are really gone to `gone`; called with the lock
        held, which it releases while it asks the transport."""
        suspects, self.suspects = set(self.suspects), set()
        if self.transport is None:
            gone = suspects
        else:
            self.cond.release()
            try:  # asked twice: one query may go unanswered on a loaded machine
                gone = {p for p in suspects if not self.transport.alive(self._token(p))}
                if gone:
                    time.sleep(0.2)
                    gone = {p for p in gone if not self.transport.alive(self._token(p))}
            finally:
                self.cond.acquire()
        now = time.monotonic()
        if gone and self.stops.since(now - REJOIN):  # its session may be opening again
            self.suspects |= gone
            gone = set()
        self.gone |= gone
        self._confirmed = now

    def take(self, identity: tuple):
        with self.cond:
            return self.inbox.pop(identity, None)

    def begin(self, k: int, keep_from: int) -> None:
        """Cycle k begins: radio messages of cycles before `keep_from` are forgotten
        (and dropped should they still come)."""
        with self.cond:
            self.now = k
            self.oldest = keep_from
            for slot in [s for s in self.radio if s[0] < keep_from]:
                self.radio.pop(slot, None)
                self.final.pop(slot, None)
            for identity in [i for i in self.inbox if i[0] in ("sense", "tick") and i[1] < k]:
                self.inbox.pop(identity, None)
