"""B trials of a scenario stepped together: the simulator's own stages, the agents'
actions. The parallel environment (B = 1) and the vector environment (B trials) are
views of this one loop, so they cannot differ."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..config import Scenario
from ..methods import Method
from ..records import BatchResult, Pending
from ..simulation import (
    Context,
    Recorder,
    check_memory,
    decide,
    finish,
    graph,
    initial_stream,
    scores,
    sensor_noise,
)
from ..tracks import association
from ..tracks.scan import Scan
from ..world import present
from .spaces import Spaces, View, rewards


class Episodes:
    """The trials of `seeds` from step 0: `step` flies the agents' actions through one
    cycle and returns what they earn. `record` keeps `simulate`'s metrics and trace
    (the parallel environment's `result()`); without it only the observation rate is
    counted. plan=False skips the method's planning and assignment (`decide`): for
    agents that choose every action, nothing to fly for them."""

    def __init__(
        self,
        scenario: Scenario,
        method: Method,
        spaces: Spaces,
        reward: str,
        seeds: Sequence[np.random.SeedSequence],
        record: bool = False,
        plan: bool = True,
    ) -> None:
        check_memory(scenario, len(seeds), trace=record)
        s = self.scenario = scenario
        self.method, self.spaces, self.reward, self.seeds = method, spaces, reward, list(seeds)
        self.plan = plan
        self.ctx = Context.of(s, method, self.seeds)
        self.state, self.trajectory, rngs = initial_stream(s, self.seeds, keep=record)
        self.noises = sensor_noise(rngs, s.n_uavs, s.n_targets, s.steps)
        B = len(self.seeds)
        self.seen = np.zeros((B, s.n_targets))  # steps each target was in some UAV's view
        self.present = np.zeros((B, s.n_targets))  # steps each target was there
        self.tally = self.recorder = None
        if record:
            self.tally = scores(s, B, timed=B == 1)
            self.recorder = Recorder(s.steps, timed=B == 1)
        self.pending: Pending | None = self._decide()

    @property
    def k(self) -> int:
        """The step about to be flown (the steps flown so far)."""
        return self.state.k

    @property
    def done(self) -> bool:
        return self.pending is None

    @property
    def alive(self) -> np.ndarray:
        """(B, Nu) the UAVs alive at the pending cycle (none once done)."""
        if self.pending is None:
            return np.zeros(self.state.alive.shape, dtype=bool)
        return self.pending.alive

    @property
    def current(self) -> Pending:
        """The pending cycle; RuntimeError once the episodes are over."""
        if self.pending is None:
            raise RuntimeError("the episode is over: call reset()")
        return self.pending

    def step(self, actions: np.ndarray | None) -> np.ndarray:
        """Fly `actions` (B, Nu) indices into the action set (None: the method's) and
        return what they earn (B, Nu), read off the next cycle (0 after the last)."""
        if self.pending is None:
            raise RuntimeError("the episode is over: call reset()")
        k, pending = self.state.k, self.pending
        self.state, cycle = finish(self.state, pending, self.ctx, actions)
        self.seen += pending.observed.any(axis=1)
        self.present += present(self.trajectory.at(k))  # NaN: away (target.stay)
        if self.tally is not None and self.recorder is not None:  # record=True: both
            self.tally.add(cycle, self.trajectory.at(k))
            self.recorder.record(k, cycle)
        self.pending = self._decide()
        if self.pending is None:
            return np.zeros(pending.alive.shape)
        p = self.pending
        there = present(self.trajectory.at(p.k))
        earned = rewards(self.reward, p.observed, self.state.cov, p.belief[1], there)
        return np.where(pending.alive, earned, 0.0)  # a UAV already down did not act

    def view(self) -> View:
        """What the pending cycle shows; once done, the state flown to with its
        predicted estimates (nothing in view). With tracks, each UAV's confirmed
        tracks after fusion and which of them its own scan met (`in_view_now`)."""
        if self.pending is not None:
            return view_of(self.pending, self.scenario)
        s = self.state
        links = graph(s.uavs, s.alive, self.scenario)
        observed = np.zeros(s.alive.shape + (self.scenario.n_targets,), dtype=bool)
        label = met = None
        if s.book is not None:
            label = np.where(s.book.confirmed & s.alive[..., None], s.book.label, -1)
            met = np.zeros(label.shape, dtype=bool)
        return View(
            k=s.k,
            believed=s.uavs,
            uavs=s.uavs,
            mean=s.mean,
            cov=s.cov,
            links=links,
            alive=s.alive,
            observed=observed,
            label=label,
            met=met,
        )

    def observation_rate(self) -> np.ndarray:
        """(B,) the observation rate of each trial over the steps flown."""
        if self.k == 0:
            raise RuntimeError("no step flown yet")
        if (self.present == self.k).all():  # every target there throughout
            return (self.seen / self.k).mean(axis=-1)  # as metrics.Tally computes it
        return self.seen.sum(axis=-1) / np.maximum(self.present.sum(axis=-1), 1)

    def batch_result(self) -> BatchResult:
        """The steps flown as `simulation.run` reports them (record=True only)."""
        if self.tally is None or self.recorder is None:
            raise RuntimeError("these episodes keep no record (record=False)")
        traces = self.recorder.traces(self.trajectory.whole(self.k))
        return BatchResult(self.method.name, self.scenario, self.tally.summary(), traces)

    def _decide(self) -> Pending | None:
        k = self.state.k
        if k >= self.scenario.steps:
            return None
        return decide(self.state, self.trajectory.at(k), next(self.noises), self.ctx, self.plan)


def view_of(pending: Pending, scenario: Scenario) -> View:
    """What a pending cycle shows the agents (`View`): the radio graph of the UAVs'
    positions (or, after a policy's beacons, `Pending.beacons`: whom each UAV heard and
    the states they sent), each UAV's fused estimates, and with tracks each UAV's
    confirmed tracks and which of them its own scan met (`in_view_now`). One reading for the
    environments and a learned policy flown as a method (`env.policy`)."""
    p = pending
    links, heard = graph(p.uavs, p.alive, scenario), None
    if p.beacons is not None:  # a policy's cycle: whom each UAV heard, and their states
        links, heard = p.beacons
    label = met = None
    if p.tracks is not None:
        t = p.tracks
        label = np.where(t.book.confirmed & p.alive[..., None], t.book.label, -1)
        assert p.scan is not None  # a tracked cycle carries its scans
        met = in_view_now(t.mean, t.cov, label >= 0, p.scan, scenario.tracker.gate_probability)
    return View(
        k=p.k,
        believed=p.believed,
        uavs=p.uavs,
        mean=p.fused.mean,
        cov=p.fused.cov,
        links=links,
        alive=p.alive,
        observed=p.observed,
        label=label,
        met=met,
        heard=heard,
        detected=p.detected,  # what each UAV measured: it cannot know what it missed
    )


def in_view_now(
    mean: np.ndarray, cov: np.ndarray, confirmed: np.ndarray, scan: Scan, gate_probability: float
) -> np.ndarray:
    """Which tracks a UAV saw itself this scan, (B, Nu, K) bool: one of its own
    measurements (`Scan`, clutter or not: it cannot tell) lies in the gate
    d2 <= chi2.ppf(P_G, 2) of a confirmed track's estimate (mean (B, Nu, K, 4), cov
    (B, Nu, K, 4, 4)). What a UAV of unknown association knows in place of the truth's
    "inside my disk": a track it measured, not a target."""
    B, Nu, K = confirmed.shape
    Z = scan.z.shape[2]
    P = B * Nu
    inn = association.innovations(
        mean.reshape(P, K, 4), cov.reshape(P, K, 4, 4),
        scan.z.reshape(P, Z, 2), scan.R.reshape(P, Z, 2, 2),
    )  # fmt: skip
    gated = association.gate(
        inn.d2, confirmed.reshape(P, K), scan.valid.reshape(P, Z), gate_probability
    )
    return gated.any(axis=-1).reshape(B, Nu, K)
