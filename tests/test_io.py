"""Outside formats, each read back by an independent library: the trace file by numpy,
the tables by pandas and pyarrow, the Dataset by xarray, the tracks by Stone Soup."""

import json

import numpy as np
import pytest

import uavtrack
import uavtrack.io
from uavtrack import cli
from uavtrack.errors import UsageError
from uavtrack.io import trace as trace_file

from .test_files import on_a_small_disk

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
        assert int(data["format"]) == trace_file.FORMAT
        assert str(data["uavtrack"]) == uavtrack.__version__
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
    uavtrack.io.to_xarray(result).to_netcdf(path, engine="h5netcdf")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert dict(ds.sizes) == {"step": 30, "uav": 5, "target": 4, "state": 4, "state_": 4}
        assert ds.attrs["dt"] == 0.5 and ds.attrs["seed"] == 3
        assert uavtrack.Scenario.from_dict(json.loads(ds.attrs["scenario"])) == FAILING
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


def test_netcdf_time_is_a_cf_time_axis_and_every_variable_is_named(tmp_path, saved, capsys):
    out = tmp_path / "run.nc"
    code, _, err = run_cli(capsys, "export", saved, "--out", out)
    assert code == 0, err
    with xr.open_dataset(out, engine="h5netcdf", decode_times=False) as raw:
        assert raw["time"].attrs["units"] == "seconds since 2000-01-01"
        assert raw["time"].attrs["standard_name"] == "time"
        assert np.allclose(raw["time"].values, np.arange(30) * 0.5, rtol=0, atol=1e-12)
        for name, variable in {**raw.data_vars, **raw.coords}.items():
            assert variable.attrs.get("long_name"), name
        assert raw["uav_altitude"].attrs["standard_name"] == "height"
    with xr.open_dataset(out, engine="h5netcdf") as ds:  # decode_times: CF time to dates
        assert np.issubdtype(ds["time"].dtype, np.datetime64)
        since = ds["time"].values - np.datetime64("2000-01-01T00:00:00")
        elapsed = since / np.timedelta64(1, "s")
        assert np.allclose(elapsed, np.arange(30) * 0.5, rtol=0, atol=1e-9)
        times = ds["time"].to_index()
        assert times[0].year == 2000 and (times[3] - times[1]).total_seconds() == 1.0
        assert ds.attrs["uavtrack"] == uavtrack.__version__


def test_one_call_from_a_path_a_result_or_a_trace_read(saved, result):
    from uavtrack.io.stonesoup import to_stonesoup
    from uavtrack.simulation import Trace

    stamped = ("decision_time_ms", "decision_wall_ms")  # measured: another run's times
    from_path = uavtrack.io.to_xarray(saved).drop_vars(stamped)
    from_result = uavtrack.io.to_xarray(result).drop_vars(stamped)
    assert from_path.identical(from_result)
    assert uavtrack.io.to_xarray(trace_file.read(saved)).drop_vars(stamped).identical(from_path)
    old = tables.to_xarray(result.trace, FAILING, "distributed", 3)  # the explicit form
    assert old.drop_vars(stamped).identical(from_result)
    frames, explicit = uavtrack.io.to_frames(str(saved)), tables.to_frames(result.trace, 0.5)
    for name in tables.TABLES:
        keep = [c for c in explicit[name].columns if c not in stamped]
        pd.testing.assert_frame_equal(frames[name][keep], explicit[name][keep])
    pytest.importorskip("stonesoup")
    truths, tracks = uavtrack.io.to_stonesoup(saved)
    truths_, tracks_ = to_stonesoup(result.trace, 0.5)
    assert {t.id: len(t) for t in tracks} == {t.id: len(t) for t in tracks_}
    for bad, message in (
        (lambda: uavtrack.io.to_xarray(result.trace), "a bare Trace needs its scenario"),
        (lambda: uavtrack.io.to_xarray(3), "expected a trace file's path"),
        (lambda: uavtrack.io.to_xarray(result, FAILING), "go with a bare Trace"),
        (lambda: uavtrack.io.to_frames(result.trace), "needs its step dt"),
        (lambda: uavtrack.io.to_stonesoup(result.trace), "needs its step dt"),
        (lambda: uavtrack.io.to_stonesoup(saved, 0.5), "dt goes with a bare Trace"),
    ):
        with pytest.raises(UsageError, match=message):
            bad()
    assert isinstance(result.trace, Trace)


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
    # the units travel in the Parquet schema, field by field
    import pyarrow.parquet as pq

    schema = {n: pq.read_schema(out / f"{n}.parquet") for n in tables.TABLES}
    units = {
        ("uavs", "x"): b"m", ("uavs", "speed"): b"m/s", ("uavs", "heading"): b"rad",
        ("uavs", "bank_angle"): b"rad", ("uavs", "decision_time_ms"): b"ms",
        ("steps", "time"): b"s", ("targets", "best_vy"): b"m/s", ("pairs", "est_y"): b"m",
        ("pairs", "P_x_x"): b"m^2", ("pairs", "P_x_vy"): b"m^2/s", ("pairs", "P_vx_vy"): b"m^2/s^2",
        ("uavs", "bytes"): b"byte", ("steps", "node_bytes"): b"byte",
    }  # fmt: skip
    for (table, column), unit in units.items():
        assert schema[table].field(column).metadata[b"unit"] == unit, (table, column)
    for table, column in (("steps", "messages"), ("uavs", "alive"), ("pairs", "in_view")):
        assert not schema[table].field(column).metadata  # counts and flags have none
    assert frames["pairs"].attrs["units"]["P_y_vx"] == "m^2/s"  # pandas keeps them too
    on_air = frames["uavs"]["bytes"].sum() + frames["steps"]["node_bytes"].sum()
    assert on_air == result.trace.bytes.sum() + result.trace.node_bytes.sum() > 0
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
    assert run_cli(capsys, "export", folder, "--out", tmp_path / "trials.parquet")[0] == 0
    import pyarrow.parquet as pq

    schema = pq.read_schema(tmp_path / "trials.parquet")
    assert schema.field("rmse_best").metadata[b"unit"] == b"m"
    assert schema.field("decision_time_ms").metadata[b"unit"] == b"ms"
    assert not schema.field("observation_rate").metadata
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
    # an intact job file copied over another job's name: refused, naming it
    victim.write_text(json.dumps(json.loads(victim.read_text()) | {"sha256": "x"}))
    other = sorted((folder / "raw").glob("*distributed*.json"))[0]
    kept = other.read_bytes()
    other.write_bytes(sorted((folder / "raw").glob("*distributed*.json"))[1].read_bytes())
    code, _, err = run_cli(capsys, "export", folder, "--out", tmp_path / "copied.csv")
    assert code == 2 and f"{other}: holds the result of job" in err, err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "copied.csv").exists()
    other.write_bytes(kept)
    # a manifest that cannot be read: refused, not exported with the swept field blank
    manifest = folder / "manifest.json"
    deep = "[" * 200_000 + "]" * 200_000  # deeper than json parses: a RecursionError
    for broken in ("{not json", "[]", '{"scenario": {"steps": -1}}', deep, "/dev/zero"):
        manifest.unlink()
        if broken == "/dev/zero":  # read whole, 24 GB went before the kernel's OOM killer
            manifest.symlink_to(broken)
        else:
            manifest.write_text(broken)
        code, _, err = run_cli(capsys, "export", folder, "--out", tmp_path / "broken.csv")
        assert code == 2 and f"{manifest}: cannot be read" in err, err
        assert len(err.strip().splitlines()) == 1 and not (tmp_path / "broken.csv").exists()
        code, _, err = run_cli(
            capsys, "sweep", "planner.horizon", 2, 3, "--trials", 3, "--set", "steps=15",
            "--method", "distributed", "--method", "greedy", "--out", folder, "--no-progress",
        )  # fmt: skip
        assert code == 2 and err.count("\n") == 1 and str(folder) in err, err  # named


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
        ((saved, "--out", saved, "--format", "netcdf", "--force"), "is SOURCE itself"),
        ((tmp_path / "taken", "--out", tmp_path / "taken", "--force"), "is SOURCE itself"),
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
    # each UAV's tracks are one set: OSPA per living UAV and step, averaged, is ours
    o, g = [], []
    stamps = {track.id: {s.timestamp for s in track} for track in per_uav}
    for t in times:
        X = [path[t] for path in truths]
        for i in range(5):
            Y = [tr[t] for tr in per_uav if tr.metadata["uav"] == i and t in stamps[tr.id]]
            if Y:
                assert len(Y) == 4
                o.append(ospa.compute_OSPA_distance(Y, X).value)
                g.append(gospa.compute_gospa_metric(Y, X)[0].value["distance"])
    assert len(o) == 30 * 5 - 20  # UAV 1 fails at step 10
    assert np.mean(o) == pytest.approx(result.ospa, abs=1e-12)
    assert np.mean(g) == pytest.approx(result.gospa, abs=1e-12)
    state = next(t for t in per_uav if t.id == "uav-2-target-1")[0]
    x, y, vx, vy = result.trace.mean[0, 2, 1]
    assert state.state_vector.ravel().tolist() == [x, vx, y, vy]  # Stone Soup's order


def test_export_never_replaces_what_exists(tmp_path, saved, capsys):
    folder = tmp_path / "sweep"
    assert run_cli(capsys, *SWEEP, "--out", folder)[0] == 0
    for source, name in ((saved, "mine.nc"), (folder, "mine.csv"), (folder, "mine.parquet")):
        existing = tmp_path / name
        existing.write_text("mine")
        code, out, err = run_cli(capsys, "export", source, "--out", existing)
        assert code == 2 and out == "" and len(err.strip().splitlines()) == 1, err
        assert f"--out: {existing} exists" in err
        assert existing.read_text() == "mine"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


SWEEP = ("sweep", "planner.horizon", 2, "--trials", 1, "--set", "steps=5", "--no-progress",
         "--workers", 1)  # fmt: skip


@pytest.mark.integration
@pytest.mark.parametrize("out", ["run.nc", "tables"])
def test_a_full_disk_during_export_is_one_line_and_leaves_nothing(tmp_path, saved, out):
    folder = tmp_path / "small"
    folder.mkdir()
    proc = on_a_small_disk(folder, 40_000, "-m", "uavtrack.cli", "export", saved, "--out", out)
    assert proc.returncode == 1 and proc.stdout == "", proc.stderr[-2000:]
    assert proc.stderr.count("\n") == 1 and "File too large" in proc.stderr
    assert proc.stderr.startswith(f"uavtrack: error: cannot write {out if out == 'run.nc' else ''}")
    assert out in proc.stderr
    assert list(folder.iterdir()) == []


def rewrite(path, source, **changes):
    """A copy of trace file `source` at `path` with some arrays changed (None: removed)."""
    with np.load(source, allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files}
    for name, value in changes.items():
        if value is None:
            arrays.pop(name)
        else:
            arrays[name] = np.asarray(value)
    np.savez_compressed(path, **arrays)
    return path


def test_a_trace_whose_arrays_disagree_is_refused_in_one_line(tmp_path, saved, capsys):
    with np.load(saved) as data:
        short, wide = data["uavs"][:12], data["cov"][:, :, :3]
    cases = [
        (rewrite(tmp_path / "short.npz", saved, uavs=short), "uavs is (12, 5, 5), where"),
        (rewrite(tmp_path / "wide.npz", saved, cov=wide), "cov is (30, 5, 3, 4, 4), where"),
        (rewrite(tmp_path / "text.npz", saved, rounds=np.full((30, 5), "x")), "rounds holds"),
    ]
    for path, message in cases:
        for out in ("t.nc", "t"):
            code, stdout, err = run_cli(capsys, "export", path, "--out", tmp_path / out)
            assert code == 2 and stdout == "" and len(err.strip().splitlines()) == 1, err
            assert f"{path}: " in err and message in err
    assert not (tmp_path / "t.nc").exists() and not (tmp_path / "t").exists()


def lying_header(path, source, name: str, shape: tuple[int, ...]):
    """A copy of `source` whose array `name` declares `shape` in its .npy header, its
    data left as it was: what `numpy.load` would allocate whole before any check."""
    import io
    import zipfile

    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            raw = zin.read(info)
            if info.filename == f"{name}.npy":
                array = np.load(io.BytesIO(raw))
                head = io.BytesIO()
                np.lib.format.write_array_header_1_0(
                    head, {"descr": array.dtype.str, "fortran_order": False, "shape": shape}
                )
                raw = (
                    np.lib.format.magic(1, 0) + head.getvalue()[8:] + raw[len(raw) - array.nbytes :]
                )
            zout.writestr(info.filename, raw)
    return path


def test_a_trace_is_checked_from_its_headers_before_any_array_is_read(tmp_path, saved, capsys):
    """An extra array, an array declaring a billion steps (7.5 GB), an array whose bytes
    are not what its header says: each refused in one line, with no more memory than a
    small trace takes (the data are never read)."""
    import tracemalloc

    with np.load(saved) as data:
        steps = data["targets"].shape[0]
    extra = np.zeros((200_000, 1))  # 1.6 MB, compressed to a few KiB
    cases = [
        (rewrite(tmp_path / "extra.npz", saved, more=extra), "unknown array 'more'"),
        (
            lying_header(tmp_path / "huge.npz", saved, "cov", (10**9, 5, 4, 4, 4)),
            "bytes where its header declares",
        ),
        (
            lying_header(tmp_path / "steps.npz", saved, "targets", (steps + 1, 4, 4)),
            "bytes where its header declares",
        ),
    ]
    for path, message in cases:
        tracemalloc.start()
        code, stdout, err = run_cli(capsys, "export", path, "--out", tmp_path / "t.nc")
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert code == 2 and stdout == "" and len(err.strip().splitlines()) == 1, err
        assert message in err, err
        assert peak < 20 * 2**20, peak  # far below a read of the arrays' declared sizes
    assert not (tmp_path / "t.nc").exists()
    # a scenario nested deeper than json parses, and an archive of other arrays
    with np.load(saved) as data:
        arrays = {name: data[name] for name in data.files}
    np.savez_compressed(tmp_path / "deep.npz", **{**arrays, "scenario": np.array("[" * 10**5)})
    np.savez(tmp_path / "plain.npz", a=np.zeros(3))
    refusals = {
        "deep.npz": "its scenario cannot be read (nested too deeply)",
        "plain.npz": "not a uavtrack trace file (unknown array 'a')",
    }
    for name, message in refusals.items():
        code, _, err = run_cli(capsys, "export", tmp_path / name, "--out", tmp_path / "t.nc")
        assert code == 2 and err.count("\n") == 1 and message in err, err
        assert err.count("not a uavtrack trace file") <= 1  # said once
    # a header that agrees with its bytes, but not with the scenario's steps
    long = rewrite(tmp_path / "long.npz", saved, targets=np.zeros((10**4, 4, 4)))
    code, _, err = run_cli(capsys, "export", long, "--out", tmp_path / "t.nc")
    assert code == 2 and "targets has 10000 steps, its scenario 30" in err, err


def test_export_to_a_link_to_nothing_is_refused_naming_it(tmp_path, saved, capsys):
    for name in ("gone.nc", "gone"):
        link = tmp_path / f"link-{name}"
        link.symlink_to(tmp_path / name)
        code, out, err = run_cli(capsys, "export", saved, "--out", link)
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        assert f"--out: {link} is a link to {tmp_path / name}, which does not exist" in err
        assert link.is_symlink() and not (tmp_path / name).exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_which_versions_a_trace_is_read_from(tmp_path, saved, capsys):
    now = uavtrack.__version__
    # the same format by another version: read, with a note naming both versions
    other = rewrite(tmp_path / "other.npz", saved, uavtrack="0.0.7")
    code, out, err = run_cli(capsys, "export", other, "--out", tmp_path / "o.nc")
    assert code == 0, err
    assert err == (
        f"uavtrack: note: {other} was written by uavtrack 0.0.7; uavtrack {now} reads it as "
        f"trace format {trace_file.FORMAT}\n"
    )
    with xr.open_dataset(tmp_path / "o.nc", engine="h5netcdf") as ds:
        assert ds.attrs["uavtrack"] == "0.0.7"  # the version that ran the trial
    with pytest.warns(trace_file.TraceVersionWarning, match="written by uavtrack 0.0.7"):
        assert trace_file.read(other).version == "0.0.7"
    # a file from before the format number: its layout is format 1
    unnumbered = rewrite(tmp_path / "unnumbered.npz", saved, format=None)
    assert run_cli(capsys, "export", unnumbered, "--out", tmp_path / "u.nc")[0:3:2] == (0, "")
    # a newer format is refused, naming both versions
    newer = rewrite(tmp_path / "newer.npz", saved, format=trace_file.FORMAT + 1, uavtrack="0.3.0")
    code, out, err = run_cli(capsys, "export", newer, "--out", tmp_path / "n.nc")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert f"trace format {trace_file.FORMAT + 1}, written by uavtrack 0.3.0, is newer" in err
    assert f"than uavtrack {now} reads (format {trace_file.FORMAT})" in err
    odd = rewrite(tmp_path / "odd.npz", saved, format="two")
    code, out, err = run_cli(capsys, "export", odd, "--out", tmp_path / "d.nc")
    assert code == 2 and "unknown trace format two" in err
    assert sorted(p.name for p in tmp_path.glob("*.nc")) == ["o.nc", "u.nc"]


CF_TABLES = {
    # the entries of the CF standard name table for the names uavtrack writes, with their
    # canonical units; the file uses no area type and no region name
    "names.xml": "<standard_name_table><version_number>the names uavtrack writes"
    "</version_number><last_modified>2026-12-04</last_modified>"
    '<entry id="time"><canonical_units>s</canonical_units></entry>'
    '<entry id="height"><canonical_units>m</canonical_units></entry></standard_name_table>',
    "areas.xml": "<area_type_table><version_number>none used</version_number>"
    "<date>2026-12-04</date></area_type_table>",
    "regions.xml": "<standard_region_list><version_number>none used</version_number>"
    "<date>2026-12-04</date></standard_region_list>",
}


def cf_checker(tmp_path):
    """The CF checker (the cfchecker package) with offline tables; skipped, saying why,
    where it cannot run (it needs the UDUNITS-2 library, Debian's libudunits2-0)."""
    pytest.importorskip("netCDF4")
    try:
        from cfchecker.cfchecks import CFChecker
    except (ImportError, FileNotFoundError) as exc:  # cfunits raises the latter
        pytest.skip(f"the CF checker cannot run here: {exc}")
    for name, text in CF_TABLES.items():
        (tmp_path / name).write_text(f'<?xml version="1.0"?>\n{text}\n')
    return CFChecker(
        cfStandardNamesXML=str(tmp_path / "names.xml"),
        cfAreaTypesXML=str(tmp_path / "areas.xml"),
        cfRegionNamesXML=str(tmp_path / "regions.xml"),
        version="CF-1.8", silent=True,
    )  # fmt: skip


@pytest.mark.integration  # the CF checker finds UDUNITS-2 by running ldconfig
@pytest.mark.parametrize("association", ["known", "jpda"])
def test_the_cf_checker_finds_no_error_in_an_exported_netcdf(tmp_path, capsys, association):
    trace, nc = tmp_path / "t.npz", tmp_path / "t.nc"
    more = [] if association == "known" else [
        "--set", f'tracker.association="{association}"', "--set", "sensor.clutter_rate=2",
    ]  # fmt: skip
    code, _, err = run_cli(
        capsys, "run", "--steps", 20, "--trace", trace, "--set", "faults.failures=[[1, 8]]", *more
    )
    assert code == 0, err
    assert run_cli(capsys, "export", trace, "--out", nc)[0] == 0
    checker = cf_checker(tmp_path)
    results = checker.checker(str(nc))
    capsys.readouterr()
    found = [
        m for part in [results["global"], *results["variables"].values()]
        for kind in ("FATAL", "ERROR") for m in part[kind]
    ]  # fmt: skip
    assert found == []
    warned = {v for v, part in results["variables"].items() if part["WARN"]}
    assert warned <= {"state", "state_"}  # text coordinates: CF prefers auxiliary ones
    with xr.open_dataset(nc) as back:  # and xarray reads the names back as text
        assert back.state.values.tolist() == ["x", "y", "vx", "vy"]
        assert back.attrs["Conventions"] == "CF-1.8"  # what the checker checked it against
