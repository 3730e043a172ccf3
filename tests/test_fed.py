"""UAV programs fed from outside: a world that replays recorded scans and poses tells
each program its own over the transport, and vehicles fly the decisions as MAVLink
setpoints; the programs' tracks are the batch replay's on the same scans."""

import contextlib

import numpy as np
import pytest

import uavtrack
from uavtrack.agents import run_swarm
from uavtrack.errors import UsageError
from uavtrack.io import replay

from .test_replay import DECIDED, REALISTIC, same

FED = REALISTIC.with_overrides({"dt": 0.1})  # the vehicles fly in real time: 0.1 s a cycle


def recorded(steps, seed):
    scenario = FED.with_overrides({"steps": steps})
    run = uavtrack.simulate(scenario, seed=seed)
    assert run.trace is not None
    return scenario, replay.of_trace(run.trace, scenario, seed)


def test_a_memory_swarm_fed_a_recording_is_the_batch_replay():
    scenario, rec = recorded(30, 3)
    fed = run_swarm(scenario, "distributed", seed=3, recording=rec)
    batch = replay.replay(rec, scenario, "distributed", seed=3)
    assert fed.result.trace is not None and batch.trace is not None
    assert same(batch.trace, fed.result.trace, DECIDED + ("alive", "uavs")) == []
    assert fed.result.gospa == batch.gospa and fed.result.seed is None


def test_a_recording_on_the_ground_alone_is_refused_for_the_programs():
    scenario, rec = recorded(3, 0)
    flat = replay.Recording(**{**rec.__dict__, "polar": np.full(rec.polar.shape, np.nan)})
    with pytest.raises(UsageError, match="told range and bearing"):
        run_swarm(scenario, recording=flat)


@pytest.mark.integration
@pytest.mark.parametrize("steps", [pytest.param(100, marks=pytest.mark.slow), 25])
def test_zenoh_programs_fed_a_recording_fly_mavlink_vehicles_and_track_as_the_batch(steps):
    mavlink = pytest.importorskip("tests.test_mavlink")
    pytest.importorskip("zenoh")
    from uavtrack.io.mavlink import ARDUPLANE_GUIDED, LocalFrame, MavlinkPilot

    scenario, rec = recorded(steps, 4)
    frame = LocalFrame(47.4, 8.5)
    with contextlib.ExitStack() as stack:
        pairs = [
            stack.enter_context(mavlink.flying(rec.poses[0, i], scenario.dt, frame))
            for i in range(rec.sensors)
        ]
        for _, vehicle in pairs:
            vehicle.connect("ardupilot", deadline=30.0)
        pilot = MavlinkPilot([v for _, v in pairs], frame, scenario.dt, deadline=30.0)
        fed = run_swarm(scenario, "distributed", seed=4, transport="zenoh", recording=rec,
                        pilot=pilot)  # fmt: skip
    batch = replay.replay(rec, scenario, "distributed", seed=4)
    trace = fed.result.trace
    assert trace is not None and batch.trace is not None
    assert same(batch.trace, trace) == [] and fed.traffic.lost == {}
    for i, (side, _) in enumerate(pairs):  # each vehicle flew its program's every decision
        assert side.mode == ARDUPLANE_GUIDED and all(in_mode for in_mode, _ in side.flown)
        rolls = [roll for _, roll in side.flown][:steps]
        assert rolls == pytest.approx(-trace.action[: len(rolls), i], abs=1e-6)
        assert len(rolls) >= steps - 1


def test_swarm_recording_from_the_command_line_is_the_run(tmp_path, capsys):
    from uavtrack import cli
    from uavtrack.io import trace as trace_file

    run, tables, fed = tmp_path / "run.npz", tmp_path / "rec", tmp_path / "fed.npz"
    for args in (
        ("run", "--config", "realistic", "--steps", 20, "--seed", 6, "--trace", run),
        ("export", run, "--out", tables),
        ("swarm", "--recording", tables, "--seed", 6, "--trace", fed),
    ):
        assert cli.main([str(a) for a in args]) == 0, capsys.readouterr().err
    capsys.readouterr()
    assert same(trace_file.read(run).trace, trace_file.read(fed).trace) == []
    assert cli.main(["swarm", "--recording", str(tables), "--team", "3x3"]) == 2
    assert "the recording sets them" in capsys.readouterr().err
