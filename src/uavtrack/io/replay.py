"""Recorded scans in: each UAV's trackers and the team's agreement on scans a team of
sensors recorded, in place of the simulator's world (`uavtrack replay`).

A `Recording` holds, step by step, where each sensor believes it is and its scan:
measurements converted to the ground with their covariances. `replay` runs the cycle's
own stages on it (`simulation.decided`, `simulation.finish` without flight): the local
trackers of unlabelled scans (gnn or jpda), the method's fusion of tracks over the radio
graph (given, or from the sensors' positions and r_C), and the planner and assignment
on the tracks, as the team would decide. A replay of a simulated run's own scans gives
that run's tracks, labels and assignments exactly (`of_trace`).

The tables and bags that hold a recording on disk are read by `io.recording`; this
module needs numpy alone.
"""

# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from .. import network, sensing, simulation, world
from ..config import Scenario, ScenarioError
from ..methods import Method, get
from ..records import BatchResult, Result, State, Trace
from ..tracks import scan as scans

__all__ = ["REFUSED", "TRUTHLESS", "Recording", "of_trace", "replay", "scenario_for"]

TRUTHLESS = ("rounds", "messages", "delivered", "bytes", "conflicts", "failed")
"""The metrics a replay without truth still computes; the others are NaN."""

REFUSED = {
    "faults.failure_rate": "a sensor fails where the recording stops it: leave it 0",
    "faults.failures": "a sensor fails where the recording stops it: leave it empty",
    "faults.position_std": "the recorded poses are where the sensors believe they are: leave it 0",
}
"""Settings a replay refuses, with why: the recording, not the scenario, says them."""


@dataclass(frozen=True, kw_only=True)
class Recording:
    """Scans of a team of N sensors over T steps of the scenario's dt, each padded to Z.

    poses (T, N, 5): where each sensor believes it is, x, y, altitude [m], speed [m/s],
    heading [rad]; alive (T, N): it reports at the step (a sensor that stops does not
    come back); z (T, N, Z, 2) its measurements on the ground [m], R (T, N, Z, 2, 2)
    their covariances [m^2], valid (T, N, Z) a measurement, not padding (at the front of
    each row, in the order the sensor received them); polar (T, N, Z, 2) range [m] and
    bearing [rad] where known (else NaN); origin (T, N, Z) for evaluation only: the
    target measured, -1 clutter or unknown, -2 padding.

    links (T, N, N) bool: the radio graph, if recorded (None: sensors within r_C).
    prior: each UAV's briefing, the targets' mean (M, 4) and covariance (M, 4, 4) it
    starts with as confirmed tracks (None: no track at the start). targets (T, M', 4):
    the truth, if known (NaN: a target away), for the scores.
    """

    poses: np.ndarray
    alive: np.ndarray
    z: np.ndarray
    R: np.ndarray
    valid: np.ndarray
    polar: np.ndarray
    origin: np.ndarray
    links: np.ndarray | None = None
    prior: tuple[np.ndarray, np.ndarray] | None = None
    targets: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.poses.ndim != 3 or self.poses.shape[2] != 5 or self.poses.shape[0] < 1:
            raise ValueError(f"poses must be (T, N, 5) with T >= 1, not {self.poses.shape}")
        T, N = self.poses.shape[:2]
        Z = self.valid.shape[-1] if self.valid.ndim == 3 else -1
        shapes = {
            "alive": (self.alive, (T, N)),
            "valid": (self.valid, (T, N, Z)),
            "z": (self.z, (T, N, Z, 2)),
            "R": (self.R, (T, N, Z, 2, 2)),
            "polar": (self.polar, (T, N, Z, 2)),
            "origin": (self.origin, (T, N, Z)),
        }
        if self.links is not None:
            shapes["links"] = (self.links, (T, N, N))
        for name, (value, shape) in shapes.items():
            if value.shape != shape:
                raise ValueError(f"{name} must be {shape} for {T} steps of {N} sensors, not "
                                 f"{value.shape}")  # fmt: skip
        if (np.diff(self.alive.astype(np.int8), axis=0) > 0).any():
            i = int(np.nonzero((np.diff(self.alive.astype(np.int8), axis=0) > 0).any(axis=0))[0][0])
            raise ValueError(f"sensor {i} reports again after it stopped: a sensor that stops "
                             "does not come back (or the recording's step is not the "
                             "scenario's dt)")  # fmt: skip
        if (self.valid & ~self.alive[..., None]).any():
            raise ValueError("a sensor has measurements at a step it does not report")
        if not np.isfinite(self.poses[self.alive]).all():
            raise ValueError("a reporting sensor's pose is not finite")
        ok = np.isfinite(self.z[self.valid]).all() and np.isfinite(self.R[self.valid]).all()
        if not ok:
            raise ValueError("a measurement or its covariance is not finite")
        R = self.R[self.valid]
        if R.size and (
            (R[:, 0, 1] != R[:, 1, 0]).any()
            or (R[:, 0, 0] <= 0).any()
            or (R[:, 0, 0] * R[:, 1, 1] <= R[:, 0, 1] ** 2).any()
        ):
            raise ValueError("a measurement's covariance R is not symmetric positive definite")
        if self.prior is not None:
            mean, cov = self.prior
            M = mean.shape[0]
            if mean.shape != (M, 4) or cov.shape != (M, 4, 4) or M < 1:
                raise ValueError(f"prior must be a mean (M, 4) and a covariance (M, 4, 4), M >= "
                                 f"1, not {mean.shape} and {cov.shape}")  # fmt: skip
            if not (np.isfinite(mean).all() and _definite(cov)):
                raise ValueError("the prior's means must be finite and its covariances "
                                 "symmetric positive definite")  # fmt: skip
        if self.targets is not None and (
            self.targets.ndim != 3 or self.targets.shape[0] != T or self.targets.shape[2] != 4
        ):
            raise ValueError(f"targets must be (T, M, 4) for {T} steps, not {self.targets.shape}")
        if self.targets is not None and self.prior is not None:
            m, truth = self.prior[0].shape[0], self.targets.shape[1]
            if m != truth:
                raise ValueError(f"the briefing has {m} targets and the truth {truth}: give both "
                                 "for the same targets")  # fmt: skip

    @property
    def steps(self) -> int:
        return self.poses.shape[0]

    @property
    def sensors(self) -> int:
        return self.poses.shape[1]


def _definite(cov: np.ndarray) -> bool:
    """Whether every covariance of (..., n, n) is symmetric positive definite."""
    if not np.allclose(cov, np.swapaxes(cov, -1, -2), rtol=1e-9, atol=0):
        return False
    try:
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        return False
    return True


def scenario_for(recording: Recording, scenario: Scenario) -> Scenario:
    """The scenario a replay of `recording` runs: `scenario` with its team, steps and
    briefing from the recording (its targets: the prior's, else the truth's, else the
    scenario's). Refuses, in one line, what the recording says instead (`REFUSED`) and
    known association (a recording's measurements come unlabelled)."""
    if not scenario.tracker.unlabelled:
        raise ScenarioError(
            "replay runs the trackers of unlabelled scans: set tracker.association to gnn or jpda"
        )
    given = {
        "faults.failure_rate": scenario.faults.failure_rate > 0,
        "faults.failures": bool(scenario.faults.failures),
        "faults.position_std": scenario.faults.position_std > 0,
    }
    for name, on in given.items():
        if on:
            raise ScenarioError(f"{name}: {REFUSED[name]} in a replay")
    if recording.prior is not None:
        m = recording.prior[0].shape[0]
    elif recording.targets is not None:
        m = recording.targets.shape[1]
    else:
        m = scenario.n_targets
    changes = {
        "n_uavs": recording.sensors,
        "n_targets": m,
        "steps": recording.steps,
        "tracker.briefing": recording.prior is not None,
    }
    return scenario.with_overrides(changes, origin="the recording")


def replay(
    recording: Recording,
    scenario: Scenario,
    method: str | Method = "distributed",
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
) -> Result:
    """Run `method`'s trackers, fusion, planner and assignment on `recording`'s scans.

    `scenario` gives the tracker, radio and planner (`scenario_for` sets the rest);
    `seed` draws the radio's faults (``faults.loss``, ``delay``), if any. Returns a
    `Result` with its trace: the sensors where they were, each one's tracks and
    assignment at every step. Without truth (``recording.targets`` None) the targets
    are NaN and every metric but `TRUTHLESS` is NaN.
    """
    method = get(method)
    scenario = scenario_for(recording, scenario)
    seeds = [np.random.SeedSequence(seed)]
    ctx = simulation.Context.of(scenario, method, seeds)
    T, M = recording.steps, scenario.n_targets
    truth = recording.targets if recording.targets is not None else np.full((T, M, 4), np.nan)
    state = _start(recording, scenario)
    tally = simulation.scores(scenario, 1, timed=True)
    rec = simulation.Recorder(T, timed=True)
    for k in range(T):
        alive = recording.alive[k][None]
        step = at(recording, k, alive, truth[k], scenario)
        state = replace(state, uavs=step.uavs, alive=alive)
        observed, sensed, links = step.observed, step.sensed, step.links
        uavs = step.uavs
        pending = simulation.decided(state, sensed, alive, uavs, observed, ctx, method.plans, links)
        pending, actions = simulation.chosen(state, pending, ctx)
        state, cycle = simulation.finish(state, pending, ctx, actions, fly=False)
        tally.add(cycle, truth[k][None])
        rec.record(k, cycle)
        if progress is not None:
            progress(k + 1)
    batch = BatchResult(method.name, scenario, tally.summary(), rec.traces(truth[None]))
    return result_of(batch, recording)


def result_of(batch: BatchResult, recording: Recording) -> Result:
    """The `Result` of a replay's one trial: no seed (no truth was drawn from one) and,
    without truth, every metric but `TRUTHLESS` NaN."""
    return simulation.result_of(batch, None, TRUTHLESS if recording.targets is None else None)


@dataclass(frozen=True, kw_only=True)
class Step:
    """What a recording gives the cycle at a step (B = 1): the sensors' poses uavs (1, N,
    5), the pairs in view of the truth observed (1, N, M), the scans as the sensing stage
    gives them (`simulation.Sensed`) and the radio graph (None: within r_C)."""

    uavs: np.ndarray
    alive: np.ndarray
    observed: np.ndarray
    sensed: simulation.Sensed
    links: network.Links | None

    def graph(self, scenario: Scenario) -> np.ndarray:
        """The radio graph as an adjacency (1, N, N), self-loops of the living included."""
        if self.links is not None:
            return self.links.adjacency()
        return simulation.graph(self.uavs, self.alive, scenario)


def at(
    recording: Recording, k: int, alive: np.ndarray, truth: np.ndarray, scenario: Scenario
) -> Step:
    """Step k of `recording` for the sensors `alive` (1, N), with the truth (M, 4) (NaN:
    away): the one reading of a recording, for `replay` and the agents' world."""
    uavs = recording.poses[k][None]
    observed = sensing.in_view(uavs[:, :, None, :], truth[None, None], scenario.sensor)
    observed &= alive[..., None]
    sensed = simulation.Sensed(detected=observed, polar=np.zeros((0, 2)), scan=_scan(recording, k))
    links = None
    if recording.links is not None:
        adj = network.closed(recording.links[k][None]) & alive[:, :, None] & alive[:, None]
        links = network.links(adj, "dense")
    return Step(uavs=uavs, alive=alive, observed=observed, sensed=sensed, links=links)


def briefing(recording: Recording, scenario: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """The prior every UAV starts from as one mean (M, 4) and one covariance (4, 4), as
    the agents' Hello carries it; refused if the recording's targets have different
    covariances. Without a briefing: zeros and the identity, which no UAV reads."""
    if recording.prior is None:
        return np.zeros((scenario.n_targets, 4)), np.eye(4)
    mean, cov = recording.prior
    if not (cov == cov[0]).all():
        raise ValueError(
            "the agents take one briefing covariance for every target; this recording's differ"
        )
    return mean, cov[0]


def _scan(recording: Recording, k: int) -> scans.Scan:
    """Step k's scans (B = 1), padded to the most measurements of any sensor at k, as
    the simulator pads them; padding holds z = 0 and R = I."""
    valid = recording.valid[k]
    Z = int(valid.sum(axis=-1).max(initial=0))
    valid = valid[:, :Z]
    z = np.where(valid[..., None], recording.z[k, :, :Z], 0.0)
    R = np.where(valid[..., None, None], recording.R[k, :, :Z], np.eye(2))
    polar = np.where(valid[..., None], np.nan_to_num(recording.polar[k, :, :Z]), 0.0)
    origin = np.where(valid, recording.origin[k, :, :Z], scans.NONE)
    return scans.Scan(polar=polar[None], z=z[None], R=R[None], valid=valid[None],
                      origin=origin[None])  # fmt: skip


def _start(recording: Recording, scenario: Scenario) -> State:
    """The state at step 0: the sensors at their first poses, each with the recording's
    briefing as confirmed tracks, or none."""
    M = scenario.n_targets
    if recording.prior is not None:
        mean, cov = recording.prior
    else:
        mean, cov = np.zeros((M, 4)), np.broadcast_to(np.eye(4), (M, 4, 4))
    return simulation.start_state(scenario, recording.poses[0][None], mean[None], cov, None)


def of_trace(trace: Trace, scenario: Scenario, seed: int | None) -> Recording:
    """A simulated run's own scans as a `Recording`: the UAVs' true states as their
    poses (a run without ``faults.position_std``), its scans converted as the run's
    UAVs converted them, its truth, and, with ``tracker.briefing`` and the run's `seed`,
    the briefing its UAVs started with (`world.prior_of`)."""
    if trace.scan_valid is None:
        raise ValueError("this trace holds no scans: a run with tracker.association gnn or jpda")
    if scenario.faults.position_std > 0:
        raise ValueError(f"faults.position_std: {REFUSED['faults.position_std']}")
    valid = trace.scan_valid
    believed = np.broadcast_to(trace.uavs[:, :, None, :], valid.shape + (5,))
    z, R = simulation.convert(believed[valid], trace.scan_polar[valid], scenario)
    zz = np.zeros(valid.shape + (2,))
    RR = np.broadcast_to(np.eye(2), valid.shape + (2, 2)).copy()
    zz[valid], RR[valid] = z, R
    prior = None
    if scenario.tracker.briefing:
        if seed is None:
            raise ValueError("the run's briefing is drawn from its seed, which this trace lacks")
        prior = world.prior_of(scenario, seed)
    return Recording(
        poses=trace.uavs,
        alive=trace.alive,
        z=zz,
        R=RR,
        valid=valid,
        polar=np.where(valid[..., None], trace.scan_polar, np.nan),
        origin=trace.scan_origin,
        prior=prior,
        targets=trace.targets,
    )
