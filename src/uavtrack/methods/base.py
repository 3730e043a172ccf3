"""The paper's method and its two baselines, one interface, chosen by name.

A method decides two things in the cycle: how the UAVs' local estimates are fused
(`fuse`) and how bids become an assignment of UAVs to targets (`assign`). Everything
else (sensing, filtering, planning, control) is shared. Both talk over the cycle's
`radio.Radio`, so lost and late messages reach every method the same way.

* ``distributed`` (the paper's): the D_i flooding protocol and max-consensus over the
  radio with per-UAV stopping, then beacons and bids to one-hop neighbours and each
  UAV's Hungarian auction over its neighbourhood (`assignment.local`).
* ``centralized``: every UAV uploads its tables to a central node whatever the radio
  range; the node takes the most confident estimate of each target over the team
  (max-consensus on the complete graph), plans for every UAV it heard from and solves
  one global assignment, and sends each UAV the fused estimates and its target.
* ``greedy``: the same fusion as distributed; each UAV takes the target of its own
  highest bid, with no interaction.

Faults (`config.FaultModel`): a lost bid leaves the receiver with the last bid it held
of that neighbour (or, with ``robust.stale``, drops the neighbour from its auction); a
lost upload leaves the UAV out of the central fusion and assignment; a lost download
leaves the UAV with its own estimates and its previous target. A failed UAV takes part
in nothing.

A new auction rule plugs in by subclassing `Distributed` and replacing `solve` (see
examples/custom_method.py); `register` adds a method to the `registry` the command line
and the experiments read, and other packages can add theirs by entry point.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from . import assignment, fusion, gate, registry, timing
from .errors import UsageError
from .radio import Radio


@dataclass(frozen=True)
class Setting:
    """What a run fixes for the methods: robustness options and the fault settings.

    forward(tuples, k): tuples (dict of (B, N, M, ...) arrays with "mean", "cov",
    "stamp") predicted forward to step k, with their confidence "gamma" recomputed.
    plan(uavs, mean, top=None): bids (B, N, M) and first actions of UAVs at `uavs`
    (B, N, 5) with fused estimates `mean` (B, N, M, 4), as `planning.plan` under the
    scenario (top: how many best bids each UAV needs, None: all). prune: whether a
    method may ask for fewer than all bids (``planner.prune``, and a radio that neither
    loses nor delays, so that every UAV knows the neighbourhoods its bids serve).
    rule: the fusion rule of each consensus round (``fusion.rule``). gate: the
    measurement gate's threshold on a squared Mahalanobis distance (``robust.gate``,
    `gate.threshold`; None: off).
    """

    faulty: bool
    delay: int
    budget: int | None
    extra_rounds: int
    stale: bool
    forward: Callable
    plan: Callable
    prune: bool = False
    rule: str = "max_consensus"
    gate: float | None = None


@dataclass(frozen=True)
class Held:
    """The last bid each UAV heard of each other: value (B, N, N, M) [trial, receiver,
    sender], and the step it was sent, stamp (B, N, N) (-1: never heard)."""

    value: np.ndarray
    stamp: np.ndarray


@dataclass(frozen=True)
class Inputs:
    """What a method sees in one cycle for B trials: the radio, each UAV's local
    estimates after its filter (mean (B, N, M, 4), cov (B, N, M, 4, 4), gamma (B, N, M)),
    the UAV states as the UAVs believe them (B, N, 5), who is alive (B, N), each UAV's
    previous target (B, N) (-1: none), the bids held (`Held`, when messages get lost),
    and with the measurement gate (``robust.gate``) what each UAV measured
    (`gate.Measured`)."""

    k: int
    radio: Radio
    mean: np.ndarray
    cov: np.ndarray
    gamma: np.ndarray
    believed: np.ndarray
    alive: np.ndarray
    previous: np.ndarray
    held: Held | None
    setting: Setting
    measured: gate.Measured | None = None


@dataclass(frozen=True)
class Fused:
    """Each UAV's fused estimates (mean, cov), the rounds it ran (B, N), messages sent
    and delivered (B,), seconds of central work (B, N, 2; CPU, wall), for the centralized
    method under faults the targets the central node sent (B, N), and from the D_i protocol
    the largest closed neighbourhood each UAV belongs to (B, N) (`fusion.Depth`)."""

    mean: np.ndarray
    cov: np.ndarray
    rounds: np.ndarray
    sent: np.ndarray
    delivered: np.ndarray
    seconds: np.ndarray | None = None
    target: np.ndarray | None = None
    largest: np.ndarray | None = None
    gamma: np.ndarray | None = None  # 1 / trace(cov), when the fusion already has it


@dataclass(frozen=True)
class Assigned:
    """Targets (B, N) (-1 for a failed UAV), seconds of each UAV's assignment (B, N, 2):
    CPU and wall (`timing`; a method's own (B, N) stands for both), messages sent and
    delivered (B,), and the bids held for the next cycle."""

    target: np.ndarray
    seconds: np.ndarray
    sent: np.ndarray
    delivered: np.ndarray
    held: Held | None = None


class Method:
    """Interface of a decision method; subclasses override `fuse` and `assign`."""

    name: ClassVar[str]
    central: ClassVar[bool] = False
    """Whether one node plans for everyone (its decision time is the whole team's)."""

    def fuse(self, inputs: Inputs) -> Fused:
        """Consensus over the radio: the D_i protocol, then max-consensus rounds."""
        return consensus(inputs)

    def assign(self, inputs: Inputs, fused: Fused, bids: np.ndarray) -> Assigned:
        """Targets from bids (B, N, M)."""
        raise NotImplementedError

    def top(self, setting: Setting, largest: np.ndarray | None) -> np.ndarray | None:
        """How many of its best bids each UAV's assignment can read (B, N), or None: all
        (the default: a method that does not say needs every bid). The planner scores
        only what can be among them (`planning.plan_top`); the others are NaN.

        largest (B, N): the most members of a closed neighbourhood each UAV belongs to
        (`fusion.Depth`; None when the fusion did not learn it)."""
        return None

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


def consensus(inputs: Inputs) -> Fused:
    """The paper's fusion (Algorithm 2 lines 15-25) over the cycle's radio.

    Without delay the tuples travel as the index of the UAV whose local estimate they
    are; with delay they travel by value with their time stamps (estimates of earlier
    cycles), predicted forward before use when ``robust.stale``.
    """
    s, radio, alive = inputs.setting, inputs.radio, inputs.alive
    depth = fusion.learn_depth(radio, alive, s.budget)
    rounds = np.where(alive, depth.depth + s.extra_rounds, 0)
    if s.budget is not None:
        rounds = np.minimum(rounds, s.budget)
    admit = gated(inputs)
    if s.delay == 0 and s.rule == "max_consensus":
        tuples = {"gamma": inputs.gamma, "source": fusion.identity(inputs.gamma.shape)}
        out = fusion.consensus(radio, tuples, rounds, admit=admit)
        source = out.tuples["source"]
        mean, cov = fusion.gather(source, inputs.mean), fusion.gather(source, inputs.cov)
        gamma = out.tuples["gamma"]  # travelled with the source: confidence(cov) exactly
    else:
        stamp = np.full(inputs.gamma.shape, inputs.k)
        tuples = {"gamma": inputs.gamma, "mean": inputs.mean, "cov": inputs.cov, "stamp": stamp}
        receive = (lambda t: s.forward(t, inputs.k)) if s.stale else None
        out = fusion.consensus(radio, tuples, rounds, receive=receive, rule=s.rule, admit=admit)
        mean, cov = out.tuples["mean"], out.tuples["cov"]
        gamma = None
    if s.delay > 0:  # counted when sent: what is read d cycles later is not known yet
        flood, tuples_ = (
            radio.transmitted("flood", depth.ran),
            radio.transmitted("consensus", rounds),
        )
        sent, delivered = flood[0] + tuples_[0], flood[1] + tuples_[1]
    else:
        sent, delivered = depth.sent + out.sent, depth.delivered + out.delivered
    return Fused(mean, cov, rounds, sent, delivered, largest=depth.largest, gamma=gamma)


def gated(inputs: Inputs):
    """The consensus's admit(own, offered, links) under the measurement gate
    (``robust.gate``, `gate.admitted`), or None without it. Tuples that travel as the
    index of the UAV whose estimate they are ("source") are looked up in the local
    estimates."""
    s, measured = inputs.setting, inputs.measured
    if s.gate is None or measured is None:
        return None

    def estimates(tuples: dict) -> tuple[np.ndarray, np.ndarray]:
        if "source" in tuples:
            source = tuples["source"]
            return fusion.gather(source, inputs.mean), fusion.gather(source, inputs.cov)
        return tuples["mean"], tuples["cov"]

    def admit(own: dict, offered: dict, links) -> np.ndarray:
        return gate.admitted(links, estimates(own), estimates(offered), measured, s.gate)

    return admit


class Distributed(Method):
    """The paper's method: Algorithm 2 with Algorithm 1's neighbourhood auction."""

    name = "distributed"

    @staticmethod
    def solve(bids: np.ndarray) -> np.ndarray:
        """The neighbourhood problem: targets (n,) of the n members, Remark 2."""
        return assignment.hungarian(bids)

    @property
    def built_in_solve(self) -> bool:
        """Whether `solve` is this class's own, which reads only each member's k best
        bids in a problem of k members (a subclass's may read any bid)."""
        return type(self).solve is Distributed.solve

    def top(self, setting: Setting, largest: np.ndarray | None) -> np.ndarray | None:
        """A UAV's bids serve the auction of every neighbourhood it belongs to, and in
        an auction of k members only each member's k best bids matter
        (`assignment.hungarian`): it needs as many as the largest of them has members.
        A replaced `solve` may read any bid: then all."""
        if not setting.prune or not self.built_in_solve:
            return None
        return largest

    def assign(self, inputs: Inputs, fused: Fused, bids: np.ndarray) -> Assigned:
        s, radio, k = inputs.setting, inputs.radio, inputs.k
        B, n, m = bids.shape
        radio.send("beacon", {})
        radio.send("bids", {"bids": bids, "stamp": np.full((B, n), k)})
        beacon, inbox = radio.receive("beacon"), radio.receive("bids")
        sent = np.zeros(B, dtype=np.int64)
        delivered = np.zeros(B, dtype=np.int64)
        everyone = np.ones((B, n), dtype=bool)
        if s.delay > 0:  # counted when sent, as the fusion's
            once = inputs.alive.astype(np.int64)
            for protocol in ("beacon", "bids"):
                more = radio.transmitted(protocol, once, first=0)
                sent, delivered = sent + more[0], delivered + more[1]
        for arrived in (beacon, inbox) if s.delay == 0 else ():
            if arrived is not None:
                sent, delivered = fusion.count(arrived, everyone, sent, delivered)
        alive = inputs.alive
        idx = np.arange(n)
        held = inputs.held
        if inbox is None:  # nothing has arrived yet: every UAV alone
            members = np.zeros((B, n, n), dtype=bool)
            view = bids
        elif s.delay == 0 and held is None:  # all bids current, none lost: one shared view
            members = inbox.delivered.adjacency()
            view = bids
        else:
            got = inbox.delivered.adjacency()  # bids that arrived this cycle
            heard = beacon.delivered.adjacency() if beacon is not None else got
            members, view, stamp = bid_view(
                got,
                inbox.content["bids"][:, None],
                inbox.content["stamp"][:, None],
                heard,
                held,
                s.stale,
            )
            held = held if held is None else Held(view, stamp)
            view = np.array(np.broadcast_to(view, (B, n, n, m)))
            view[:, idx, idx] = bids  # a UAV's own bids are current
        if not alive.all():
            members = members & alive[:, :, None] & alive[:, None, :]
        solve = None if self.built_in_solve else self.solve  # None: the auction's own fast path
        target, seconds = assignment.auction(view, members, solve)
        return Assigned(np.where(alive, target, -1), seconds, sent, delivered, held)


def bid_view(
    got: np.ndarray,
    bids: np.ndarray,
    stamp: np.ndarray,
    heard: np.ndarray,
    held: Held | None,
    stale: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A receiver's auction after this cycle's arrivals: who takes part, and the bids it
    holds of each sender. Broadcasts over leading receiver axes.

    got (..., N) bool: the senders whose bid arrived this cycle; bids (..., N, M) and
    stamp (..., N): those bids and the step they were sent; heard (..., N): the senders
    whose beacon arrived; held: the bids held before (None when messages are never
    lost: nothing to remember). Without `stale`, a sender heard by its beacon takes part
    with the last bid held of it, however old; with `stale`, only senders whose bid
    arrived take part. Returns (members (..., N), bids held (..., N, M), their stamps).
    """
    if held is None:
        return got, bids, stamp
    value = np.where(got[..., None], bids, held.value)
    stamp = np.where(got, stamp, held.stamp)
    members = got if stale else heard & (stamp >= 0)
    return members, value, stamp


class Centralized(Method):
    """A central node with everyone's data: global fusion, one global assignment."""

    name = "centralized"
    central = True

    def fuse(self, inputs: Inputs) -> Fused:
        if not inputs.setting.faulty:
            return self._perfect(inputs)
        return self._over_links(inputs)

    @staticmethod
    def _perfect(inputs: Inputs) -> Fused:
        b, n, _ = inputs.gamma.shape
        source = np.broadcast_to(np.argmax(inputs.gamma, axis=-2)[:, None, :], inputs.gamma.shape)
        rounds = np.full((b, n), 1 if n > 1 else 0, dtype=np.int64)
        # every UAV uploads its table and downloads the fused one
        messages = np.full(b, 2 * n if n > 1 else 0, dtype=np.int64)
        mean, cov = fusion.gather(source, inputs.mean), fusion.gather(source, inputs.cov)
        s, measured = inputs.setting, inputs.measured
        if s.gate is not None and measured is not None:  # as `take_download`
            use = gate.agreeing(mean, cov, measured, s.gate, (inputs.mean, inputs.cov))
            mean = np.where(use[..., None], mean, inputs.mean)
            cov = np.where(use[..., None, None], cov, inputs.cov)
        return Fused(mean, cov, rounds, messages, messages.copy())

    @staticmethod
    def _over_links(inputs: Inputs) -> Fused:
        """Uploads, the central node's work, downloads, with faults."""
        s, radio, k = inputs.setting, inputs.radio, inputs.k
        B, n, m = inputs.gamma.shape
        stamp = np.full((B, n, m), k)
        tuples = {"gamma": inputs.gamma, "mean": inputs.mean, "cov": inputs.cov, "stamp": stamp}
        radio.send("upload", {**tuples, "uavs": inputs.believed, "alive": inputs.alive})
        upload, up_ok = radio.receive_central("upload")
        sent, delivered = np.zeros(B, dtype=np.int64), np.zeros(B, dtype=np.int64)
        seconds = np.zeros((B, n, 2))
        if s.delay > 0:  # counted when sent: uploads now, downloads below
            up = radio.transmitted_central("upload")
            sent, delivered = sent + up[0], delivered + up[1]
        if upload is None:
            down, down_target = nothing_heard(B, n, m), np.full((B, n), -1, dtype=np.int64)
        else:
            up_ok = up_ok & upload["alive"]
            if s.delay == 0:
                sent += upload["alive"].sum(axis=1)
                delivered += up_ok.sum(axis=1)
            start = timing.start()
            down, down_target = central_node(
                {key: upload[key] for key in tuples}, up_ok, upload["uavs"], s, k
            )
            seconds += timing.since(start) / B
        radio.send("download", {**down, "target": down_target, "alive": inputs.alive})
        if s.delay > 0:
            down_sent = radio.transmitted_central("download")
            sent, delivered = sent + down_sent[0], delivered + down_sent[1]
        download, down_ok = radio.receive_central("download")
        mean, cov = inputs.mean, inputs.cov
        target = None
        if download is not None:
            down_ok = down_ok & inputs.alive
            if s.delay == 0:
                sent += download["alive"].sum(axis=1)
                delivered += down_ok.sum(axis=1)
            mean, cov = take_download(mean, cov, download, down_ok, s, k, inputs.measured)
            target = np.where(down_ok, download["target"], -1)
        rounds = np.where(inputs.alive, 1, 0)
        return Fused(mean, cov, rounds, sent, delivered, seconds, target)

    def assign(self, inputs: Inputs, fused: Fused, bids: np.ndarray) -> Assigned:
        B, n, _ = bids.shape
        none = np.zeros(B, dtype=np.int64)
        if not inputs.setting.faulty:
            target, seconds = assignment.centralized(bids)
            return Assigned(target, np.repeat(seconds[:, None], n, axis=1), none, none)
        # the node's target if its download arrived, else the previous one, else the own best
        target = fused.target if fused.target is not None else np.full((B, n), -1)
        target = np.where(target >= 0, target, inputs.previous)
        target = np.where(target >= 0, target, assignment.greedy(bids))
        target = np.where(inputs.alive, target, -1)
        return Assigned(target, fused.seconds, none, none)


def nothing_heard(B: int, n: int, m: int) -> dict[str, np.ndarray]:
    """A download that carries no estimate (confidence -inf): the node heard nobody."""
    return {
        "gamma": np.full((B, n, m), -np.inf),
        "mean": np.zeros((B, n, m, 4)),
        "cov": np.zeros((B, n, m, 4, 4)),
        "stamp": np.zeros((B, n, m), dtype=np.int64),
    }


def central_node(
    got: dict, heard: np.ndarray, uavs: np.ndarray, setting: Setting, k: int
) -> tuple[dict, np.ndarray]:
    """The central node's work on the uploads it received.

    got: the uploaded tuples (B, N, M, ...) ("gamma", "mean", "cov", "stamp"); heard
    (B, N): whose upload arrived; uavs (B, N, 5): the states they reported. Per target
    the most confident uploaded estimate (ties to the lowest UAV), predicted forward with
    ``robust.stale``; bids of every UAV heard from, planned from its reported state; one
    global assignment over them. Returns the download of every UAV (the fused tuples,
    (B, N, M, ...), confidence -inf where the node heard nobody) and its target (B, N),
    -1 for a UAV not heard from.
    """
    B, n, m = got["gamma"].shape
    if setting.stale:
        got = setting.forward(got, k)
    score = np.where(heard[..., None], got["gamma"], -np.inf)
    best = np.argmax(score, axis=1)  # per target, the most confident uploader
    b, j = np.arange(B)[:, None], np.arange(m)
    central = {key: value[b, best, j] for key, value in got.items()}  # (B, M, ...)
    value = np.zeros((B, n, m))  # bids of the UAVs heard from, planned from their reports
    t, i = np.nonzero(heard)
    if t.size:
        value[t, i] = setting.plan(uavs[t, i][None], central["mean"][t][None])[0][0]
    targets, _ = assignment.centralized(value, heard)
    anyone = heard.any(axis=1)
    down = nothing_heard(B, n, m)
    for key, value in central.items():
        down[key] = np.where(
            anyone.reshape((B,) + (1,) * value.ndim),
            np.repeat(value[:, None], n, axis=1),
            down[key],
        )
    return down, np.where(anyone[:, None], targets, -1)


def take_download(
    mean: np.ndarray,
    cov: np.ndarray,
    got: dict,
    arrived: np.ndarray,
    setting: Setting,
    k: int,
    measured: gate.Measured | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A UAV's estimates after the central node's download: the downloaded tuple of each
    target where it arrived and carries one (predicted forward with ``robust.stale``)
    and, with ``robust.gate``, agrees with the UAV's measurement (`gate.agreeing`), its
    own otherwise. mean (B, N, M, 4), cov (B, N, M, 4, 4); arrived (B, N)."""
    got = {key: got[key] for key in ("gamma", "mean", "cov", "stamp")}
    if setting.stale:
        got = setting.forward(got, k)
    use = arrived[..., None] & np.isfinite(got["gamma"])  # (B, N, M)
    if setting.gate is not None and measured is not None:
        use &= gate.agreeing(got["mean"], got["cov"], measured, setting.gate, (mean, cov))
    return (
        np.where(use[..., None], got["mean"], mean),
        np.where(use[..., None, None], got["cov"], cov),
    )


class Greedy(Method):
    """Same fusion as distributed; each UAV takes its own best bid."""

    name = "greedy"

    def top(self, setting: Setting, largest: np.ndarray | None) -> np.ndarray | None:
        """Its own best bid only."""
        if not setting.prune or largest is None:
            return None
        return np.ones(largest.shape, dtype=np.int64)

    def assign(self, inputs: Inputs, fused: Fused, bids: np.ndarray) -> Assigned:
        start = timing.start()
        out = assignment.greedy(bids)
        seconds = np.empty(out.shape + (2,))
        seconds[...] = timing.since(start) / out.size
        none = np.zeros(bids.shape[0], dtype=np.int64)
        return Assigned(np.where(inputs.alive, out, -1), seconds, none, none)


METHODS: dict[str, Method] = {
    m.name: registry.register(m) for m in (Distributed(), Centralized(), Greedy())
}
"""The built-in methods by name; `registry` holds every method (plugins and `register`)."""


def register(method: Method) -> Method:
    """Make `method` available by its name (in this process) and return it."""
    if not isinstance(method, Method):
        raise TypeError(f"a method must be a uavtrack.methods.Method, not {type(method).__name__}")
    return registry.register(method)


def get(method: str | Method) -> Method:
    """A method by name (``distributed``, ``centralized``, ``greedy``, or any registered)
    or an instance."""
    if isinstance(method, Method):
        return method
    if not isinstance(method, str):
        raise ValueError(f"unknown method {method!r}; choose one of: {', '.join(registry.names())}")
    found = registry.load(method)
    if not isinstance(found, Method):
        raise UsageError(
            f"method {method!r} is a {type(found).__name__}, not a uavtrack.methods.Method"
        )
    return found
