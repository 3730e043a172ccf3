"""The messages of the agent form: small typed records with a schema version, and what
each may hold in a run.

Every message is a msgspec ``Struct`` encoded as MessagePack, tagged with its kind, the
schema `VERSION` and the run it belongs to; arrays travel as (dtype, shape, bytes). On
the wire each travels in a `security.Envelope` that names its sender and receiver.

World -> everyone: `Hello` (the run's scenario, method, fault key, priors and the
programs' public keys; signed by the world). World -> one program: `Sense` (a UAV's
measurements, believed pose and radio links of one cycle), `Tick` (the central node's
cycle). Program -> world: `Ready`, then a `Report` per cycle (the action and what the
trace records). Program -> program: `Radio`, one per receiver and round, bundling the
parts of the protocols that run in that round (the D_i flooding with the consensus,
beacons with bids, uploads, downloads).

`decode` returns None for anything malformed, of another version or of another run;
`Spec.check` says why a well-formed message cannot belong to the run (a sender out of
range, an array of the wrong shape or type, a value that is not finite, an action or a
target that does not exist, a cycle outside the window). The receiver drops such a
message and counts it by that reason: nothing a peer sends stops a program.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import msgspec
import numpy as np

VERSION = 4
"""Schema version; a message of another version is dropped."""


class Array(msgspec.Struct, array_like=True, frozen=True):
    """A numpy array on the wire."""

    dtype: str
    shape: tuple[int, ...]
    data: bytes

    @classmethod
    def of(cls, value: Any) -> Array:
        value = np.asarray(value)  # (ascontiguousarray would make a 0-d array 1-d)
        return cls(value.dtype.str, value.shape, value.tobytes(order="C"))

    def array(self) -> np.ndarray:
        dtype = np.dtype(self.dtype)
        if dtype.kind not in "biuf" or any(n < 0 for n in self.shape):
            raise ValueError("array of another kind")
        if dtype.itemsize * int(np.prod(self.shape)) != len(self.data):
            raise ValueError("array does not match its shape")
        return np.frombuffer(self.data, dtype=dtype).reshape(self.shape)


class Hello(msgspec.Struct, tag="hello", frozen=True):
    """The run: its scenario (JSON), method, the trial's fault key, every UAV's prior
    (mean (Nt, 4) and covariance (4, 4)), the deadline of a round [s], whether its
    messages are authenticated and the programs' X25519 public keys (the world's last),
    the step the run is at (-1: not started; programs join only before), and the members:
    the programs whose authentic Ready the world has (and has not lost since), whose
    numbers no other program may take."""

    version: int
    run: str
    scenario: str
    method: str
    key: Array
    prior_mean: Array
    prior_cov: Array
    deadline: float
    authenticated: bool
    publics: list[bytes]
    step: int = -1
    members: list[int] = []


class Sense(msgspec.Struct, tag="sense", frozen=True):
    """One cycle for one UAV: its believed state (5,), which targets it observes (Nt,)
    and their range-bearing measurements (K, 2), who it can hear this cycle (N,) bool,
    who is alive (N,) bool, and whether the central node is (centralized method).
    alive[uav] False tells the agent it has failed."""

    version: int
    run: str
    k: int
    uav: int
    believed: Array
    observed: Array
    z: Array
    links: Array
    alive: Array
    central: bool = True


class Tick(msgspec.Struct, tag="tick", frozen=True):
    """One cycle for the central node: who is alive (N,)."""

    version: int
    run: str
    k: int
    alive: Array


class Ready(msgspec.Struct, tag="ready", frozen=True):
    """A program has heard every other and is ready for the first cycle."""

    version: int
    run: str
    program: int


class Report(msgspec.Struct, tag="report", frozen=True):
    """A UAV's decision of one cycle and what the trace records of it (the central
    node's report has empty arrays, action and target -1)."""

    version: int
    run: str
    k: int
    uav: int
    action: int
    target: int
    mean: Array
    cov: Array
    bids: Array
    rounds: int
    sent: int
    delivered: int
    decision_ms: float  # CPU time of planning and assignment (`timing`)
    decision_wall_ms: float  # the same in wall time
    published: int = 0
    bytes: int = 0
    received: int = 0
    drops: dict[str, int] = {}


class Part(msgspec.Struct, array_like=True, frozen=True):
    """One protocol's share of a radio message: its round, the round from which the
    sender's content is final (-1: not final; a final part may carry no content when
    the content of that round was sent before) and the content."""

    protocol: str
    round: int
    final: int
    content: dict[str, Array] | None


class Radio(msgspec.Struct, tag="radio", frozen=True):
    """What a program sends one receiver in one round of cycle k: a part per protocol."""

    version: int
    run: str
    k: int
    sender: int
    parts: list[Part]


Message = Hello | Sense | Tick | Ready | Report | Radio
_encoder = msgspec.msgpack.Encoder()
_decoder = msgspec.msgpack.Decoder(Message)


def encode(message: Message) -> bytes:
    return _encoder.encode(message)


def decode(payload: bytes, run: str) -> Message | None:
    """The message, or None when it is malformed, of another version or of another run."""
    try:
        message = _decoder.decode(payload)
    except (msgspec.DecodeError, msgspec.ValidationError, ValueError, TypeError):
        return None
    if message.version != VERSION or message.run != run:
        return None
    return message


def packed(content: dict[str, Any]) -> dict[str, Array]:
    return {name: Array.of(value) for name, value in content.items()}


# ---------------------------------------------------------------- what a run admits

F, I, B = "<f8", "<i8", "|b1"
FINITE, SCORE, BID = "finite", "score", "bid"
"""Values: finite; finite or -inf (a confidence with nothing behind it); finite or NaN
(a bid not scored, `planner.prune`)."""


@dataclass(frozen=True)
class Spec:
    """What the messages of one run may hold: n UAVs, m targets, `programs` programs
    (the central node is number n), `actions` bank angles, rounds up to `rounds`, and
    the window of cycles a receiver keeps (`behind` before the current one, `ahead`
    after it)."""

    n: int
    m: int
    programs: int
    actions: int
    rounds: int
    behind: int
    ahead: int = 2

    @classmethod
    def of(cls, scenario, central: bool) -> Spec:
        n = scenario.n_uavs
        budget = scenario.faults.round_budget or 0
        return cls(
            n=n,
            m=scenario.n_targets,
            programs=n + int(central),
            actions=3,
            rounds=n + scenario.robust.extra_rounds + budget + 3,
            behind=scenario.faults.delay + 1,
        )

    def contents(self, protocol: str) -> dict[str, tuple[str, tuple[int, ...], str]] | None:
        """The arrays of a protocol's content: name -> (dtype, shape, values)."""
        n, m = self.n, self.m
        tuples = {
            "gamma": (F, (m,), SCORE),
            "mean": (F, (m, 4), FINITE),
            "cov": (F, (m, 4, 4), FINITE),
            "stamp": (I, (m,), FINITE),
        }
        return {
            "presence": {"heard": (B, (self.programs,), FINITE)},
            "flood": {"known": (B, (n,), FINITE)},
            "consensus": {**tuples, "origin": (I, (m,), FINITE)},
            "beacon": {"position": (F, (3,), FINITE)},
            "bids": {"bids": (F, (m,), BID), "stamp": (I, (), FINITE)},
            "upload": {**tuples, "uav": (F, (5,), FINITE)},
            "download": {**tuples, "target": (I, (), FINITE)},
        }.get(protocol)

    def arrays(self, content: dict[str, Array], kinds: dict) -> dict[str, np.ndarray] | str:
        """The arrays of `content` if they are exactly `kinds`, else the reason not."""
        if content.keys() != kinds.keys():
            return "unexpected fields"
        out = {}
        for name, (dtype, shape, values) in kinds.items():
            wire = content[name]
            if wire.dtype != dtype or tuple(wire.shape) != shape:
                return "wrong shape or type"
            try:
                value = wire.array()
            except ValueError:
                return "wrong shape or type"
            if dtype == F and not _admits(value, values):
                return "not finite"
            out[name] = value
        return out

    def radio(self, message: Radio, k: int) -> list[tuple[str, int, int, Any]] | str:
        """A radio message's parts as (protocol, round, final, arrays or None) if the
        run admits it at current cycle k, else the reason not."""
        if not (k - self.behind <= message.k <= k + self.ahead or message.k == -1):
            return "outside the window of cycles"
        if not 0 <= message.sender < self.programs or len(message.parts) > 4:
            return "unexpected fields"
        out = []
        for part in message.parts:
            kinds = self.contents(part.protocol)
            if kinds is None or (part.protocol == "presence") != (message.k == -1):
                return "unknown protocol"
            if not (0 <= part.round <= self.rounds and -1 <= part.final <= part.round):
                return "round out of range"
            content = None
            if part.content is not None:
                content = self.arrays(part.content, kinds)
                if isinstance(content, str):
                    return content
            elif part.final < 0:
                return "unexpected fields"
            out.append((part.protocol, part.round, part.final, content))
        return out

    def sense(self, message: Sense, me: int) -> dict[str, np.ndarray] | str:
        """A Sense message's arrays if it is this UAV's and well formed, else the reason."""
        if message.uav != me:
            return "not for this program"
        try:
            K = int(np.count_nonzero(message.observed.array()))
        except ValueError:
            return "wrong shape or type"
        n, m = self.n, self.m
        kinds = {
            "believed": (F, (5,), FINITE),
            "observed": (B, (m,), FINITE),
            "z": (F, (K, 2), FINITE),
            "links": (B, (n,), FINITE),
            "alive": (B, (n,), FINITE),
        }
        wire = {name: getattr(message, name) for name in kinds}
        return self.arrays(wire, kinds)

    def tick(self, message: Tick) -> dict[str, np.ndarray] | str:
        return self.arrays({"alive": message.alive}, {"alive": (B, (self.n,), FINITE)})

    def report(self, message: Report) -> dict[str, np.ndarray] | str:
        """A Report's arrays if the run admits it, else the reason not."""
        counts = (message.rounds, message.sent, message.delivered, message.published)
        if min(counts + (message.bytes, message.received)) < 0 or message.rounds > self.rounds:
            return "count out of range"
        times = (message.decision_ms, message.decision_wall_ms)
        if not all(np.isfinite(t) and t >= 0 for t in times):
            return "not finite"
        if message.uav == self.n:  # the central node decides nothing of its own
            if (message.action, message.target) != (-1, -1):
                return "action or target out of range"
            return {}
        if not 0 <= message.action < self.actions or not 0 <= message.target < self.m:
            return "action or target out of range"
        m = self.m
        kinds = {
            "mean": (F, (m, 4), FINITE),
            "cov": (F, (m, 4, 4), FINITE),
            "bids": (F, (m,), BID),
        }
        return self.arrays({name: getattr(message, name) for name in kinds}, kinds)


def _admits(value: np.ndarray, values: str) -> bool:
    if values == FINITE:
        return bool(np.isfinite(value).all())
    if values == SCORE:
        return bool((np.isfinite(value) | (value == -np.inf)).all())
    return not bool(np.isinf(value).any())  # BID: finite or NaN
