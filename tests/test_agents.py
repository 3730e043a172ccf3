"""The agent form: one program per UAV, equal to the batch simulator."""

import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import uavtrack
from uavtrack.agents import messages, run_swarm
from uavtrack.agents.transport import Bus, Mailbox, MemoryTransport
from uavtrack.equivalence import assert_same_trace

pytest.importorskip("msgspec")

FAULTS = [
    {},
    {"faults.loss": 0.3},
    {"faults.loss": 0.3, "faults.delay": 2, "robust.stale": True},
    {"faults.loss": 0.2, "faults.burst_length": 4.0, "robust.extra_rounds": 2},
    {"faults.failures": [[1, 8]], "faults.position_std": 3.0, "robust.position_noise": True},
    {"faults.round_budget": 1, "faults.delay": 1},
]


@pytest.mark.parametrize("faults", FAULTS, ids=lambda f: ",".join(f) or "no-faults")
@pytest.mark.parametrize("method", ["distributed", "centralized", "greedy"])
def test_memory_swarm_equals_the_simulator(method, faults):
    scenario = uavtrack.Scenario(steps=25).with_overrides(faults)
    swarm = run_swarm(scenario, method, seed=3, transport="memory")
    reference = uavtrack.simulate(scenario, method, seed=3)
    assert_same_trace(swarm.result.trace, reference.trace)
    assert swarm.result.observation_rate == reference.observation_rate
    assert swarm.traffic.published > 0 and swarm.traffic.dropped == 0


@pytest.mark.parametrize("method", ["distributed", "greedy"])
def test_memory_swarm_prunes_bids_as_the_simulator_does(method):
    # 20 targets, UAVs spread out: small neighbourhoods, so the planner scores only a
    # few bids per UAV (NaN elsewhere), learned by each program from its flooding
    scenario = uavtrack.Scenario().scaled(6, 20).with_overrides({"steps": 12})
    swarm = run_swarm(scenario, method, seed=5, transport="memory")
    reference = uavtrack.simulate(scenario, method, seed=5)
    assert np.isnan(reference.trace.bids).mean() > 0.3
    assert_same_trace(swarm.result.trace, reference.trace)


def zenoh_or_skip():
    pytest.importorskip("zenoh")


@pytest.mark.parametrize("method", ["distributed", "centralized", "greedy"])
def test_zenoh_swarm_of_processes_equals_run(method):
    zenoh_or_skip()
    scenario = uavtrack.Scenario(steps=15)
    swarm = run_swarm(scenario, method, seed=4, transport="zenoh")
    reference = uavtrack.simulate(scenario, method, seed=4)
    assert_same_trace(swarm.result.trace, reference.trace)
    assert swarm.transport == "zenoh" and swarm.traffic.bytes > 0


def test_a_world_asked_for_any_port_tells_its_programs_the_real_one():
    zenoh_or_skip()
    scenario = uavtrack.Scenario(steps=5)
    told = {}
    swarm = run_swarm(
        scenario,
        "greedy",
        seed=1,
        transport="zenoh",
        listen="tcp/127.0.0.1:0",
        announce=lambda run, endpoint: told.update(endpoint=endpoint),
        spawn=True,
    )
    assert told["endpoint"].startswith("tcp/127.0.0.1:") and not told["endpoint"].endswith(":0")
    assert_same_trace(swarm.result.trace, uavtrack.simulate(scenario, "greedy", seed=1).trace)


def test_two_swarms_at_once_do_not_hear_each_other():
    zenoh_or_skip()
    scenarios = [uavtrack.Scenario(steps=12), uavtrack.Scenario(steps=12, comm_range=80.0)]
    out = [None, None]

    def go(k):
        out[k] = run_swarm(scenarios[k], "distributed", seed=k, transport="zenoh")

    threads = [threading.Thread(target=go, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    for k in range(2):
        reference = uavtrack.simulate(scenarios[k], "distributed", seed=k)
        assert_same_trace(out[k].result.trace, reference.trace)
        assert out[k].traffic.dropped == 0  # nothing foreign arrived
    assert out[0].run != out[1].run


def children_of(pid):
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def alive(pid):
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_a_killed_uav_program_fails_and_the_others_go_on():
    zenoh_or_skip()
    scenario = uavtrack.Scenario(steps=40, comm_range=80.0)
    joined: dict = {}
    done: dict = {}

    def announce(run, endpoint):
        joined.update(run=run, endpoint=endpoint)

    def world():
        done["swarm"] = run_swarm(
            scenario,
            "distributed",
            seed=5,
            transport="zenoh",
            spawn=False,
            announce=announce,
            deadline=0.5,
            realtime=True,
        )

    thread = threading.Thread(target=world)
    thread.start()
    deadline = time.monotonic() + 20
    while "endpoint" not in joined and time.monotonic() < deadline:
        time.sleep(0.05)
    programs = [
        subprocess.Popen(
            [sys.executable, "-m", "uavtrack.agents", joined["run"], str(i), joined["endpoint"]],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        for i in range(scenario.n_uavs)
    ]
    try:
        time.sleep(9)  # the run paces 0.5 s per cycle: well under way
        programs[2].send_signal(signal.SIGKILL)
        thread.join(timeout=120)
    finally:
        for p in programs:
            if p.poll() is None:
                p.kill()
            p.wait()
    tr = done["swarm"].result.trace
    assert not done["swarm"].traffic.failed  # no failure of the fault model: a lost program
    failed_at = done["swarm"].traffic.lost[2]
    assert 0 < failed_at < scenario.steps and not tr.alive[failed_at:, 2].any()
    assert not tr.observed[failed_at:, 2].any() and (tr.assignment[failed_at:, 2] == -1).all()
    assert tr.alive[:, [0, 1, 3, 4]].all()
    assert tr.observed[failed_at:, [0, 1, 3, 4]].any()
    # the others adapt: after it is gone, no living UAV counts it in its auction, so the
    # four cover the four targets more often than with it among them
    after = tr.assignment[failed_at + 1 :, [0, 1, 3, 4]]
    assert (after >= 0).all()
    covered_after = np.mean([len(set(row)) for row in after])
    assert covered_after >= 3.0


def test_malformed_foreign_and_old_messages_are_dropped_and_counted():
    run = "abc123"
    good = messages.Tick(messages.VERSION, run, 3, messages.Array.of(np.ones(2, dtype=bool)))
    foreign = messages.Tick(messages.VERSION, "other", 3, good.alive)
    old = messages.Tick(messages.VERSION + 1, run, 3, good.alive)
    assert messages.decode(messages.encode(good), run) == good
    for payload in (
        b"\x93garbage",
        messages.encode(good)[:-3],
        messages.encode(foreign),
        messages.encode(old),
        b"",
    ):
        assert messages.decode(payload, run) is None
    bad_array = messages.Array("<f8", (3,), b"\x00" * 5)
    assert messages.arrays({"x": bad_array}) is None
    box = Mailbox(run)
    box.handler("k", b"nonsense")
    box.handler("k", messages.encode(good))
    assert box.dropped == 1 and box.take(("tick", 3)) == good


def test_garbage_on_the_bus_does_not_change_the_run():
    scenario = uavtrack.Scenario(steps=10)
    bus = Bus()
    noise = MemoryTransport(bus)
    original = MemoryTransport.subscribe

    def subscribe(self, key, handler):  # every program also gets garbage on its keys
        original(self, key, handler)
        handler(key, b"\xc1not msgpack")

    MemoryTransport.subscribe = subscribe
    try:
        swarm = run_swarm(scenario, "distributed", seed=1, transport="memory")
    finally:
        MemoryTransport.subscribe = original
    del noise
    reference = uavtrack.simulate(scenario, "distributed", seed=1)
    assert_same_trace(swarm.result.trace, reference.trace)
    # one garbage message per subscription: the world's one (reports), and four per UAV
    # program (its sense, radio, tick and hello keys), each counted where it was dropped
    assert swarm.traffic.dropped == 1 + 4 * scenario.n_uavs
    assert swarm.traffic.program_dropped == {i: 4 for i in range(scenario.n_uavs)}


def test_failures_of_the_fault_model_are_not_lost_programs():
    scenario = uavtrack.Scenario(steps=12).with_overrides({"faults.failures": [[1, 4], [3, 7]]})
    swarm = run_swarm(scenario, "distributed", seed=2, transport="memory")
    assert swarm.traffic.failed == {1: 4, 3: 7} and swarm.traffic.lost == {}


def test_realtime_overruns_are_the_cycles_longer_than_dt():
    scenario = uavtrack.Scenario(steps=6, dt=0.02)
    swarm = run_swarm(scenario, "distributed", seed=2, transport="memory", realtime=True)
    took = swarm.traffic.cycle_seconds
    assert swarm.traffic.overruns == [k for k, t in enumerate(took) if t > scenario.dt]


def hello_on(bus, scenario, method="distributed", run="r1"):
    """A world that only says hello, every 50 ms, until `stop` is set."""
    from uavtrack.agents.world import WorldProgram

    world = WorldProgram(scenario, method, 0, MemoryTransport(bus), run)
    stop = threading.Event()

    def say():
        while not stop.is_set():
            world.hello(np.zeros((scenario.n_targets, 4)), np.eye(4))
            time.sleep(0.05)

    threading.Thread(target=say, daemon=True).start()
    return stop


def test_a_program_tells_why_it_did_not_run():
    from uavtrack.agents.program import serve

    bus = Bus()
    assert serve(MemoryTransport(bus), "r1", 0, first=0.3).end == "no world"
    stop = hello_on(bus, uavtrack.Scenario(steps=3))
    try:
        out = serve(MemoryTransport(bus), "r1", 5, first=5)
        assert (out.end, out.programs, out.central) == ("not in run", 5, False)
        MemoryTransport(bus).announce("uavtrack/r1/alive/2")  # program 2 runs already
        assert serve(MemoryTransport(bus), "r1", 2, first=5).end == "taken"
    finally:
        stop.set()


def test_uavtrack_agent_exit_codes(capsys, monkeypatch):
    from uavtrack.agents import transport

    bus = Bus()
    monkeypatch.setattr(transport, "ZenohTransport", lambda listen, connect: MemoryTransport(bus))
    monkeypatch.setattr("uavtrack.cli.swarm.AGENT_WAIT", 0.3)
    code, _, err = run_cli(capsys, "agent", "--run", "nope", "--uav", "0", "--connect", "x")
    assert code == 1 and "no world of run nope answered" in err
    stop = hello_on(bus, uavtrack.Scenario(steps=3), "centralized")
    try:
        code, _, err = run_cli(capsys, "agent", "--run", "r1", "--uav", "6", "--connect", "x")
        assert code == 2 and "run r1 has programs 0 to 5 only" in err
    finally:
        stop.set()


def run_cli(capsys, *args):
    from uavtrack import cli

    code = cli.main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize(
    "args,message",
    [
        (["--transport", "pigeon"], "'pigeon' is not one of"),
        (["--listen", "tcp/127.0.0.1:7447"], "need --transport zenoh"),
        (["--transport", "zenoh", "--connect", "tcp/127.0.0.1:1"], "cannot listen on"),
        (["--transport", "zenoh", "--listen", "tcp/no-such-host:x"], "cannot listen on"),
        (["--transport", "zenoh", "--listen", ""], "--listen is empty"),
        (["--listen", ""], "need --transport zenoh"),
    ],
)
def test_swarm_bad_input_is_one_line(capsys, args, message):
    if "zenoh" in args:
        zenoh_or_skip()
    code, _, err = run_cli(capsys, "swarm", "--set", "steps=5", *args)
    assert code == 2 and message in err and err.count("\n") == 1


def test_swarm_port_in_use_is_refused(capsys):
    zenoh_or_skip()
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        code, _, err = run_cli(
            capsys,
            "swarm",
            "--transport",
            "zenoh",
            "--listen",
            f"tcp/127.0.0.1:{port}",
            "--set",
            "steps=5",
        )
    assert code == 2 and "Address already in use" in err


def test_ctrl_c_stops_every_program(tmp_path):
    zenoh_or_skip()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "uavtrack.cli",
            "swarm",
            "--transport",
            "zenoh",
            "--set",
            "steps=100000",
            "--realtime",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 60
    programs = []
    while time.monotonic() < deadline and len(programs) < 5:
        time.sleep(0.3)
        programs = children_of(proc.pid)
    assert len(programs) >= 5
    time.sleep(2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err.strip().startswith("uavtrack: interrupted")
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(alive(p) for p in programs):
        time.sleep(0.2)
    assert not any(alive(p) for p in programs)
