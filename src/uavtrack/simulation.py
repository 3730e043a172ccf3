"""The decision cycle (paper Fig. 3, Algorithm 2) and runs of it.

    truth -> sensing -> local filter -> max-consensus -> planning -> auction -> control

`step` is one cycle for a batch of independent trials (leading axis B), one call per
stage; an environment can hand in the actions to fly instead of the method's. `run`
iterates it; `simulate` is one trial with its full trace.

The cycle's records (`State`, `Pending`, `Cycle`, `Trace`, `Result`) are declared in
`records`, below the metrics, and named here too.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from functools import cache, cached_property
from numbers import Integral
from typing import Any, Protocol

import numpy as np

from . import _process, estimation, flight, fusion, network, planning, sensing, timing, world
from .airspace import avoidance, response
from .config import G, Scenario, ScenarioError, SensorModel
from .faults import PROTOCOLS, Faults, trial_key
from .flight.unicycle import Unicycle
from .methods import Assigned, Distributed, Fused, Held, Inputs, Method, Setting, get
from .methods.base import FusedTracks, Local, beacon_of, wire_of
from .metrics import METRICS, NEES_BINS_PER_DECADE, NEES_DECADES, PER_UAV_SETS
from .numerics import lsap
from .numerics.buffers import Buffers
from .radio import (
    Inbox,
    Limit,
    Radio,
    RadioState,
    counted,
    frame_bytes,
    int_bytes,
    part_bytes,
)
from .records import (
    RECORDED as RECORDED,
)
from .records import (
    TRACKED as TRACKED,
)
from .records import (
    BatchResult as BatchResult,
)
from .records import (
    Cycle as Cycle,
)
from .records import (
    Pending as Pending,
)
from .records import (
    Result as Result,
)
from .records import (
    State as State,
)
from .records import (
    Trace as Trace,
)
from .robust import gate
from .tracks import columns, manage
from .tracks import scan as scans
from .tracks.scoring import Scores
from .tracks.scoring import series as series
from .world import Targets, detection_stream, draw_start, streams
from .world import trial_seed as trial_seed  # public here too

NOISE_BLOCK = 64
"""Most steps of sensor noise drawn at once per trial (a draw of n normals equals n
draws of 1, so the block changes no number)."""

NOISE_BYTES = 64 * 2**20
"""Most memory a block of sensor noise takes; large teams draw fewer steps at once."""


def sensor_noise(
    rngs: Sequence[np.random.Generator], n_uavs: int, n_targets: int, steps: int
) -> Iterator[np.ndarray]:
    """The standard normals of each step's measurements, (B, Nu, Nt, 2) per step, from
    each trial's sensor stream, drawn a block of steps at a time."""
    per_step = len(rngs) * n_uavs * n_targets * 2 * 8
    block = int(np.clip(NOISE_BYTES // per_step, 1, NOISE_BLOCK))
    for start in range(0, steps, block):
        count = min(block, steps - start)
        draws = [rng.standard_normal((count, n_uavs, n_targets, 2)) for rng in rngs]
        noise = draws[0][:, None] if len(draws) == 1 else np.stack(draws, axis=1)
        del draws  # the block alone stays
        yield from noise


STRAIGHT = 1
"""Index of the zero bank angle in the action set (-phi, 0, +phi): a failed UAV's."""


@dataclass(frozen=True)
class Constants:
    """What a run derives once from its scenario."""

    A: np.ndarray
    Q: np.ndarray
    actions: np.ndarray
    tracker: estimation.Tracker

    @classmethod
    def of(cls, scenario: Scenario) -> Constants:
        tracker = estimation.Tracker.of(scenario.dt, scenario.acceleration_std(), scenario.tracker)
        return cls(
            A=tracker.A,
            Q=tracker.Q,
            actions=planning.action_set(np.radians(scenario.uav.bank_angle_deg)),
            tracker=tracker,
        )


@dataclass(frozen=True, kw_only=True)
class Context:
    """What a run fixes: the scenario, the method, derived constants, the fault
    realisation of its trials and the methods' settings."""

    scenario: Scenario
    method: Method
    const: Constants
    faults: Faults
    setting: Setting
    detection: scans.Draws | None = None
    """Each trial's draws of missed detections, clutter and scan order
    (`tracks.scan.Draws`), when the sensor misses or sees clutter, or the scans come
    unlabelled; None for the paper's sensor."""
    buffers: Buffers | None = None
    """Set by the batch driver (`run`) alone, which owns its states: the full-size
    arrays its cycles reuse (`numerics.buffers`), and each state's estimates are
    updated in place. None: a cycle leaves the state it is given untouched."""

    @cached_property
    def associator(self) -> Associator:
        """How the cycle reads measurements: the oracle (known association) or tracks."""
        return TRACKING if self.scenario.tracker.unlabelled else ORACLE

    @classmethod
    def of(
        cls, scenario: Scenario, method: Method, seeds: Sequence[np.random.SeedSequence]
    ) -> Context:
        why = refusal(scenario, method)
        if why is not None:
            raise ScenarioError(why)
        tracked = scenario.tracker.unlabelled
        const = Constants.of(scenario)
        keys = np.stack([trial_key(world.children(s)[2]) for s in seeds])
        faults = Faults(scenario.faults, keys, scenario.n_uavs)
        f, robust = scenario.faults, scenario.robust
        setting = Setting(
            faulty=faults.active or scenario.radio.bandwidth_bps is not None,
            delay=f.delay,
            budget=f.round_budget,
            extra_rounds=robust.extra_rounds,
            stale=robust.stale,
            forward=_forward(scenario.dt, *scenario.acceleration_std()),
            plan=lambda uavs, mean, top=None: _plan(uavs, mean, scenario, top),
            prune=scenario.prunes,
            rule=scenario.fusion.rule,
            gate=None if robust.gate is None else gate.threshold(robust.gate),
            scenario=scenario,
            trigger=scenario.fusion.trigger,
            refresh=scenario.fusion.refresh,
            encoding=scenario.radio.encoding,
            wire=wire_of(scenario, method.plans),
        )
        detection = None
        if not scenario.sensor.ideal or tracked:
            detection = scans.Draws.of([detection_stream(s) for s in seeds])
        return cls(
            scenario=scenario,
            method=method,
            const=const,
            faults=faults,
            setting=setting,
            detection=detection,
        )


def refusal(scenario: Scenario, method: Method) -> str | None:
    """Why `method` cannot run `scenario` (a piece not built yet, docs/how-to/pairs.md),
    or None: what `Context.of` refuses, for a caller to check every run before any.
    The method's own refusal (`Method.refusal`) comes first."""
    own = method.refusal(scenario)
    if own is not None:
        return own
    listed = scenario.radio.encoding != "full" or scenario.fusion.trigger is not None
    if method.central and listed:
        return (
            "radio.encoding (compact, quantized) and fusion.trigger act on the consensus of the "
            f"distributed and greedy methods; method {method.name} uploads and downloads "
            "whole tables, which they do not encode yet: leave both unset"
        )
    return None


def _plan(
    uavs: np.ndarray, mean: np.ndarray, scenario: Scenario, top: np.ndarray | None
) -> tuple[np.ndarray, ...]:
    uavs, drift = _air(uavs, scenario)
    p = planning.plan(uavs, mean, *_planner(scenario), G, top, drift)
    return p.value, p.action


def first_values(uavs: np.ndarray, mean: np.ndarray, scenario: Scenario) -> np.ndarray:
    """`planning.first_values` under the scenario, as a run plans: uavs (..., Nu, 5),
    mean (..., Nu, Nt, 4) -> (..., Nu, Nt, 3)."""
    uavs, drift = _air(uavs, scenario)
    return planning.first_values(uavs, mean, *_planner(scenario), G, drift)


def _air(uavs: np.ndarray, scenario: Scenario) -> tuple[np.ndarray, np.ndarray | None]:
    """The UAVs as the planner flies them: in the moving air mass with ``planner.wind``;
    at the cruise speed with ``uav.min_speed`` (a UAV the filter slowed flies on at it)."""
    if scenario.uav.min_speed is not None:
        uavs = uavs.copy()
        uavs[..., world.V] = scenario.uav.speed
    if scenario.planner.wind and scenario.wind.speed > 0:
        drift = np.array(scenario.wind.velocity())
        return planning.air_relative(uavs, drift), drift
    return uavs, None


def _planner(scenario: Scenario) -> tuple[SensorModel, float, int, float, float]:
    """sensor, bank angle, horizon, dT and discount: `planning.plan`'s settings."""
    p = scenario.planner
    bank = np.radians(scenario.uav.bank_angle_deg)
    return scenario.sensor, bank, p.horizon, scenario.dt, p.discount


def _forward(
    dt: float, sigma_1: float, sigma_2: float
) -> Callable[[fusion.Estimates, int], fusion.Estimates]:
    """forward(tuples, k): time-stamped tuples predicted to step k (eq. 23 applied
    k - stamp times), their confidence recomputed (eq. 22)."""
    A, Q = estimation.transition(dt), estimation.process_noise(dt, sigma_1, sigma_2)

    @cache
    def power(n: int) -> tuple[np.ndarray, np.ndarray]:  # A^n and its accumulated noise
        An, Qn = np.eye(4), np.zeros((4, 4))
        for _ in range(n):
            An, Qn = A @ An, A @ Qn @ A.T + Q
        return An, Qn

    def forward(tuples: fusion.Estimates, k: int) -> fusion.Estimates:
        lag = k - fusion.required(tuples.stamp, "stamp")
        mean = fusion.required(tuples.mean, "mean").copy()
        cov = fusion.required(tuples.cov, "cov").copy()
        for n in np.unique(lag[lag > 0]):
            at = lag == n
            An, Qn = power(int(n))
            mean[at] = mean[at] @ An.T
            cov[at] = An @ cov[at] @ An.T + Qn
        finite = np.isfinite(fusion.required(tuples.gamma, "gamma"))
        gamma = np.where(finite, estimation.confidence(cov), -np.inf)
        return replace(tuples, mean=mean, cov=cov, stamp=np.full(lag.shape, k), gamma=gamma)

    return forward


def _world(state: State, ctx: Context) -> tuple[np.ndarray, np.ndarray]:
    """Who is alive at this step and where the UAVs believe they are."""
    faults, k = ctx.faults, state.k
    alive = faults.alive(k, state.alive) if ctx.setting.faulty else state.alive
    return alive, world.believed(state.uavs, faults.position_error(k))


def _radio(
    state: State,
    ctx: Context,
    alive: np.ndarray,
    rows: np.ndarray | None = None,
    links: network.Links | None = None,
) -> Radio:
    """The cycle's radio (`limit`: `rows`, the measurements each UAV's scan holds) over
    `links`, or the UAVs within r_C when None."""
    if links is None:
        links = network.radio_links(state.uavs, alive, ctx.scenario.comm_range)
    broadcast = ctx.scenario.radio.frames == "broadcast"
    return Radio(
        state.k, links, alive, ctx.faults, state.radio, limit(ctx, state.k, rows), broadcast
    )


def limit(ctx: Context, k: int, rows: np.ndarray | None = None) -> Limit | None:
    """``radio.bandwidth_bps``: the channel and the frames its shares are counted in at
    cycle k (`radio.Limit`), each at its largest (every UAV number at its largest, every
    tuple or track slot in a round); None: unlimited. With tracks the centralized upload
    is each UAV's scan, `rows` (B, N) measurements."""
    scenario, method = ctx.scenario, ctx.method
    bps = scenario.radio.bandwidth_bps
    if bps is None:
        return None
    shape = ctx.setting.wire or wire_of(scenario, method.plans)
    n = shape.n

    def largest(parts: Any, count: int) -> Any:
        return frame_bytes(k, n, parts, count) + int_bytes(n)

    def part(protocol: str, rows: Any = None) -> Any:
        return part_bytes(protocol, 1, -1, shape.bytes(protocol, rows))

    listed = shape.slots or shape.m if shape.tuples != "full" else None
    rounds = int(largest(part("flood") + part("consensus", listed), 2))
    number = int(int_bytes(n)) if scenario.radio.frames == "broadcast" else 0
    beacon = int(largest(part("beacon"), 1)) if shape.avoid else 0  # sent alone
    if method.central:
        upload = largest(part("upload", rows), 1)
        upload = int(upload) if np.ndim(upload) == 0 else np.asarray(upload, dtype=np.int64)
        download = int(largest(part("download"), 1))
        return Limit(
            bytes_per_cycle=bps * scenario.dt / 8, first=upload, round=rounds,
            download=download, central=True, beacon=beacon, broadcast=number,
        )  # fmt: skip
    first = beacon  # the greedy method's first priority: its beacon alone
    if isinstance(method, Distributed) and method.plans:  # a policy sends no bids
        first = int(largest(part("beacon") + part("bids"), 2))
    return Limit(bytes_per_cycle=bps * scenario.dt / 8, first=first, round=rounds, broadcast=number)


def arriving_labels(radio: Radio) -> np.ndarray | None:
    """The labels (B, L') of the bids sent cycles ago that arrive now (``faults.delay``),
    which this cycle's columns hold too: a receiver knows them from the bids (None: no
    delay, or no bids by label)."""
    if radio.delay == 0:
        return None
    inbox = radio.receive("bids")
    if inbox is None or "labels" not in inbox.content:
        return None
    return inbox.content["labels"]


def measured(
    state: State, observed: np.ndarray, z: np.ndarray, R: np.ndarray, ctx: Context
) -> gate.Measured | None:
    """What the measurement gate reads (``robust.gate``; None without it)."""
    if ctx.setting.gate is None:
        return None
    memory = ctx.scenario.robust.gate_memory
    recent = gate.recent(state.seen, state.k, memory, observed.shape)
    return gate.Measured.of(observed, z, R, recent)


def decide(
    state: State, targets: np.ndarray, noise: np.ndarray, ctx: Context, plan: bool = True
) -> Pending:
    """The first part of the cycle at step k = state.k for every trial: faults, sensing,
    local filters, fusion, planning and assignment.

    targets: (B, Nt, 4) true target states at k; noise: (B, Nu, Nt, 2) standard normals.
    plan=False stops after fusion, for agents that choose every action themselves: no
    bids (NaN), no auction (no messages; every UAV keeps its last target) and the
    method's own actions fly straight. What the UAVs sense and know is unchanged.

    The run's associator (`Context.associator`) reads the measurements: the oracle of
    known association (the paper) or the trackers of unlabelled scans. Every other
    stage is the same call for both.
    """
    alive, believed = _world(state, ctx)
    observed, polar = observe(state.uavs, targets, noise, alive, ctx.scenario)
    sensed = detect(state.uavs, believed, observed, polar, alive, ctx)
    return decided(state, sensed, alive, believed, observed, ctx, plan)


def decided(
    state: State,
    sensed: Sensed,
    alive: np.ndarray,
    believed: np.ndarray,
    observed: np.ndarray,
    ctx: Context,
    plan: bool = True,
    links: network.Links | None = None,
) -> Pending:
    """`decide` from what the sensors gave (`Sensed`): the local filters, fusion,
    planning and assignment. A replay of recorded scans (`uavtrack.io.replay`) enters
    here with its own scans and, if it has one, its radio graph `links` (None: UAVs
    within r_C of each other's true positions, `state.uavs`)."""
    scenario, method, associator = ctx.scenario, ctx.method, ctx.associator
    rows = sensed.scan.valid.sum(axis=-1) if method.central and sensed.scan is not None else None
    radio = _radio(state, ctx, alive, rows, links)
    fusion = associator.fuse(state, ctx, sensed, believed, alive, radio)
    fused, owned = fusion.fused, fusion.owned
    if plan:
        start = timing.start()
        top = method.top(ctx.setting, fused.largest)
        bids, best = ctx.setting.plan(believed, fused.mean, top)
        bids = associator.weigh(bids, fusion, alive, scenario)
        plan_seconds = timing.since(start)
        auction = associator.auction(ctx, fusion, bids, alive)
        slot, assigned, taken = auction.slot, auction.assigned, auction.taken
        chosen = np.take_along_axis(best, np.maximum(slot, 0)[..., None], axis=-1)[..., 0]
        own = np.where(alive & (slot >= 0), chosen, STRAIGHT)
    else:  # no bids, no auction: every UAV keeps its target, and flies straight
        kept = np.where(alive, state.target, -1)
        nothing = np.zeros(alive.shape[0], dtype=np.int64)
        assigned = Assigned(
            target=kept, seconds=np.zeros(alive.shape), sent=nothing, delivered=nothing,
            held=state.held,
        )  # fmt: skip
        bids = np.full(alive.shape + (fused.mean.shape[2],), np.nan)
        own, plan_seconds = np.full(alive.shape, STRAIGHT), np.zeros(2)
        taken = None if owned is None else columns.label_column(kept, owned.labels)
    return Pending(
        k=state.k,
        uavs=state.uavs,
        believed=believed,
        alive=alive,
        observed=observed,
        radio=radio,
        fused=fused,
        bids=bids,
        assigned=assigned,
        own=own,
        plan_seconds=plan_seconds,
        belief=fusion.belief,
        detected=sensed.detected,
        tracks=fusion.tracks,
        scan=sensed.scan,
        columns=taken,
        labels=None if fusion.cols is None else fusion.cols.labels,
        held=None if owned is None else (owned.labels >= 0).sum(axis=1),
    )


@dataclass(kw_only=True, slots=True)  # made once a cycle, read, dropped
class Sensed:
    """What the sensors gave at a step: detected (B, Nu, Nt) the pairs measured, polar
    (M, 2) their measurements in ``np.nonzero(detected)`` order, and, for an associator
    that reads scans (gnn, jpda), each UAV's unlabelled scan with its clutter."""

    detected: np.ndarray
    polar: np.ndarray
    scan: scans.Scan | None = None


def detect(
    uavs: np.ndarray,
    believed: np.ndarray,
    observed: np.ndarray,
    polar: np.ndarray,
    alive: np.ndarray,
    ctx: Context,
) -> Sensed:
    """What each UAV measures of the pairs `observed` (polar (K, 2) in the order of
    ``np.nonzero(observed)``): a missed target is not measured; with unknown association
    the rest, with the clutter, comes as one unlabelled scan per UAV, shuffled and
    converted from where each UAV believes it is (`tracks.scan`)."""
    sensor, draws = ctx.scenario.sensor, ctx.detection
    detected = observed
    if draws is not None:
        detected = scans.detected(draws.detect, observed, sensor.detection_probability)
        polar = polar[detected[observed]]
    if draws is None or not ctx.associator.scans:
        return Sensed(detected=detected, polar=polar)
    nothing = (np.zeros(0, dtype=np.int64), np.zeros((0, 2)))
    false = [
        scans.clutter(rng, uavs[b], alive[b], sensor) if sensor.clutter_rate > 0 else nothing
        for b, rng in enumerate(draws.clutter)
    ]
    raw, valid, origin = scans.assemble(draws.order, detected, polar, false, shuffle=True)
    where = np.broadcast_to(believed[:, :, None], raw.shape[:3] + believed.shape[-1:])
    z, R = convert(where[valid], raw[valid], ctx.scenario)
    zz = np.zeros(raw.shape)
    RR = np.broadcast_to(np.eye(2), raw.shape + (2,)).copy()
    zz[valid], RR[valid] = z, R
    scan = scans.Scan(polar=raw, z=zz, R=RR, valid=valid, origin=origin)
    return Sensed(detected=detected, polar=polar, scan=scan)


@dataclass(kw_only=True, slots=True)  # made once a cycle, read, dropped
class Fusion:
    """What an associator's filters and the team's fusion give: the inputs the auction
    reads, the fused estimates per slot, each UAV's own belief before the fusion (the
    oracle's filters), and with tracks the tracks and the step's label columns (`cols`;
    `owned` without the late bids' labels)."""

    inputs: Inputs
    fused: Fused
    belief: estimation.Belief
    tracks: FusedTracks | None = None
    cols: columns.Columns | None = None
    owned: columns.Columns | None = None
    confirmed: np.ndarray | None = None  # (B, Nu, K): the living UAVs' confirmed slots


@dataclass(kw_only=True, slots=True)  # made once a cycle, read, dropped
class Auction:
    """The auction's outcome: assigned (targets, or with tracks labels, to follow),
    slot (B, Nu) the slot whose best action each UAV flies (-1: none, it flies
    straight), and with tracks the column of the label each took (conflicts count them)."""

    assigned: Assigned
    slot: np.ndarray
    taken: np.ndarray | None = None


@dataclass(kw_only=True, slots=True)  # made once a cycle, read, dropped
class Predicted:
    """The state's estimates at k + 1 (`Associator.close`): each UAV's slots and modes,
    with ``robust.gate`` the step each slot last met a measurement (`gate.seen`), and
    with tracks what the book, the central node, the held bids' labels, the tombstones
    and the trigger carry over."""

    mean: np.ndarray
    cov: np.ndarray
    modes: estimation.Modes | None
    book: manage.Book | None = None
    central: manage.Slots | None = None
    labels: np.ndarray | None = None
    tombs: np.ndarray | None = None
    told_labels: np.ndarray | None = None
    seen: np.ndarray | None = None


class Associator(Protocol):
    """How the one cycle turns measurements into slots: the oracle of known association
    (`Oracle`, the paper: slot j is target j) or a tracker of unlabelled scans
    (`Tracking`, gnn or jpda). `decide` and `finish` call these four stages."""

    scans: bool
    """Whether the UAVs' measurements come as unlabelled scans with clutter."""

    def fuse(
        self,
        state: State,
        ctx: Context,
        sensed: Sensed,
        believed: np.ndarray,
        alive: np.ndarray,
        radio: Radio,
    ) -> Fusion:
        """Each UAV's local update and the team's fusion."""
        ...

    def weigh(
        self, bids: np.ndarray, fusion: Fusion, alive: np.ndarray, scenario: Scenario
    ) -> np.ndarray:
        """The planner's bids per slot (B, Nu, K), as the auction reads them."""
        ...

    def auction(self, ctx: Context, fusion: Fusion, bids: np.ndarray, alive: np.ndarray) -> Auction:
        """The method's assignment over the slots' bids."""
        ...

    def close(self, state: State, pending: Pending, ctx: Context) -> Predicted:
        """The estimates after fusion predicted to the next step (eq. 23)."""
        ...


class Oracle:
    """Known association (the paper): each measurement's true origin is known, slot j
    holds target j on every UAV and its label is j. The local filters are the paper's
    converted-measurement Kalman filters (or the IMM), the fusion the method's
    max-consensus per target (`Method.fuse`), the bids by target."""

    scans = False

    def fuse(
        self,
        state: State,
        ctx: Context,
        sensed: Sensed,
        believed: np.ndarray,
        alive: np.ndarray,
        radio: Radio,
    ) -> Fusion:
        b, i, _ = np.nonzero(sensed.detected)
        z, R = convert(believed[b, i], sensed.polar, ctx.scenario)
        owned = ctx.buffers is not None
        detected = sensed.detected
        belief = ctx.const.tracker.update(state.mean, state.cov, state.modes, detected, z, R, owned)
        mean, cov = belief[:2]
        inputs = Inputs(
            k=state.k,
            radio=radio,
            mean=mean,
            cov=cov,
            gamma=estimation.confidence(cov),
            believed=believed,
            alive=alive,
            previous=state.target,
            held=state.held,
            setting=ctx.setting,
            measured=measured(state, detected, z, R, ctx),
            buffers=ctx.buffers,
            told=state.told,
            recent=own_recent(state, ctx.scenario),
        )
        return Fusion(inputs=inputs, fused=ctx.method.fuse(inputs), belief=belief)

    def weigh(
        self, bids: np.ndarray, fusion: Fusion, alive: np.ndarray, scenario: Scenario
    ) -> np.ndarray:
        return bids

    def auction(self, ctx: Context, fusion: Fusion, bids: np.ndarray, alive: np.ndarray) -> Auction:
        assigned = ctx.method.assign(fusion.inputs, fusion.fused, bids)
        return Auction(assigned=assigned, slot=assigned.target)  # slot j is target j

    def close(self, state: State, pending: Pending, ctx: Context) -> Predicted:
        fused = pending.fused
        mean, cov, modes = ctx.const.tracker.close(
            *pending.belief, fused.mean, fused.cov, ctx.buffers
        )
        seen = None
        if ctx.setting.gate is not None:
            seen = gate.seen(state.seen, pending.detected, state.k)
        return Predicted(mean=mean, cov=cov, modes=modes, seen=seen)


class Tracking:
    """Unknown association (gnn, jpda): each UAV's scan comes unlabelled, its tracks and
    the team's agreement on them (`Method.fuse_tracks`) replace the per-target filters
    and max-consensus, and the auction runs over team labels (`tracks.columns`)."""

    scans = True

    def fuse(
        self,
        state: State,
        ctx: Context,
        sensed: Sensed,
        believed: np.ndarray,
        alive: np.ndarray,
        radio: Radio,
    ) -> Fusion:
        scan = sensed.scan
        assert state.book is not None and scan is not None, "a tracked run has tracks and scans"
        local = Local(
            book=state.book,
            mean=state.mean,
            cov=state.cov,
            z=scan.z,
            R=scan.R,
            valid=scan.valid,
            tracker=ctx.const.tracker,
            modes=state.modes,
            central=state.central,
            tombs=state.tombs,
            seen=state.seen,
        )
        inputs = Inputs(
            k=state.k,
            radio=radio,
            mean=state.mean,
            cov=state.cov,
            gamma=estimation.confidence(state.cov),
            believed=believed,
            alive=alive,
            previous=state.target,
            held=state.held,
            setting=ctx.setting,
            told=state.told,
            told_labels=state.told_labels,
            recent=own_recent(state, ctx.scenario),
        )
        tracks = ctx.method.fuse_tracks(inputs, local)
        B, Nu = alive.shape
        fused = Fused(
            mean=tracks.mean,
            cov=tracks.cov,
            rounds=tracks.rounds,
            sent=tracks.sent,
            delivered=tracks.delivered,
            seconds=np.zeros((B, Nu, 2)),
            told=tracks.told,
        )
        confirmed = tracks.book.confirmed & alive[..., None]
        more = arriving_labels(radio)
        cols = columns.of(tracks.book.label, confirmed, more)
        if tracks.target is not None:  # a central node's labels, as columns
            fused = replace(fused, target=columns.label_column(tracks.target, cols.labels))
        held = state.held
        if held is not None and state.labels is not None:  # the held bids by this step's labels
            held = Held(columns.relabel(held.value, state.labels, cols.labels), held.stamp)
        inputs = replace(
            inputs,
            mean=tracks.mean,
            cov=tracks.cov,
            gamma=estimation.confidence(tracks.cov),
            previous=columns.label_column(state.target, cols.labels),
            held=held,
            holds=columns.holds(cols),
            columns=cols,
        )
        owned = cols if more is None else columns.of(tracks.book.label, confirmed)  # no late ones
        return Fusion(
            inputs=inputs,
            fused=fused,
            belief=(tracks.mean, tracks.cov, None),
            tracks=tracks,
            cols=cols,
            owned=owned,
            confirmed=confirmed,
        )

    def weigh(
        self, bids: np.ndarray, fusion: Fusion, alive: np.ndarray, scenario: Scenario
    ) -> np.ndarray:
        assert fusion.tracks is not None and fusion.confirmed is not None
        book = fusion.tracks.book
        return np.where(fusion.confirmed, manage.weighed(bids, book, scenario), np.nan)

    def auction(self, ctx: Context, fusion: Fusion, bids: np.ndarray, alive: np.ndarray) -> Auction:
        cols, owned, tracks = fusion.cols, fusion.owned, fusion.tracks
        assert cols is not None and owned is not None and tracks is not None
        inputs, fused = fusion.inputs, fusion.fused
        assigned = ctx.method.assign(inputs, fused, columns.bids(np.nan_to_num(bids), cols))
        confirmed = fusion.confirmed
        assert confirmed is not None
        slot = columns.slot_of(assigned.target, cols, np.where(confirmed, bids, -np.inf))
        slot = np.where(alive, slot, -1)
        label = np.take_along_axis(tracks.book.label, np.maximum(slot, 0)[..., None], axis=-1)
        followed = np.where(slot >= 0, label[..., 0], -1)
        taken = np.where(alive, columns.label_column(followed, owned.labels), -1)
        return Auction(assigned=replace(assigned, target=followed), slot=slot, taken=taken)

    def close(self, state: State, pending: Pending, ctx: Context) -> Predicted:
        tracks, tracker = pending.tracks, ctx.const.tracker
        assert tracks is not None
        own, modes = tracks.own, None
        if own is not None and own.modes is not None:  # an IMM: fused tracks restart their modes
            modes = manage.restart(own.modes, tracks.changed == 2, tracks.mean, tracks.cov, tracker)
            mean, cov, modes = tracker.close(own.mean, own.cov, modes, tracks.mean, tracks.cov)
        else:
            mean, cov = estimation.predict(tracks.mean, tracks.cov, tracker.A, tracker.Q)
        central = state.central
        if tracks.central is not None:
            c = tracks.central
            m, P, node_modes = tracker.close(c.mean, c.cov, c.modes, c.mean, c.cov)
            book = manage.survive(c.book, ctx.scenario)
            central = manage.Slots(book=book, mean=m, cov=P, modes=node_modes)
        return Predicted(
            mean=mean,
            cov=cov,
            modes=modes,
            book=manage.survive(tracks.book, ctx.scenario),
            central=central,
            labels=pending.labels,
            tombs=tracks.tombs if tracks.tombs is not None else state.tombs,
            told_labels=tracks.told_labels,
            seen=tracks.seen,
        )


ORACLE: Associator = Oracle()
TRACKING: Associator = Tracking()


def finish(
    state: State,
    pending: Pending,
    ctx: Context,
    actions: np.ndarray | None = None,
    fly: bool = True,
) -> tuple[State, Cycle]:
    """The rest of the cycle: fly the method's actions, or `actions` (B, Nu) indices into
    the action set instead (a failed UAV does not move), record the cycle and predict
    the estimates to k + 1. Returns the state at k + 1 and the cycle's record.

    fly=False records the cycle without flying (the UAVs stay where they are): a look at
    what the cycle would decide that leaves the aircraft of `state.flight` untouched."""
    scenario, method, const = ctx.scenario, ctx.method, ctx.const
    uavs, alive, fused, assigned, bids = (
        pending.uavs,
        pending.alive,
        pending.fused,
        pending.assigned,
        pending.bids,
    )
    target = assigned.target
    actions = pending.own if actions is None else np.where(alive, actions, STRAIGHT)
    beacons, beaconed = state.beacons, (0, 0)
    if scenario.planner.avoidance != "none":
        actions, beacons, beaconed = avoid(state, pending, ctx, actions)
    recent = own_recent(state, scenario)
    if recent is not None:
        recent = response.recent(recent, actions)
    pilot = state.flight if state.flight is not None else Unicycle(scenario.dt)
    commanded, bank = command(uavs, actions, scenario, const)
    if fly:
        new_uavs = pilot.fly(commanded, bank, alive)  # a failed UAV is down
    else:
        new_uavs = uavs
    B, Nu = alive.shape
    share = pending.plan_seconds / (B if method.central else B * Nu)  # (2,): CPU, wall
    ms = 1e3 * (share + timing.both(assigned.seconds, alive.shape))
    recorded = (fused.mean, fused.cov, bids)
    if not alive.all():  # a failed UAV holds no estimate and makes no bid: NaN
        recorded = tuple(
            np.where(alive.reshape(alive.shape + (1,) * (x.ndim - 2)), x, np.nan) for x in recorded
        )
    tracks = pending.tracks
    cycle = Cycle(
        uavs=uavs,
        observed=pending.observed,
        mean=recorded[0],
        cov=recorded[1],
        bids=recorded[2],
        assignment=target,
        action=bank,
        rounds=fused.rounds,
        messages=fused.sent + assigned.sent + beaconed[0],
        delivered=fused.delivered + assigned.delivered + beaconed[1],
        late=np.zeros((B, len(PROTOCOLS)), dtype=np.int64),
        bytes=pending.radio.bytes[:, :Nu],
        node_bytes=pending.radio.bytes[:, Nu],
        conflicts=conflicts(
            target if pending.columns is None else pending.columns,
            alive,
            pending.width,
            pending.held,
        ),
        alive=alive,
        decision_time_ms=np.where(alive, ms[..., timing.CPU], np.nan),
        decision_wall_ms=np.where(alive, ms[..., timing.WALL], np.nan),
        confidence=fused.gamma,
        # a failed UAV holds no track (its slots stay as they were, unread)
        label=None if tracks is None else np.where(alive[..., None], tracks.book.label, -1),
        status=None
        if tracks is None
        else np.where(alive[..., None], tracks.book.status, 0).astype(np.int8),
        existence=None
        if tracks is None
        else np.where(alive[..., None] & tracks.book.present, tracks.book.existence, 0.0),
        scan=pending.scan,
    )
    predicted = ctx.associator.close(state, pending, ctx)
    new = State(
        k=pending.k + 1,
        uavs=new_uavs,
        mean=predicted.mean,
        cov=predicted.cov,
        alive=alive,
        target=np.where(target >= 0, target, state.target),
        radio=pending.radio.close(),
        held=assigned.held,
        flight=state.flight,
        modes=predicted.modes,
        seen=predicted.seen,
        book=predicted.book,
        central=predicted.central,
        labels=predicted.labels,
        tombs=predicted.tombs,
        beacons=beacons,
        recent=recent,
        told=fused.told,
        told_labels=predicted.told_labels,
    )
    return new, cycle


def command(
    uavs: np.ndarray, actions: np.ndarray, scenario: Scenario, const: Constants
) -> tuple[np.ndarray, np.ndarray]:
    """What the UAVs (B, Nu, 5) are told to fly for actions (B, Nu): the UAVs with the
    speed each flies at (``uav.min_speed``: actions 3 to 5 are the banks at it,
    `avoidance.speeds`), and the bank angles (B, Nu). Without it, the UAVs as they are.
    The one reading of an action, for the batch and the agents' world."""
    slow = scenario.uav.min_speed
    if slow is None:
        return uavs, const.actions[actions]
    out = uavs.copy()
    out[..., world.V] = np.where(actions >= 3, slow, scenario.uav.speed)
    return out, const.actions[actions % 3]


def own_recent(state: State, scenario: Scenario) -> np.ndarray | None:
    """With ``planner.avoidance_model = "measured"``, each UAV's recent commands (B, Nu)
    at this step (`airspace.response.recent`; straight flight at the start); else None."""
    if scenario.planner.avoidance_model != "measured":
        return None
    if state.recent is not None:
        return state.recent
    return np.full(state.alive.shape, response.START, dtype=np.int64)


def avoid(
    state: State, pending: Pending, ctx: Context, actions: np.ndarray
) -> tuple[np.ndarray, avoidance.Heard, tuple[Any, Any]]:
    """``planner.avoidance``: the actions (B, Nu) filtered by `avoidance.choose` from
    the beacons each UAV heard. A method that sent no beacon this cycle (centralized,
    greedy) has one sent now, one message per link, counted as the others (returned as
    (sent, delivered)); the distributed method's beacon carries the states already."""
    scenario, alive, k = ctx.scenario, pending.alive, pending.k
    B, Nu = alive.shape
    inbox, counts = beaconed(state, pending, ctx)
    heard = state.beacons if state.beacons is not None else avoidance.Heard.nothing(B, Nu)
    memory = avoidance.memory_of(ctx.setting.delay, scenario.faults.loss)
    if inbox is None:  # nothing has arrived yet (the first cycles of a delay)
        got, sent = np.zeros((B, Nu, Nu), dtype=bool), np.full((B, Nu), -1)
        heard = heard.update(got, pending.believed, sent, k, memory)
    else:
        content = inbox.content
        got = inbox.delivered.adjacency()
        heard = heard.update(
            got, content["uavs"], content["stamp"], k, memory, content.get("recent")
        )
    values = None
    if pending.columns is None:  # each UAV's scores of its target, by first action
        target = np.maximum(pending.assigned.target, 0)[..., None, None]
        mean = np.take_along_axis(pending.fused.mean, target, axis=2)  # (B, Nu, 1, 4)
        values = first_values(pending.believed, mean, scenario)[:, :, 0]
    chosen = avoidance.choose_in(
        scenario, actions, pending.believed, alive, heard, k, values, own_recent(state, scenario)
    )
    return chosen, heard, counts


def beaconed(state: State, pending: Pending, ctx: Context) -> tuple[Inbox | None, tuple[Any, Any]]:
    """This cycle's beacons (`methods.base.beacon_of`): sent now, one message per link,
    unless the cycle sent them already (the distributed method's, with its bids).
    Returns what arrives now (None in the first cycles of a delay) and the messages
    (sent, delivered) of the beacons sent here ((0, 0) for those sent before)."""
    scenario, radio, alive, k = ctx.scenario, pending.radio, pending.alive, pending.k
    if radio.sending("beacon"):
        return radio.receive("beacon"), (0, 0)
    radio.send("beacon", beacon_of(pending.believed, k, own_recent(state, scenario)))
    wire = ctx.setting.wire or wire_of(scenario, ctx.method.plans)
    size = int(wire.bytes("beacon"))  # what the shares afford
    radio.on_air(part_bytes("beacon", 0, -1, size), 1, radio.afforded(alive))
    inbox = radio.receive("beacon")
    B, Nu = alive.shape
    zero, everyone = np.zeros(B, dtype=np.int64), np.ones((B, Nu), dtype=bool)
    once = alive.astype(np.int64)
    counts = counted(
        ctx.setting.delay,
        lambda: [radio.transmitted("beacon", once, first=0)],
        [fusion.count(inbox, everyone, zero, zero)] if inbox is not None else [],
    )
    return inbox, counts


def step(
    state: State,
    targets: np.ndarray,
    noise: np.ndarray,
    ctx: Context,
    actions: np.ndarray | None = None,
) -> tuple[State, Cycle]:
    """One decision cycle at step k = state.k for every trial: `decide`, then `finish`
    with `actions` (B, Nu) indices into the action set, or else the method's: its
    planned ones, or those it chooses itself (`Method.actions`, a learned policy)."""
    pending = decide(state, targets, noise, ctx, plan=ctx.method.plans)
    if actions is None:
        pending, actions = chosen(state, pending, ctx)
    return finish(state, pending, ctx, actions)


def chosen(state: State, pending: Pending, ctx: Context) -> tuple[Pending, np.ndarray | None]:
    """The actions a method that does not plan chooses itself (`Method.actions`, a
    learned policy), after the UAVs exchange beacons of their whole states (`beaconed`,
    counted with the cycle's messages; what arrived is `Pending.beacons`), its time to
    choose added to the cycle's decision time; None for a method that plans (its
    planned actions fly)."""
    if ctx.method.plans:
        return pending, None
    inbox, (sent, delivered) = beaconed(state, pending, ctx)
    B, Nu = pending.alive.shape
    if inbox is None:  # nothing has arrived yet (the first cycles of a delay)
        heard = (np.zeros((B, Nu, Nu), dtype=bool), np.zeros((B, Nu, 5)))
    else:
        heard = (inbox.delivered.adjacency(), np.asarray(inbox.content["uavs"]))
    a = pending.assigned
    assigned = replace(a, sent=a.sent + sent, delivered=a.delivered + delivered)
    pending = replace(pending, assigned=assigned, beacons=heard)
    start = timing.start()
    actions = ctx.method.actions(state, pending, ctx)
    return replace(pending, plan_seconds=pending.plan_seconds + timing.since(start)), actions


def graph(uavs: np.ndarray, alive: np.ndarray, scenario: Scenario) -> np.ndarray:
    """The radio graph at this step as an adjacency (B, Nu, Nu): within r_C (3-D), both
    UAVs alive (`network.radio_links`, which the cycle uses)."""
    return network.radio_links(uavs, alive, scenario.comm_range, "dense").adjacency()


def sense(
    uavs: np.ndarray,
    believed: np.ndarray,
    targets: np.ndarray,
    noise: np.ndarray,
    alive: np.ndarray,
    scenario: Scenario,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which pairs observe, and their converted measurements (eqs. 2-12).

    uavs (B, Nu, 5) true states (what the sensor sees from), believed (B, Nu, 5) the
    UAVs' own idea of them (what the conversion uses); targets (B, Nt, 4); noise
    (B, Nu, Nt, 2) standard normals; alive (B, Nu). Returns observed (B, Nu, Nt) and,
    for the K observing pairs in the order of ``np.nonzero(observed)``, z^C (K, 2) and
    R (K, 2, 2).
    """
    observed, z = observe(uavs, targets, noise, alive, scenario)
    b, i, _ = np.nonzero(observed)
    zc, R = convert(believed[b, i], z, scenario)
    return observed, zc, R


def observe(
    uavs: np.ndarray, targets: np.ndarray, noise: np.ndarray, alive: np.ndarray, scenario: Scenario
) -> tuple[np.ndarray, np.ndarray]:
    """The world's side of sensing: which pairs observe (B, Nu, Nt), and the noisy
    range-bearing measurements (K, 2) of the K observing pairs in the order of
    ``np.nonzero(observed)`` (eqs. 2-4)."""
    observed = sensing.in_view(uavs[:, :, None, :], targets[:, None, :, :], scenario.sensor)
    if not alive.all():
        observed &= alive[:, :, None]
    b, i, j = np.nonzero(observed)
    return observed, sensing.measure(uavs[b, i], targets[b, j], scenario.sensor, noise[b, i, j])


def convert(believed: np.ndarray, z: np.ndarray, scenario: Scenario):
    """A UAV's side of sensing: its range-bearing measurements z (K, 2) converted from
    where it believes it is, believed (K, 5) (eqs. 5-12); with ``robust.position_noise``
    its own position-error variance is added to R. Returns z^C (K, 2), R (K, 2, 2)."""
    zc, R = sensing.convert(believed, z, scenario.sensor)
    if scenario.robust.position_noise and scenario.faults.position_std > 0:
        R = R + scenario.faults.position_std**2 * np.eye(2)  # z^C is offset by the UAV's error
    return zc, R


def conflicts(
    target: np.ndarray, alive: np.ndarray, n_targets: int, present: np.ndarray | None = None
) -> np.ndarray:
    """Per trial, the targets followed by two or more UAVs while another target has none.

    target: (B, Nu) (-1 for a failed UAV); alive (B, Nu); present (B,): how many of the
    n_targets each trial has (None: all; with tracks, the labels held confirmed, as the
    trial would count them alone). Returns (B,) int.
    """
    B = target.shape[0]
    valid = alive & (target >= 0)
    code = (np.arange(B)[:, None] * n_targets + target)[valid]
    counts = np.bincount(code, minlength=B * n_targets).reshape(B, n_targets)
    empty = counts == 0
    if present is not None:
        empty &= np.arange(n_targets) < present[:, None]
    return np.where(empty.any(axis=-1), (counts >= 2).sum(axis=-1), 0)


def initial_state(
    scenario: Scenario, seeds: Sequence[np.random.SeedSequence]
) -> tuple[State, np.ndarray, list[np.random.Generator]]:
    """The state at step 0 of each trial, the target trajectories (B, T, Nt, 4) and the
    sensor-noise generators, from each trial's truth and sensor streams."""
    state, targets, sensor_rngs = initial_stream(scenario, seeds, keep=True)
    return state, targets.whole(), sensor_rngs


def initial_stream(
    scenario: Scenario, seeds: Sequence[np.random.SeedSequence], keep: bool = False
) -> tuple[State, Targets, list[np.random.Generator]]:
    """`initial_state` with the targets drawn as the run reaches them (`world.Targets`,
    `Targets.at(k)`), keeping the steps passed only if `keep` (as a trace needs): the
    memory of a run without a trace does not grow with its steps."""
    truth_rngs, sensor_rngs = zip(*(streams(s) for s in seeds), strict=True)
    drawn = [draw_start(scenario, rng) for rng in truth_rngs]
    targets = Targets(
        np.stack([d[0] for d in drawn]), list(truth_rngs), scenario, keep, seeds=list(seeds)
    )
    uavs = np.stack([d[1] for d in drawn])
    prior = np.stack([d[2] for d in drawn])
    pilot, uavs = flight.start(scenario, seeds, uavs)
    state = start_state(scenario, uavs, prior, drawn[0][3], pilot)
    return state, targets, list(sensor_rngs)


def start_state(
    scenario: Scenario, uavs: np.ndarray, prior: np.ndarray, P0: np.ndarray, pilot: Any
) -> State:
    """The state at step 0 of B trials: the UAVs (B, Nu, 5) flown by `pilot` (None: the
    paper's unicycle), each UAV's belief of target j N(prior[b, j], P0) with prior
    (B, Nt, 4) and P0 (4, 4) or per target (Nt, 4, 4); with unknown association these
    are confirmed tracks of every UAV when ``tracker.briefing``, else it has none."""
    B, Nu, Nt = uavs.shape[0], uavs.shape[1], prior.shape[1]
    mean = np.broadcast_to(prior[:, None], (B, Nu, Nt, 4)).copy()
    cov = np.broadcast_to(P0, (B, Nu, Nt, 4, 4)).copy()
    held = None
    if scenario.faults.loss > 0:
        held = Held(np.zeros((B, Nu, Nu, Nt)), np.full((B, Nu, Nu), -1, dtype=np.int64))
    tracker = estimation.Tracker.of(scenario.dt, scenario.acceleration_std(), scenario.tracker)
    book = central = labels = tombs = None
    if scenario.tracker.unlabelled:  # the briefed targets as confirmed tracks
        briefing = scenario.tracker.briefing
        node = manage.briefed(mean[:, :1], cov[:, :1], scenario.track_slots, briefing)
        central = manage.Slots(
            book=node[0], mean=node[1], cov=node[2], modes=tracker.start(node[1], node[2])[2]
        )
        book, mean, cov = manage.briefed(mean, cov, scenario.track_slots, briefing)
        labels = np.broadcast_to(np.arange(Nt if briefing else 0), (B, Nt if briefing else 0))
        labels = labels.copy()
        tombs = np.full((B, Nu, scenario.track_slots, 2), -1, dtype=np.int64)
    mean, cov, modes = tracker.start(mean, cov)
    return State(
        k=0,
        uavs=uavs,
        mean=mean,
        cov=cov,
        alive=np.ones((B, Nu), dtype=bool),
        target=np.full((B, Nu), -1, dtype=np.int64),
        radio=RadioState(),
        held=held,
        flight=pilot,
        modes=modes,
        book=book,
        central=central,
        labels=labels,
        tombs=tombs,
    )


# ---------------------------------------------------------------- runs


def run(
    scenario: Scenario,
    method: str | Method = "distributed",
    seeds: Sequence[int | np.random.SeedSequence] = (0,),
    trace: bool = False,
    progress: Callable[[int], None] | None = None,
) -> BatchResult:
    """Run len(seeds) independent trials as one batch (leading axis B).

    `progress`, if given, is called with the number of steps done after every step.
    Decision times are measured only for a single trial (see `metrics.METRICS`).
    """
    method = get(method)
    # for callers whose types no checker saw
    if not isinstance(scenario, Scenario):  # pyright: ignore[reportUnnecessaryIsInstance]
        raise TypeError(f"scenario must be a uavtrack.Scenario, not {type(scenario).__name__}")
    seeds = [
        s if isinstance(s, np.random.SeedSequence) else np.random.SeedSequence(s) for s in seeds
    ]
    if not seeds:
        raise ValueError("seeds is empty: give at least one seed (one per trial)")
    check_memory(scenario, len(seeds), trace)
    ctx = Context.of(scenario, method, seeds)
    if ctx.associator.scans and scenario.n_targets <= PER_UAV_SETS:  # the track scoring's
        # GOSPA: one problem of max(Nt, K) a side per UAV and step, and the team's
        side = max(scenario.n_targets, scenario.track_slots)
        lsap.load_if_worth(len(seeds) * scenario.steps * (scenario.n_uavs + 1), side)
    if not ctx.associator.scans:  # this loop owns its states: their arrays are reused
        ctx = replace(ctx, buffers=Buffers())
        if len(seeds) * scenario.n_uavs * scenario.n_targets * 128 >= LARGE_STATE:
            _process.keep_freed_memory()
    state, targets, sensor_rngs = initial_stream(scenario, seeds, keep=trace)
    B, T, Nu, Nt = len(seeds), scenario.steps, scenario.n_uavs, scenario.n_targets
    tally = scores(scenario, B, timed=B == 1)
    rec = Recorder(T, timed=B == 1) if trace else None
    noises = sensor_noise(sensor_rngs, Nu, Nt, T)
    for k, noise in enumerate(noises):
        truth = targets.at(k)
        state, cycle = step(state, truth, noise, ctx)
        tally.add(cycle, truth)
        if rec is not None:
            rec.record(k, cycle)
        if progress is not None:
            progress(k + 1)
    traces = rec.traces(targets.whole()) if rec is not None else None
    return BatchResult(method.name, scenario, tally.summary(), traces)


LARGE_STATE = 64 * 2**20
"""Bytes of covariances from which a run asks the allocator to keep freed memory
(`_process.keep_freed_memory`): 256 x 256 UAVs and targets in one trial."""


def scores(scenario: Scenario, batch: int, timed: bool) -> Scores:
    """The metrics of a run of `batch` trials (`tracks.scoring.Scores.of`)."""
    return Scores.of(scenario, batch, timed)


class Recorder:
    """Per-step arrays of every `Cycle` field, allocated at the first step."""

    def __init__(self, steps: int, timed: bool) -> None:
        self.steps, self.timed = steps, timed
        self.arrays: dict[str, np.ndarray] = {}
        self.tracked: list[dict[str, np.ndarray]] = []  # per step, `TRACKED`'s arrays

    def record(self, k: int, cycle: Cycle) -> None:
        if not self.arrays:
            for f in RECORDED:
                value = getattr(cycle, f.name)
                B = value.shape[0]
                self.arrays[f.name] = np.empty(
                    (B, self.steps) + value.shape[1:], f.metadata["dtype"]
                )
        for name, array in self.arrays.items():
            array[:, k] = getattr(cycle, name)
        if cycle.label is not None and cycle.status is not None and cycle.scan is not None:
            scan = cycle.scan
            assert cycle.existence is not None, "a cycle of tracks records their existence"
            self.tracked.append(
                {
                    "label": cycle.label,
                    "status": cycle.status,
                    "existence": cycle.existence,
                    "scan_polar": scan.polar,
                    "scan_z": scan.z,
                    "scan_valid": scan.valid,
                    "scan_origin": scan.origin,
                }
            )
        if not self.timed:
            self.arrays["decision_time_ms"][:, k] = np.nan
            self.arrays["decision_wall_ms"][:, k] = np.nan

    def traces(self, trajectory: np.ndarray) -> list[Trace]:
        """One Trace per trial, over the steps of `trajectory` (B, T', Nt, 4), T' at
        most the steps recorded (an episode cut short)."""
        n = trajectory.shape[1]
        extra = self._tracked(n)
        return [
            Trace(
                trajectory[b],
                **{name: a[b, :n] for name, a in self.arrays.items()},
                **{name: a[b] for name, a in extra.items()},
            )
            for b in range(trajectory.shape[0])
        ]

    def _tracked(self, n: int) -> dict[str, np.ndarray]:
        """`TRACKED`'s arrays (B, T, ...) of the first n steps, scans padded to the most
        measurements of any step."""
        if not self.tracked:
            return {}
        steps = self.tracked[:n]
        Z = max(step["scan_valid"].shape[-1] for step in steps)
        out = {}
        for name, (_, _, dtype) in TRACKED.items():
            parts = [step[name] for step in steps]
            if name.startswith("scan"):
                fill = -2 if name == "scan_origin" else 0
                parts = [
                    np.pad(
                        p,
                        [(0, 0), (0, 0), (0, Z - p.shape[2])] + [(0, 0)] * (p.ndim - 3),
                        constant_values=fill,
                    )
                    for p in parts
                ]
            out[name] = np.stack(parts, axis=1).astype(dtype)
        return out


def memory_estimate(scenario: Scenario, batch: int = 1, trace: bool = False) -> dict[str, float]:
    """Bytes a batch of `batch` trials needs at its peak, by the field that drives each part.

    The parts are the target trajectories (steps x n_targets, or a block of steps without
    a trace: `world.Targets`), the planner's tree of
    3^h sequences, the radio (n_uavs^2 bits of the flooding and the auction, and the
    consensus tuples on each radio link, whose number is estimated from the UAVs'
    density at the start and over the field; with lost or late messages each UAV's
    copy of every neighbour's bids), the per-pair state of the cycle (n_uavs x
    n_targets estimates and a block of sensor noise), the trace (steps x n_uavs x
    n_targets) and each trial's NEES histograms. The estimate is checked against
    measured peaks in the tests.
    """
    T, Nu, Nt = scenario.steps, scenario.n_uavs, scenario.n_targets
    f = 8  # bytes per float
    history = 1 + scenario.faults.delay
    pairs = batch * Nu * Nt
    noise = min(pairs * 2 * f * NOISE_BLOCK, max(NOISE_BYTES, pairs * 2 * f))
    radio = batch * Nu * Nu * 16
    if Nu < network.SPARSE_FROM:  # the dense form: an N x N x Nt array per round
        radio += batch * Nu * Nu * Nt * f * 4
    else:  # the edge form: a row of Nt confidences per link, a few arrays of them
        radio += batch * Nu * (1 + _neighbours(scenario)) * Nt * f * 6
    if scenario.faults.loss > 0 or scenario.faults.delay > 0:  # each UAV's view of the bids
        radio += batch * Nu * Nu * Nt * f * 3
    # the targets' states: a block of steps (`world.Targets`), or every step when kept for
    # a trace or drawn whole (manoeuvring targets); their draws' temporaries: a block of
    # every trial at once, or a manoeuvring trial's whole run, 14 arrays of (Nt, 2) per
    # step (the closed form's sums, their concatenations and the fold; 13 to 15 measured)
    turning = scenario.target.motion == "manoeuvring"
    block = min(T, Targets.BLOCK + 1)
    kept = T if trace or turning else block
    temporaries = T if turning else batch * block
    parts = {
        "steps": batch * kept * Nt * 4 * f * 2 + temporaries * Nt * 2 * f * 14,
        "planner.horizon": planning.memory(batch * Nu, Nt, 3, scenario.planner.horizon),
        "n_uavs": radio,
        "n_targets": pairs * f * 20 * 6 * history + 2 * noise,
    }
    if trace:
        parts["steps"] += batch * T * (Nu * Nt * (4 + 16 + 1 + 1) + Nu * 12) * f
    # the NEES histograms of each trial (every UAV's, the team's best), and a copy of
    # one where its median is read (`metrics.NeesSpread`)
    bins = (NEES_DECADES[1] - NEES_DECADES[0]) * NEES_BINS_PER_DECADE + 2
    parts["trials"] = batch * 3 * bins * f
    return parts


def _neighbours(scenario: Scenario) -> float:
    """Expected radio neighbours of a UAV: the team at its start (a square of side
    `Scenario.start_side`) or spread over the field, whichever is denser; at most all."""
    n, r = scenario.n_uavs, scenario.comm_range
    disk = np.pi * r * r
    start = max(scenario.start_side(), r) ** 2
    spread = max(scenario.field_size, r) ** 2
    return min(n - 1, (n - 1) * disk / min(start, spread))


def check_memory(scenario: Scenario, batch: int = 1, trace: bool = False) -> None:
    """Refuse, with a one-line ScenarioError, a run that cannot fit in the memory available."""
    parts = memory_estimate(scenario, batch, trace)
    need, have = sum(parts.values()), _process.available_memory()
    if need <= 0.9 * have:
        return
    field_ = max(parts, key=lambda name: parts[name])
    hint = {
        "steps": "steps (or run without a trace)" if trace else "steps",
        "planner.horizon": "planner.horizon (or n_uavs, n_targets)",
        "n_uavs": "n_uavs",
        "n_targets": "n_targets (or n_uavs)",
        "trials": "the trials run at once",
    }[field_]
    trials = f" for {batch} trials at once" if batch > 1 else ""
    fewer = " or the trials run at once" if batch > 1 else ""
    raise ScenarioError(
        f"this run needs about {_size(need)} of memory{trials} and {_size(have)} are "
        f"available; reduce {hint}{fewer}"
    )


def _size(n: float) -> str:
    return f"{n / 2**30:.1f} GiB" if n >= 2**30 else f"{n / 2**20:.0f} MiB"


def simulate(
    scenario: Scenario | None = None,
    method: str | Method = "distributed",
    seed: int | np.random.SeedSequence = 0,
    trace: bool = True,
    progress: Callable[[int], None] | None = None,
) -> Result:
    """Simulate one trial of `scenario` with `method` ("distributed", "centralized", "greedy").

    `seed` is an integer (numpy's too) or a `numpy.random.SeedSequence`, such as
    `trial_seed(seed, t)`; `progress` as in `run`.
    """
    scenario = Scenario() if scenario is None else scenario
    # pyright holds that no Integral int is a bool, which True is
    if isinstance(seed, Integral) and not isinstance(seed, bool):  # pyright: ignore[reportUnnecessaryIsInstance]
        seed = int(seed)
        if seed < 0:
            raise ValueError(f"seed must be >= 0, got {seed}")
    elif not isinstance(seed, np.random.SeedSequence):
        raise TypeError(f"seed must be an integer or a SeedSequence, not {type(seed).__name__}")
    batch = run(scenario, method, [seed], trace=trace, progress=progress)
    return result_of(batch, seed if isinstance(seed, int) else None)


def result_of(batch: BatchResult, seed: int | None, only: Sequence[str] | None = None) -> Result:
    """The `Result` of the one trial of a batch; with `only`, every other metric NaN (a
    replay of scans without truth, which those read)."""
    m = {name: values[0] for name, values in batch.metrics.items()}
    if only is not None:
        m = {k: v if k in only else np.full(np.shape(v), np.nan) for k, v in m.items()}
    return Result(
        method=batch.method,
        seed=seed,
        scenario=batch.scenario,
        per_target=m["per_target"],
        trace=batch.traces[0] if batch.traces else None,
        **{name: float(m[name]) for name in METRICS if name != "per_target"},
    )
