"""Outside formats, each read back by an independent library: the trace file by numpy,
the tables by pandas and pyarrow, the Dataset by xarray, the tracks by Stone Soup."""

import json

import numpy as np
import pytest

import uavtrack
from uavtrack import cli
from uavtrack.errors import UsageError
from uavtrack.io import trace as trace_file

pd = pytest.importorskip("pandas")
xr = pytest.importorskip("xarray")
pytest.importorskip("pyarrow")
pytest.importorskip("h5netcdf")
from uavtrack.io import tables  # noqa: E402

FAILING = uavtrack.Scenario(steps=30).with_overrides({"faults.failures": [[1, 10]]})


def run_cli(capsys, *args):
    code = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def result():
    return uavtrack.simulate(FAILING, "distributed", seed=3, trace=True)


@pytest.fixture
def saved(tmp_path, capsys):
    path = tmp_path / "run.npz"
    code, _, err = run_cli(
        capsys, "run", "--steps", 30, "--seed", 3, "--trace", path,
        "--set", "faults.failures=[[1, 10]]",
    )  # fmt: skip
    assert code == 0, err
    return path


def test_the_trace_file_carries_its_scenario(saved, result):
    with np.load(saved, allow_pickle=False) as data:  # plain numpy, no pickles
        assert float(data["dt"]) == 0.5 and str(data["method"]) == "distributed"
        assert int(data["seed"]) == 3
        assert uavtrack.Scenario.from_dict(json.loads(str(data["scenario"]))) == FAILING
    back = trace_file.read(saved)
    assert back.scenario == FAILING and back.seed == 3 and back.dt == 0.5
    for name, array in result.trace.arrays().items():
        if name.startswith("decision_"):  # measured times, another run's
            continue
        assert np.array_equal(getattr(back.trace, name), array, equal_nan=True), name


def test_a_file_that_is_no_trace_is_named(tmp_path):
    np.savez(tmp_path / "old.npz", **{"targets": np.zeros(3)})
    with pytest.raises(UsageError, match="not a uavtrack trace file, missing"):
        trace_file.read(tmp_path / "old.npz")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(UsageError, match="not a NumPy .npz archive"):
        trace_file.read(tmp_path / "text.npz")


def test_xarray_dataset_round_trips_through_netcdf(tmp_path, result):
    path = tmp_path / "run.nc"
    tables.to_xarray(result.trace, FAILING, "distributed", 3).to_netcdf(path, engine="h5netcdf")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert dict(ds.sizes) == {"step": 30, "uav": 5, "target": 4, "state": 4, "state_": 4}
        assert ds.attrs["dt"] == 0.5 and ds.attrs["seed"] == 3
        assert uavtrack.Scenario.from_dict(json.loads(ds.attrs["scenario"])) == FAILING
        assert np.array_equal(ds["time"], np.arange(30) * 0.5)
        assert np.array_equal(ds["uav_heading"], result.trace.uavs[..., 4])
        assert ds["uav_x"].attrs["units"] == "m"
        e = ds["estimate"].sel(state="vy", uav=2, target=1)
        assert np.array_equal(e, result.trace.mean[:, 2, 1, 3])
        assert np.array_equal(ds["observed"].values, result.trace.observed)
        # a failed UAV's estimates are NaN from its failure, as documented
        assert ds["estimate"].sel(uav=1).isel(step=slice(10, None)).isnull().all()
        assert not ds["estimate"].sel(uav=1).isel(step=slice(0, 10)).isnull().any()
        # the observation rate, from the Dataset alone
        rate = ds["observed"].any("uav").mean(("step", "target"))
        assert float(rate) == pytest.approx(result.observation_rate, abs=1e-12)


def test_tidy_tables_read_back_by_pandas(tmp_path, saved, capsys, result):
    out = tmp_path / "tables"
    code, stdout, err = run_cli(capsys, "export", saved, "--out", out)
    assert code == 0, err
    frames = {n: pd.read_parquet(out / f"{n}.parquet") for n in tables.TABLES}
    uavs, targets, pairs = frames["uavs"], frames["targets"], frames["pairs"]
    assert len(uavs) == 30 * 5 and len(targets) == 30 * 4 and len(pairs) == 30 * 5 * 4
    row = uavs[(uavs.step == 12) & (uavs.uav == 3)].iloc[0]
    assert row.x == result.trace.uavs[12, 3, 0] and row.time == 6.0
    pair = pairs[(pairs.step == 7) & (pairs.uav == 0) & (pairs.target == 2)].iloc[0]
    assert pair.P_x_vy == result.trace.cov[7, 0, 2, 0, 3]
    assert pair.est_vx == result.trace.mean[7, 0, 2, 2]
    # the paper's metric and the team's best estimate, recomputed from the tables alone
    rate = targets.groupby("step").in_view.mean().mean()
    assert rate == pytest.approx(result.observation_rate, abs=1e-12)
    err2 = (targets.best_x - targets.x) ** 2 + (targets.best_y - targets.y) ** 2
    assert np.sqrt(err2.mean()) == pytest.approx(result.rmse_best, rel=1e-9)
    csv = tmp_path / "csv"
    assert run_cli(capsys, "export", saved, "--format", "csv", "--out", csv)[0] == 0
    back = pd.read_csv(csv / "pairs.csv")
    assert np.allclose(back.est_x, pairs.est_x, equal_nan=True, rtol=1e-15)


def test_a_results_folder_becomes_one_row_per_trial(tmp_path, capsys):
    folder = tmp_path / "sweep"
    code, _, err = run_cli(
        capsys, "sweep", "planner.horizon", 2, 3, "--trials", 3, "--set", "steps=15",
        "--method", "distributed", "--method", "greedy", "--out", folder,
        "--no-progress", "--workers", 1,
    )  # fmt: skip
    assert code == 0, err
    out = tmp_path / "trials.csv"
    assert run_cli(capsys, "export", folder, "--out", out)[0] == 0  # csv, by its suffix
    rows = pd.read_csv(out)
    assert len(rows) == 2 * 2 * 3  # values x methods x trials
    assert set(rows["planner.horizon"]) == {2.0, 3.0}
    summary = json.loads((folder / "summary.json").read_text())
    means = rows.groupby(["method", "planner.horizon"]).observation_rate.mean()
    for method, per_value in summary["methods"].items():
        for value, described in zip(summary["values"], per_value, strict=True):
            assert means[(method, value)] == pytest.approx(described["mean"], abs=1e-12)
    # a job file changed by hand is left out, and said so
    victim = sorted((folder / "raw").glob("*greedy*.json"))[0]
    record = json.loads(victim.read_text())
    record["metrics"]["observation_rate"][0] = 1.0  # without a new checksum
    victim.write_text(json.dumps(record))
    code, _, err = run_cli(capsys, "export", folder, "--out", tmp_path / "again.parquet")
    assert code == 0 and "left out 1 job file(s) that fail their checksum" in err
    assert len(pd.read_parquet(tmp_path / "again.parquet")) == 2 * 2 * 3 - 3


def test_export_refuses_bad_input_and_leaves_nothing(tmp_path, saved, capsys):
    (tmp_path / "taken").mkdir()
    cases = [
        ((tmp_path / "nothing.npz", "--out", tmp_path / "a"), "does not exist"),
        ((saved, "--out", tmp_path / "taken"), "exists; give a new folder"),
        ((saved, "--out", tmp_path / "no" / "b"), "does not exist"),
        ((saved, "--format", "xlsx", "--out", tmp_path / "c"), "xlsx"),
        ((tmp_path, "--format", "netcdf", "--out", tmp_path / "d.nc"), "parquet or csv"),
        ((saved, "--format", "csv", "--out", tmp_path / "e.csv"), "go in a folder"),
        ((saved, "--format", "csv", "--out", tmp_path / "f.parquet"), "names parquet"),
        ((tmp_path / "taken", "--out", tmp_path / "g.csv"), "no manifest.json"),
    ]
    before = sorted(p.name for p in tmp_path.iterdir())
    for args, message in cases:
        code, _, err = run_cli(capsys, "export", *args)
        assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_stone_soup_metrics_on_our_tracks_equal_ours(result):
    stonesoup = pytest.importorskip("stonesoup")  # noqa: F841
    from stonesoup.measures import Euclidean
    from stonesoup.metricgenerator.ospametric import GOSPAMetric, OSPAMetric

    from uavtrack.io.stonesoup import POSITION, to_stonesoup

    truths, tracks = to_stonesoup(result.trace, 0.5)
    assert len(truths) == 4 and len(tracks) == 4
    ospa = OSPAMetric(c=20, p=1, measure=Euclidean(mapping=POSITION))
    gospa = GOSPAMetric(c=20, p=1, measure=Euclidean(mapping=POSITION))
    times = sorted({state.timestamp for path in truths for state in path})
    assert len(times) == 30
    o, g = [], []
    for t in times:
        X = [path[t] for path in truths]
        Y = [track[t] for track in tracks if t in {s.timestamp for s in track}]
        o.append(ospa.compute_OSPA_distance(Y, X).value)
        g.append(gospa.compute_gospa_metric(Y, X)[0].value["distance"])
    assert np.mean(o) == pytest.approx(result.ospa_best, abs=1e-12)
    assert np.mean(g) == pytest.approx(result.gospa_best, abs=1e-12)
    # per UAV: a track for each UAV and target, ending where the UAV fails
    _, per_uav = to_stonesoup(result.trace, 0.5, tracks="uavs")
    lengths = {track.id: len(track) for track in per_uav}
    assert (
        len(lengths) == 20 and lengths["uav-1-target-0"] == 10 and lengths["uav-0-target-3"] == 30
    )
    state = next(t for t in per_uav if t.id == "uav-2-target-1")[0]
    x, y, vx, vy = result.trace.mean[0, 2, 1]
    assert state.state_vector.ravel().tolist() == [x, vx, y, vy]  # Stone Soup's order
