"""The world program: the truth of one trial, and the physics between the UAV programs.

It owns what no UAV may read: the targets' and UAVs' true states, the sensor noise
(the trial's sensor stream, drawn exactly as the batch simulator draws it), which UAVs
are in radio range and which are alive, and each UAV's position error. Every cycle it
sends each living UAV only its own measurements, its believed pose and whom it can hear
(`messages.Sense`), waits for every UAV's decision (`messages.Report`, with a
deadline), flies the UAVs and records the cycle with the simulator's own `Cycle`,
`metrics.Tally` and `simulation.Recorder`, so a swarm's trace and metrics have the
format of `uavtrack run`'s.

A program takes its number only by an authentic message (its presence as it meets the
others, then its `Ready`; sealed with its own key): then it is a member, and the world's
Hello names it, so no other program takes the number. A member that misses its report
of a cycle, or whose process is gone (its own liveliness token dropped, confirmed by
asking for it again; a token is a hint, see `transport.Mailbox`), is lost from that
cycle on: the cycle records it as failed (no estimate, no observation, no decision), so
every metric masks it in the one place it masks failed UAVs. Without the central node
(centralized method), each UAV keeps its own filter and its last assigned target. Why
each was lost is kept (`Traffic.why`) and told to the program (`messages.Lost`).

The radio messages the programs could not wait for are counted in the cycle (`Cycle.
late`, from their reports). A world that was stopped (`stops`) past the Zenoh lease
lost its programs' sessions and what was in flight on them: it believes no token gone
while their sessions open again (`transport.REJOIN`), and asks again, every second, for
the reports of the cycle that do not come.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import records, simulation, world
from ..config import Scenario
from ..faults import PROTOCOLS
from ..flight.unicycle import Unicycle
from ..io import replay
from ..io.replay import Recording
from ..methods import get
from ..radio import Budget
from ..tracks import columns
from ..tracks.team import CONFIRMED
from .messages import VERSION, Array, Hello, Lost, Sense, Spec, Tick
from .security import WORLD, Gate, Keyring
from .stops import STOPS
from .transport import ANY_JOIN, LEASE, REJOIN, Link, Mailbox, Transport, inbox_key, keys


@dataclass(kw_only=True)
class Traffic:
    """What a swarm run cost and what happened to its programs.

    cycle_seconds: wall time of each cycle [s]; published, bytes: radio messages
    published and their bytes (every program's); received: messages delivered to the
    programs; overruns: the steps whose cycle took longer than dt (with --realtime);
    drops: messages dropped by the world and every program, by reason; failed: UAVs
    failed by the fault model (uav -> step); lost: programs gone or silent past their
    deadline (program -> step; the central node is program N), and why: why each was
    lost, in one line; late: radio messages that missed their cycle (`records.Cycle.
    late`), by protocol, and late_from: the first step with one (-1: none), from which the
    trace may differ from the simulator's.
    """

    cycle_seconds: list[float] = field(default_factory=list)
    published: int = 0
    bytes: int = 0
    received: int = 0
    overruns: list[int] = field(default_factory=list)
    drops: dict[str, int] = field(default_factory=dict)
    failed: dict[int, int] = field(default_factory=dict)
    lost: dict[int, int] = field(default_factory=dict)
    why: dict[int, str] = field(default_factory=dict)
    late: dict[str, int] = field(default_factory=dict)
    late_from: int = -1
    program_drops: dict[int, dict[str, int]] = field(default_factory=dict)

    @property
    def dropped(self) -> int:
        """Messages dropped, whatever the reason, by the world and every program."""
        return sum(self.drops.values())

    def count_late(self, k: int, late: np.ndarray) -> None:
        """The late messages of step k, (P,) by protocol (`faults.PROTOCOLS`)."""
        for protocol, count in zip(PROTOCOLS, late.tolist(), strict=True):
            if count:
                self.late[protocol] = self.late.get(protocol, 0) + count
        if late.any() and self.late_from < 0:
            self.late_from = k


class WorldProgram:
    """The truth of one trial of `scenario` (seeded like `simulate(scenario, seed=seed)`).

    keyring: the run's keys (`security.Keyring`; None: messages are not authenticated).
    recording: recorded scans and poses in place of the truth (`replay.Recording`, its
    scenario `replay.scenario_for`'s): each UAV program is told its own and the world's
    trace equals `replay.replay`'s. pilot: what flies the UAVs' decisions (a
    `io.mavlink.MavlinkPilot`; None: the scenario's aircraft), whose flight a recording's
    poses then replace.
    """

    def __init__(
        self,
        scenario: Scenario,
        method: str,
        seed: int,
        transport: Transport,
        run: str,
        deadline: float = 2.0,
        startup: float = 60.0,
        keyring: Keyring | None = None,
        recording: Recording | None = None,
        pilot: Any = None,
    ) -> None:
        self.scenario, self.method = scenario, get(method)
        self.recording, self.pilot = recording, pilot
        self.transport, self.run, self.deadline, self.startup = transport, run, deadline, startup
        self.keyring = keyring
        self.keys = keys(run)
        self.seeds = [np.random.SeedSequence(seed)]
        self.ctx = simulation.Context.of(scenario, self.method, self.seeds)
        programs = len(self.programs)
        gate = (
            keyring.gate()
            if keyring is not None
            else Gate(run=run, me=WORLD, programs=programs, credential=None)
        )
        self.link = Link(transport, gate)
        self.spec = Spec.of(scenario, self.method.central, self.method.plans)
        self.stops = STOPS.watch()  # a stop of the world is not its programs' fault
        self.mailbox = Mailbox(gate, self.spec, transport, self.stops)
        transport.subscribe(inbox_key(run, WORLD), self.mailbox.handler)
        transport.subscribe(ANY_JOIN, self.mailbox.joined)  # any run's: a program of
        # another run hears this world's Hello, and can tell its user
        transport.watch(self.keys["alive"], self.mailbox.lost)
        self.traffic = Traffic()
        self.check: Callable[[], None] | None = None
        self.supervise: Callable[[int], None] | None = None
        """Called as each cycle k begins; raises to end the run (its programs' launcher
        gone, and every program with it)."""
        self.clock: Callable[[int], None] | None = None
        """Told each step k as it begins, before the step's Sense goes out (the ROS 2 /clock)."""
        self.step = -1
        self.members: set[int] = set()
        """Programs heard from (an authentic message) and not gone or lost since."""
        self.central_alive = self.method.central
        self.prior: tuple[np.ndarray, np.ndarray] | None = None
        self._answered = 0
        self.began = -float("inf")  # when the current cycle began (monotonic clock)
        self.asked: dict[int, Sense | Tick] = {}  # this cycle's message to each program

    def _gone(self) -> set[int]:
        """The members whose processes are gone: heard from, then their own tokens
        confirmed gone (a token is a hint: it only cuts the wait for the report of a
        program that will not send one)."""
        with self.mailbox.cond:  # an authentic word, on Zenoh's thread, takes one back
            return self.mailbox.gone & self.members

    @property
    def programs(self) -> list[int]:
        """The programs of the run: the UAVs, and the central node (N) if any."""
        n = self.scenario.n_uavs
        return list(range(n)) + ([n] if self.method.central else [])

    def hello(self) -> None:
        assert self.prior is not None  # set by run_trial before the first Hello
        prior_mean, prior_cov = self.prior
        message = Hello(
            version=VERSION,
            run=self.run,
            scenario=self.scenario.model_dump_json(),
            method=self.method.name,
            key=Array.of(self.ctx.faults.key[0]),
            prior_mean=Array.of(prior_mean),
            prior_cov=Array.of(prior_cov),
            deadline=self.deadline,
            authenticated=self.link.gate.authenticates,
            publics=self.keyring.public() if self.keyring is not None else [],
            step=self.step,
            members=sorted(self.members),
        )
        self.link.hello(message)

    def wait_ready(self) -> None:
        """Publish the run until every program has said it is ready.

        `self.check`, if set, is called while waiting and raises when the programs cannot
        come any more (their processes exited)."""
        deadline = time.monotonic() + self.startup
        waiting = set(self.programs)
        while waiting:
            if self.check is not None:
                self.check()
            self.hello()
            self.mailbox.wait(lambda: False, min(deadline, time.monotonic() + 0.2))
            waiting = {p for p in waiting if self.mailbox.take(("ready", p)) is None}
            with self.mailbox.cond:  # a program that went before the run is no member
                self.members = (self.mailbox.heard - self.mailbox.gone) & set(self.programs)
            if waiting and time.monotonic() > deadline:
                raise TimeoutError(self._not_started(waiting))
        self.members = set(self.programs)  # all ready: one gone since is lost at step 0

    def _not_started(self, waiting: set[int]) -> str:
        """Which programs kept the run from starting (never heard from, or gone), and
        which were there (members: heard from, by authentic messages)."""
        missing = sorted(waiting - self.members) or sorted(waiting)
        started = sorted(set(self.programs) - set(missing))
        names = ", ".join(map(str, missing))
        there = f"; {', '.join(map(str, started))} started and waited for them" if started else ""
        which = "programs" if len(missing) > 1 else "program"
        return f"{which} {names} did not start within {self.startup:g} s{there}"

    def run_trial(
        self, trace: bool = True, realtime: bool = False, progress: Callable | None = None
    ) -> records.BatchResult:
        """Run every cycle; returns the trial's metrics and trace as `simulation.run` does."""
        s, ctx, rec = self.scenario, self.ctx, self.recording
        T, Nu, Nt = s.steps, s.n_uavs, s.n_targets
        if rec is None:
            state, trajectory, sensor_rngs = simulation.initial_stream(s, self.seeds, keep=trace)
            uavs, alive = state.uavs, state.alive
            self.prior = (state.mean[0, 0, :Nt], state.cov[0, 0, 0])  # the briefed
            pilot = state.flight if state.flight is not None else Unicycle(s.dt)
            noises = simulation.sensor_noise(sensor_rngs, Nu, Nt, T)
            truth = None
        else:
            trajectory = None
            uavs, alive = rec.poses[:1], np.ones((1, Nu), dtype=bool)
            self.prior = replay.briefing(rec, s)
            pilot = None
            noises = (None for _ in range(T))
            truth = rec.targets if rec.targets is not None else np.full((T, Nt, 4), np.nan)
        if self.pilot is not None:
            pilot = self.pilot
        self.wait_ready()
        tally = simulation.scores(s, 1, timed=True)
        recorder = simulation.Recorder(T, timed=True) if trace else None
        told = np.ones(Nu, dtype=bool)  # the UAVs sent a Sense last cycle
        due = time.monotonic()  # when the next cycle is due (with realtime)
        for k, noise in enumerate(noises):
            begin = self.began = time.monotonic()
            self.step = k
            if self.supervise is not None:
                self.supervise(k)
            if self.clock is not None:
                self.clock(k)
            self.mailbox.begin(k, k)
            self._answer_joins()
            self._tell_lost()
            was = alive
            if rec is not None:  # a sensor that stops recording has failed
                alive = alive & rec.alive[k][None]
            else:
                alive = ctx.faults.alive(k, alive) if ctx.setting.faulty else alive.copy()
            for i in np.flatnonzero(was[0] & ~alive[0]):
                self.traffic.failed.setdefault(int(i), k)
                self.members.discard(int(i))  # its program ends with its UAV
            self._lose(k, alive, dict.fromkeys(self._gone(), self._gone_why()))
            if rec is None:
                assert trajectory is not None and noise is not None
                believed = world.believed(uavs, ctx.faults.position_error(k))
                graph = simulation.graph(uavs, alive, s)
                targets = trajectory.at(k)
                observed, z = simulation.observe(uavs, targets, noise, alive, s)
                sensed = simulation.detect(uavs, believed, observed, z, alive, ctx)  # as `decide`
            else:
                assert truth is not None
                step = replay.at(rec, k, alive, truth[k], s)
                uavs = believed = step.uavs
                graph, targets = step.graph(s), truth[k][None]
                observed, sensed = step.observed, step.sensed
            scan = sensed.scan
            self.send(
                k, believed[0], sensed.detected[0], sensed.polar, graph[0], alive[0], told, scan
            )
            told = alive[0].copy()
            cycle, actions = self.collect(k, uavs, observed, alive, scan)
            self.traffic.count_late(k, cycle.late[0])
            if recorder is not None:
                recorder.record(k, cycle)
            tally.add(cycle, targets)
            if pilot is not None:  # a recording's next poses replace where it flew
                uavs = pilot.fly(*simulation.command(uavs, actions, s, ctx.const), alive)
            took = time.monotonic() - begin
            self.traffic.cycle_seconds.append(took)
            if realtime:
                if took > s.dt:
                    self.traffic.overruns.append(k)
                due += s.dt
                now = time.monotonic()
                if now < due:
                    time.sleep(due - now)
                else:  # late: the schedule starts again now; a late cycle is not made up
                    due = now
            if progress is not None:
                progress(k + 1)
        for drops in (self.mailbox.reasons(), *self.traffic.program_drops.values()):
            for reason, count in drops.items():
                self.traffic.drops[reason] = self.traffic.drops.get(reason, 0) + count
        traces = None
        if recorder is not None:
            if truth is not None:  # a recording's
                traces = recorder.traces(truth[None])
            else:
                assert trajectory is not None
                traces = recorder.traces(trajectory.whole())
        return records.BatchResult(self.method.name, s, tally.summary(), traces)

    def _answer_joins(self) -> None:
        """A program that asked for a Hello hears this run's, with the step it is at: one
        of this run learns that it cannot join a run under way, one of another run that
        it came to the wrong world."""
        if self.mailbox.joins > self._answered:
            self._answered = self.mailbox.joins
            self.hello()

    def _lose(self, k: int, alive: np.ndarray, programs: dict[int, str]) -> None:
        """Programs lost at step k (gone or silent), each with why: failed from k on,
        `alive` (1, N) updated in place; each is told (`messages.Lost`)."""
        n = self.scenario.n_uavs
        self.members -= set(programs)
        for i, why in sorted(programs.items()):
            if i < n and alive[0, i]:
                alive[0, i] = False
                if i in self.traffic.failed:
                    continue
            elif not (i == n and self.central_alive):
                continue
            if i == n:
                self.central_alive = False
            if i not in self.traffic.lost:
                self.traffic.lost[i], self.traffic.why[i] = k, why
                self._tell(i)

    def _tell(self, i: int) -> None:
        """Tell lost program i why it is lost."""
        k, why = self.traffic.lost[i], self.traffic.why[i]
        self.link.send(i, Lost(version=VERSION, run=self.run, k=k, program=i, reason=why))

    def _tell_lost(self) -> None:
        """Every lost program hears why again, once a cycle: one out of reach when it was
        lost hears it once it is back (one message per lost program; none if it is gone)."""
        for i in self.traffic.lost:
            self._tell(i)

    def _gone_why(self) -> str:
        """Why a program whose token is gone is lost (confirmed gone, `REJOIN` s after the
        world ran again if it was stopped)."""
        if self.stops.since(time.monotonic() - 2 * REJOIN):
            return (
                f"its Zenoh session closed while the world was stopped and did not open "
                f"again within {REJOIN:g} s of the world running again"
            )
        return (
            "its liveliness token went: its process ended, or it was out of reach longer "
            f"than the Zenoh session's lease ({LEASE:g} s)"
        )

    def afford(self, k: int, graph: np.ndarray, alive: np.ndarray, scan=None) -> Array | None:
        """With ``radio.bandwidth_bps``, what every share affords at cycle k (`Sense`,
        `radio.Budget` of the radio graph (N, N) the cycle's links are, and with tracks
        the measurements of each UAV's scan), as the batch's radio counts it; None: an
        unlimited radio."""
        rows = None if scan is None or not self.method.central else scan.valid.sum(axis=-1)
        limit = simulation.limit(self.ctx, k, rows)
        if limit is None:
            return None
        others = graph & ~np.eye(len(graph), dtype=bool)
        budget = Budget.of(limit, others.sum(axis=0)[None], alive[None])
        columns = (budget.first, budget.rounds, budget.served)
        return Array.of(np.stack([np.asarray(c[0], dtype=np.int64) for c in columns], axis=1))

    def send(self, k, believed, observed, z, graph, alive, told, scan=None) -> None:
        """Each UAV told last cycle its Sense (a UAV no longer alive learns it has failed),
        and the central node its Tick. With a scan (unknown association) a UAV is told its
        measurements unlabelled, in the order of its scan, and no target's index."""
        rows = np.nonzero(observed)[0]  # the UAV of each measurement, in order
        alive_array = Array.of(alive)
        afford = self.afford(k, graph, alive, scan)
        self.asked = {}
        for i in np.flatnonzero(told):
            if scan is not None:
                seen, mine = np.zeros(0, dtype=bool), scan.polar[0, i][scan.valid[0, i]]
            else:
                seen, mine = observed[i], z[rows == i]
            message = Sense(
                version=VERSION,
                run=self.run,
                k=k,
                uav=int(i),
                believed=Array.of(believed[i]),
                observed=Array.of(seen),
                z=Array.of(mine),
                links=Array.of(graph[i]),
                alive=alive_array,
                central=self.central_alive,
                afford=afford,
            )
            self.link.send(int(i), message)
            self.asked[int(i)] = message
        if self.central_alive:
            n = self.scenario.n_uavs
            self.asked[n] = Tick(
                version=VERSION, run=self.run, k=k, alive=alive_array, afford=afford
            )
            self.link.send(n, self.asked[n])

    def collect(self, k, uavs, observed, alive, scan=None):
        """Wait for every living UAV's report (and the central node's); build the Cycle.
        A program whose report does not come is lost from this cycle on: `alive` (1, N)
        and `observed` are updated in place. Returns the cycle and the actions (1, N)."""
        s = self.scenario
        Nu, Nt = s.n_uavs, s.n_targets
        K = s.track_slots if scan is not None else Nt  # the estimates: targets or slots
        expected = [i for i in range(Nu) if alive[0, i]] + ([Nu] if self.central_alive else [])
        mailbox = self.mailbox
        limit = time.monotonic() + self.cycle_deadline()

        def ready() -> bool:
            gone = self._gone()
            return all(("report", k, i) in mailbox.inbox or i in gone for i in expected)

        def ask_again() -> None:
            """After the world was stopped: what was in flight on the sessions that
            closed meanwhile is gone, this cycle's Sense or the report answering it; each
            program whose report has not come is sent its message again (it answers
            with its report), until it comes."""
            if self.stops.since(self.began - REJOIN):
                with mailbox.cond:
                    due = [i for i in expected if ("report", k, i) not in mailbox.inbox]
                for i in due:
                    if i in self.asked:
                        self.link.send(i, self.asked[i])

        mailbox.wait(ready, limit, meanwhile=ask_again)
        reports = {}
        for i in expected:
            got = mailbox.take(("report", k, i))
            if got is not None:
                reports[i] = got
        gone, late = self._gone(), f"no report of step {k} within the cycle's deadline"
        self._lose(
            k,
            alive,
            {
                i: self._gone_why() if i in gone else f"{late} ({self.cycle_deadline():g} s)"
                for i in set(expected) - set(reports)
            },
        )
        observed &= alive[:, :, None]
        mean = np.full((1, Nu, K, 4), np.nan)
        cov = np.full((1, Nu, K, 4, 4), np.nan)
        bids = np.full((1, Nu, K), np.nan)
        label = np.full((1, Nu, K), -1, dtype=np.int64)
        status = np.zeros((1, Nu, K), dtype=np.int8)
        existence = np.zeros((1, Nu, K))
        target = np.full((1, Nu), -1, dtype=np.int64)
        actions = np.full((1, Nu), simulation.STRAIGHT, dtype=np.int64)
        rounds = np.zeros((1, Nu), dtype=np.int64)
        decision, wall = np.full((1, Nu), np.nan), np.full((1, Nu), np.nan)
        sent = delivered = 0
        missed = np.zeros(len(PROTOCOLS), dtype=np.int64)
        on_air = np.zeros((1, Nu + 1), dtype=np.int64)  # the node's last
        for i, (report, arrays) in reports.items():
            on_air[0, i] = report.radio_bytes
            sent += report.sent
            delivered += report.delivered
            for protocol, count in report.late.items():
                missed[list(PROTOCOLS).index(protocol)] += count
            self.traffic.published += report.published
            self.traffic.bytes += report.bytes
            self.traffic.received += report.received
            self.traffic.program_drops[i] = dict(report.drops)
            if i == Nu or not alive[0, i]:
                continue
            mean[0, i], cov[0, i], bids[0, i] = arrays["mean"], arrays["cov"], arrays["bids"]
            if scan is not None:
                label[0, i], status[0, i] = arrays["label"], arrays["status"]
                existence[0, i] = arrays["existence"]
            target[0, i], actions[0, i] = report.target, report.action
            rounds[0, i], decision[0, i] = report.rounds, report.decision_ms
            wall[0, i] = report.decision_wall_ms
        cycle = records.Cycle(
            uavs=uavs,
            observed=observed,
            mean=mean,
            cov=cov,
            bids=bids,
            assignment=target,
            action=simulation.command(uavs, actions, self.scenario, self.ctx.const)[1],
            rounds=rounds,
            messages=np.array([sent]),
            delivered=np.array([delivered]),
            late=missed[None],
            bytes=on_air[:, :Nu],
            node_bytes=on_air[:, Nu],
            conflicts=self._conflicts(target, alive, label, status),
            alive=alive.copy(),
            decision_time_ms=decision,
            decision_wall_ms=wall,
            label=label if scan is not None else None,
            status=status if scan is not None else None,
            existence=existence if scan is not None else None,
            scan=scan,
        )
        return cycle, actions

    def _conflicts(self, target, alive, label, status) -> np.ndarray:
        """`simulation.conflicts` of the targets followed; with tracks, of the team labels
        followed, among the labels the living UAVs hold confirmed (`tracks.columns`)."""
        if not self.scenario.tracker.unlabelled:
            return simulation.conflicts(target, alive, self.scenario.n_targets)
        cols = columns.of(label, (status == CONFIRMED) & alive[..., None])
        taken = np.where(alive, columns.label_column(target, cols.labels), -1)
        return simulation.conflicts(taken, alive, cols.width)

    def cycle_deadline(self) -> float:
        """How long the world waits for the reports of a cycle: every round of every
        protocol may take up to a round's deadline."""
        s = self.scenario
        rounds = 2 * (s.n_uavs + 2) + (s.faults.round_budget or 0) + s.robust.extra_rounds
        return self.deadline * (rounds + 4) + 5.0
