"""The decision cycle (paper Fig. 3, Algorithm 2) and runs of it.

    truth -> sensing -> local filter -> max-consensus -> planning -> auction -> control

`step` is one cycle for a batch of independent trials (leading axis B); `run`
iterates it; `simulate` is one trial with its full trace.

Randomness: each trial has its own `numpy.random.SeedSequence`, split into a truth
stream (initial layout, target accelerations) and a sensor stream (measurement
noise, one standard-normal pair per UAV-target pair per step, whether or not the
pair is in view). The methods therefore see the same targets and the same noise in
a trial (common random numbers), and a trial gives the same result alone or in a
batch.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from numbers import Integral

import numpy as np

from . import estimation, fusion, network, planning, sensing, world
from .config import G, Scenario, ScenarioError
from .methods import Method, get
from .metrics import METRICS, Tally

NOISE_BLOCK = 64
"""Steps of sensor noise drawn at once per trial (a draw of n normals equals n draws of 1)."""


@dataclass(frozen=True)
class Constants:
    """What a run derives once from its scenario."""

    A: np.ndarray
    Q: np.ndarray
    actions: np.ndarray

    @classmethod
    def of(cls, scenario: Scenario) -> Constants:
        return cls(
            A=estimation.transition(scenario.dt),
            Q=estimation.process_noise(
                scenario.dt, scenario.target.sigma_1, scenario.target.sigma_2
            ),
            actions=planning.action_set(np.radians(scenario.uav.bank_angle_deg)),
        )


@dataclass(frozen=True)
class State:
    """What persists between cycles, for B trials.

    uavs: (B, Nu, 5); mean: (B, Nu, Nt, 4) and cov: (B, Nu, Nt, 4, 4), each UAV's
    fused belief s_bar, P_bar after the last cycle (the prior before the first).
    """

    k: int
    uavs: np.ndarray
    mean: np.ndarray
    cov: np.ndarray


@dataclass(frozen=True)
class Cycle:
    """What one cycle decided and measured, for B trials.

    observed (B, Nu, Nt); bids (B, Nu, Nt); target (B, Nu) assigned target;
    action (B, Nu) index of the bank angle flown; rounds (B, Nu) D_i;
    messages (B,) consensus messages; decision_time (B, Nu) seconds of planning and
    assignment per UAV (see `metrics.METRICS["decision_time_ms"]`).
    """

    observed: np.ndarray
    bids: np.ndarray
    target: np.ndarray
    action: np.ndarray
    rounds: np.ndarray
    messages: np.ndarray
    decision_time: np.ndarray


def step(
    state: State,
    targets: np.ndarray,
    noise: np.ndarray,
    scenario: Scenario,
    method: Method,
    const: Constants,
) -> tuple[State, Cycle]:
    """One decision cycle at step k = state.k for every trial.

    targets: (B, Nt, 4) true target states at k; noise: (B, Nu, Nt, 2) standard normals.
    Returns the state at k+1 (UAVs moved, beliefs fused at k) and the cycle's record.
    """
    uavs = state.uavs
    graph = network.adjacency(uavs, scenario.comm_range)
    observed, z, R = sense(uavs, targets, noise, scenario)
    mean, cov = estimation.filter_step(
        state.mean,
        state.cov,
        observed,
        z,
        R,
        *((const.A, const.Q) if state.k > 0 else (None, None)),
    )
    fused = method.fuse(estimation.confidence(cov), graph)
    if fused.rounds.any():  # otherwise every UAV kept its own estimates
        mean, cov = fusion.gather(fused.source, mean), fusion.gather(fused.source, cov)
    start = time.perf_counter()
    plan = planning.plan(
        uavs,
        mean,
        scenario.sensor,
        np.radians(scenario.uav.bank_angle_deg),
        scenario.planner.horizon,
        scenario.dt,
        scenario.planner.discount,
        G,
    )
    plan_seconds = time.perf_counter() - start
    target, assign_seconds = method.assign(plan.value, graph)
    action = np.take_along_axis(plan.action, target[..., None], axis=-1)[..., 0]
    new_uavs = world.fly(uavs, const.actions[action], scenario.dt, G)
    share = plan_seconds / (uavs.shape[0] if method.central else uavs.shape[0] * uavs.shape[1])
    cycle = Cycle(
        observed, plan.value, target, action, fused.rounds, fused.messages, share + assign_seconds
    )
    return State(state.k + 1, new_uavs, mean, cov), cycle


def sense(
    uavs: np.ndarray, targets: np.ndarray, noise: np.ndarray, scenario: Scenario
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which pairs observe, and their converted measurements (eqs. 2-12).

    uavs (B, Nu, 5); targets (B, Nt, 4); noise (B, Nu, Nt, 2) standard normals.
    Returns observed (B, Nu, Nt) and, for the K observing pairs in the order of
    ``np.nonzero(observed)``, z^C (K, 2) and R (K, 2, 2).
    """
    observed = sensing.in_view(uavs[:, :, None, :], targets[:, None, :, :], scenario.sensor)
    b, i, j = np.nonzero(observed)
    seen_by = uavs[b, i]
    z = sensing.measure(seen_by, targets[b, j], scenario.sensor, noise[b, i, j])
    zc, R = sensing.convert(seen_by, z, scenario.sensor)
    return observed, zc, R


# ---------------------------------------------------------------- initial conditions


def streams(seed: int | np.random.SeedSequence) -> tuple[np.random.Generator, np.random.Generator]:
    """(truth, sensor) generators of one trial, independent streams of its seed.

    The children are derived from the seed's spawn key, not with `SeedSequence.spawn`,
    whose counter would give a reused seed object different streams.
    """
    seq = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    truth, sensor = (
        np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, k), pool_size=seq.pool_size)
        for k in range(2)
    )
    return np.random.default_rng(truth), np.random.default_rng(sensor)


def trial_seed(seed: int, trial: int) -> np.random.SeedSequence:
    """The seed of trial `trial` of an experiment seeded with `seed`.

    Equal to ``SeedSequence(seed).spawn(n)[trial]`` for any n > trial.
    """
    return np.random.SeedSequence(seed, spawn_key=(trial,))


def initial_conditions(
    scenario: Scenario, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Draw one trial's truth and prior (all assumed; see the parameter table).

    Targets start uniformly in the field with N(0, v0^2) velocity components; UAVs
    start in a square of side `uav.start_spread` at the field centre with uniform
    headings; every UAV's prior of target j is N(cue_j, P0) with cue_j the true position
    plus N(0, sigma_p0^2) noise and zero velocity, and P0 = diag(sigma_p0^2, sigma_p0^2,
    sigma_v0^2, sigma_v0^2), so the prior is consistent.

    Returns uavs (Nu, 5), target trajectories (T, Nt, 4), prior mean (Nt, 4), P0 (4, 4).
    """
    nu, nt, L = scenario.n_uavs, scenario.n_targets, scenario.field_size
    tgt = scenario.target
    targets = np.concatenate(
        [rng.uniform(0.0, L, (nt, 2)), rng.normal(0.0, tgt.initial_velocity_std, (nt, 2))], axis=1
    )
    uavs = np.empty((nu, 5))
    half = scenario.uav.start_spread / 2
    uavs[:, :2] = L / 2 + rng.uniform(-half, half, (nu, 2))
    uavs[:, 2] = scenario.altitudes()
    uavs[:, 3] = scenario.uav.speed
    uavs[:, 4] = rng.uniform(-np.pi, np.pi, nu)
    est = scenario.estimation
    prior = np.zeros((nt, 4))
    prior[:, :2] = targets[:, :2] + rng.normal(0.0, est.initial_position_std, (nt, 2))
    P0 = np.diag([est.initial_position_std**2] * 2 + [est.initial_velocity_std**2] * 2)
    accel = rng.standard_normal((scenario.steps - 1, nt, 2)) * [tgt.sigma_1, tgt.sigma_2]
    trajectory = world.target_trajectories(targets, accel, scenario.dt, L)
    return uavs, trajectory, prior, P0


# ---------------------------------------------------------------- runs


@dataclass(frozen=True)
class Trace:
    """Everything a run did, step by step (T steps, Nu UAVs, Nt targets).

    targets (T, Nt, 4) truth; uavs (T, Nu, 5) at the time of the cycle; mean
    (T, Nu, Nt, 4) and cov (T, Nu, Nt, 4, 4) each UAV's fused estimate; observed
    (T, Nu, Nt); bids (T, Nu, Nt); assignment (T, Nu) target index; action (T, Nu)
    bank angle flown [rad]; rounds (T, Nu) D_i; messages (T,); decision_time_ms (T, Nu)
    [ms] (NaN in the traces of a batch, where it is not measured).
    """

    targets: np.ndarray
    uavs: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    observed: np.ndarray
    bids: np.ndarray
    assignment: np.ndarray
    action: np.ndarray
    rounds: np.ndarray
    messages: np.ndarray
    decision_time_ms: np.ndarray

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


@dataclass(frozen=True)
class BatchResult:
    """Per-trial metrics of a batch (see `metrics.Tally.summary`) and optional traces."""

    method: str
    scenario: Scenario
    metrics: dict[str, np.ndarray]
    traces: list[Trace] | None = field(default=None, repr=False)


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
    if not isinstance(scenario, Scenario):
        raise TypeError(f"scenario must be a uavtrack.Scenario, not {type(scenario).__name__}")
    seeds = list(seeds)
    if not seeds:
        raise ValueError("seeds is empty: give at least one seed (one per trial)")
    check_memory(scenario, len(seeds), trace)
    const = Constants.of(scenario)
    B, T, Nu, Nt = len(seeds), scenario.steps, scenario.n_uavs, scenario.n_targets
    truth_rngs, sensor_rngs = zip(*(streams(s) for s in seeds), strict=True)
    drawn = [initial_conditions(scenario, rng) for rng in truth_rngs]
    uavs = np.stack([d[0] for d in drawn])
    trajectory = np.stack([d[1] for d in drawn])  # (B, T, Nt, 4)
    mean = np.broadcast_to(np.stack([d[2] for d in drawn])[:, None], (B, Nu, Nt, 4)).copy()
    cov = np.broadcast_to(drawn[0][3], (B, Nu, Nt, 4, 4)).copy()
    del drawn  # the per-trial copies of the trajectories
    state = State(0, uavs, mean, cov)
    tally = Tally(B, Nu, Nt, timed=B == 1)
    rec = _Recorder(B, T, Nu, Nt, timed=B == 1) if trace else None
    for k in range(T):
        if k % NOISE_BLOCK == 0:  # the same numbers as one draw per step, fewer calls
            noise = np.stack(
                [rng.standard_normal((NOISE_BLOCK, Nu, Nt, 2)) for rng in sensor_rngs], axis=1
            )
        before = state.uavs
        state, cycle = step(
            state, trajectory[:, k], noise[k % NOISE_BLOCK], scenario, method, const
        )
        tally.add(
            cycle.observed,
            trajectory[:, k],
            state.mean,
            state.cov,
            cycle.rounds,
            cycle.messages,
            cycle.decision_time,
        )
        if rec is not None:
            rec.record(k, before, state, cycle, const)
        if progress is not None:
            progress(k + 1)
    traces = rec.traces(trajectory) if rec is not None else None
    return BatchResult(method.name, scenario, tally.summary(), traces)


def memory_estimate(scenario: Scenario, batch: int = 1, trace: bool = False) -> dict[str, int]:
    """Bytes a batch of `batch` trials needs at its peak, by the field that drives each part.

    The parts are the target trajectories (steps x n_targets), the per-step work of the
    cycle (n_uavs x n_targets, with the planner's tree of 3^h sequences and the N x N
    radio graph), and the trace (steps x n_uavs x n_targets). The estimate is checked
    against measured peaks in the tests.
    """
    T, Nu, Nt = scenario.steps, scenario.n_uavs, scenario.n_targets
    f = 8  # bytes per float
    parts = {
        "steps": batch * T * Nt * 4 * f * 2 + T * Nt * 2 * f * 8,
        "planner.horizon": planning.memory(batch * Nu, Nt, 3, scenario.planner.horizon),
        "n_uavs": batch * Nu * Nu * f * (8 + (Nt if Nu < fusion.SPARSE_FROM else 3 * Nt)),
        "n_targets": batch * Nu * Nt * f * (20 * 6 + NOISE_BLOCK * 2 * 2),
    }
    if trace:
        parts["steps"] += batch * T * (Nu * Nt * (4 + 16 + 1 + 1) + Nu * 9) * f
    return parts


def check_memory(scenario: Scenario, batch: int = 1, trace: bool = False) -> None:
    """Refuse, with a one-line ScenarioError, a run that cannot fit in the memory available."""
    parts = memory_estimate(scenario, batch, trace)
    need, have = sum(parts.values()), available_memory()
    if need <= 0.9 * have:
        return
    field = max(parts, key=parts.get)
    hint = {
        "steps": "steps (or run without a trace)" if trace else "steps",
        "planner.horizon": "planner.horizon (or n_uavs, n_targets)",
        "n_uavs": "n_uavs",
        "n_targets": "n_targets (or n_uavs)",
    }[field]
    trials = f" for {batch} trials at once" if batch > 1 else ""
    raise ScenarioError(
        f"this run needs about {_size(need)} of memory{trials} and {_size(have)} are "
        f"available; reduce {hint}"
    )


def _size(n: float) -> str:
    return f"{n / 2**30:.1f} GiB" if n >= 2**30 else f"{n / 2**20:.0f} MiB"


def available_memory() -> int:
    """Bytes of memory available to new allocations (MemAvailable on Linux)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as info:
            for line in info:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return 2**62  # unknown: do not refuse


class _Recorder:
    """Preallocated per-step arrays for traces."""

    def __init__(self, B: int, T: int, Nu: int, Nt: int, timed: bool) -> None:
        self.timed = timed
        self.uavs = np.empty((B, T, Nu, 5))
        self.mean = np.empty((B, T, Nu, Nt, 4))
        self.cov = np.empty((B, T, Nu, Nt, 4, 4))
        self.observed = np.empty((B, T, Nu, Nt), dtype=bool)
        self.bids = np.empty((B, T, Nu, Nt))
        self.assignment = np.empty((B, T, Nu), dtype=np.int64)
        self.action = np.empty((B, T, Nu))
        self.rounds = np.empty((B, T, Nu), dtype=np.int64)
        self.messages = np.empty((B, T), dtype=np.int64)
        self.decision_time_ms = np.full((B, T, Nu), np.nan)

    def record(
        self, k: int, uavs: np.ndarray, state: State, cycle: Cycle, const: Constants
    ) -> None:
        self.uavs[:, k] = uavs
        self.mean[:, k] = state.mean
        self.cov[:, k] = state.cov
        self.observed[:, k] = cycle.observed
        self.bids[:, k] = cycle.bids
        self.assignment[:, k] = cycle.target
        self.action[:, k] = const.actions[cycle.action]
        self.rounds[:, k] = cycle.rounds
        self.messages[:, k] = cycle.messages
        if self.timed:
            self.decision_time_ms[:, k] = 1e3 * cycle.decision_time

    def traces(self, trajectory: np.ndarray) -> list[Trace]:
        return [
            Trace(
                trajectory[b],
                self.uavs[b],
                self.mean[b],
                self.cov[b],
                self.observed[b],
                self.bids[b],
                self.assignment[b],
                self.action[b],
                self.rounds[b],
                self.messages[b],
                self.decision_time_ms[b],
            )
            for b in range(trajectory.shape[0])
        ]


@dataclass(frozen=True)
class Result:
    """One trial: the paper's metric, the estimation quality, costs, and the trace.

    The metrics are those of `metrics.METRICS` (units and meaning there):
    observation_rate (Sec. 7); per_target (Nt,); rmse and nees over every UAV's fused
    estimate; rmse_best and nees_best of the team's best estimate; rounds: mean D_i per
    UAV and step; messages per step; decision_time_ms per UAV and cycle.
    """

    method: str
    seed: int | None
    scenario: Scenario
    observation_rate: float
    per_target: np.ndarray
    rmse: float
    rmse_best: float
    nees: float
    nees_best: float
    rounds: float
    messages: float
    decision_time_ms: float
    trace: Trace | None = field(default=None, repr=False)

    def summary(self) -> dict:
        """JSON-ready metrics (the names of `metrics.METRICS`)."""
        out = {"method": self.method, "seed": self.seed}
        for name in METRICS:
            value = getattr(self, name)
            out[name] = [float(x) for x in value] if name == "per_target" else float(value)
        return out


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
    if isinstance(seed, Integral) and not isinstance(seed, bool):
        seed = int(seed)
        if seed < 0:
            raise ValueError(f"seed must be >= 0, got {seed}")
    elif not isinstance(seed, np.random.SeedSequence):
        raise TypeError(f"seed must be an integer or a SeedSequence, not {type(seed).__name__}")
    batch = run(scenario, method, [seed], trace=trace, progress=progress)
    m = {name: values[0] for name, values in batch.metrics.items()}
    return Result(
        method=batch.method,
        seed=seed if isinstance(seed, int) else None,
        scenario=scenario,
        per_target=m["per_target"],
        trace=batch.traces[0] if trace else None,
        **{name: float(m[name]) for name in METRICS if name != "per_target"},
    )
