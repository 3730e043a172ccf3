"""The messages of the agent form: small typed records with a schema version, and what
each may hold in a run.

Every message is a msgspec ``Struct`` encoded as MessagePack, tagged with its kind, the
schema `VERSION` and the run it belongs to; arrays travel as (dtype, shape, bytes). On
the wire each travels in a `security.Envelope` that names its sender and receiver.

World -> everyone: `Hello` (the run's scenario, method, fault key, priors and the
programs' public keys; signed by the world). World -> one program: `Sense` (a UAV's
measurements, believed pose and radio links of one cycle), `Tick` (the central node's
cycle), `Lost` (the world no longer counts this program, and why). Program -> world:
`Ready`, then a `Report` per cycle (the action, what the trace records, and the radio
messages of the cycle that missed it). Program -> program: `Radio`, one per receiver and
round, bundling the parts of the protocols that run in that round (the D_i flooding with
the consensus, beacons with bids, uploads, downloads).

`decode` returns None for anything malformed, of another version or of another run;
`Spec` is the one rule of what a message of the run may hold, field by field
(`DOMAINS`): `Spec.radio`, `sense`, `tick` and `report` say why a well-formed message
cannot belong to the run (a sender out of range, an array of the wrong shape or type, a
value that is not finite, a covariance that is not positive definite, a confidence that
is not 1 / trace of it, a bid beyond the Fisher bound, an action or a target that does
not exist, a cycle outside the window), and `Spec.estimates` which estimates of an
admitted message lie beyond the run's plausibility bounds (`plausibility.Bounds`). The
receiver drops such a message, or does not use such an estimate, and counts it by that
reason: nothing a peer sends stops a program.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import msgspec
import numpy as np

from .. import estimation
from ..faults import PROTOCOLS
from ..methods.base import wire_of
from ..numerics.codec import SCALE, decoded_cov, mirrored
from ..radio import ROWS, WIRE_VERSION, described, packed_layout, packs, unpack_rows
from ..robust.plausibility import CONSISTENT, Bounds

VERSION = WIRE_VERSION
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


class Hello(msgspec.Struct, tag="hello", frozen=True, kw_only=True):
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


class Sense(msgspec.Struct, tag="sense", frozen=True, kw_only=True):
    """One cycle for one UAV: its believed state (5,), which targets it observes (Nt,)
    and their range-bearing measurements (K, 2), who it can hear this cycle (N,) bool,
    who is alive (N,) bool, and whether the central node is (centralized method).
    alive[uav] False tells the agent it has failed. With unknown association
    (``tracker.association`` gnn or jpda) the scan comes unlabelled: observed is empty
    (0,) and z (Z, 2) holds the detections and clutter in the order the sensor gave them.
    With ``radio.bandwidth_bps`` the world, which emulates the radio, says what every
    UAV's share affords this cycle, afford (N, 3): its first-priority frame (0 or 1), its
    rounds of flooding and consensus, and whether the central node's download reaches it
    (0 or 1) (`radio.Budget`): a program sends only what its share affords, and waits only
    for what its senders' do."""

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
    afford: Array | None = None  # with radio.bandwidth_bps: (N, 3), `radio.Budget`


class Tick(msgspec.Struct, tag="tick", frozen=True, kw_only=True):
    """One cycle for the central node: who is alive (N,), and with a limited radio what
    every share affords (as in `Sense`)."""

    version: int
    run: str
    k: int
    alive: Array
    afford: Array | None = None  # with radio.bandwidth_bps: (N, 3), `radio.Budget`


class Ready(msgspec.Struct, tag="ready", frozen=True):
    """A program has heard every other and is ready for the first cycle."""

    version: int
    run: str
    program: int


class Report(msgspec.Struct, tag="report", frozen=True, kw_only=True):
    """A UAV's decision of one cycle and what the trace records of it (the central
    node's report has empty arrays, action and target -1). With unknown association the
    estimates and bids are the K track slots', label and status (K,) say whose, and the
    target is the team label followed (-1: none)."""

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
    late: dict[str, int] = {}  # messages of this cycle that missed it, by protocol
    radio_bytes: int = 0  # the frames it sent to other programs this cycle, on the wire
    label: Array | None = None  # with unknown association: each slot's team label
    status: Array | None = None  # and its status (0 empty, 1 tentative, 2 confirmed)
    existence: Array | None = None  # and its probability of existence (0: empty)


class Lost(msgspec.Struct, tag="lost", frozen=True, kw_only=True):
    """The world no longer counts this program, from step k, and why (one line): it
    missed the cycle's deadline, or its session ended. Not a failure of the fault model."""

    version: int
    run: str
    k: int
    program: int
    reason: str


class Part(msgspec.Struct, array_like=True, frozen=True):
    """One protocol's share of a radio message: its round, the round from which the
    sender's content is final (-1: not final; a final part may carry no content when
    the content of that round was sent before) and the content."""

    protocol: str
    round: int
    final: int
    content: dict[str, Array] | None


class Radio(msgspec.Struct, tag="radio", frozen=True, kw_only=True):
    """What a program sends one receiver in one round of cycle k: a part per protocol."""

    version: int
    run: str
    k: int
    sender: int
    parts: list[Part]


Message = Hello | Sense | Tick | Ready | Report | Radio | Lost
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


def unpacked(content: dict[str, Array], kinds: dict, most: int) -> dict[str, Array] | str:
    """A packed content (`radio.packs`) as its fields (`kinds`), each an array of its
    own, or why it cannot be: the byte array `radio.ROWS` of (rows, a record's bytes),
    at most `most` rows, beside the fields that travel as they are."""
    layout = packed_layout(kinds)
    if content.keys() != layout.keys():
        return "unexpected fields"
    wire = content[ROWS]
    width = layout[ROWS][1][1]
    if wire.dtype != "|u1" or len(wire.shape) != 2 or wire.shape[1] != width:
        return "wrong shape or type"
    if not 0 <= wire.shape[0] <= most:
        return "wrong shape or type"
    try:
        rows = unpack_rows(wire.array(), kinds)
    except ValueError:
        return "wrong shape or type"
    return {name: Array.of(rows[name]) if name in rows else content[name] for name in kinds}


# ---------------------------------------------------------------- what a run admits

F, I, B = "<f8", "<i8", "|b1"

DOMAINS = {
    "flags": "any booleans",
    "known": "booleans, the sender's own entry set",
    "finite": "finite",
    "position": "x and y within the field plus the run's margin, altitude in (0, 20000] m",
    "uav state": "x, y and altitude as a position, speed in (0, the UAVs' largest], "
    "heading in [-2 pi, 2 pi]",
    "confidence": "1 / trace of the target's cov (eq. 22), to 1e-9 relative",
    "confidence or none": "as confidence, or -inf: no estimate (the target's mean, cov and "
    "stamp are then not read; they must be finite)",
    "estimate": "finite; one whose x or y is outside the field plus the run's margin, or "
    "whose speed is above the run's largest, is not used (`Spec.estimates`)",
    "covariance": "symmetric positive definite, eigenvalues at most the run's cap; one whose "
    "smallest eigenvalue is below the run's floor (the sensor's best accuracy) is not used",
    "stamp": "a cycle in [k - (rounds + 1) behind, k], k the message's cycle",
    "cycle": "the message's cycle k",
    "uav index": "a UAV, 0 to N - 1",
    "recent commands": "the last two actions, 3 p2 + p1, 0 to 8 (airspace.response)",
    "target or none": "a target, 0 to M - 1, or -1: none",
    "bids": "each in [0, the run's largest bid], or NaN (not scored) where the run prunes "
    "bids (planner.prune without losses or delays), at least one scored",
    "track status": "0 empty, 1 tentative or 2 confirmed; the slot's label is -1 exactly "
    "where it is empty, and the labels of a sender's slots are distinct",
    "track estimate": "finite; a confirmed track outside the field plus the run's margin or "
    "faster than its largest is not used (`Spec.tracks`)",
    "track covariance": "as covariance, for the slots with a track (an empty slot's must be "
    "finite); a confirmed track's below the run's floor is not used",
    "track stamp": "for the slots with a track, a cycle in [0, k]",
    "tombstones": "rows (label, cycle): label -1 (none) or a team label with a cycle in [0, k], "
    "each label once, none naming a track the sender holds with an older stamp",
    "slot bids": "for a confirmed slot, in [0, the run's largest bid]; NaN elsewhere",
    "bid labels": "the label of each confirmed slot a bid is for, -1 for none, each once",
    "label or none": "a team label (below the run's largest), or -1: none",
    "measurement covariance": "as covariance, of a measurement (2 x 2)",
    "ground positions": "x and y within the field plus the run's margin",
    "counts": "a count in [0, the run's largest label]",
    "existence": "a track's existence probability, in [0, 1]",
    "targets": "the targets a consensus message lists, each once, 0 to M - 1 (up to M of "
    "them); the other fields' rows are theirs",
    "covariance triangle": "each row the upper triangle (row by row) of a covariance, "
    "which must be as covariance once mirrored",
    "log variances": "each row a covariance's four variances, 2^(code / 256) each "
    "(`numerics.codec.QUANTIZED`); with the row's correlations, as covariance once decoded",
    "correlations": "each row a covariance's six correlations above the diagonal, row by "
    "row, code / 127 each, every code in [-127, 127]; with the row's log variances, as "
    "covariance once decoded",
    "slots": "the track slots a listed consensus carries, each once, 0 to K - 1 (up to K "
    "of them); the other fields' rows are theirs, each a confirmed track",
    "team label": "a team label (below the run's largest), each once",
    "afford": "per UAV: its first-priority frame (0 or 1), its rounds (0 or more), whether "
    "the central node's download reaches it (0 or 1)",
}
"""What the values of a field may be, beyond its dtype and shape (`Spec.contents`); the
run's numbers are `plausibility.Bounds`."""


@dataclass(frozen=True, kw_only=True)
class Spec:
    """What the messages of one run may hold: n UAVs, m targets, `programs` programs
    (the central node is number n), `actions` bank angles, rounds up to `rounds`, the
    window of cycles a receiver keeps (`behind` before the current one, `ahead` after
    it), and the limits of an honest claim (`plausibility.Bounds`; None: shapes, types
    and the scenario-free rules only).

    It is the one rule between what arrives and what uses it: a receiver (`agent`, the
    world) reads only what `radio`, `sense`, `tick` and `report` return, and every
    receiver handles all of it (a test sends every kind with every field at every bad
    value; another draws admitted contents and runs the receivers on them). NaN bids,
    admitted where the run prunes, can leave a neighbour unable to serve an auction:
    `assignment.able` says which, and the receiver drops it from that auction.
    """

    n: int
    m: int
    programs: int
    actions: int
    rounds: int
    behind: int
    ahead: int = 2
    bounds: Bounds | None = None
    slots: int = 0
    """Track slots K per UAV with unknown association (0: known association)."""
    scan: int = 0
    """The most measurements a scan may hold with unknown association."""
    labels: int = 0
    """With unknown association, the labels of the run are below this: a UAV starts at
    most K tracks a scan, each under a label of its own (`tracks.manage`)."""
    avoid: bool = False
    """With ``planner.avoidance`` or a method that does not plan (a learned policy): the
    beacon carries the sender's whole state (x, y, altitude, speed, heading), which the
    avoidance filter and the policy's observation read."""
    recent: bool = False
    """With ``planner.avoidance_model = "measured"``: the beacon carries the sender's
    recent commands (`airspace.response.recent`)."""
    tuples: str = "full"
    """How the consensus carries its tuples (`radio.layout`): "full", "listed"
    (``fusion.trigger``: the targets it lists), "compact" or "quantized"
    (``radio.encoding``)."""
    limited: bool = False
    """With ``radio.bandwidth_bps``: Sense and Tick carry what the shares afford."""
    book: tuple[str, ...] = ()
    """The track book's fields beyond M-of-N's a download carries (`manage.sent_fields`)."""
    plans: bool = True
    """Whether the run's method plans (`Method.plans`); a learned policy's UAVs follow
    no target (their reports name -1)."""

    @classmethod
    def of(cls, scenario, central: bool, plans: bool = True) -> Spec:
        """The run's spec: `scenario`, with a central node or not, a method that plans
        or not (`Method.plans`: without, the beacon carries the whole state)."""
        wire = wire_of(scenario, plans)
        n, budget = wire.n, scenario.faults.round_budget or 0
        tracked = wire.slots > 0
        return cls(
            n=n,
            m=wire.m,
            programs=n + int(central),
            actions=3 if scenario.uav.min_speed is None else 6,
            rounds=n + scenario.robust.extra_rounds + budget + 3,
            behind=scenario.faults.delay + 1,
            bounds=Bounds.of(scenario),
            slots=wire.slots,
            labels=scenario.labels,
            # a Poisson count of clutter beyond 10 times its mean and 50 has a
            # probability below 1e-20 at any rate
            scan=scenario.n_targets + 50 + 10 * math.ceil(scenario.sensor.clutter_rate)
            if tracked
            else 0,
            avoid=wire.avoid,
            recent=wire.recent,
            tuples=wire.tuples,
            limited=scenario.radio.bandwidth_bps is not None,
            book=wire.book,
            plans=plans,
        )

    def contents(self, protocol: str) -> dict[str, tuple[str, tuple[int, ...], str]] | None:
        """The arrays of a protocol's content: name -> (dtype, shape, domain), the
        domain one of `DOMAINS`: the wire's one declaration, `radio.described`, and
        the programs' presence (None for a protocol that does not exist)."""
        if protocol == "presence":
            return {"heard": (B, (self.programs,), "flags")}
        if protocol not in ("flood", "consensus", "beacon", "bids", "upload", "download"):
            return None
        return described(
            protocol, self.n, self.m, self.slots, self.avoid, self.tuples, self.book, self.recent
        )

    def arrays(
        self, content: dict[str, Array], kinds: dict, k: int = 0, sender: int = 0, most: int = -1
    ) -> dict[str, np.ndarray] | str:
        """The arrays of `content` if they are exactly `kinds` and within their
        domains (of a message of cycle k from `sender`), else the reason not. Every
        field's shape, type and finiteness is checked before any domain, and
        covariances before what is computed from them. Fields whose first axis is -1
        hold up to `most` rows (-1: a scan's, `scan`)."""
        most = self.scan if most < 0 else most
        if content.keys() != kinds.keys():
            return "unexpected fields"
        out = {}
        rows = None  # the length of the fields whose first axis is -1: any up to `scan`
        for name, (dtype, shape, _) in kinds.items():
            wire = content[name]
            if shape[:1] == (-1,) and len(wire.shape) == len(shape) and wire.shape:
                rows = wire.shape[0] if rows is None else rows
                shape = (rows if 0 <= rows <= most else -1, *shape[1:])
            if wire.dtype != dtype or tuple(wire.shape) != shape:
                return "wrong shape or type"
            try:
                value = wire.array()
            except ValueError:
                return "wrong shape or type"
            out[name] = value
        for name, (_, _, domain) in kinds.items():
            reason = self._finite(domain, out[name])
            if reason is not None:
                return reason
        order = sorted(kinds, key=lambda name: kinds[name][2] != "covariance")
        for name in order:
            reason = self._domain(kinds[name][2], out[name], out, k, sender)
            if reason is not None:
                return reason
        return out

    def _finite(self, domain: str, value: np.ndarray) -> str | None:
        """Why a field's floats are not what its domain admits: finite, NaN only as a
        bid not scored (every bid of a method that does not plan), -inf only as a
        confidence of no estimate."""
        if value.dtype.kind != "f":
            return None
        nan = np.isnan(value)
        if domain == "slot bids":  # NaN where no confirmed track: checked with the labels
            pass
        elif domain == "bids" and not self.plans:  # a learned policy scores nothing
            if not nan.all():
                return "bids of a method that does not bid"
        elif domain == "bids":
            if nan.all() or nan.any() and not (self.bounds is None or self.bounds.unscored):
                return "bids not scored"
        elif nan.any():
            return "not finite"
        if np.isposinf(value).any():
            return "not finite"
        if np.isneginf(value).any() and domain != "confidence or none":
            return "not finite"
        return None

    def _domain(self, domain: str, value, arrays: dict, k: int, sender: int) -> str | None:
        """Why finite `value` is outside `domain` (None: it is inside)."""
        b = self.bounds
        live = np.isfinite(arrays["gamma"]) if "gamma" in arrays else slice(None)
        if "status" in arrays:  # track slots: only those with a track are read
            live = arrays["status"] != 0
        if domain in TRACK_DOMAINS:
            return self._track_domain(domain, value, arrays, k, live)
        if domain == "known":
            return None if sender < value.size and value[sender] else "sender not in its own set"
        if domain == "recent commands":
            return None if ((value >= 0) & (value < 9)).all() else "recent commands out of range"
        if domain == "uav index":
            return None if ((value >= 0) & (value < self.n)).all() else "index out of range"
        if domain == "target or none":
            return None if -1 <= value < self.m else "index out of range"
        if domain == "cycle":
            return None if value == k else "stamp out of range"
        if domain == "stamp":
            oldest = max(0, k - (self.rounds + 1) * self.behind)
            ok = (value[live] >= oldest) & (value[live] <= k)
            return None if ok.all() else "stamp out of range"
        if domain in ("confidence", "confidence or none"):
            return _confidence(value, arrays["cov"], domain == "confidence")
        if domain == "covariance":
            return _covariance(value[live], b)
        if domain == "covariance triangle":  # (rows, 10): the upper triangle of each
            return _covariance(mirrored(value), b)
        if domain == "log variances":  # decoded with the correlations
            return None
        if domain == "correlations":  # (rows, 6), with the log variances (rows, 4)
            if not ((value >= -SCALE) & (value <= SCALE)).all():
                return "correlation out of range"
            return _covariance(decoded_cov(arrays["var"], value), b)
        if domain == "afford":
            flags = np.isin(value[:, [0, 2]], (0, 1)).all()
            return None if flags and (value[:, 1] >= 0).all() else "count out of range"
        if domain == "targets":
            distinct = len(np.unique(value)) == len(value)
            inside = ((value >= 0) & (value < self.m)).all()
            return None if distinct and inside else "index out of range"
        if domain == "uav state":
            return self._uav(value)
        if b is None:
            return None
        if domain == "position":
            return _position(value[None], b) or _altitude(value[2], b)
        if domain == "bids":
            scored = value[~np.isnan(value)]
            return None if ((scored >= 0) & (scored <= b.bid)).all() else "bid out of bounds"
        return None

    def _track_domain(self, domain: str, value, arrays: dict, k: int, live) -> str | None:
        """`_domain` of the fields of track slots."""
        if domain == "track status":
            label = arrays["label"]
            if not np.isin(value, (0, 1, 2)).all() or ((label >= 0) != (value != 0)).any():
                return "track status out of range"
            return None if _distinct(label) else "labels not distinct"
        labels = (value >= -1) & (value < self.labels)
        if domain == "slots":
            inside = ((value >= 0) & (value < self.slots)).all()
            return None if inside and _distinct(value.astype(np.int64)) else "index out of range"
        if domain == "team label":
            if not (labels & (value >= 0)).all():
                return "index out of range"
            return None if _distinct(value.astype(np.int64)) else "labels not distinct"
        if domain == "label or none":
            return None if labels.all() else "index out of range"
        if domain == "bid labels":
            if not labels.all():
                return "index out of range"
            return None if _distinct(value) else "labels not distinct"
        if domain == "track covariance":
            return _covariance(value[live], self.bounds)
        if domain == "measurement covariance":
            return _covariance(value, self.bounds)
        if domain == "ground positions":
            return None if self.bounds is None else _position(value, self.bounds)
        if domain == "counts":
            return None if ((value >= 0) & (value < self.labels)).all() else "count out of range"
        if domain == "existence":
            return None if ((value >= 0) & (value <= 1)).all() else "probability out of range"
        if domain == "track stamp":
            return None if ((value[live] >= 0) & (value[live] <= k)).all() else "stamp out of range"
        if domain == "tombstones":
            label, step = value[:, 0], value[:, 1]
            some = label >= 0
            if not ((label >= -1) & (label < self.labels)).all():
                return "index out of range"
            if not ((step[some] >= 0) & (step[some] <= k)).all():
                return "stamp out of range"
            if not _distinct(label):
                return "labels not distinct"
            return _buried(label[some], step[some], arrays)
        if domain == "slot bids":
            confirmed = arrays["status"] == 2 if "status" in arrays else arrays["label"] >= 0
            if (np.isnan(value) != ~confirmed).any():
                return "bids not scored"
            scored = value[confirmed]
            bound = np.inf if self.bounds is None else self.bounds.bid
            return None if ((scored >= 0) & (scored <= bound)).all() else "bid out of bounds"
        return None  # "track estimate": finite (`_finite`); plausibility is `tracks`'

    def tracks(self, content: dict[str, np.ndarray]) -> tuple[dict, dict[str, int]]:
        """`estimates` for a checked content of track slots (a consensus round's or a
        download's): a track beyond the run's plausibility bounds is taken as no track
        (its slot empty), as if the sender did not hold it. Returns the content and the
        tracks left out by reason."""
        status = content["status"]
        # every track: a download's tentative ones are taken too
        bad, reasons = _implausible(content["mean"], content["cov"], status != 0, self.bounds)
        if not bad.any():
            return content, {}
        out = dict(content)
        out["status"] = np.where(bad, 0, status)
        out["label"] = np.where(bad, -1, content["label"])
        return out, reasons

    def estimates(self, content: dict[str, np.ndarray]) -> tuple[dict, dict[str, int]]:
        """The estimates of a checked tuple content ("gamma", "mean", "cov", ...) that
        a receiver may use: one (a target's) whose position is outside the field plus
        the run's margin, whose speed is above the run's largest or whose covariance is
        below the sensor's best accuracy is replaced by no estimate (confidence -inf,
        mean 0, covariance I), as if that sender had none. Returns the content and the
        estimates replaced by reason.

        These bounds are kept apart from `radio`'s, which refuse whole messages: an
        honest UAV that adopted a plausible lie may itself come to hold an estimate
        beyond them (a Kalman update of a confident wrong prior moves its velocity far),
        and must not be silenced for the targets it knows."""
        gamma, mean, cov = content["gamma"], content["mean"], content["cov"]
        bad, reasons = _implausible(mean, cov, np.isfinite(gamma), self.bounds)
        if not bad.any():
            return content, {}
        out = dict(content)
        out["gamma"] = np.where(bad, -np.inf, gamma)
        out["mean"] = np.where(bad[:, None], 0.0, mean)
        out["cov"] = np.where(bad[:, None, None], np.eye(4), cov)
        return out, reasons

    def _uav(self, value) -> str | None:
        b = self.bounds
        if not -2 * np.pi <= value[4] <= 2 * np.pi:
            return "heading out of range"
        if b is None:
            return None
        if not 0 < value[3] <= b.uav_speed:
            return "speed out of bounds"
        return _position(value[None], b) or _altitude(value[2], b)

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
                # the targets, or the track slots, a consensus lists
                most = (self.slots or self.m) if part.protocol == "consensus" else -1
                wire = part.content
                if packs(part.protocol, self.tuples):  # its rows in one byte array
                    wire = unpacked(wire, kinds, most)
                    if isinstance(wire, str):
                        return wire
                content = self.arrays(wire, kinds, message.k, message.sender, most)
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
        if self.slots:  # an unlabelled scan: no target is named
            m, K = 0, message.z.shape[0] if len(message.z.shape) == 2 else -1
            if not 0 <= K <= self.scan:
                return "wrong shape or type"
        kinds = {
            "believed": (F, (5,), "finite"),
            "observed": (B, (m,), "flags"),
            "z": (F, (K, 2), "finite"),
            "links": (B, (n,), "flags"),
            "alive": (B, (n,), "flags"),
        }
        if self.limited:
            kinds["afford"] = (I, (n, 3), "afford")
        wire = {name: v for name in kinds if (v := getattr(message, name)) is not None}
        return self.arrays(wire, kinds)

    def tick(self, message: Tick) -> dict[str, np.ndarray] | str:
        kinds: dict[str, tuple[str, tuple[int, ...], str]] = {"alive": (B, (self.n,), "flags")}
        if self.limited:
            kinds["afford"] = (I, (self.n, 3), "afford")
        wire = {name: v for name in kinds if (v := getattr(message, name)) is not None}
        return self.arrays(wire, kinds)

    def report(self, message: Report) -> dict[str, np.ndarray] | str:
        """A Report's arrays if the run admits it, else the reason not."""
        counts = (message.rounds, message.sent, message.delivered, message.published)
        counts += (message.bytes, message.received, message.radio_bytes)
        if not all(0 <= c <= COUNT for c in counts) or message.rounds > self.rounds:
            return "count out of range"
        if len(message.drops) > 64 or not all(
            len(reason) <= 80 and 0 <= c <= COUNT for reason, c in message.drops.items()
        ):
            return "count out of range"
        most = self.programs * (self.rounds + 1)  # a message per sender and round
        if not all(p in PROTOCOLS and 0 <= c <= most for p, c in message.late.items()):
            return "count out of range"
        times = (message.decision_ms, message.decision_wall_ms)
        if not all(np.isfinite(t) and 0 <= t <= MILLISECONDS for t in times):
            return "not finite"
        if message.uav == self.n:  # the central node decides nothing of its own
            if (message.action, message.target) != (-1, -1):
                return "action or target out of range"
            return {}
        target_ok = 0 <= message.target < self.m
        if self.slots:  # a team label, or none
            target_ok = message.target >= -1
        elif not self.plans:  # a learned policy's UAV follows no target
            target_ok = message.target == -1
        if not 0 <= message.action < self.actions or not target_ok:
            return "action or target out of range"
        m = self.m
        kinds = {
            "mean": (F, (m, 4), "estimate"),
            "cov": (F, (m, 4, 4), "covariance"),
            "bids": (F, (m,), "bids"),
        }
        if self.slots:
            K = self.slots
            kinds = {
                "mean": (F, (K, 4), "track estimate"),
                "cov": (F, (K, 4, 4), "track covariance"),
                "bids": (F, (K,), "slot bids"),
                "label": (I, (K,), "label or none"),
                "status": (I, (K,), "track status"),
                "existence": (F, (K,), "existence"),
            }
        wire = {name: getattr(message, name) for name in kinds}
        if any(value is None for value in wire.values()):
            return "unexpected fields"
        arrays = self.arrays(wire, kinds)
        if isinstance(arrays, str) or self.bounds is None:
            return arrays
        return _recorded(arrays, self.bounds) or arrays


def _implausible(
    mean: np.ndarray, cov: np.ndarray, live: np.ndarray, bounds: Bounds | None
) -> tuple[np.ndarray, dict[str, int]]:
    """Which of the estimates `live` (mean (M, 4), cov (M, 4, 4)) lie beyond the run's
    plausibility bounds: outside the field plus its margin, faster than its largest, a
    covariance below the sensor's best accuracy (the last reason named wins); and how
    many by reason."""
    bad = np.zeros(live.shape, dtype=bool)
    if bounds is None or not live.any():
        return bad, {}
    reasons = np.full(live.shape, "", dtype=object)
    inside = ((mean[:, :2] >= bounds.low) & (mean[:, :2] <= bounds.high)).all(axis=1)
    slow = np.hypot(mean[:, 2], mean[:, 3]) <= bounds.speed
    sharp = np.linalg.eigvalsh(cov)[:, 0] >= bounds.floor
    reasons[live & ~sharp] = "covariance below the sensor's accuracy"
    reasons[live & ~slow] = "speed out of bounds"
    reasons[live & ~inside] = "position out of bounds"
    bad = reasons != ""
    found, counts = np.unique(reasons[bad].astype(str), return_counts=True)
    return bad, dict(zip(found.tolist(), counts.tolist(), strict=True))


TRACK_DOMAINS = frozenset(
    ("track status", "label or none", "bid labels", "track covariance", "track stamp")
    + ("tombstones", "slot bids", "track estimate", "measurement covariance", "counts")
    + ("ground positions", "slots", "team label", "existence")
)


def _buried(label: np.ndarray, step: np.ndarray, arrays: dict) -> str | None:
    """Why tombstones (label, step) contradict the tracks they travel with: a sender holds
    a track under a label it says was deleted after the track's stamp. An honest UAV
    buries such a track before it sends (`tracks.team.bury`), so this is a lie about the
    deletion or about the track."""
    if not ("status" in arrays or "slots" in arrays) or not label.size:
        return None
    live = arrays["status"] != 0 if "status" in arrays else slice(None)  # listed: all
    held, stamp = arrays["label"][live].astype(np.int64), arrays["stamp"][live]
    order = np.argsort(label)
    at = np.minimum(np.searchsorted(label[order], held), label.size - 1)
    named = label[order][at] == held
    return "tombstone of a track it holds" if (named & (stamp < step[order][at])).any() else None


def _distinct(label: np.ndarray) -> bool:
    """The labels other than -1 are distinct."""
    held = np.sort(label[label >= 0])
    return not (held[1:] == held[:-1]).any()


COUNT = 2**48
"""The largest count a report may carry (messages, bytes, drops of one cycle)."""
MILLISECONDS = 1e9
"""The longest decision time a report may carry [ms] (eleven days)."""


def _confidence(gamma: np.ndarray, cov: np.ndarray, required: bool) -> str | None:
    live = np.isfinite(gamma)
    if required and not live.all():
        return "not finite"
    expected = estimation.confidence(cov[live])
    if not (np.abs(gamma[live] - expected) <= CONSISTENT * np.abs(expected)).all():
        return "confidence disagrees with covariance"
    return None


def _covariance(P: np.ndarray, bounds: Bounds | None) -> str | None:
    """Why covariances P (..., 4, 4) are not symmetric positive definite within the
    run's [floor, cap] (`plausibility.Bounds`), or None."""
    if not P.size:
        return None
    scale = np.abs(P).max(axis=(-2, -1))
    if bounds is not None and not (scale <= bounds.cap).all():  # |P_ij| <= lambda_max
        return "covariance beyond the run's largest"
    if not (np.abs(P - np.swapaxes(P, -1, -2)).max(axis=(-2, -1)) <= CONSISTENT * scale).all():
        return "covariance not positive definite"
    eig = np.linalg.eigvalsh(P)
    if not (eig[..., 0] > 0).all():
        return "covariance not positive definite"
    if bounds is not None and not (eig[..., -1] <= bounds.cap).all():
        return "covariance beyond the run's largest"
    return None


def _position(xy: np.ndarray, bounds: Bounds) -> str | None:
    inside = (xy[..., :2] >= bounds.low) & (xy[..., :2] <= bounds.high)
    return None if inside.all() else "position out of bounds"


def _altitude(h: float, bounds: Bounds) -> str | None:
    low, high = bounds.altitude
    return None if low < h <= high else "position out of bounds"


def _recorded(arrays: dict, bounds: Bounds) -> str | None:
    """Why a report's estimates cannot be recorded (None: they can): the world's
    metrics read them, so they must stay where arithmetic is safe, yet an honest UAV
    misled by a member may hold one beyond `Spec.estimates`' bounds. Positions are
    refused beyond the field plus twice the run's margin (a misled estimate moves at
    most at a plausible speed from a plausible place), covariances below the floor of a
    filter that took in an estimate at the floor (`plausibility.Bounds.adopted`)."""
    margin = -bounds.low
    live = arrays["status"] != 0 if "status" in arrays else slice(None)
    xy = arrays["mean"][live, :2]
    if not ((xy >= bounds.low - margin) & (xy <= bounds.high + margin)).all():
        return "position out of bounds"
    if not (np.linalg.eigvalsh(arrays["cov"][live])[:, 0] >= bounds.adopted).all():
        return "covariance below the sensor's accuracy"
    return None
