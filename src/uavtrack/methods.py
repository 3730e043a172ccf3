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

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from . import assignment, fusion, registry
from .radio import Radio


@dataclass(frozen=True)
class Setting:
    """What a run fixes for the methods: robustness options and the fault settings.

    forward(tuples, k): tuples (dict of (B, N, M, ...) arrays with "mean", "cov",
    "stamp") predicted forward to step k, with their confidence "gamma" recomputed.
    plan(uavs, mean): bids (B, N, M) and first actions of UAVs at `uavs` (B, N, 5) with
    fused estimates `mean` (B, N, M, 4), as `planning.plan` under the scenario.
    """

    faulty: bool
    delay: int
    budget: int | None
    extra_rounds: int
    stale: bool
    forward: Callable
    plan: Callable


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
    previous target (B, N) (-1: none), the bids held (`Held`, when messages get lost)."""

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


@dataclass(frozen=True)
class Fused:
    """Each UAV's fused estimates (mean, cov), the rounds it ran (B, N), messages sent
    and delivered (B,), seconds of central work (B, N) and, for the centralized method
    under faults, the targets the central node sent (B, N)."""

    mean: np.ndarray
    cov: np.ndarray
    rounds: np.ndarray
    sent: np.ndarray
    delivered: np.ndarray
    seconds: np.ndarray | None = None
    target: np.ndarray | None = None


@dataclass(frozen=True)
class Assigned:
    """Targets (B, N) (-1 for a failed UAV), seconds of each UAV's assignment (B, N),
    messages sent and delivered (B,), and the bids held for the next cycle."""

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
    if s.delay == 0:
        tuples = {"gamma": inputs.gamma, "source": fusion.identity(inputs.gamma.shape)}
        out = fusion.consensus(radio, tuples, rounds)
        source = out.tuples["source"]
        mean, cov = fusion.gather(source, inputs.mean), fusion.gather(source, inputs.cov)
    else:
        stamp = np.full(inputs.gamma.shape, inputs.k)
        tuples = {"gamma": inputs.gamma, "mean": inputs.mean, "cov": inputs.cov, "stamp": stamp}
        receive = (lambda t: s.forward(t, inputs.k)) if s.stale else None
        out = fusion.consensus(radio, tuples, rounds, receive=receive)
        mean, cov = out.tuples["mean"], out.tuples["cov"]
    return Fused(mean, cov, rounds, depth.sent + out.sent, depth.delivered + out.delivered)


class Distributed(Method):
    """The paper's method: Algorithm 2 with Algorithm 1's neighbourhood auction."""

    name = "distributed"

    @staticmethod
    def solve(bids: np.ndarray) -> np.ndarray:
        """The neighbourhood problem: targets (n,) of the n members, Remark 2."""
        return assignment.hungarian(bids)

    def assign(self, inputs: Inputs, fused: Fused, bids: np.ndarray) -> Assigned:
        s, radio, k = inputs.setting, inputs.radio, inputs.k
        B, n, m = bids.shape
        radio.send("beacon", {})
        radio.send("bids", {"bids": bids, "stamp": np.full((B, n), k)})
        beacon, inbox = radio.receive("beacon"), radio.receive("bids")
        sent = np.zeros(B, dtype=np.int64)
        delivered = np.zeros(B, dtype=np.int64)
        everyone = np.ones((B, n), dtype=bool)
        for arrived in (beacon, inbox):
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
            offered = inbox.content
            if held is not None:  # remember the last bid heard of each neighbour
                value = np.where(got[..., None], offered["bids"][:, None], held.value)
                stamp = np.where(got, offered["stamp"][:, None], held.stamp)
                held = Held(value, stamp)
                heard = beacon.delivered.adjacency() if beacon is not None else got
                members = got if s.stale else heard & (stamp >= 0)
                view = value.copy()
            else:
                members = got
                view = np.broadcast_to(offered["bids"][:, None], (B, n, n, m)).copy()
            view[:, idx, idx] = bids  # a UAV's own bids are current
        if not alive.all():
            members = members & alive[:, :, None] & alive[:, None, :]
        target, seconds = assignment.auction(view, members, type(self).solve)
        return Assigned(np.where(alive, target, -1), seconds, sent, delivered, held)


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
        return Fused(mean, cov, rounds, messages, messages.copy())

    @staticmethod
    def _over_links(inputs: Inputs) -> Fused:
        """Uploads, central fusion, planning and assignment, downloads, with faults."""
        s, radio, k = inputs.setting, inputs.radio, inputs.k
        B, n, m = inputs.gamma.shape
        stamp = np.full((B, n, m), k)
        tuples = {"gamma": inputs.gamma, "mean": inputs.mean, "cov": inputs.cov, "stamp": stamp}
        radio.send("upload", {**tuples, "uavs": inputs.believed, "alive": inputs.alive})
        upload, up_ok = radio.receive_central("upload")
        sent, delivered = np.zeros(B, dtype=np.int64), np.zeros(B, dtype=np.int64)
        seconds = np.zeros((B, n))
        down_tuples = {
            "gamma": np.full((B, n, m), -np.inf),
            "mean": inputs.mean,
            "cov": inputs.cov,
            "stamp": stamp,
        }
        down_target = np.full((B, n), -1, dtype=np.int64)
        if upload is not None:
            up_ok = up_ok & upload["alive"]
            sent += upload["alive"].sum(axis=1)
            delivered += up_ok.sum(axis=1)
            got = {key: upload[key] for key in tuples}
            if s.stale:
                got = s.forward(got, k)
            score = np.where(up_ok[..., None], got["gamma"], -np.inf)  # (B, N, M)
            best = np.argmax(score, axis=1)  # per target, the most confident uploader
            heard = up_ok.any(axis=1)  # trials where the node heard anyone
            b, j = np.arange(B)[:, None], np.arange(m)
            central = {key: value[b, best, j] for key, value in got.items()}  # (B, M, ...)
            start = time.perf_counter()  # the node plans for the UAVs it heard from, as they were
            value, _ = s.plan(upload["uavs"], np.repeat(central["mean"][:, None], n, axis=1))
            targets, _ = assignment.centralized(value, up_ok)
            seconds += (time.perf_counter() - start) / B
            for key, value in central.items():
                down_tuples[key] = np.where(
                    heard.reshape((B,) + (1,) * value.ndim),
                    np.repeat(value[:, None], n, axis=1),
                    down_tuples[key],
                )
            down_target = np.where(heard[:, None], targets, -1)
        radio.send("download", {**down_tuples, "target": down_target, "alive": inputs.alive})
        download, down_ok = radio.receive_central("download")
        mean, cov = inputs.mean, inputs.cov
        target = None
        if download is not None:
            down_ok = down_ok & inputs.alive
            sent += download["alive"].sum(axis=1)
            delivered += down_ok.sum(axis=1)
            got = {key: download[key] for key in tuples}
            if s.stale:
                got = s.forward(got, k)
            use = down_ok[..., None] & np.isfinite(got["gamma"])  # (B, N, M)
            mean = np.where(use[..., None], got["mean"], mean)
            cov = np.where(use[..., None, None], got["cov"], cov)
            target = np.where(down_ok, download["target"], -1)
        rounds = np.where(inputs.alive, 1, 0)
        return Fused(mean, cov, rounds, sent, delivered, seconds, target)

    def assign(self, inputs: Inputs, fused: Fused, bids: np.ndarray) -> Assigned:
        B, n, _ = bids.shape
        none = np.zeros(B, dtype=np.int64)
        if not inputs.setting.faulty:
            target, seconds = assignment.centralized(bids)
            return Assigned(target, np.repeat(seconds[:, None], n, axis=-1), none, none)
        # the node's target if its download arrived, else the previous one, else the own best
        target = fused.target if fused.target is not None else np.full((B, n), -1)
        target = np.where(target >= 0, target, inputs.previous)
        target = np.where(target >= 0, target, assignment.greedy(bids))
        target = np.where(inputs.alive, target, -1)
        return Assigned(target, fused.seconds, none, none)


class Greedy(Method):
    """Same fusion as distributed; each UAV takes its own best bid."""

    name = "greedy"

    def assign(self, inputs: Inputs, fused: Fused, bids: np.ndarray) -> Assigned:
        start = time.perf_counter()
        out = assignment.greedy(bids)
        seconds = np.full(out.shape, (time.perf_counter() - start) / out.size)
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
    return registry.load(method)
