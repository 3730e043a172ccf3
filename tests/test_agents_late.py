"""Nothing late is silent, and a stopped world blames no healthy program.

The simulator's radio is never late. A swarm's program waits a round's deadline for each
message the fault model delivers; one that has not come by then is late (or never sent:
its sender stopped or gone), and the program decides without it, maybe otherwise than
the simulator. Each is counted by protocol (the trace's ``late``, the swarm's ``--json``,
a note), so a swarm's trace equals the simulator's up to the first late message or lost
program, and the run says from which step it may differ.

A world stopped (SIGSTOP) past the Zenoh lease loses its programs' sessions and what was
in flight on them; it notices its own stop, waits for the sessions to open again and asks
again for the reports that did not come. A program it loses is told why, and the world
says why, in one line.
"""

import json
import os
import signal
import subprocess
import sys
import threading
import time
import types
from contextlib import contextmanager
from pathlib import Path

import msgspec
import numpy as np
import pytest

import uavtrack
from uavtrack.agents import messages, run_swarm
from uavtrack.agents import world as world_module
from uavtrack.agents.security import WORLD, Gate
from uavtrack.agents.stops import SLACK, TICK, Stops
from uavtrack.agents.transport import REJOIN, Bus, Link, Mailbox, MemoryTransport
from uavtrack.faults import PROTOCOLS
from uavtrack.testing import differences

pytestmark = pytest.mark.integration  # the agent form against real deadlines

ROOT = Path(__file__).resolve().parents[1]


def head(trace, k: int):
    """The first k steps of a trace."""
    arrays = trace.arrays() if hasattr(trace, "arrays") else vars(trace)
    names = ("targets", *uavtrack.simulation.Trace.__dataclass_fields__)
    return types.SimpleNamespace(
        **{n: arrays[n][:k] for n in names if arrays.get(n) is not None and arrays[n].ndim}
    )


def first_late(trace) -> int | None:
    steps = np.flatnonzero(trace.late.sum(axis=1))
    return int(steps[0]) if steps.size else None


def decoded(body: bytes):
    return msgspec.msgpack.Decoder(messages.Message).decode(body)


def hold(monkeypatch, sender: int, step: int, protocols: set[str], seconds: float, to=None):
    """The radio messages of program `sender` at `step` carrying round 1 of one of
    `protocols` (round 0 for those of one round), to receiver `to` or any, reach their
    receivers `seconds` late."""
    send = Link.send_body
    held = []

    def send_body(link, receiver, body):
        if link.gate.me == sender and (to is None or receiver == to):
            message = decoded(body)
            parts = {p.protocol for p in getattr(message, "parts", []) if p.round <= 1}
            if isinstance(message, messages.Radio) and message.k == step and parts & protocols:
                held.append(receiver)
                threading.Timer(seconds, send, (link, receiver, body)).start()
                return len(link.gate.seal(receiver, body))  # its size when it goes
        return send(link, receiver, body)

    monkeypatch.setattr(Link, "send_body", send_body)
    return held


def losing(monkeypatch) -> threading.Event:
    """An event set once the world has lost a program."""
    lost = threading.Event()
    lose = world_module.WorldProgram._lose

    def _lose(self, k, alive, programs):
        lose(self, k, alive, programs)
        if programs:
            lost.set()

    monkeypatch.setattr(world_module.WorldProgram, "_lose", _lose)
    return lost


def run_cli(capsys, *args):
    from uavtrack import cli

    code = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_late_radio_messages_are_counted_by_protocol_in_the_trace_and_the_json(
    monkeypatch, capsys, tmp_path
):
    # UAV 1's first round of flooding and consensus at step 3 comes 2.5 s late, past its
    # receivers' deadline (1 s): they decide without it, and say so
    held = hold(monkeypatch, 1, 3, {"consensus"}, 2.5)
    path = tmp_path / "swarm.npz"
    code, out, err = run_cli(
        capsys, "swarm", "--set", "steps=8", "--set", "comm_range=80", "--seed", 5,
        "--deadline", 1, "--json", "--trace", path,
    )  # fmt: skip
    assert code == 0, err
    assert held
    swarm = json.loads(out)["swarm"]
    with np.load(path) as arrays:
        trace = types.SimpleNamespace(**{name: arrays[name] for name in arrays.files})
    assert trace.late.shape == (8, len(PROTOCOLS)) and trace.late.dtype == np.int64
    flood, consensus = (list(PROTOCOLS).index(p) for p in ("flood", "consensus"))
    assert trace.late[3, flood] >= 1 and trace.late[3, consensus] >= 1
    by_protocol = {p: int(c) for p, c in zip(PROTOCOLS, trace.late.sum(axis=0), strict=True) if c}
    assert swarm["late_by_protocol"] == by_protocol
    assert swarm["late_messages"] == int(trace.late.sum())
    assert first_late(trace) == swarm["late_from_step"] <= 3  # (earlier on a loaded machine)
    # no faults: every message a receiver counts sent arrived or is counted late
    assert (trace.delivered + trace.late.sum(axis=1) == trace.messages).all()
    reference = uavtrack.simulate(
        uavtrack.Scenario(steps=8, comm_range=80.0), "distributed", seed=5
    ).trace
    until = swarm["late_from_step"]
    assert differences(head(trace, until), head(reference, until)) == []
    assert swarm["lost"] == {}
    notes = [line for line in err.splitlines() if "missed their cycle" in line]
    assert len(notes) == 1 and f"from step {until}" in notes[0]
    assert "may differ from the simulator's from that step" in notes[0]


@pytest.mark.parametrize(
    "sender,step,protocol,to",
    [(2, 2, "upload", None), (5, 4, "download", 0)],
    ids=["upload", "download"],
)
def test_a_late_upload_or_download_is_counted_not_skipped_silently(
    monkeypatch, sender, step, protocol, to
):
    # centralized: program 5 is the central node; the message comes 2.5 s late, past
    # its receiver's deadline (1 s)
    held = hold(monkeypatch, sender, step, {protocol}, 2.5, to=to)
    scenario = uavtrack.Scenario(steps=7)
    swarm = run_swarm(scenario, "centralized", seed=1, transport="memory", deadline=1.0)
    trace = swarm.result.trace
    assert held and swarm.traffic.lost == {}
    assert trace.late[step, list(PROTOCOLS).index(protocol)] >= 1
    reference = uavtrack.simulate(scenario, "centralized", seed=1).trace
    assert equal_until_counted(swarm, reference) is not None
    assert (trace.delivered + trace.late.sum(axis=1) == trace.messages).all()


def test_a_uav_waits_for_its_download_while_the_node_waits_for_the_uploads(monkeypatch):
    # the central node sends the downloads only once the uploads are in (it may wait a
    # round's deadline for them) and its work is done: here that work takes 1.4 rounds'
    # deadlines at step 2, and the UAVs, waiting two, take their downloads on time
    from uavtrack.agents import agent

    work = agent.central_node

    def slow(got, heard, reported, setting, k, clock=None):
        if k == 2:
            time.sleep(1.4)
        return work(got, heard, reported, setting, k, clock)

    monkeypatch.setattr(agent, "central_node", slow)
    scenario = uavtrack.Scenario(steps=4)
    swarm = run_swarm(scenario, "centralized", seed=1, transport="memory", deadline=1.0)
    reference = uavtrack.simulate(scenario, "centralized", seed=1).trace
    assert equal_until_counted(swarm, reference) is None  # nothing late: the same trace


def test_a_swarm_on_time_counts_no_late_message():
    scenario = uavtrack.Scenario(steps=6)
    for method in ("distributed", "centralized"):
        swarm = run_swarm(scenario, method, seed=2, transport="memory")
        reference = uavtrack.simulate(scenario, method, seed=2).trace
        assert differences(swarm.result.trace, reference) == []  # late included: zeros
        assert swarm.traffic.late == {} and swarm.traffic.late_from == -1
        assert reference.late.shape == (6, len(PROTOCOLS)) and not reference.late.any()


def test_a_program_the_world_loses_is_told_why_not_that_it_failed(monkeypatch, capsys):
    # uavtrack agent as program 2 of a world on an in-process bus: program 2 takes
    # longer than the cycle's deadline at step 3 (it answers once the world has lost it)
    from uavtrack.agents import agent, transport
    from uavtrack.agents.program import serve

    bus = Bus()
    run = "a1b2c3d4e5f6"
    monkeypatch.setattr(
        transport, "ZenohTransport", lambda listen, connect, options=None: MemoryTransport(bus)
    )
    told = losing(monkeypatch)
    cycle = agent.UavAgent.cycle

    def slow(self, k, sense, central=True):
        if self.me == 2 and k == 3:
            assert told.wait(120)
        return cycle(self, k, sense, central)

    monkeypatch.setattr(agent.UavAgent, "cycle", slow)
    scenario = uavtrack.Scenario(steps=8)
    world = world_module.WorldProgram(
        scenario, "distributed", 1, MemoryTransport(bus), run, deadline=0.05, startup=60
    )
    done = {}
    threads = [threading.Thread(target=lambda: done.update(batch=world.run_trial()))]
    threads += [
        threading.Thread(target=serve, args=(MemoryTransport(bus), run, i), daemon=True)
        for i in (0, 1, 3, 4)
    ]
    for thread in threads:
        thread.start()
    code, out, err = run_cli(capsys, "agent", "--run", run, "--uav", 2, "--connect", "x")
    threads[0].join(120)
    deadline = f"{world.cycle_deadline():g} s"
    why = f"no report of step 3 within the cycle's deadline ({deadline})"
    assert code == 1 and err.count("\n") == 1, err
    assert f"UAV program 2 of run {run}: the world lost it at step 3 ({why})" in err
    assert "after 4 of 8 cycles" in err and "fault model" not in err  # its late one too
    assert world.traffic.lost == {2: 3} and world.traffic.why == {2: why}
    trace = done["batch"].traces[0]
    assert not trace.alive[3:, 2].any() and trace.alive[:, [0, 1, 3, 4]].all()


def test_the_swarm_says_in_one_line_why_it_lost_a_program(monkeypatch, capsys):
    from uavtrack.agents import agent

    cycle = agent.UavAgent.cycle
    release = losing(monkeypatch)

    def slow(self, k, sense, central=True):
        if self.me == 4 and k == 2:
            release.wait(120)
        return cycle(self, k, sense, central)

    monkeypatch.setattr(agent.UavAgent, "cycle", slow)
    code, out, err = run_cli(
        capsys, "swarm", "--set", "steps=5", "--deadline", 0.05, "--json"
    )  # fmt: skip
    assert code == 0, err
    swarm = json.loads(out)["swarm"]
    assert swarm["lost"] == {"4": 2}
    why = swarm["lost_why"]["4"]
    assert why.startswith("no report of step 2 within the cycle's deadline (")
    assert f"uavtrack: note: program 4 lost at step 2: {why}\n" in err


def test_realtime_a_late_cycle_is_not_made_up(monkeypatch):
    # cycle 4 takes 1.25 s at dt = 0.25 s: the cycles after it start dt apart again, not
    # back to back until the schedule is caught up (the world's own step log: progress
    # is told each step as the previous cycle ends and the schedule allows the next)
    from uavtrack.agents import agent

    cycle = agent.UavAgent.cycle

    def slow(self, k, sense, central=True):
        if self.me == 0 and k == 4:
            time.sleep(1.25)
        return cycle(self, k, sense, central)

    monkeypatch.setattr(agent.UavAgent, "cycle", slow)
    starts = []
    scenario = uavtrack.Scenario(steps=12, dt=0.25)
    swarm = run_swarm(
        scenario, "distributed", seed=1, transport="memory", realtime=True,
        progress=lambda k: starts.append(time.monotonic()),
    )  # fmt: skip
    assert 4 in swarm.traffic.overruns
    gaps = np.diff(starts)
    assert gaps[3] >= 1.25  # the late cycle
    short = int((gaps[4:] < scenario.dt / 2).sum())  # a cycle made up is a short gap
    assert short <= 1, gaps  # one allowed to a loaded machine's scheduler; made up: 4


def test_after_a_stop_the_world_asks_again_for_what_the_closed_sessions_lost(monkeypatch):
    # a world that was stopped past the lease: its programs' sessions closed and what was
    # in flight on them went with them. Here UAV 2's report of step 3 is lost so, and the
    # world notices its stop: it asks again, UAV 2 answers, nobody is lost
    stops = Stops()
    monkeypatch.setattr(world_module, "STOPS", stops)
    send = Link.send_body
    swallowed = []

    def send_body(link, receiver, body):
        if link.gate.me == 2 and receiver == WORLD:
            message = decoded(body)
            if isinstance(message, messages.Report) and message.k == 3:
                swallowed.append(message.k)
                if len(swallowed) == 1:
                    stops.saw(15.0, time.monotonic())  # the world ran again just now
                    return 0
        return send(link, receiver, body)

    monkeypatch.setattr(Link, "send_body", send_body)
    scenario = uavtrack.Scenario(steps=6)
    swarm = run_swarm(scenario, "distributed", seed=3, transport="memory", deadline=1.0)
    assert swallowed == [3, 3]  # asked again, UAV 2 sent its report again
    assert swarm.traffic.lost == {}
    reference = uavtrack.simulate(scenario, "distributed", seed=3).trace
    equal_until_counted(swarm, reference)


def test_a_stop_is_seen_by_the_ticks_that_come_late():
    stops = Stops()
    stops.tick(10.0, 10.0 + TICK + SLACK / 2)  # a busy moment, not a stop
    assert stops.resumed is None and not stops.since(0.0)
    stops.tick(20.0, 20.0 + TICK + 15.0)
    assert stops.resumed == 35.1 and stops.seconds == pytest.approx(15.0, rel=1e-12)
    assert stops.since(35.1) and not stops.since(35.2)
    stops.saw(3.0, 30.0)  # an older stop does not hide the last one
    assert stops.resumed == 35.1


class NoTokens(MemoryTransport):
    """A network on which no token is alive."""

    def __init__(self) -> None:
        super().__init__(Bus())

    def alive(self, key: str) -> set[str]:
        return set()


@pytest.mark.parametrize("ago", [0.0, REJOIN + 1.0], ids=["just-resumed", "long-ago"])
def test_a_token_gone_just_after_a_stop_is_not_believed_until_sessions_can_open_again(ago):
    stops = Stops()
    stops.saw(15.0, time.monotonic() - ago)
    box = Mailbox(
        Gate(run="r", me=WORLD, programs=3, credential=None), transport=NoTokens(), stops=stops
    )
    box.heard.add(1)
    box.lost("uavtrack/r/alive/1")
    gone = box.wait(lambda: box.is_gone(1), time.monotonic() + 2.0)
    assert gone == (ago > REJOIN)
    assert (1 in box.suspects) == (ago <= REJOIN)  # kept, to be asked again


def test_the_session_lease_and_reconnection_are_uavtracks_unless_a_file_sets_them(tmp_path):
    pytest.importorskip("zenoh")
    from uavtrack.agents.transport import LEASE, ZenohOptions, zenoh_config

    conf = zenoh_config([], ["tcp/127.0.0.1:1"])
    assert json.loads(conf.get_json("transport/link/tx/lease")) == 1000 * LEASE == 10000
    assert json.loads(conf.get_json("connect/retry")) == {
        "period_init_ms": 1000, "period_max_ms": 4000, "period_increase_factor": 2.0
    }  # fmt: skip
    path = tmp_path / "z.json5"
    path.write_text("{ transport: { link: { tx: { lease: 3000 } } } }")
    conf = zenoh_config([], [], options=ZenohOptions(config=str(path)))
    assert json.loads(conf.get_json("transport/link/tx/lease")) == 3000


def test_traces_of_formats_1_and_2_are_read_with_no_late_messages_and_no_bytes(tmp_path):
    import dataclasses

    from uavtrack.io import trace as trace_file

    result = uavtrack.simulate(uavtrack.Scenario(steps=5), seed=1)
    assert result.trace is not None
    trace_file.write(tmp_path / "new.npz", result)
    with np.load(tmp_path / "new.npz") as data:
        added = ("late", "bytes", "node_bytes")
        arrays = {name: data[name] for name in data.files if name not in added}
        late = data["late"]
    assert int(arrays.pop("format")) == trace_file.FORMAT == 4
    np.savez(tmp_path / "old.npz", format=np.array(1), **arrays)
    np.savez(tmp_path / "unnumbered.npz", **arrays)
    np.savez(tmp_path / "two.npz", format=np.array(2), late=late, **arrays)
    nothing = np.zeros_like(result.trace.bytes)
    no_node = np.zeros_like(result.trace.node_bytes)
    for name in ("old.npz", "unnumbered.npz", "two.npz"):
        read = trace_file.read(tmp_path / name).trace
        assert read.late.shape == (5, len(PROTOCOLS)) and not read.late.any()
        assert read.bytes.shape == (5, 5) and not read.bytes.any()
        assert read.node_bytes.shape == (5,) and not read.node_bytes.any()
        expected = dataclasses.replace(result.trace, bytes=nothing, node_bytes=no_node)
        assert differences(read, expected) == []
    assert result.trace.bytes.any()


def test_a_trace_of_tracks_of_format_3_is_read_without_existence(tmp_path):
    from uavtrack.io import trace as trace_file

    scenario = uavtrack.Scenario(steps=5).with_overrides({"tracker.association": "gnn"})
    result = uavtrack.simulate(scenario, seed=1)
    assert result.trace is not None and result.trace.existence is not None
    trace_file.write(tmp_path / "new.npz", result)
    with np.load(tmp_path / "new.npz") as data:
        arrays = {name: data[name] for name in data.files if name not in ("existence", "format")}
    np.savez(tmp_path / "three.npz", format=np.array(3), **arrays)
    read = trace_file.read(tmp_path / "three.npz").trace
    assert read.existence is None
    assert np.array_equal(read.label, result.trace.label) and np.array_equal(
        read.mean, result.trace.mean
    )
    np.savez(tmp_path / "four.npz", format=np.array(4), **arrays)  # format 4 may lack it too
    assert trace_file.read(tmp_path / "four.npz").trace.existence is None


# ------------------------------------------------------------ real processes, over Zenoh


@contextmanager
def busy(processes: int = 4):
    """`processes` processes spinning beside the test; stopped by pid at the end."""
    spin = [sys.executable, "-c", "while True: pass"]
    spinning = []
    try:
        for _ in range(processes):
            spinning.append(subprocess.Popen(spin))
        yield
    finally:
        for process in spinning:
            process.kill()
        for process in spinning:
            process.wait()


def equal_until_counted(swarm, reference) -> int | None:
    """Check that a swarm's trace equals the simulator's up to the first step with a
    late message or a lost program, and that its counts agree with its trace; returns
    that step (None: the two traces are equal)."""
    trace, traffic = swarm.result.trace, swarm.traffic
    late = first_late(trace)
    assert late == (traffic.late_from if traffic.late else None)
    assert traffic.late == {
        p: int(c) for p, c in zip(PROTOCOLS, trace.late.sum(axis=0), strict=True) if c
    }
    counted = [k for k in (late, min(traffic.lost.values(), default=None)) if k is not None]
    until = min(counted, default=len(trace.messages))
    assert differences(head(trace, until), head(reference, until)) == [], (until, traffic.late)
    return min(counted, default=None)


@pytest.mark.parametrize("method", ["centralized", "distributed"])
def test_under_load_a_swarm_equals_the_simulator_or_counts_what_was_late(method):
    # four busy processes beside six programs and the world on this machine, and a
    # round's deadline of 0.2 s: messages may miss their cycle, never silently
    pytest.importorskip("zenoh")
    scenario = uavtrack.Scenario(steps=40)
    with busy():
        for seed in (0, 1):
            swarm = run_swarm(scenario, method, seed=seed, transport="zenoh", deadline=0.2)
            reference = uavtrack.simulate(scenario, method, seed=seed).trace
            equal_until_counted(swarm, reference)


@pytest.mark.slow  # 22 s: the stop outlasts the lease; the stops' logic is tested above
def test_a_world_stopped_for_15_s_mid_run_loses_no_program(tmp_path):
    # the world (the process of uavtrack swarm) stopped past the Zenoh lease once it has
    # run 10 cycles, then continued: every program is still a member at the end
    pytest.importorskip("zenoh")
    path = tmp_path / "swarm.npz"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    argv = [sys.executable, "-m", "tests.netns", "world", "swarm", "--transport", "zenoh",
            "--set", "steps=30", "--seed", "1", "--json", "--trace", str(path)]  # fmt: skip
    world = subprocess.Popen(
        argv, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    said, reached = [], threading.Event()

    def read() -> None:
        for line in world.stderr:
            said.append(line)
            if line.strip() == "step 10":
                reached.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert reached.wait(300), "".join(said)
        os.kill(world.pid, signal.SIGSTOP)
        threading.Event().wait(15.0)  # the stop's length is the scenario, not a limit
        os.kill(world.pid, signal.SIGCONT)
        out, _ = world.communicate(timeout=300)
    finally:
        if world.poll() is None:
            os.kill(world.pid, signal.SIGCONT)
            world.kill()
            world.wait()
    reader.join(10)
    assert world.returncode == 0, "".join(said)
    result = json.loads(out)
    assert result["swarm"]["lost"] == {} and result["swarm"]["failed"] == {}, "".join(said)
    assert not [line for line in said if " lost at step " in line]
    with np.load(path) as arrays:
        trace = types.SimpleNamespace(**{name: arrays[name] for name in arrays.files})
    assert trace.alive.all()
    swarm = types.SimpleNamespace(
        result=types.SimpleNamespace(trace=trace),
        traffic=types.SimpleNamespace(
            late=result["swarm"]["late_by_protocol"],
            late_from=result["swarm"]["late_from_step"],
            lost={},
        ),
    )
    scenario = uavtrack.Scenario(steps=30)
    equal_until_counted(swarm, uavtrack.simulate(scenario, "distributed", seed=1).trace)


@pytest.mark.slow  # the programs wait out their full patience: kept out of CI's 15 minutes
def test_a_world_silent_past_the_programs_wait_ends_the_run_saying_why():
    """The world stops answering (its cycle held, as a stopped process) for longer than
    a program waits for its next cycle: every program ends, saying the world went
    silent. The world, going on, loses them all, names what they said (not a guess from
    their Zenoh tokens), and the command ends with exit code 1 and one line."""
    pytest.importorskip("zenoh")
    from uavtrack.cli.swarm import check_not_all_lost
    from uavtrack.errors import RunError

    wait = 10.0  # each program waits this long for its next cycle (swarm's startup)

    def hold(k: int) -> None:
        if k == 3:
            time.sleep(2.5 * wait)  # the scenario's silence, not a limit

    scenario = uavtrack.Scenario(steps=12)
    swarm = run_swarm(scenario, transport="zenoh", seed=1, patience=wait, progress=hold)
    traffic = swarm.traffic
    assert set(traffic.lost) == set(range(5)), traffic.lost
    for program in range(5):
        why = traffic.why[program]
        assert why.startswith("its process ended (exit code 1): "), why
        assert "the world ended or went silent for 10 s at step 3" in why, why
    with pytest.raises(RunError) as caught:
        check_not_all_lost(traffic, 5)
    text = str(caught.value)
    assert text.startswith("every program was lost, the first at step ") and "\n" not in text
    assert "went silent" in text and "wrote nothing" in text
