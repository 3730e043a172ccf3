"""The swarm across hosts: the world and each UAV program on a network stack of its own
(Linux network namespaces joined through a router, `tests.netns`), started by hand with
key files as on separate machines, and the links between them cut, restored and
flapped while the swarm runs.

Every cut is placed by the world's progress (its ``step K`` lines), never by the clock,
and lasts a set time. A cut shorter than the Zenoh session's lease keeps the cut UAV a
member: the world waits for its report (simulated time stops for every UAV), and its
radio neighbours, who wait for its messages a round's deadline, count them lost in the
trace's ``delivered``. The trace equals the simulator's up to the first lost message,
and no difference from the simulator comes before a counted loss. A cut longer than the
lease (``-m slow``) ends the session: the world loses the UAV from that cycle and it
stays out, as a failure of the fault model at that step.

Skipped, with the reason, where network namespaces cannot be made (not root, no
iproute2, a container without the capability).
"""

import json
import subprocess
import sys
import time
import types

import numpy as np
import pytest

import uavtrack
from uavtrack.testing import differences

from . import netns

pytest.importorskip("zenoh")

UAVS = 5
SEED = 5
CUT = 5.0
"""Seconds a link is cut."""
RANGE = 80.0
"""Radio range [m]: at seed 5, UAVs 1 and 2 have a radio neighbour at every step of the
first 40, so whatever cycle a cut of theirs lands in, a message is lost there."""


@pytest.fixture
def network():
    reason = netns.unavailable()
    if reason is not None:
        pytest.skip(f"the swarm across hosts needs network namespaces: {reason}")
    with netns.Network(UAVS + 1) as net:
        yield net


def reach(network, host: int, port: int = 9000) -> bool:
    """Whether host `host` can open a TCP connection to the world's host within 1 s."""
    probe = (
        "import socket, sys\n"
        f"try: socket.create_connection(({network.address(0)!r}, {port}), timeout=1).close()\n"
        "except OSError: sys.exit(1)"
    )
    return subprocess.run(["ip", "netns", "exec", network.names[host], sys.executable, "-c",
                           probe], timeout=60).returncode == 0  # fmt: skip


@pytest.mark.integration
def test_the_harness_joins_the_hosts_and_cuts_them_silently(network):
    listen = (
        "import socket\n"
        f"s = socket.create_server(({network.address(0)!r}, 9000))\n"
        "while True: s.accept()[0].close()"
    )
    network.start(0, [sys.executable, "-c", listen])
    up = time.monotonic() + 60
    while not reach(network, 1) and time.monotonic() < up:
        time.sleep(0.1)
    assert reach(network, 1) and reach(network, 2)
    network.cut(1)  # a host cut from everyone, silently: the connection times out
    assert not reach(network, 1) and reach(network, 2)
    network.restore(1)
    network.cut(2, 0)  # only between two hosts
    assert reach(network, 1) and not reach(network, 2)
    network.restore(2, 0)
    network.carrier(1, False)
    assert not reach(network, 1)
    network.carrier(1, True)
    assert reach(network, 1) and reach(network, 2)
    names = [network.router, *network.names]
    network.close()  # the listener stopped, by pid, and every namespace gone
    assert network.processes[0].poll() is not None
    assert not any((netns.NETNS_DIR / name).exists() for name in names)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="network namespaces are Linux's")
def test_without_root_or_iproute2_the_harness_says_why(monkeypatch):
    monkeypatch.setattr(netns.os, "geteuid", lambda: 1000)
    assert netns.unavailable() == "creating network namespaces needs root (running as uid 1000)"
    monkeypatch.setattr(netns.os, "geteuid", lambda: 0)
    monkeypatch.setattr(netns.shutil, "which", lambda name: None)
    assert netns.unavailable() == "the ip command (iproute2) is not installed"


@pytest.mark.integration
def test_namespaces_left_by_a_killed_harness_are_swept(network):
    dead = subprocess.Popen([sys.executable, "-c", ""])
    dead.wait()  # a pid no process holds now
    left = f"{netns.PREFIX}{dead.pid}-abcdef-r"
    subprocess.run(["ip", "netns", "add", left], check=True)
    try:
        assert left in netns.sweep_stale()
        assert not (netns.NETNS_DIR / left).exists()
        assert all((netns.NETNS_DIR / name).exists() for name in network.names)  # alive: kept
    finally:
        subprocess.run(["ip", "netns", "delete", left], capture_output=True)


def host(uav: int) -> int:
    """The host of UAV program `uav` (host 0 is the world's)."""
    return uav + 1


def scenario(steps: int) -> uavtrack.Scenario:
    return uavtrack.Scenario(steps=steps, comm_range=RANGE)


def across(network, folder, steps, act=None, realtime=True):
    """Run a swarm of `UAVS` programs over `network`; `act(network, swarm)` runs once the
    programs are started. Returns the world's exit code, its JSON, its trace (read back
    with numpy), the programs' exit codes and words, and the swarm (its cycles' times)."""
    args = ["--set", f"steps={steps}", "--set", f"comm_range={RANGE}", "--seed", str(SEED)]
    swarm = netns.Swarm(network, UAVS, folder, args + (["--realtime"] if realtime else []))
    swarm.join()
    if act is not None:
        act(network, swarm)
    code, out, programs = swarm.finish()
    assert code == 0, swarm.said
    with np.load(swarm.trace) as arrays:
        trace = types.SimpleNamespace(**{name: arrays[name] for name in arrays.files})
    return json.loads(out), trace, programs, swarm


def simulated(steps: int):
    return uavtrack.simulate(scenario(steps), "distributed", seed=SEED).trace


def head(trace, k: int):
    """The first k steps of a trace."""
    return types.SimpleNamespace(
        **{name: getattr(trace, name)[:k] for name in ("targets", *FIELDS) if hasattr(trace, name)}
    )


FIELDS = ("uavs", "observed", "assignment", "action", "alive", "rounds", "messages",
          "delivered", "conflicts", "mean", "cov", "bids")  # fmt: skip


def first_difference(a, b) -> int | None:
    """The first step at which traces a and b differ (None: they agree)."""
    for k in range(len(a.messages)):
        if differences(head(a, k + 1), head(b, k + 1)):
            return k
    return None


def first_loss(trace) -> int | None:
    """The first step at which a radio message sent was not delivered (None: none)."""
    short = np.flatnonzero(trace.delivered < trace.messages)
    return int(short[0]) if short.size else None


def all_ran(programs, steps: int) -> None:
    for i, (code, said) in enumerate(programs):
        assert code == 0 and f"ran {steps} of {steps} cycles" in said, (i, code, said)


@pytest.mark.integration
def test_a_swarm_across_hosts_equals_the_simulator(network, tmp_path):
    steps = 20
    result, trace, programs, _ = across(network, tmp_path, steps, realtime=False)
    assert result["swarm"]["lost"] == {} and result["swarm"]["transport"] == "zenoh"
    all_ran(programs, steps)
    reference = simulated(steps)
    assert differences(trace, reference) == []
    assert result["observation_rate"] == pytest.approx(
        uavtrack.simulate(scenario(steps), "distributed", seed=SEED).observation_rate, rel=1e-12
    )


def cut_for(hosts, seconds=CUT, at=8, between=None):
    """An act: once the world has run `at` cycles, cut `hosts` (each from every other
    host, or only from host `between`) for `seconds` seconds, then restore them."""

    def act(network, swarm):
        assert swarm.reached(at), swarm.said
        for h in hosts:
            network.cut(h, between)
        act.begun = swarm.step
        time.sleep(seconds)  # the cut's length is the scenario, not a limit
        for h in hosts:
            network.restore(h, between)

    return act


def check_cut(result, trace, programs, steps, at):
    """A cut shorter than the session's lease: nobody lost, every program ran every
    cycle, the world waited (one cycle lasted about the cut), the cut's losses counted
    in the trace, which equals the simulator's before them and differs only after."""
    assert result["swarm"]["lost"] == {} and result["swarm"]["failed"] == {}
    assert trace.alive.all()
    all_ran(programs, steps)
    assert result["swarm"]["cycle_ms_max"] >= 1e3 * (CUT - 1.0)  # the world waited
    lost = first_loss(trace)
    assert lost is not None and lost >= at, trace.delivered - trace.messages
    reference = simulated(steps)
    assert differences(head(trace, lost), head(reference, lost)) == []
    differ = first_difference(trace, reference)
    assert differ is None or differ >= lost
    return lost


@pytest.mark.integration
def test_one_uav_cut_for_5_s_stays_a_member_and_the_run_ends(network, tmp_path):
    steps = 20
    act = cut_for([host(1)])
    result, trace, programs, _ = across(network, tmp_path, steps, act)
    check_cut(result, trace, programs, steps, act.begun)


@pytest.mark.integration
@pytest.mark.slow  # 20 s; one UAV cut for 5 s runs by default
def test_the_world_cut_from_half_the_swarm_for_5_s_loses_nobody(network, tmp_path):
    steps = 20
    act = cut_for([host(1), host(2)], between=0)  # the world's host from UAVs 1 and 2
    result, trace, programs, _ = across(network, tmp_path, steps, act)
    check_cut(result, trace, programs, steps, act.begun)


@pytest.mark.integration
@pytest.mark.slow  # 14 s; the cuts of 5 s above run by default
def test_a_link_flapping_every_second_loses_nobody_silently(network, tmp_path):
    # ten flaps (10 s) mid-run: on an idle machine nobody is lost; on a loaded one TCP's
    # backed-off retransmissions can keep the flapping host silent past the lease, and the
    # rule then is that only that UAV is lost, the run finishes and says why
    steps = 20
    seen = {}

    def act(network, swarm):
        assert swarm.reached(8), swarm.said
        seen["from"] = swarm.step
        with network.flapping(host(2), down=0.5, up=0.5) as flaps:
            while len(flaps) < 10 and not swarm.finished(limit=0.5):
                pass
        seen["flaps"] = len(flaps)

    result, trace, programs, _ = across(network, tmp_path, steps, act)
    assert seen["flaps"] >= 3
    lost, why = result["swarm"]["lost"], result["swarm"]["lost_why"]
    assert set(lost) <= {"2"} and set(why) == set(lost), (lost, why)
    others = [i for i in range(UAVS) if i != 2]
    assert trace.alive[:, others].all()
    all_ran([programs[i] for i in others], steps)
    if lost:
        k = lost["2"]
        assert k >= seen["from"] and not trace.alive[k:, 2].any() and why["2"]
    else:
        all_ran(programs, steps)
    reference = simulated(steps)
    assert differences(head(trace, seen["from"]), head(reference, seen["from"])) == []
    loss, differ = first_loss(trace), first_difference(trace, reference)
    assert differ is None or loss is not None and seen["from"] <= loss <= differ


def lease() -> float:
    """The Zenoh session's lease [s]: a peer silent this long is gone."""
    from uavtrack.agents.transport import zenoh_config

    return json.loads(zenoh_config([], []).get_json("transport/link/tx/lease")) / 1e3


@pytest.mark.slow
@pytest.mark.integration
def test_a_uav_cut_past_the_lease_is_lost_from_that_cycle_and_stays_out(network, tmp_path):
    # long enough that the world runs on after the cut is restored: the program comes
    # back to a run that no longer counts it, and ends when the world does
    steps = 60
    seconds = lease() + 5.0
    act = cut_for([host(1)], seconds=seconds)
    result, trace, programs, _ = across(network, tmp_path, steps, act)
    lost = result["swarm"]["lost"]
    assert set(lost) == {"1"} and lost["1"] >= act.begun
    k = lost["1"]
    assert trace.alive[:k].all() and not trace.alive[k:, 1].any()
    assert trace.alive[:, [0, 2, 3, 4]].all()  # nobody outside the cut
    assert np.isnan(trace.mean[k:, 1]).all() and (trace.assignment[k:, 1] == -1).all()
    all_ran([p for i, p in enumerate(programs) if i != 1], steps)
    code, said = programs[1]
    assert code != 0 and f"of {steps} cycles" in said, said
    assert result["swarm"]["cycle_ms_max"] >= 1e3 * (lease() - 1.0)
    reference = simulated(steps)
    first = first_loss(trace)
    assert differences(head(trace, first), head(reference, first)) == []


def partitions(*args: str, cwd=None) -> subprocess.CompletedProcess:
    """``python benchmarks/partitions.py args`` (from the root of this checkout)."""
    return subprocess.run(
        [sys.executable, str(netns.ROOT / "benchmarks" / "partitions.py"), *args],
        cwd=cwd or netns.ROOT, capture_output=True, text=True, timeout=900,
    )  # fmt: skip


@pytest.mark.integration
def test_the_partitions_benchmark_refuses_a_bad_out_before_any_run(tmp_path):
    (tmp_path / "taken").mkdir()
    done = partitions("--out", str(tmp_path / "taken"))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "--out:" in done.stderr.strip().splitlines()[-1] and done.stdout == ""


@pytest.mark.slow
@pytest.mark.integration
def test_the_partitions_benchmark_measures_every_case(network, tmp_path):
    out = tmp_path / "partitions.json"
    done = partitions("--seeds", "1", "--steps", "30", "--out", str(out))
    assert done.returncode == 0, done.stderr
    cases = json.loads(out.read_text())["cases"]
    assert list(cases) == [
        "clean", "cut 5 s", "world from UAVs 1, 2", "flapping", "cut past the lease"
    ]  # fmt: skip
    assert cases["clean"]["mean"]["equal_to_simulator"] == 1
    for name, case in cases.items():
        (run,) = case["runs"]
        assert set(run["lost"]) == ({"1"} if name == "cut past the lease" else set()), name
        if run["lost"]:
            assert run["fault"] == {"faults.failures": [[1, run["lost"]["1"]]]}
        else:
            assert run["fault"]["faults.loss"] == pytest.approx(
                run["messages_lost"] / run["messages_sent"], rel=1e-12
            )
    assert cases["cut 5 s"]["mean"]["longest_cycle_s"] >= CUT - 1.0
