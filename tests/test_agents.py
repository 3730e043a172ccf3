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
    failed_at = done["swarm"].traffic.failed[2]
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
    assert swarm.traffic.dropped > 0


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
