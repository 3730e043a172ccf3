"""The world program: the truth of one trial, and the physics between the UAV programs.

It owns what no UAV may read: the targets' and UAVs' true states, the sensor noise
(the trial's sensor stream, drawn exactly as the batch simulator draws it), which UAVs
are in radio range and which are alive, and each UAV's position error. Every cycle it
sends each living UAV only its own measurements, its believed pose and whom it can hear
(`messages.Sense`), waits for every UAV's decision (`messages.Report`, with a
deadline), flies the UAVs and records the cycle with the simulator's own `Cycle`,
`metrics.Tally` and `simulation.Recorder`, so a swarm's trace and metrics have the
format of `uavtrack run`'s.

A UAV whose report misses the deadline, or whose program is gone (its liveliness
token dropped), has failed from the next cycle on.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .. import simulation, world
from ..config import G, Scenario
from ..methods import get
from ..metrics import Tally
from .agent import keys
from .messages import VERSION, Array, Hello, Report, Sense, Tick, encode
from .transport import Mailbox, Transport


@dataclass
class Traffic:
    """What a swarm run cost and what happened to its programs.

    cycle_seconds: wall time of each cycle [s]; published, bytes: radio messages
    published and their bytes (every program's); overruns: the steps whose cycle took
    longer than dt (with --realtime); dropped: malformed, foreign or old messages
    dropped (the world's and every program's); failed: UAVs failed by the fault model
    (uav -> step); lost: programs gone or silent past their deadline (uav -> step).
    """

    cycle_seconds: list[float] = field(default_factory=list)
    published: int = 0
    bytes: int = 0
    overruns: list[int] = field(default_factory=list)
    dropped: int = 0
    failed: dict[int, int] = field(default_factory=dict)
    lost: dict[int, int] = field(default_factory=dict)
    program_dropped: dict[int, int] = field(default_factory=dict)


class WorldProgram:
    """The truth of one trial of `scenario` (seeded like `simulate(scenario, seed=seed)`)."""

    def __init__(
        self,
        scenario: Scenario,
        method: str,
        seed: int,
        transport: Transport,
        run: str,
        deadline: float = 2.0,
        startup: float = 60.0,
    ) -> None:
        self.scenario, self.method = scenario, get(method)
        self.transport, self.run, self.deadline, self.startup = transport, run, deadline, startup
        self.keys = keys(run)
        self.seeds = [np.random.SeedSequence(seed)]
        self.ctx = simulation.Context.of(scenario, self.method, self.seeds)
        self.mailbox = Mailbox(run)
        transport.subscribe(self.keys["report"], self.mailbox.handler)
        transport.watch(self.keys["alive"], self._gone)
        self.gone: set[int] = set()
        self.traffic = Traffic()
        self.check: Callable[[], None] | None = None

    def _gone(self, key: str) -> None:
        tail = key.rsplit("/", 1)[-1]
        if tail.isdigit():
            self.gone.add(int(tail))

    @property
    def programs(self) -> list[int]:
        """The programs of the run: the UAVs, and the central node (N) if any."""
        n = self.scenario.n_uavs
        return list(range(n)) + ([n] if self.method.central else [])

    def hello(self, prior_mean: np.ndarray, prior_cov: np.ndarray) -> None:
        message = Hello(
            VERSION,
            self.run,
            self.scenario.model_dump_json(),
            self.method.name,
            Array.of(self.ctx.faults.key[0]),
            Array.of(prior_mean),
            Array.of(prior_cov),
            self.deadline,
        )
        self.transport.publish(self.keys["hello"], encode(message))

    def wait_ready(self, prior_mean, prior_cov) -> None:
        """Publish the run until every program has said it is ready (a report of step -1).

        `self.check`, if set, is called while waiting and raises when the programs cannot
        come any more (their processes exited)."""
        deadline = time.monotonic() + self.startup
        waiting = set(self.programs)
        while waiting:
            if self.check is not None:
                self.check()
            self.hello(prior_mean, prior_cov)
            self.mailbox.wait(lambda: False, min(deadline, time.monotonic() + 0.2))
            waiting = {p for p in waiting if self.mailbox.take(("report", -1, p)) is None}
            if waiting and time.monotonic() > deadline:
                raise TimeoutError(self._not_started(waiting))

    def _not_started(self, waiting: set[int]) -> str:
        """Which programs kept the run from starting, and which were there."""
        present = {
            int(k.rsplit("/", 1)[-1])
            for k in self.transport.alive(self.keys["alive"])
            if k.rsplit("/", 1)[-1].isdigit()
        }
        missing = sorted(waiting - present) or sorted(waiting)
        started = sorted(set(self.programs) - set(missing))
        names = ", ".join(map(str, missing))
        there = f"; {', '.join(map(str, started))} started and waited for them" if started else ""
        which = "programs" if len(missing) > 1 else "program"
        return f"{which} {names} did not start within {self.startup:g} s{there}"

    def run_trial(
        self, trace: bool = True, realtime: bool = False, progress: Callable | None = None
    ) -> simulation.BatchResult:
        """Run every cycle; returns the trial's metrics and trace as `simulation.run` does."""
        s, ctx = self.scenario, self.ctx
        state, trajectory, sensor_rngs = simulation.initial_state(s, self.seeds)
        uavs, alive = state.uavs, state.alive
        self.wait_ready(state.mean[0, 0], state.cov[0, 0, 0])
        T, Nu, Nt = s.steps, s.n_uavs, s.n_targets
        tally = Tally(
            1, Nu, Nt, timed=True, cutoff=s.evaluation.ospa_cutoff, order=s.evaluation.ospa_order
        )
        recorder = simulation.Recorder(T, timed=True) if trace else None
        previous = np.full((1, Nu), -1, dtype=np.int64)
        started = time.monotonic()
        noises = simulation.sensor_noise(sensor_rngs, Nu, Nt, T)
        for k, noise in enumerate(noises):
            begin = time.monotonic()
            was = alive
            alive = ctx.faults.alive(k, alive) if ctx.setting.faulty else alive.copy()
            for i in np.flatnonzero(was[0] & ~alive[0]):
                self.traffic.failed.setdefault(int(i), k)
            alive[0, sorted(i for i in self.gone if i < Nu)] = False
            for i in np.flatnonzero(was[0] & ~alive[0]):
                if int(i) not in self.traffic.failed:
                    self.traffic.lost.setdefault(int(i), k)
            believed = world.believed(uavs, ctx.faults.position_error(k))
            graph = simulation.graph(uavs, alive, s)
            targets = trajectory[:, k]
            observed, z = simulation.observe(uavs, targets, noise, alive, s)
            self.send(k, believed[0], observed[0], z, graph[0], alive[0], was[0])
            cycle, previous = self.collect(k, uavs, observed, alive, previous)
            if recorder is not None:
                recorder.record(k, cycle)
            tally.add(cycle, targets)
            new = world.fly(uavs, ctx.const.actions[self.actions], s.dt, G)
            uavs = np.where(alive[..., None], new, uavs)
            took = time.monotonic() - begin
            self.traffic.cycle_seconds.append(took)
            if realtime:
                if took > s.dt:
                    self.traffic.overruns.append(k)
                due = started + (k + 1) * s.dt  # the schedule: a late cycle is not made up
                if time.monotonic() < due:
                    time.sleep(due - time.monotonic())
            if progress is not None:
                progress(k + 1)
        self.traffic.dropped = self.mailbox.dropped + sum(self.traffic.program_dropped.values())
        traces = recorder.traces(trajectory) if recorder is not None else None
        return simulation.BatchResult(self.method.name, s, tally.summary(), traces)

    def send(self, k, believed, observed, z, graph, alive, was) -> None:
        rows = np.nonzero(observed)[0]  # the UAV of each measurement, in order
        alive_array = Array.of(alive)
        for i in range(self.scenario.n_uavs):
            if not was[i]:
                continue  # failed before: told already
            message = Sense(
                VERSION,
                self.run,
                k,
                i,
                Array.of(believed[i]),
                Array.of(observed[i]),
                Array.of(z[rows == i]),
                Array.of(graph[i]),
                alive_array,
            )
            self.transport.publish(f"{self.keys['sense']}{i}", encode(message))
        if self.method.central:
            self.transport.publish(
                self.keys["tick"], encode(Tick(VERSION, self.run, k, alive_array))
            )

    def collect(self, k, uavs, observed, alive, previous):
        """Wait for every living UAV's report (and the central node's); build the Cycle."""
        s = self.scenario
        Nu, Nt = s.n_uavs, s.n_targets
        expected = [i for i in range(Nu) if alive[0, i]] + ([Nu] if self.method.central else [])
        mailbox = self.mailbox
        limit = time.monotonic() + self.cycle_deadline()
        mailbox.wait(
            lambda: all(("report", k, i) in mailbox.inbox or i in self.gone for i in expected),
            limit,
        )
        reports: dict[int, Report] = {}
        for i in expected:
            report = mailbox.take(("report", k, i))
            if report is None:
                self.gone.add(i)  # missed its deadline: failed from the next cycle
            else:
                reports[i] = report
        mean = np.full((1, Nu, Nt, 4), np.nan)
        cov = np.full((1, Nu, Nt, 4, 4), np.nan)
        bids = np.full((1, Nu, Nt), np.nan)
        target = np.full((1, Nu), -1, dtype=np.int64)
        actions = np.full((1, Nu), simulation.STRAIGHT, dtype=np.int64)
        rounds = np.zeros((1, Nu), dtype=np.int64)
        decision = np.full((1, Nu), np.nan)
        sent = delivered = 0
        for i, report in reports.items():
            sent += report.sent
            delivered += report.delivered
            self.traffic.published += report.published
            self.traffic.bytes += report.bytes
            self.traffic.program_dropped[i] = report.dropped
            if i == Nu:
                continue
            try:
                mean[0, i] = report.mean.array().reshape(Nt, 4)
                cov[0, i] = report.cov.array().reshape(Nt, 4, 4)
                bids[0, i] = report.bids.array().reshape(Nt)
            except ValueError:
                self.mailbox.dropped += 1
                continue
            target[0, i], actions[0, i] = report.target, report.action
            rounds[0, i], decision[0, i] = report.rounds, report.decision_ms
        self.actions = actions
        cycle = simulation.Cycle(
            uavs=uavs,
            observed=observed,
            mean=mean,
            cov=cov,
            bids=bids,
            assignment=target,
            action=self.ctx.const.actions[actions],
            rounds=rounds,
            messages=np.array([sent]),
            delivered=np.array([delivered]),
            conflicts=simulation.conflicts(target, alive, Nt),
            alive=alive,
            decision_time_ms=decision,
        )
        return cycle, np.where(target >= 0, target, previous)

    def cycle_deadline(self) -> float:
        """How long the world waits for the reports of a cycle: every round of every
        protocol may take up to a round's deadline."""
        s = self.scenario
        rounds = 2 * (s.n_uavs + 2) + (s.faults.round_budget or 0) + s.robust.extra_rounds
        return self.deadline * (rounds + 4) + 5.0
