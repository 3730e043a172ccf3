"""What every method shares: the `Method` interface, the records a cycle hands it
(`Inputs`, `Fused`, `Assigned`, `Held`, `Setting`), and the consensus fusion of the
distributed and greedy methods (`consensus`, with the robust gate, `gated`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any, ClassVar

import numpy as np

from .. import estimation, fusion, network
from ..config import Scenario
from ..numerics.buffers import Buffers, take
from ..numerics.codec import CODECS, Codec
from ..radio import Radio, Wire, counted
from ..robust import gate
from ..tracks import association, manage, team
from ..tracks.columns import Columns


@dataclass(frozen=True, kw_only=True)
class Setting:
    """What a run fixes for the methods: robustness options and the fault settings.

    forward(tuples, k): tuples (`fusion.Estimates` with mean, cov and stamp) predicted
    forward to step k, with their confidence gamma recomputed.
    plan(uavs, mean, top=None): bids (B, N, M) and first actions of UAVs at `uavs`
    (B, N, 5) with fused estimates `mean` (B, N, M, 4), as `planning.plan` under the
    scenario (top: how many best bids each UAV needs, None: all). prune: whether a
    method may ask for fewer than all bids (``planner.prune``, and a radio that neither
    loses nor delays, so that every UAV knows the neighbourhoods its bids serve).
    rule: the fusion rule of each consensus round (``fusion.rule``). gate: the
    measurement gate's threshold on a squared Mahalanobis distance (``robust.gate``,
    `gate.threshold`; None: off). scenario: the run's (the trackers of unknown
    association read their settings there). trigger and refresh: ``fusion.trigger`` and
    ``fusion.refresh``; encoding: ``radio.encoding`` (`compact`: any but full, whose
    `codec` says how an estimate travels).
    """

    faulty: bool
    delay: int
    budget: int | None
    extra_rounds: int
    stale: bool
    forward: Callable[[fusion.Estimates, int], fusion.Estimates]
    plan: Callable[..., tuple[np.ndarray, ...]]
    prune: bool = False
    rule: str = "max_consensus"
    gate: float | None = None
    scenario: Scenario | None = None
    trigger: float | None = None
    refresh: int = 10
    encoding: str = "full"
    wire: Wire | None = None
    """The run's message shapes (`wire_of`), read once per run; None: read on use."""

    @property
    def compact(self) -> bool:
        """Whether estimates travel listed and encoded (`codec`): any encoding but full."""
        return self.encoding != "full"

    @property
    def codec(self) -> Codec | None:
        """How an estimate travels (`numerics.codec.Codec`), None: float64 as it is."""
        return CODECS.get(self.encoding)

    @property
    def tuples(self) -> str:
        """How the consensus messages carry their tuples (`radio.layout`)."""
        return self.encoding if self.compact else "listed" if self.trigger is not None else "full"


@dataclass(frozen=True)
class Held:
    """The last bid each UAV heard of each other: value (B, N, N, M) [trial, receiver,
    sender], and the step it was sent, stamp (B, N, N) (-1: never heard)."""

    value: np.ndarray
    stamp: np.ndarray


@dataclass(frozen=True, kw_only=True)
class Inputs:
    """What a method sees in one cycle for B trials: the radio, each UAV's local
    estimates after its filter (mean (B, N, M, 4), cov (B, N, M, 4, 4), gamma (B, N, M)),
    the UAV states as the UAVs believe them (B, N, 5), who is alive (B, N), each UAV's
    previous target (B, N) (-1: none), the bids held (`Held`, when messages get lost),
    and with the measurement gate (``robust.gate``) what each UAV measured
    (`gate.Measured`).

    With tracks (unknown association) the bids' targets (B, N, L) are the columns of team
    labels, while mean, cov and gamma stay per track slot (B, N, K, ...): `columns`
    (`tracks.columns.Columns`) says which label each column is (``columns.labels`` (B,
    L)) and which column each slot holds (``columns.column`` (B, N, K), -1: not
    confirmed), and ``columns.per_label(inputs.mean)`` gives each UAV's estimate of each
    column's target (B, N, L, 4), NaN where it holds none. holds (B, N, L) says which
    labels each UAV holds confirmed: a UAV knows a label only from its own tracks and the
    bids that reached it, so the bids it holds of a sender count only for such labels.
    docs: Your own method, with tracks."""

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
    holds: np.ndarray | None = None
    buffers: Buffers | None = None
    """A run's arrays reused across cycles (`numerics.buffers`), for the full-size
    results of fusion; None: every result a new array."""
    told: np.ndarray | None = None
    """With ``fusion.trigger``: the confidence each UAV last sent of each target (B, N,
    M) (NaN: never); with tracks, of each slot (B, N, K)."""
    told_labels: np.ndarray | None = None
    """With ``fusion.trigger`` and tracks: the label each UAV last sent of each slot
    (B, N, K) (-1: never)."""
    columns: Columns | None = None
    """With tracks: the team labels of the bids' columns and the column of each track
    slot (`tracks.columns.Columns`); None with known association (column j: target j)."""
    recent: np.ndarray | None = None
    """With ``planner.avoidance_model = "measured"``: each UAV's recent commands (B, N),
    which its beacon carries (`airspace.response.recent`)."""


def beacon_of(believed: np.ndarray, k: int, recent: np.ndarray | None) -> dict[str, np.ndarray]:
    """The avoidance beacons' content: each UAV's state as it believes it (B, N, 5), the
    step, and with the measured model its recent commands (B, N)."""
    content = {"uavs": believed, "stamp": np.full(believed.shape[:2], k)}
    if recent is not None:
        content["recent"] = recent
    return content


@dataclass(frozen=True, kw_only=True)
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
    told: np.ndarray | None = None  # with fusion.trigger: `Inputs.told` after this cycle


@dataclass(frozen=True, kw_only=True)
class Assigned:
    """Targets (B, N) (-1 for a failed UAV), seconds of each UAV's assignment (B, N, 2):
    CPU and wall (`timing`; a method's own (B, N) stands for both), messages sent and
    delivered (B,), and the bids held for the next cycle."""

    target: np.ndarray
    seconds: np.ndarray
    sent: np.ndarray
    delivered: np.ndarray
    held: Held | None = None


@dataclass(frozen=True, kw_only=True)
class Local:
    """What a method's track fusion starts from, with unknown association
    (``tracker.association`` gnn or jpda): each UAV's tracks predicted to this scan
    (`manage.Book` book, mean (B, N, K, 4), cov (B, N, K, 4, 4)), its scan (z (B, N, Z,
    2), R (B, N, Z, 2, 2), valid (B, N, Z)), the run's filter (`estimation.Tracker`) and
    with an IMM each slot's modes, a central node's tracks predicted to this scan
    (`manage.Slots` with N = 1; None for a method without one), and the tombstones each
    UAV knows (`team.TrackSet`; None for a method that keeps none)."""

    book: manage.Book
    mean: np.ndarray
    cov: np.ndarray
    z: np.ndarray
    R: np.ndarray
    valid: np.ndarray
    tracker: estimation.Tracker
    modes: estimation.Modes | None = None
    central: manage.Slots | None = None
    tombs: np.ndarray | None = None
    seen: np.ndarray | None = None  # with robust.gate: the step each slot last met a scan


@dataclass(frozen=True, kw_only=True)
class FusedTracks:
    """Each UAV's tracks after its scan and the fusion (book, mean, cov as in `Local`),
    changed (B, N, K) int8 (`team.agree`'s codes: 0 the UAV's own filter, 1 its own track
    with a fused estimate, 2 a track new to it, 3 emptied), the rounds each UAV ran
    (B, N), messages sent and delivered (B,), each UAV's own tracks after its scan,
    before the fusion (own; with an IMM its modes, which the fused estimates restart),
    and the central node's tracks after the scans (None without one)."""

    book: manage.Book
    mean: np.ndarray
    cov: np.ndarray
    changed: np.ndarray
    rounds: np.ndarray
    sent: np.ndarray
    delivered: np.ndarray
    own: manage.Slots | None = None
    central: manage.Slots | None = None
    tombs: np.ndarray | None = None
    told: np.ndarray | None = None  # with fusion.trigger: `Inputs.told` after this cycle
    told_labels: np.ndarray | None = None  # and `Inputs.told_labels`
    target: np.ndarray | None = None  # the labels a central node sent to follow (B, N)
    seen: np.ndarray | None = None  # with robust.gate: `Local.seen` after this cycle


class Method:
    """Interface of a decision method; subclasses override `fuse` and `assign`."""

    name: ClassVar[str]
    central: ClassVar[bool] = False
    """Whether one node plans for everyone (its decision time is the whole team's)."""
    plans: ClassVar[bool] = True
    """Whether the cycle plans and assigns (`simulation.decide`); a method whose UAVs
    choose their actions otherwise (`actions`, a learned policy) sets it False."""
    local: bool = True
    """Whether each UAV decides from what it holds and hears alone, so that the agent
    form can run it (a graph policy reads the whole team's observations: False)."""

    def fuse(self, inputs: Inputs) -> Fused:
        """Consensus over the radio: the D_i protocol, then max-consensus rounds."""
        return consensus(inputs)

    def fuse_tracks(self, inputs: Inputs, local: Local) -> FusedTracks:
        """With unknown association: each UAV's own tracker runs on its scan
        (`manage.scan`), then the team agrees on tracks over the radio (`team_fusion`)."""
        return team_fusion(inputs, local)

    def assign(self, inputs: Inputs, fused: Fused, bids: np.ndarray) -> Assigned:
        """Targets from bids (B, N, M)."""
        raise NotImplementedError

    def refusal(self, scenario: Scenario) -> str | None:
        """Why this method cannot run `scenario`, in one line, or None (every built-in
        method runs every scenario the model takes)."""
        return None

    def actions(self, state: Any, pending: Any, ctx: Any) -> np.ndarray | None:
        """The actions (B, N) the UAVs fly this cycle (indices into the action set) from
        the cycle's `records.State`, `records.Pending` and `simulation.Context` (the
        records name this module: not named here), or None: the planned ones."""
        return None

    def choose(self, view: Any, scenario: Scenario) -> np.ndarray:
        """The actions (B, N) a method that does not plan chooses from a cycle's view
        (`env.spaces.View`): how one UAV program asks it (the agent form), its view
        holding its own row. A method that plans chooses none."""
        raise NotImplementedError(f"method {self.name!r} plans: it chooses from no view")

    def top(self, setting: Setting, largest: np.ndarray | None) -> np.ndarray | None:
        """How many of its best bids each UAV's assignment can read (B, N), or None: all
        (the default: a method that does not say needs every bid). The planner scores
        only what can be among them (`planning.plan_top`); the others are NaN.

        largest (B, N): the most members of a closed neighbourhood each UAV belongs to
        (`fusion.Depth`; None when the fusion did not learn it)."""
        return None

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


def fusion_rounds(inputs: Inputs) -> tuple[fusion.Depth, np.ndarray]:
    """The D_i protocol over the cycle's radio (`fusion.learn_depth`) and the rounds
    (B, N) each living UAV fuses for: its depth plus ``extra_rounds``, at most the
    round budget; 0 for the dead."""
    s, alive = inputs.setting, inputs.alive
    depth = fusion.learn_depth(inputs.radio, alive, s.budget)
    rounds = np.where(alive, depth.depth + s.extra_rounds, 0)
    if s.budget is not None:
        rounds = np.minimum(rounds, s.budget)
    return depth, rounds


def wire_of(scenario: Scenario, plans: bool = True) -> Wire:
    """What shapes a run's messages (`radio.Wire`): its team, its track slots and the
    download's book fields with unknown association, the beacon and the consensus
    listing. The one reading of these settings the batch's bytes, the radio's shares and
    the agents' admission share. The beacon carries the sender's whole state with
    ``planner.avoidance`` or for a method that does not plan (`Method.plans`: a learned
    policy reads its neighbours' states)."""
    tracked = scenario.tracker.unlabelled
    return Wire(
        n=scenario.n_uavs,
        m=scenario.n_targets,
        slots=scenario.track_slots if tracked else 0,
        avoid=scenario.planner.avoidance != "none" or not plans,
        tuples=scenario.radio.encoding
        if scenario.radio.encoding != "full"
        else "listed"
        if scenario.fusion.trigger is not None
        else "full",
        book=manage.sent_fields(scenario.tracker) if tracked else (),
        recent=scenario.planner.avoidance_model == "measured",
    )


def shaped(inputs: Inputs) -> Wire:
    """The run's `radio.Wire` (`wire_of`; a method run without a scenario: the team and
    targets of its inputs)."""
    setting = inputs.setting
    if setting.wire is not None:
        return setting.wire
    if setting.scenario is None:
        return Wire(n=inputs.alive.shape[1], m=inputs.gamma.shape[-1])
    return wire_of(setting.scenario)


def wire(inputs: Inputs, protocol: str, rows: np.ndarray | None = None) -> np.ndarray | int:
    """The bytes of `protocol`'s content as the agent form sends it (`radio.Wire.bytes`;
    `rows`: a scan's measurements, (B, N))."""
    return shaped(inputs).bytes(protocol, rows)


def rounds_on_air(
    inputs: Inputs, depth: fusion.Depth, rounds: np.ndarray, carried: list[np.ndarray] | None
) -> None:
    """The frames of the D_i flooding with the consensus (`radio.Radio.rounds_on_air`):
    every round's tuples, or with `carried` (`fusion.Outcome.carried`) those listed."""
    shape = shaped(inputs)
    flood = shape.bytes("flood")
    if carried is None:
        tuples: Any = shape.bytes("consensus", tuples="full")
    else:
        tuples = [shape.bytes("consensus", rows) for rows in carried]
    inputs.radio.rounds_on_air(depth.ran, rounds, int(flood), tuples, inputs.alive)


def sending(
    inputs: Inputs, view: Callable[[fusion.Estimates], tuple[np.ndarray, ...]] | None = None
) -> fusion.Sending | None:
    """Which tuples the consensus messages carry: with ``fusion.trigger`` a target's in
    the first round when its confidence changed by more than the trigger since the UAV
    last sent it, or it never did, or the cycle is a refresh (k a multiple of
    ``fusion.refresh``), and in later rounds what changed; with the compact encoding
    alone, everything in the first round and what changed in the later ones; None: the
    paper's, everything in every round. view: what of a tuple counts as its change
    (`fusion.Sending.view`)."""
    s = inputs.setting
    if s.trigger is None and not s.compact:
        return None
    first = None
    if s.trigger is not None:
        first = fusion.triggered(inputs.gamma, inputs.told, inputs.k, s.trigger, s.refresh)
    budget = inputs.radio.now.budget
    until = None if budget is None else budget.rounds
    return fusion.Sending(first=first, changes=True, view=view, until=until)


def told_after(inputs: Inputs, out: fusion.Outcome) -> np.ndarray | None:
    """`Inputs.told` after this cycle's consensus (None without the trigger)."""
    if inputs.setting.trigger is None or out.last is None:
        return None
    before = np.full(out.last.shape, np.nan) if inputs.told is None else inputs.told
    return np.where(np.isnan(out.last), before, out.last)


def consensus(inputs: Inputs) -> Fused:
    """The paper's fusion (Algorithm 2 lines 15-25) over the cycle's radio.

    Without delay the tuples travel as the index of the UAV whose local estimate they
    are; with delay they travel by value with their time stamps (estimates of earlier
    cycles), predicted forward before use when ``robust.stale``. With the compact
    encoding a tuple that travelled holds the values it arrived with (`radio.wire_mean`,
    `radio.wire_cov`) and their confidence: by index, N + i stands for UAV i's estimate
    so delivered (`Held`).
    """
    s, radio = inputs.setting, inputs.radio
    depth, rounds = fusion_rounds(inputs)
    held = Arrived(inputs)
    admit = gated(inputs, held)
    if s.delay == 0 and s.rule == "max_consensus":
        tuples = fusion.Estimates(gamma=inputs.gamma, source=fusion.identity(inputs.gamma.shape))
        how = sending(inputs, held.view)
        receive = held.arrived if s.compact else None
        out = fusion.consensus(radio, tuples, rounds, admit=admit, receive=receive, sending=how)
        source = fusion.required(out.tuples.source, "source")
        pool = inputs.buffers
        mean = held.gather(source, "mean", take(pool, "fused mean", inputs.mean.shape))
        cov = held.gather(source, "cov", take(pool, "fused cov", inputs.cov.shape))
        gamma = out.tuples.gamma  # travelled with the source: confidence(cov) exactly
    else:
        how = sending(inputs)  # its change: a change of any field, whose the tuple is too
        tuples = fusion.Estimates(
            gamma=inputs.gamma,
            mean=inputs.mean,
            cov=inputs.cov,
            stamp=np.full(inputs.gamma.shape, inputs.k),
            origin=None if how is None else fusion.identity(inputs.gamma.shape),
        )

        def arrive(t: fusion.Estimates) -> fusion.Estimates:  # as it arrives, to now
            t = delivered(t, s.codec) if s.codec is not None else t
            return s.forward(t, inputs.k) if s.stale else t

        on = s.stale or s.compact
        out = fusion.consensus(
            radio, tuples, rounds, receive=arrive if on else None, rule=s.rule,
            admit=admit, sending=how,
        )  # fmt: skip
        mean, cov = fusion.required(out.tuples.mean, "mean"), fusion.required(out.tuples.cov, "cov")
        gamma = None
    rounds_on_air(inputs, depth, rounds, out.carried)
    sent, delivered_ = counted(
        s.delay,
        lambda: (radio.transmitted("flood", depth.ran), radio.transmitted("consensus", rounds)),
        ((depth.sent, depth.delivered), (out.sent, out.delivered)),
    )
    return Fused(
        mean=mean,
        cov=cov,
        rounds=rounds,
        sent=sent,
        delivered=delivered_,
        largest=depth.largest,
        gamma=gamma,
        told=told_after(inputs, out),
    )


def delivered(t: fusion.Estimates, codec: Codec) -> fusion.Estimates:
    """Tuples by value as an encoding delivers them (`numerics.codec.Codec.delivered`), the
    confidence computed from what arrived (-inf, no estimate, stays)."""
    mean, cov = codec.delivered(fusion.required(t.mean, "mean"), fusion.required(t.cov, "cov"))
    gamma = fusion.required(t.gamma, "gamma")
    gamma = np.where(np.isneginf(gamma), gamma, estimation.confidence(cov))
    return dataclasses.replace(t, mean=mean, cov=cov, gamma=gamma)


class Arrived:
    """A cycle's local estimates by index (`fusion.Estimates.source`), as the UAVs hold
    them and as the compact encoding delivers them: source i < N is UAV i's estimate as
    it is, N + i the same as it arrives (`radio.wire_mean`, `radio.wire_cov`, its
    confidence computed from what arrived). Without the compact encoding every source is
    below N."""

    def __init__(self, inputs: Inputs) -> None:
        self.inputs, self.n = inputs, inputs.gamma.shape[1]
        self._wired: dict[str, np.ndarray] = {}

    def wired(self, name: str) -> np.ndarray:
        """The local estimates' `name` (mean, cov, gamma) as they arrive."""
        if name not in self._wired:
            codec = self.inputs.setting.codec
            assert codec is not None, "estimates arrive as they are without an encoding"
            mean, cov = codec.delivered(self.inputs.mean, self.inputs.cov)
            self._wired |= {"mean": mean, "cov": cov, "gamma": estimation.confidence(cov)}
        return self._wired[name]

    def arrived(self, t: fusion.Estimates) -> fusion.Estimates:
        """Tuples by index as a receiver gets them over the compact encoding."""
        source, gamma = fusion.required(t.source, "source"), fusion.required(t.gamma, "gamma")
        fresh = source < self.n  # not through the radio before
        wired = fusion.gather(source % self.n, self.wired("gamma")[..., None])[..., 0]
        gamma = np.where(fresh & ~np.isneginf(gamma), wired, gamma)
        return dataclasses.replace(t, gamma=gamma, source=np.where(fresh, source + self.n, source))

    def view(self, t: fusion.Estimates) -> tuple[np.ndarray, ...]:
        """What a tuple by index holds, as an agent's tuple by value does: confidence,
        whose estimate, the estimate and its covariance (`fusion.Sending.view`)."""
        source = fusion.required(t.source, "source")
        gamma = fusion.required(t.gamma, "gamma")
        return gamma, source % self.n, self.gather(source, "mean"), self.gather(source, "cov")

    def gather(self, source: np.ndarray, name: str, out: np.ndarray | None = None) -> np.ndarray:
        """`fusion.gather` of the estimates' `name` (mean, cov) that the sources stand for."""
        values = getattr(self.inputs, name)
        through = source >= self.n
        if not through.any():
            return fusion.gather(source, values, out)
        held = fusion.gather(source % self.n, values, out)
        arrived = fusion.gather(source % self.n, self.wired(name))
        np.copyto(held, arrived, where=through.reshape(through.shape + (1,) * (held.ndim - 3)))
        return held


Admit = Callable[[fusion.Estimates, fusion.Estimates, network.Links], np.ndarray]
"""admit(own, offered, links): which offered tuples each receiver may adopt, in the
layout of `links` (`fusion.consensus`)."""


def gated(inputs: Inputs, held: Arrived | None = None) -> Admit | None:
    """The consensus's admit(own, offered, links) under the measurement gate
    (``robust.gate``, `gate.admitted`), or None without it. Tuples that travel as the
    index of the UAV whose estimate they are (`fusion.Estimates.source`) are looked up
    in the local estimates (`held`: as they are held, or arrived)."""
    held = Arrived(inputs) if held is None else held
    threshold, measured = inputs.setting.gate, inputs.measured
    if threshold is None or measured is None:
        return None

    def estimates(tuples: fusion.Estimates) -> tuple[np.ndarray, np.ndarray]:
        if tuples.source is not None:
            source = tuples.source
            return held.gather(source, "mean"), held.gather(source, "cov")
        return fusion.required(tuples.mean, "mean"), fusion.required(tuples.cov, "cov")

    listed = inputs.setting.trigger is not None or inputs.setting.compact

    def admit(own: fusion.Estimates, offered: fusion.Estimates, links: network.Links) -> np.ndarray:
        claimed = np.isfinite(fusion.required(offered.gamma, "gamma")) if listed else None
        mine, theirs = estimates(own), estimates(offered)
        return gate.admitted(links, mine, theirs, measured, threshold, claimed)

    return admit


def scanned_tracks(scanned: manage.Scanned, tombs: np.ndarray | None, k: int) -> team.TrackSet:
    """What a UAV offers the team after its scan at step k: its slots with their labels,
    status and stamps, and its tombstones (B, N, T, 2) with the confirmed tracks it
    deleted after missing them in view entered (`team.entomb`)."""
    if tombs is not None and scanned.dead is not None:
        tombs = team.entomb(tombs, scanned.dead, k)
    book = scanned.book
    return team.TrackSet(
        mean=scanned.mean, cov=scanned.cov, label=book.label, status=book.status,
        stamp=book.stamp, tombs=tombs,
    )  # fmt: skip


def team_fusion(inputs: Inputs, local: Local) -> FusedTracks:
    """Each UAV's scan on its own tracks (`manage.scan`), then the D_i protocol and as
    many rounds of track-to-track association and fusion (`team.agree`): the paper's
    fusion (Algorithm 2 lines 15-25) over tracks that carry team labels."""
    s, radio, alive = inputs.setting, inputs.radio, inputs.alive
    scenario = s.scenario
    if scenario is None:
        raise ValueError("the track fusion needs the scenario in the setting")
    scanned = manage.scan(
        local.book, local.mean, local.cov, local.z, local.R, local.valid,
        inputs.believed, alive, scenario, local.modes, local.tracker, inputs.k,
    )  # fmt: skip
    depth, rounds = fusion_rounds(inputs)
    book = scanned.book
    own = scanned_tracks(scanned, local.tombs, inputs.k)
    threshold = association.threshold(scenario.tracker.gate_probability, 4)
    listing = track_listing(inputs, own)

    def late(offered: team.TrackSet) -> team.TrackSet:  # sent cycles ago: to this scan
        mean, cov = forwarded(s, offered.mean, offered.cov, inputs.k - s.delay, inputs.k)
        return dataclasses.replace(offered, mean=mean, cov=cov)

    receive = late if s.delay > 0 else None
    scan = (local.z, local.R, local.valid)
    seen, admit = gated_tracks(s, inputs.k, local.seen, scanned.met, scan, inputs.believed)
    out = team.agree(radio, own, rounds, threshold, s.rule, listing, receive, admit)
    agreed, changed, sent, delivered = out.tracks, out.changed, out.sent, out.delivered
    rounds_on_air(inputs, depth, rounds, out.carried)
    told = told_tracks(inputs, out)
    book = manage.after_fusion(book, agreed.label, agreed.status, changed, scenario, agreed.stamp)
    sent, delivered = counted(
        s.delay,
        lambda: (radio.transmitted("flood", depth.ran), radio.transmitted("consensus", rounds)),
        ((depth.sent, depth.delivered), (sent, delivered)),
    )
    return FusedTracks(
        book=book,
        mean=agreed.mean,
        cov=agreed.cov,
        changed=changed,
        rounds=rounds,
        sent=sent,
        delivered=delivered,
        own=manage.Slots(
            book=scanned.book, mean=scanned.mean, cov=scanned.cov, modes=scanned.modes
        ),
        tombs=agreed.tombs,
        told=told[0],
        told_labels=told[1],
        seen=None if seen is None else np.where(changed >= team.ADOPTED, NEVER, seen),
    )


NEVER = -(2**40)
"""The step a slot's own scans last met it when they never did (a track adopted from
the team, or an empty slot): long enough ago for any ``robust.gate_memory``."""


def gated_tracks(
    setting: Setting,
    k: int,
    seen: np.ndarray | None,
    met: np.ndarray,
    local: tuple[np.ndarray, np.ndarray, np.ndarray],
    believed: np.ndarray,
) -> tuple[np.ndarray | None, team.Admit | None]:
    """``robust.gate`` with tracks: the step each slot last met a scan of its own UAV
    (`gate.seen`, B, N, K), and which offered tracks each receiver may take
    (`gate.tracks_admitted` against its slots met within ``robust.gate_memory`` and its
    scan); (None, None) without the gate. seen: the steps before this scan (None: the
    run's start); met (B, N, K): the slots this scan met (`manage.Scanned`); local: the
    scan's z (B, N, Z, 2), R and valid; believed (B, N, 5). The agent form calls it on
    its own row."""
    if setting.gate is None or setting.scenario is None:
        return None, None
    threshold, scenario = setting.gate, setting.scenario
    seen = gate.seen(seen, met, k)
    z, R, valid = local
    (B, N, Z), K = valid.shape, seen.shape[-1]
    scans = gate.Scanned(
        z=z.reshape(B * N, Z, 2),
        R=R.reshape(B * N, Z, 2, 2),
        valid=valid.reshape(B * N, Z),
        uav=believed.reshape(B * N, -1),
        recent=(k - seen <= scenario.robust.gate_memory).reshape(B * N, K),
    )

    admit = partial(gate.tracks_admitted, scanned=scans, sensor=scenario.sensor, gate=threshold)
    return seen, admit


def forwarded(
    setting: Setting, mean: np.ndarray, cov: np.ndarray, sent: int, k: int
) -> tuple[np.ndarray, np.ndarray]:
    """Track estimates (..., 4), (..., 4, 4) sent at step `sent` predicted to step k
    (`Setting.forward`, the targets' model), as a receiver takes tracks that arrive late."""
    stamp = np.full(mean.shape[:-1], sent, dtype=np.int64)
    tuples = fusion.Estimates(gamma=np.zeros(stamp.shape), mean=mean, cov=cov, stamp=stamp)
    out = setting.forward(tuples, k)
    return fusion.required(out.mean, "mean"), fusion.required(out.cov, "cov")


def told_tracks(inputs: Inputs, out: team.Agreement) -> tuple[np.ndarray | None, np.ndarray | None]:
    """With ``fusion.trigger``: what each UAV last sent of each slot after this cycle
    (`Inputs.told`, `Inputs.told_labels`), this cycle's where it sent one; (None, None)
    without."""
    if inputs.setting.trigger is None or out.told is None or out.told_labels is None:
        return None, None
    if inputs.told is None or inputs.told_labels is None:
        return out.told, out.told_labels
    unsent = np.isnan(out.told)
    told = np.where(unsent, inputs.told, out.told)
    return told, np.where(unsent, inputs.told_labels, out.told_labels)


def track_listing(inputs: Inputs, tracks: team.TrackSet) -> team.Listing | None:
    """Which slots the track consensus lists (`team.Listing`), as `sending` for tuples:
    with ``fusion.trigger`` those `team.triggered` picks in the first round, with the
    compact encoding every confirmed one; in later rounds what changed. None: every
    slot in every round, the full encoding."""
    s = inputs.setting
    if s.trigger is None and not s.compact:
        return None
    first = None
    if s.trigger is not None:
        first = team.triggered(
            tracks, inputs.told, inputs.told_labels, inputs.k, s.trigger, s.refresh
        )
    budget = inputs.radio.now.budget
    until = None if budget is None else budget.rounds
    return team.Listing(first=first, codec=s.codec, until=until)
