"""B trials of a scenario stepped together: the simulator's own stages, the agents'
actions. The parallel environment (B = 1) and the vector environment (B trials) are
views of this one loop, so they cannot differ."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..config import Scenario
from ..methods import Method
from ..simulation import (
    BatchResult,
    Context,
    Pending,
    Recorder,
    check_memory,
    decide,
    finish,
    graph,
    initial_state,
    scores,
    sensor_noise,
)
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
        self.state, self.trajectory, rngs = initial_state(s, self.seeds)
        self.noises = sensor_noise(rngs, s.n_uavs, s.n_targets, s.steps)
        B = len(self.seeds)
        self.seen = np.zeros((B, s.n_targets))  # steps each target was in some UAV's view
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
        if self.tally is not None and self.recorder is not None:  # record=True: both
            self.tally.add(cycle, self.trajectory[:, k])
            self.recorder.record(k, cycle)
        self.pending = self._decide()
        if self.pending is None:
            return np.zeros(pending.alive.shape)
        p = self.pending
        earned = rewards(self.reward, p.observed, self.state.cov, p.belief[1])
        return np.where(pending.alive, earned, 0.0)  # a UAV already down did not act

    def view(self) -> View:
        """What the pending cycle shows; once done, the state flown to with its
        predicted estimates (nothing in view)."""
        p = self.pending
        if p is not None:
            links = graph(p.uavs, p.alive, self.scenario)
            return View(
                k=p.k,
                believed=p.believed,
                uavs=p.uavs,
                mean=p.fused.mean,
                cov=p.fused.cov,
                links=links,
                alive=p.alive,
                observed=p.observed,
            )
        s = self.state
        links = graph(s.uavs, s.alive, self.scenario)
        observed = np.zeros(s.mean.shape[:3], dtype=bool)
        return View(
            k=s.k,
            believed=s.uavs,
            uavs=s.uavs,
            mean=s.mean,
            cov=s.cov,
            links=links,
            alive=s.alive,
            observed=observed,
        )

    def observation_rate(self) -> np.ndarray:
        """(B,) the observation rate of each trial over the steps flown."""
        if self.k == 0:
            raise RuntimeError("no step flown yet")
        return (self.seen / self.k).mean(axis=-1)  # as metrics.Tally computes it

    def batch_result(self) -> BatchResult:
        """The steps flown as `simulation.run` reports them (record=True only)."""
        if self.tally is None or self.recorder is None:
            raise RuntimeError("these episodes keep no record (record=False)")
        traces = self.recorder.traces(self.trajectory[:, : self.k])
        return BatchResult(self.method.name, self.scenario, self.tally.summary(), traces)

    def _decide(self) -> Pending | None:
        k = self.state.k
        if k >= self.scenario.steps:
            return None
        return decide(self.state, self.trajectory[:, k], next(self.noises), self.ctx, self.plan)
