"""Recorded scans in (`uavtrack.io.replay`, `uavtrack replay`): a replay of a run's own scans
is that run, a hand-made recording with clutter and misses is tracked, bad input is one
line."""

import numpy as np
import pytest

import uavtrack
from uavtrack import cli, sensing
from uavtrack.io import replay
from uavtrack.io import trace as trace_file

pd = pytest.importorskip("pandas")
pytest.importorskip("pyarrow")
from uavtrack.io import recording  # noqa: E402

REALISTIC = uavtrack.Scenario.from_toml("realistic")
DECIDED = ("label", "status", "existence", "mean", "cov", "assignment", "bids", "action", "rounds",
           "messages", "delivered", "bytes", "node_bytes", "conflicts")  # fmt: skip


def run_cli(capsys, *args):
    code = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def same(a, b, names=DECIDED):
    """The fields of two traces that differ (floats: the same machine, the same stages)."""
    return [n for n in names if not np.array_equal(getattr(a, n), getattr(b, n), equal_nan=True)]


@pytest.mark.parametrize(
    ("method", "changes"),
    [
        ("distributed", {}),  # jpda, loss 0.2, delay 1, compact, trigger, avoidance
        ("centralized", {"radio.encoding": "full", "fusion.trigger": None}),
        ("greedy", {"tracker.association": "gnn", "faults.delay": 0}),
        ("distributed", {"tracker.briefing": False, "sensor.clutter_rate": 3.0}),
    ],
)
def test_a_replay_of_a_runs_own_scans_is_that_run(method, changes):
    scenario = REALISTIC.with_overrides({"steps": 40, **changes})
    run = uavtrack.simulate(scenario, method, seed=5)
    assert run.trace is not None
    played = replay.replay(replay.of_trace(run.trace, scenario, 5), scenario, method, seed=5)
    assert played.trace is not None and same(run.trace, played.trace) == []
    assert played.gospa == run.gospa and played.observation_rate == run.observation_rate
    # the radio's faults are the seed's: another seed loses other messages
    if scenario.faults.loss > 0:
        other = replay.replay(replay.of_trace(run.trace, scenario, 5), scenario, method, seed=6)
        assert other.trace is not None and "delivered" in same(run.trace, other.trace)


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_exported_tables_replay_to_the_run_from_the_command_line(tmp_path, capsys, fmt):
    run, tables = tmp_path / "run.npz", tmp_path / "tables"
    code, _, err = run_cli(capsys, "run", "--config", "realistic", "--steps", 30, "--seed", 4,
                           "--trace", run)  # fmt: skip
    assert code == 0, err
    code, out, err = run_cli(capsys, "export", run, "--format", fmt, "--out", tables)
    assert code == 0, err
    assert f"uavtrack replay {tables} --method distributed --seed 4" in out
    import tomllib

    written = tomllib.loads((tables / "scenario.toml").read_text())
    assert written["tracker"]["association"] == "jpda" and written["faults"]["loss"] == 0.2
    read = pd.read_parquet if fmt == "parquet" else pd.read_csv
    briefing = read(tables / f"briefing.{fmt}")  # the prior each UAV starts from
    sigma = REALISTIC.estimation.initial_position_std
    assert list(briefing["target"]) == [0, 1, 2, 3] and (briefing["vx"] == 0).all()
    assert np.allclose(briefing["P_x_x"], sigma**2) and (briefing["P_x_y"] == 0).all()
    first = trace_file.read(run).trace.targets[0]  # the cue: within 4 sigma of the truth
    assert (np.hypot(briefing["x"] - first[:, 0], briefing["y"] - first[:, 1]) < 4 * sigma).all()
    played, again = tmp_path / "played.npz", tmp_path / "again"
    code, out, err = run_cli(capsys, "replay", tables, "--seed", 4, "--trace", played,
                             "--tables", again)  # fmt: skip
    assert code == 0, err
    assert "5 sensors, 30 steps" in out and "scores against it" in out
    assert same(trace_file.read(run).trace, trace_file.read(played).trace) == []
    written = pd.read_parquet(again / "tracks.parquet")  # the tracks, as export writes them
    exported = pd.read_parquet(tables / "tracks.parquet") if fmt == "parquet" else None
    if exported is not None:
        pd.testing.assert_frame_equal(written, exported)
    assert set(written["status"]) <= {"tentative", "confirmed"}


TRACKED = uavtrack.Scenario().with_overrides(
    {"tracker.association": "jpda", "sensor.detection_probability": 0.85,
     "sensor.clutter_rate": 1.0}
)  # fmt: skip


def handmade(folder, rng, steps=60, truth=True, csv=True):
    """Two targets crossing the field, three sensors above them, each with its own
    detections (P_D 0.85, 1 m std) and clutter (1 a scan, uniform in its disk)."""
    scenario = uavtrack.Scenario()
    dt, altitude = scenario.dt, np.array([415.0, 420.0, 425.0])
    radius = sensing.observation_radius(altitude, scenario.sensor)
    t = np.arange(steps) * dt
    start, velocity = np.array([[60.0, 80.0], [140.0, 120.0]]), np.array([[1.5, 0.5], [-1.5, -0.5]])
    position = start[None] + t[:, None, None] * velocity[None]  # (T, 2, 2)
    follows = np.array([0, 1, 0])
    offset = np.array([[8.0, 0.0], [-8.0, 4.0], [0.0, -12.0]])
    poses, measured = [], []
    for k in range(steps):
        for i in range(3):
            x, y = position[k, follows[i]] + offset[i]
            poses.append({"time": t[k], "uav": i, "x": x, "y": y, "altitude": altitude[i],
                          "heading": 0.3 * i})  # fmt: skip
            seen = np.hypot(*(position[k] - (x, y)).T) <= radius[i]
            points = [position[k, j] + rng.normal(0, 1.0, 2) for j in np.flatnonzero(seen)
                      if rng.random() < 0.85]  # fmt: skip
            for _ in range(rng.poisson(1.0)):
                rho, phi = radius[i] * np.sqrt(rng.random()), 2 * np.pi * rng.random()
                points.append(np.array([x + rho * np.cos(phi), y + rho * np.sin(phi)]))
            for p in rng.permutation(len(points)):
                measured.append({"time": t[k], "uav": i, "x": points[p][0], "y": points[p][1],
                                 "R_x_x": 1.0, "R_x_y": 0.0, "R_y_y": 1.0})  # fmt: skip
    folder.mkdir()
    suffix = ".csv" if csv else ".parquet"
    tables = {"uavs": pd.DataFrame(poses), "measurements": pd.DataFrame(measured)}
    if truth:
        tables["targets"] = pd.DataFrame(
            [{"time": t[k], "target": j, "x": position[k, j, 0], "y": position[k, j, 1],
              "vx": velocity[j, 0], "vy": velocity[j, 1]}
             for k in range(steps) for j in range(2)]
        )  # fmt: skip
    (folder / "scenario.toml").write_text(TRACKED.to_toml())
    for name, frame in tables.items():
        if csv:
            frame.to_csv(folder / f"{name}{suffix}", index=False)
        else:
            frame.to_parquet(folder / f"{name}{suffix}", index=False)
    return position


def test_a_handmade_recording_with_clutter_and_misses_is_tracked(tmp_path):
    position = handmade(tmp_path / "rec", np.random.default_rng(1))
    rec = recording.read(tmp_path / "rec", TRACKED)
    assert rec.prior is None and rec.targets is not None and rec.sensors == 3
    result = replay.replay(rec, TRACKED, "distributed")
    trace = result.trace
    assert trace is not None
    # the team finds both targets from nothing: at the end, each sensor holds one confirmed
    # track within 4 m of the target it flies over, and the team one label per target
    last = -1
    for i, j in enumerate([0, 1, 0]):
        held = trace.status[last, i] == 2
        error = np.hypot(*(trace.mean[last, i, held, :2] - position[last, j]).T)
        assert error.min() < 4.0 and (error < 10.0).sum() == 1
    assert result.label_purity > 0.9 and result.time_to_confirm < 10
    assert result.gospa < 15.0  # two targets, cut-off 10 m: far below a miss of both


def test_a_recording_without_truth_scores_only_what_it_can(tmp_path, capsys):
    handmade(tmp_path / "rec", np.random.default_rng(2), steps=20, truth=False, csv=False)
    code, out, err = run_cli(capsys, "replay", tmp_path / "rec", "--set",
                             "tracker.association='gnn'", "--json")  # fmt: skip
    assert "gnn" in out
    assert code == 0, err
    import json

    summary = json.loads(out)
    assert summary["gospa"] is None or summary["gospa"] != summary["gospa"]
    assert summary["messages"] > 0 and summary["recording"] == str(tmp_path / "rec")


def test_a_given_radio_graph_replaces_the_range(tmp_path):
    handmade(tmp_path / "rec", np.random.default_rng(3), steps=20)
    rec = recording.read(tmp_path / "rec", TRACKED)
    ranged = replay.replay(rec, TRACKED)
    graph = uavtrack.simulation.graph(rec.poses, rec.alive, replay.scenario_for(rec, TRACKED))
    same_graph = replay.replay(
        replay.Recording(**{**rec.__dict__, "links": graph & ~np.eye(3, dtype=bool)}), TRACKED
    )
    assert ranged.trace is not None and same_graph.trace is not None
    assert same(ranged.trace, same_graph.trace) == []
    alone = replay.replay(
        replay.Recording(**{**rec.__dict__, "links": np.zeros((20, 3, 3), dtype=bool)}), TRACKED
    )
    assert alone.trace is not None and alone.trace.messages.sum() == 0
    assert ranged.trace.messages.sum() > 0

    def shared(trace):  # labels sensors 0 and 2 (over target 0) both hold confirmed
        held = [set(trace.label[-1, i][trace.status[-1, i] == 2]) for i in (0, 2)]
        return held[0] & held[1]

    assert shared(ranged.trace) and not shared(alone.trace)  # agreement needs the radio


def test_bad_recordings_are_one_line_and_write_nothing(tmp_path, capsys):
    handmade(tmp_path / "good", np.random.default_rng(4), steps=5)
    good = {n: pd.read_csv(tmp_path / "good" / f"{n}.csv") for n in ("uavs", "measurements")}

    def folder(name, **frames):
        path = tmp_path / name
        path.mkdir()
        for table, frame in {**good, **frames}.items():
            if frame is not None:
                frame.to_csv(path / f"{table}.csv", index=False)
        (path / "scenario.toml").write_text(TRACKED.to_toml())
        return path

    off_grid = good["uavs"].assign(time=good["uavs"]["time"] + 0.1 * (good["uavs"]["uav"] == 2))
    far = good["uavs"].assign(x=good["uavs"]["x"] + 5000.0)  # other coordinates
    both = good["measurements"].assign(range=400.0, bearing=0.1)
    stalled = good["uavs"].assign(speed=np.where(good["uavs"]["uav"] == 1, 0.0, 15.0))
    stepped = good["uavs"].assign(step=(good["uavs"]["time"] / 0.5).round().astype(int))
    stepped.loc[4, "step"] += 1  # one row's step and time disagree
    ghost = pd.concat([good["measurements"], good["measurements"].iloc[:1].assign(uav=7)])
    bad_r = good["measurements"].assign(R_x_y=5.0)
    cases = [
        ((tmp_path / "nowhere",), "is not a folder"),
        ((folder("no_uavs", uavs=None),), "no uavs table"),
        ((folder("grid", uavs=off_grid),), "not on the grid of dt = 0.5 s"),
        ((folder("ghost", measurements=ghost),), "uav 7, which has no pose"),
        ((folder("bad_r", measurements=bad_r),), "not symmetric positive definite"),
        ((folder("no_cols", measurements=good["measurements"].drop(columns="R_y_y")),),
         "give x, y with R_x_x"),
        ((folder("far", uavs=far),), "outside the scenario's field (0 to 200 m"),
        ((folder("both", measurements=both),), "not both"),
        ((folder("stalled", uavs=stalled),), "speed must be above 0"),
        ((folder("stepped", uavs=stepped),), "disagree"),
        ((tmp_path / "good", "--set", "tracker.association='known'"), "gnn or jpda"),
        ((tmp_path / "good", "--set", "faults.position_std=2"), "faults.position_std"),
    ]  # fmt: skip
    before = sorted(p.name for p in tmp_path.iterdir())
    for args, message in cases:
        code, _, err = run_cli(capsys, "replay", *args, "--trace", tmp_path / "out.npz")
        assert code == 2 and message in err and len(err.strip().splitlines()) == 1, (args, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    with pytest.raises(ValueError, match="reports again"):
        rec = recording.read(tmp_path / "good", TRACKED)
        alive = rec.alive.copy()
        alive[2, 1] = False
        replay.Recording(**{**rec.__dict__, "alive": alive, "valid": rec.valid & alive[..., None]})


def test_a_bag_of_odometry_and_radar_scans_replays_close_to_the_run(tmp_path, capsys):
    """radar_msgs carries float32 directions, so a bag's scans are the run's to about a
    millimetre (a return at the nadir keeps its bearing, `ros2.NADIR`): the replay
    tracks as the run did, not bit for bit."""
    pytest.importorskip("rosbags")
    import dataclasses

    scenario = REALISTIC.with_overrides({"steps": 100, "tracker.briefing": False})
    run = uavtrack.simulate(scenario, seed=1)
    assert run.trace is not None
    bag = tmp_path / "bag"
    args = ("--config", "realistic", "--set", "tracker.briefing=false", "--steps", 100)
    code, _, err = run_cli(capsys, "run", *args, "--seed", 1, "--bag", bag)
    assert code == 0, err
    rec = recording.from_bag(bag, scenario)
    exact = replay.of_trace(run.trace, scenario, 1)
    assert np.array_equal(rec.valid, exact.valid) and np.array_equal(rec.alive, exact.alive)
    v = rec.valid
    assert np.abs(rec.z[v] - exact.z[v]).max() < 0.01
    scored = replay.replay(dataclasses.replace(rec, targets=run.trace.targets), scenario, seed=1)
    assert scored.gospa == pytest.approx(run.gospa, rel=0.02)  # 11 % off with bearings lost
    assert scored.label_purity == pytest.approx(run.label_purity, abs=0.005)
    code, out, err = run_cli(capsys, "replay", bag, "--config", "realistic", "--seed", 1)
    assert code == 0 and "5 sensors, 100 steps" in out, err


def test_a_sensor_whose_rows_stop_has_failed_and_replays_as_the_run(tmp_path, capsys):
    """A UAV that fails mid-run: the export's scenario leaves the failures to its alive
    column, and with its rows cut after it failed (it stays at its last pose) its team
    tracks as the run's did."""
    run, tables = tmp_path / "run.npz", tmp_path / "rec"
    code, _, err = run_cli(capsys, "run", "--config", "realistic", "--steps", 30, "--seed", 2,
                           "--set", "faults.failures=[[2, 12]]", "--trace", run)  # fmt: skip
    assert code == 0, err
    code, out, err = run_cli(capsys, "export", run, "--out", tables)
    assert code == 0 and "--seed 2\n" in out + "\n", err
    uavs = pd.read_parquet(tables / "uavs.parquet")
    uavs[(uavs["uav"] != 2) | (uavs["step"] < 12)].to_parquet(tables / "uavs.parquet")
    played = tmp_path / "played.npz"
    code, _, err = run_cli(capsys, "replay", tables, "--seed", 2, "--trace", played)
    assert code == 0, err
    fields = DECIDED + ("alive",)
    assert same(trace_file.read(run).trace, trace_file.read(played).trace, fields) == []


def test_recorded_clocks_jitter_and_flags_and_empty_scans_read_as_meant(tmp_path):
    """A recorder's times a few ms off the grid land on their steps, alive written 1.0
    and 0.0 reads as flags, and a measurements table of a header alone is no scan."""
    handmade(tmp_path / "rec", np.random.default_rng(6), steps=10)
    exact = recording.read(tmp_path / "rec", TRACKED)
    uavs = pd.read_csv(tmp_path / "rec" / "uavs.csv")
    shaken = np.random.default_rng(0).uniform(-0.004, 0.004, len(uavs))
    shaken_uavs = uavs.assign(time=uavs["time"] + shaken, alive=1.0)
    shaken_uavs.to_csv(tmp_path / "rec" / "uavs.csv", index=False)
    jittered = recording.read(tmp_path / "rec", TRACKED)
    assert np.array_equal(jittered.poses, exact.poses) and np.array_equal(jittered.z, exact.z)
    (tmp_path / "rec" / "measurements.csv").write_text("time,uav,x,y,R_x_x,R_x_y,R_y_y\n")
    (tmp_path / "rec" / "targets.csv").unlink()
    empty = recording.read(tmp_path / "rec", TRACKED)
    assert empty.valid.shape[:2] == (10, 3) and not empty.valid.any()
    result = replay.replay(empty, TRACKED)
    assert result.trace is not None and not (result.trace.status == 2).any()
    twice = pd.DataFrame({"step": [0, 0], "uav": [0, 0], "index": [0, 0], "x": [50.0, 51.0],
                          "y": [60.0, 61.0], "R_x_x": 1.0, "R_x_y": 0.0, "R_y_y": 1.0})  # fmt: skip
    twice.to_csv(tmp_path / "rec" / "measurements.csv", index=False)
    with pytest.raises(recording.UsageError, match="share an index"):
        recording.read(tmp_path / "rec", TRACKED)
