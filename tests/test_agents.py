"""The agent form: one program per UAV, equal to the batch simulator, delivering each
radio message only where it can be heard."""

import dataclasses
import signal
import subprocess
import sys
import threading
import time

import msgspec
import numpy as np
import pytest

import uavtrack
from uavtrack.agents import messages, run_swarm
from uavtrack.agents.security import WORLD, Envelope, Gate
from uavtrack.agents.transport import Bus, Mailbox, MemoryTransport
from uavtrack.testing import assert_same_trace

from .processes import alive, descendants_of, programs_of, wait_until

pytestmark = pytest.mark.integration  # the agent form against real deadlines

pytest.importorskip("msgspec")

FAULTS = [
    {},
    {"faults.loss": 0.3},
    {"faults.loss": 0.3, "faults.delay": 2, "robust.stale": True},
    {"faults.loss": 0.2, "faults.burst_length": 4.0, "robust.extra_rounds": 2},
    {"faults.failures": [[1, 8]], "faults.position_std": 3.0, "robust.position_noise": True},
    {"faults.round_budget": 1, "faults.delay": 1},
    {"faults.round_budget": 2, "robust.extra_rounds": 1},
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


MISSING = {"sensor.detection_probability": 0.7}  # "in view": what a UAV measured


@pytest.mark.parametrize("faults", [*FAULTS[:4], MISSING], ids=lambda f: ",".join(f) or "no-faults")
def test_memory_swarm_of_a_learned_policy_equals_the_simulator(faults):
    """Each program reads its neighbours from the beacons it heard, and its targets in
    view from what it measured, as the batch does: the same trace with losses, delay,
    failures and a sensor that misses."""
    pytest.importorskip("gymnasium")  # the policy's observation builder
    scenario = uavtrack.Scenario(steps=25).with_overrides(faults)
    swarm = run_swarm(scenario, "policy:bc", seed=3, transport="memory")
    reference = uavtrack.simulate(scenario, "policy:bc", seed=3)
    assert_same_trace(swarm.result.trace, reference.trace)
    assert np.isnan(reference.trace.bids).all() and (reference.trace.assignment == -1).all()
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


def test_unsigned_swarm_equals_the_simulator_too():
    scenario = uavtrack.Scenario(steps=10).with_overrides({"faults.loss": 0.2})
    swarm = run_swarm(scenario, "distributed", seed=2, transport="memory", sign=False)
    assert_same_trace(swarm.result.trace, uavtrack.simulate(scenario, "distributed", seed=2).trace)


def test_a_radio_message_reaches_only_the_uavs_in_range(monkeypatch):
    # every radio delivery goes to a UAV within r_C of its sender at the cycle it was
    # sent (3-D, both alive), one message per receiver and round; never to everyone
    scenario = uavtrack.Scenario().scaled(12, 10).with_overrides({"steps": 15})
    seen = []
    original = MemoryTransport.publish

    def publish(self, key, payload):
        original(self, key, payload)
        if "/to/" not in key:
            return  # the Hello, requests for it
        envelope = msgspec.msgpack.decode(payload, type=Envelope)
        message = msgspec.msgpack.Decoder(messages.Message).decode(envelope.body)
        if isinstance(message, messages.Radio) and message.k >= 0:
            seen.append((message.k, message.sender, envelope.receiver, key))

    monkeypatch.setattr(MemoryTransport, "publish", publish)
    swarm = run_swarm(scenario, "distributed", seed=4, transport="memory")
    trace = swarm.result.trace
    assert seen
    for k, sender, receiver, key in seen:
        assert key.endswith(f"/to/{receiver}")
        a, b = trace.uavs[k, sender, :3], trace.uavs[k, receiver, :3]
        assert np.linalg.norm(a - b) <= scenario.comm_range + 1e-9
    n, steps = scenario.n_uavs, scenario.steps
    per_uav_cycle = swarm.traffic.received / (n * steps)
    # what arrives: the protocol's own messages (one per link, round and protocol, fewer
    # bundled) and the world's Sense; nothing that a receiver could not hear
    assert per_uav_cycle <= swarm.result.messages / n + 1
    assert len(seen) < swarm.result.messages * steps  # protocols share messages


def zenoh_or_skip():
    pytest.importorskip("zenoh")


@pytest.mark.parametrize(
    "method,faults",
    [
        ("distributed", {}),
        ("centralized", {}),
        ("greedy", {}),
        ("distributed", {"faults.loss": 0.3, "faults.delay": 1, "robust.stale": True}),
        ("centralized", {"faults.loss": 0.3, "faults.failures": [[2, 6]]}),
    ],
)
def test_zenoh_swarm_of_processes_equals_run(method, faults):
    zenoh_or_skip()
    scenario = uavtrack.Scenario(steps=15).with_overrides(faults)
    swarm = run_swarm(scenario, method, seed=4, transport="zenoh")
    reference = uavtrack.simulate(scenario, method, seed=4)
    assert_same_trace(swarm.result.trace, reference.trace)
    assert swarm.transport == "zenoh" and swarm.traffic.bytes > 0
    assert swarm.traffic.dropped == 0


def test_zenoh_swarm_of_a_learned_policy_equals_run():
    """The shipped fine-tuned policy, one process per UAV over Zenoh: its trace is the
    batch's, with message losses and a delay."""
    zenoh_or_skip()
    pytest.importorskip("gymnasium")
    overrides = {"faults.loss": 0.2, "faults.delay": 1, "robust.stale": True}
    scenario = uavtrack.Scenario(steps=15).with_overrides(overrides)
    swarm = run_swarm(scenario, "policy:bc-ppo", seed=4, transport="zenoh")
    reference = uavtrack.simulate(scenario, "policy:bc-ppo", seed=4)
    assert_same_trace(swarm.result.trace, reference.trace)
    assert swarm.transport == "zenoh" and swarm.traffic.dropped == 0


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
        announce=lambda run, endpoint, written: told.update(endpoint=endpoint),
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
        t.join()
    for k in range(2):
        reference = uavtrack.simulate(scenarios[k], "distributed", seed=k)
        assert_same_trace(out[k].result.trace, reference.trace)
        assert out[k].traffic.dropped == 0  # nothing foreign arrived
    assert out[0].run != out[1].run


def test_foreign_and_old_messages_do_not_decode():
    run = "abc123abc123"
    alive = messages.Array.of(np.ones(2, dtype=bool))
    good = messages.Tick(version=messages.VERSION, run=run, k=3, alive=alive)
    foreign = messages.Tick(version=messages.VERSION, run="other", k=3, alive=alive)
    old = messages.Tick(version=messages.VERSION + 1, run=run, k=3, alive=alive)
    assert messages.decode(messages.encode(good), run) == good
    for payload in (messages.encode(foreign), messages.encode(old), b"", b"\x93garbage"):
        assert messages.decode(payload, run) is None
    with pytest.raises(ValueError):
        messages.Array("<f8", (3,), b"\x00" * 5).array()


def test_a_stopped_program_does_not_blame_others_for_its_own_stop(monkeypatch):
    # a wait whose half-second slice took 10 s (the process was stopped) moves its
    # deadline by the time stopped; a wait that really had nothing to wait for expires
    from uavtrack.agents import transport

    clock = {"now": 100.0}
    monkeypatch.setattr(transport.time, "monotonic", lambda: clock["now"])
    box = Mailbox(Gate(run="r", me=WORLD, programs=1, credential=None))
    arrived = {"yes": False}
    calls = []
    phase = {"stopped": True}

    def wait(timeout):  # the condition's wait: time passes, in the first phase a stop
        calls.append(timeout)
        clock["now"] += timeout + (10.0 if phase["stopped"] and len(calls) == 2 else 0.0)
        if phase["stopped"] and len(calls) == 4:  # 2 s of waiting in all, besides the stop
            arrived["yes"] = True

    monkeypatch.setattr(box.cond, "wait", wait)
    assert box.wait(lambda: arrived["yes"], deadline=clock["now"] + 2.0)
    calls.clear()
    phase["stopped"], arrived["yes"] = False, False
    assert not box.wait(lambda: arrived["yes"], deadline=clock["now"] + 2.0)
    assert len(calls) == 4  # four slices of 0.5 s, no stop


def test_failures_of_the_fault_model_are_not_lost_programs():
    scenario = uavtrack.Scenario(steps=12).with_overrides({"faults.failures": [[1, 4], [3, 7]]})
    swarm = run_swarm(scenario, "distributed", seed=2, transport="memory")
    assert swarm.traffic.failed == {1: 4, 3: 7} and swarm.traffic.lost == {}


def test_realtime_overruns_are_the_cycles_longer_than_dt():
    scenario = uavtrack.Scenario(steps=6, dt=0.02)
    swarm = run_swarm(scenario, "distributed", seed=2, transport="memory", realtime=True)
    took = swarm.traffic.cycle_seconds
    assert swarm.traffic.overruns == [k for k, t in enumerate(took) if t > scenario.dt]


def hello_on(bus, scenario, method="distributed", run="a1b2c3d4e5f6", step=-1, **world_options):
    """A world that only says hello, every 50 ms, until `stop` is set."""
    from uavtrack.agents.world import WorldProgram

    members = world_options.pop("members", set())
    world = WorldProgram(scenario, method, 0, MemoryTransport(bus), run, **world_options)
    world.prior = (np.zeros((scenario.n_targets, 4)), np.eye(4))
    world.step = step
    world.members = members
    stop = threading.Event()

    def say():
        while not stop.is_set():
            world.hello()
            time.sleep(0.05)

    threading.Thread(target=say, daemon=True).start()
    return stop


def test_a_program_tells_why_it_did_not_run():
    from uavtrack.agents.program import serve
    from uavtrack.agents.security import Keyring

    run = "a1b2c3d4e5f6"
    bus = Bus()
    assert serve(MemoryTransport(bus), run, 0, first=0.3).end == "no world"
    stop = hello_on(bus, uavtrack.Scenario(steps=3))
    try:
        out = serve(MemoryTransport(bus), run, 5, first=5)
        assert (out.end, out.programs, out.central) == ("not in run", 5, False)
        # a token is anyone's to make: it takes no number (the program goes on to meet
        # the others, none of whom come here, and gives up after `wait`)
        MemoryTransport(bus).announce(f"uavtrack/{run}/alive/2")
        assert serve(MemoryTransport(bus), run, 2, wait=0.5, first=5).end == "world gone"
        # a key of another world: the Hello it hears is not signed by the run's world
        other = Keyring(run, 5).credential(1)
        assert serve(MemoryTransport(bus), run, 1, first=0.5, credential=other).end == (
            "not authentic"
        )
    finally:
        stop.set()
    # the run's world names program 2 a member in its signed Hello: 2 is taken; a key
    # file of this run with another secret in it is no key of 1's
    ring = Keyring(run, 5)
    bus = Bus()
    stop = hello_on(bus, uavtrack.Scenario(steps=3), keyring=ring, members={2})
    try:
        assert serve(MemoryTransport(bus), run, 2, first=5, credential=ring.credential(2)).end == (
            "taken"
        )
        forged = dataclasses.replace(ring.credential(1), secret=bytes(range(32)))
        assert serve(MemoryTransport(bus), run, 1, first=5, credential=forged).end == "wrong key"
    finally:
        stop.set()
    bus = Bus()
    stop = hello_on(bus, uavtrack.Scenario(steps=30), step=7)
    try:
        out = serve(MemoryTransport(bus), run, 1, first=5)
        assert (out.end, out.at) == ("under way", 7)
    finally:
        stop.set()


def run_cli(capsys, *args):
    from uavtrack import cli

    code = cli.main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def test_uavtrack_agent_exit_codes(capsys, monkeypatch):
    from uavtrack.agents import transport

    bus = Bus()
    monkeypatch.setattr(
        transport, "ZenohTransport", lambda listen, connect, options=None: MemoryTransport(bus)
    )
    monkeypatch.setattr("uavtrack.cli.swarm.AGENT_WAIT", 0.3)
    run = "a1b2c3d4e5f6"
    code, _, err = run_cli(capsys, "agent", "--run", run, "--uav", "0", "--connect", "x")
    assert code == 1 and f"no world of run {run} answered" in err
    stop = hello_on(bus, uavtrack.Scenario(steps=3), "centralized")
    try:
        code, _, err = run_cli(capsys, "agent", "--run", run, "--uav", "6", "--connect", "x")
        assert code == 2 and f"run {run} has programs 0 to 5 only" in err
        # the world there runs another run: said at once (a key file of another run)
        other = "0123456789ab"
        code, _, err = run_cli(capsys, "agent", "--run", other, "--uav", "1", "--connect", "x")
        assert code == 2 and f"the world at x runs {run}, not run {other}" in err
    finally:
        stop.set()


def test_tls_options_with_a_ca_alone_are_refused_naming_the_three_files(tmp_path):
    from uavtrack.agents.transport import ZenohOptions

    ca = tmp_path / "ca.pem"
    ca.write_text("not read: the options are refused first\n")
    for cert, key in ((None, None), (str(ca), None), (None, str(ca))):
        with pytest.raises(ValueError, match="TLS needs all three of tls_ca, tls_cert and tls_key"):
            ZenohOptions(tls_ca=str(ca), tls_cert=cert, tls_key=key).check(["tls/127.0.0.1:1"])


def test_the_endpoints_are_uavtracks_whatever_a_zenoh_file_says(tmp_path):
    zenoh_or_skip()
    from uavtrack.agents.transport import ZenohOptions, zenoh_config

    path = tmp_path / "z.json5"
    path.write_text('{ listen: { endpoints: ["tcp/0.0.0.0:7447"] }, mode: "peer" }')
    conf = zenoh_config([], ["tcp/127.0.0.1:1"], options=ZenohOptions(config=str(path)))
    assert conf.get_json("listen/endpoints") == "[]"  # a program listens on nothing
    assert conf.get_json("mode") == '"peer"'  # what uavtrack does not set stays the file's
    assert conf.get_json("scouting/multicast/enabled") == "false"


@pytest.mark.parametrize(
    "args,message",
    [
        (["--run", "", "--uav", "0"], "a run id is 12 hexadecimal digits"),
        (["--run", "$x", "--uav", "0"], "a run id is 12 hexadecimal digits"),
        (["--run", "#", "--uav", "0"], "a run id is 12 hexadecimal digits"),
        (["--uav", "0"], "give --key FILE, or --run ID and --uav I"),
        (["--key", "/nonexistent/k.key"], "--key: cannot read"),
    ],
)
def test_uavtrack_agent_bad_input_is_one_line(capsys, args, message):
    code, out, err = run_cli(capsys, "agent", "--connect", "tcp/127.0.0.1:1", *args)
    assert code == 2 and message in err and err.count("\n") == 1 and out == ""


@pytest.mark.parametrize(
    "args,message",
    [
        (["--transport", "pigeon"], "'pigeon' is not one of"),
        (["--listen", "tcp/127.0.0.1:7447"], "need --transport zenoh"),
        (["--tls-ca", "x.pem"], "need --transport zenoh"),
        pytest.param(
            ["--transport", "zenoh", "--connect", "tcp/127.0.0.1:1"],
            "cannot connect to tcp/",
        ),
        pytest.param(
            ["--transport", "zenoh", "--listen", "tcp/no-such-host:x"],
            "cannot listen on",
        ),
        (["--transport", "zenoh", "--listen", ""], "--listen is empty"),
        (["--transport", "zenoh", "--listen", "tls/127.0.0.1:0"], "a tls/ endpoint needs"),
        (["--transport", "zenoh", "--tls-ca", "__file__"], "needs all three of --tls-ca"),
        (["--transport", "zenoh", "--tls-ca", "/nonexistent"], "--tls-ca: /nonexistent is not"),
        (["--transport", "zenoh", "--zenoh-config", "__bad__"], "--zenoh-config: "),
        (["--transport", "zenoh", "--no-spawn"], "needs --keys DIR"),
        (["--transport", "zenoh", "--keys", "."], "--keys is for --no-spawn"),
        (["--listen", ""], "need --transport zenoh"),
    ],
)
def test_swarm_bad_input_is_one_line(capsys, tmp_path, args, message):
    if "zenoh" in args:
        zenoh_or_skip()
    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: ")
    args = [{"__file__": __file__, "__bad__": str(bad)}.get(a, a) for a in args]
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


def test_zenoh_logs_never_reach_the_json_on_stdout():
    zenoh_or_skip()
    # with RUST_LOG=debug, Zenoh logs every connection on file descriptor 1
    out = subprocess.run(
        [sys.executable, "-m", "uavtrack.cli", "swarm", "--transport", "zenoh", "--json"]
        + ["--set", "steps=3"],
        capture_output=True,
        text=True,
        env={**__import__("os").environ, "RUST_LOG": "debug"},
    )
    assert out.returncode == 0, out.stderr[-2000:]
    result = __import__("json").loads(out.stdout)
    assert result["swarm"]["signed"] and result["swarm"]["received_per_uav_cycle"] > 0
    assert "zenoh" in out.stderr.lower()  # the log went to stderr, where logs belong


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
    assert wait_until(lambda: len(programs_of(proc.pid)) >= 5)
    programs = descendants_of(proc.pid)  # the launcher and its programs
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130 and err.strip().startswith("uavtrack: interrupted")
    assert wait_until(lambda: not any(alive(p) for p in programs), limit=30)


def test_a_swarm_killed_while_starting_takes_its_programs_with_it():
    zenoh_or_skip()
    proc = subprocess.Popen(
        [sys.executable, "-m", "uavtrack.cli", "swarm", "--transport", "zenoh", "--team", "8x4"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    assert wait_until(lambda: len(programs_of(proc.pid)) >= 8)
    programs = descendants_of(proc.pid)  # the launcher and its programs
    proc.kill()  # SIGKILL: no cleanup of its own; the programs must notice
    proc.wait()
    # the kernel's parent-death signal ends them at once; the watch within a second
    assert wait_until(lambda: not any(alive(p) for p in programs), limit=30)


def test_the_message_schema_page_is_what_the_code_says():
    from pathlib import Path

    from uavtrack.agents import messages
    from uavtrack.agents.schema import document

    page = Path(__file__).parent.parent / "docs" / "agents-messages.md"
    assert page.read_text() == document(), "run: python -m uavtrack.agents.schema > " + str(page)
    assert f"schema version {messages.VERSION}" in page.read_text()
    for cls in messages.Message.__args__:  # every message and every field is on the page
        assert f"### `{cls.__struct_config__.tag}`" in page.read_text()


def test_the_world_names_the_programs_that_did_not_start_by_what_it_heard_from_them():
    # programs 0-3 start and wait for 4, which never comes; a stranger holds 4's token.
    # The world names 4, from the programs' authentic presence, not from the tokens
    from uavtrack.agents.program import serve
    from uavtrack.agents.security import Keyring
    from uavtrack.agents.world import WorldProgram

    run, bus = "a1b2c3d4e5f6", Bus()
    scenario = uavtrack.Scenario(steps=3)
    ring = Keyring(run, 5)
    MemoryTransport(bus).announce(f"uavtrack/{run}/alive/4")
    link = MemoryTransport(bus)
    link.announce(f"uavtrack/{run}/alive/world")
    world = WorldProgram(scenario, "distributed", 0, link, run, startup=3.0, keyring=ring)
    ended = []

    def program(me):
        ended.append(serve(MemoryTransport(bus), run, me, credential=ring.credential(me)).end)

    threads = [threading.Thread(target=program, args=(p,), daemon=True) for p in range(4)]
    for thread in threads:
        thread.start()
    try:
        with pytest.raises(TimeoutError) as refused:
            world.run_trial()
    finally:
        link.close()  # the programs hear their world gone
        for thread in threads:
            thread.join(60)
    assert str(refused.value) == (
        "program 4 did not start within 3 s; 0, 1, 2, 3 started and waited for them"
    )
    assert ended == ["world gone"] * 4


NEW_OPTIONS = [
    {"uav.min_speed": 10.0, "comm_range": 94.0, "radio.frames": "broadcast",
     "radio.encoding": "quantized", "fusion.trigger": 0.1},
    {"uav.dynamics": "jsbsim", "planner.avoidance_model": "measured", "comm_range": 177.0,
     "radio.frames": "broadcast", "radio.encoding": "quantized", "wind.speed": 5.0},
]  # fmt: skip
NEW_OPTIONS[1] = pytest.param(NEW_OPTIONS[1], marks=pytest.mark.slow)  # 21 s: 5 measurements
"""The airspeed control, the measured model of flight, broadcast frames and quantized
tuples, together, at one altitude."""


@pytest.mark.parametrize("options", NEW_OPTIONS, ids=["airspeed", "measured"])
def test_zenoh_swarm_with_the_new_options_equals_run(options):
    """Over Zenoh, between processes, the swarm flies each new option as the batch does,
    step by step, and the filter changed what the UAVs flew."""
    zenoh_or_skip()
    if options.get("uav.dynamics") == "jsbsim":
        pytest.importorskip("jsbsim")
    scenario = uavtrack.Scenario.from_toml("one-altitude").with_overrides({"steps": 15, **options})
    swarm = run_swarm(scenario, "distributed", seed=4, transport="zenoh")
    reference = uavtrack.simulate(scenario, "distributed", seed=4)
    assert_same_trace(swarm.result.trace, reference.trace)
    assert swarm.traffic.dropped == 0
    unfiltered = {"planner.avoidance": "none", "uav.min_speed": None}
    if "planner.avoidance_model" in options:
        unfiltered["planner.avoidance_model"] = "unicycle"
    free = uavtrack.simulate(scenario.with_overrides(unfiltered), "distributed", seed=4)
    assert not np.array_equal(free.trace.action, reference.trace.action)
