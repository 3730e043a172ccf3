"""The outside formats of a run of tracks (tracker.association gnn or jpda), each read
back by an independent library: the tables by pandas, pyarrow and xarray, the tracks by
Stone Soup, the bag by rosbags, the recording by Rerun's reader."""

import numpy as np
import pytest

import uavtrack
from uavtrack import cli

pd = pytest.importorskip("pandas")
xr = pytest.importorskip("xarray")
pa_parquet = pytest.importorskip("pyarrow.parquet")
pytest.importorskip("h5netcdf")

TRACKED = uavtrack.Scenario(steps=30).with_overrides(
    {
        "tracker.association": "jpda",
        "sensor.detection_probability": 0.9,
        "sensor.clutter_rate": 2.0,
        "faults.failures": [[1, 12]],
    }
)


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A tracked run written by the command line, and the same run in Python."""
    path = tmp_path_factory.mktemp("tracked") / "run.npz"
    code = cli.main(
        ["run", "--seed", "1", "--trace", str(path), "--set", "tracker.association=jpda",
         "--set", "sensor.detection_probability=0.9", "--set", "sensor.clutter_rate=2",
         "--set", "steps=30", "--set", "faults.failures=[[1, 12]]"]
    )  # fmt: skip
    assert code == 0
    return path, uavtrack.simulate(TRACKED, seed=1, trace=True)


def test_the_tables_of_a_tracked_run_hold_its_tracks_and_measurements(tmp_path, saved, capsys):
    path, result = saved
    trace = result.trace
    out = tmp_path / "tables"
    assert cli.main(["export", str(path), "--out", str(out)]) == 0
    assert "tracks" in capsys.readouterr().out
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(
        f"{n}.parquet" for n in ("steps", "uavs", "targets", "tracks", "measurements")
    )  # no pairs: a slot is no target
    tracks = pd.read_parquet(out / "tracks.parquet")
    held = (trace.status > 0) & trace.alive[..., None]
    assert len(tracks) == int(held.sum()) > 0
    assert not (tracks["uav"].to_numpy() == 1)[tracks["step"].to_numpy() >= 12].any()
    k, i, s = (tracks[c].to_numpy() for c in ("step", "uav", "slot"))
    np.testing.assert_array_equal(tracks["label"].to_numpy(), trace.label[k, i, s])
    assert (tracks["label"] >= 0).all()
    code = {"tentative": 1, "confirmed": 2}
    np.testing.assert_array_equal(tracks["status"].map(code).to_numpy(), trace.status[k, i, s])
    for c, name in enumerate(("x", "y", "vx", "vy")):
        np.testing.assert_allclose(tracks[f"est_{name}"], trace.mean[k, i, s, c], rtol=1e-12)
    np.testing.assert_allclose(tracks["P_x_y"], trace.cov[k, i, s, 0, 1], rtol=1e-12)
    np.testing.assert_allclose(tracks["P_vy_vy"], trace.cov[k, i, s, 3, 3], rtol=1e-12)
    assert tracks["bid"][tracks["status"] == "tentative"].isna().all()
    schema = pa_parquet.read_schema(out / "tracks.parquet")
    assert schema.field("P_x_vy").metadata == {b"unit": b"m^2/s"}
    # the confirmed tracks per step, counted from the table, are the trace's
    per_step = tracks[tracks["status"] == "confirmed"].groupby("step").size()
    confirmed = ((trace.status == 2) & trace.alive[..., None]).sum(axis=(1, 2))
    np.testing.assert_array_equal(per_step.reindex(range(30), fill_value=0), confirmed)

    z = pd.read_parquet(out / "measurements.parquet")
    assert len(z) == int(trace.scan_valid.sum()) > 0
    assert z["clutter"].sum() == int((trace.scan_origin == -1).sum()) > 0
    assert (z["origin"] >= -1).all() and (z["clutter"] == (z["origin"] == -1)).all()
    assert schema_unit(out / "measurements.parquet", "bearing") == b"rad"
    # each measurement's ground position from its range and bearing and the UAV's state,
    # both read from the tables (eq. 5: z = p + sqrt(d^2 - h^2) (cos, sin))
    uavs = pd.read_parquet(out / "uavs.parquet").set_index(["step", "uav"])
    at = uavs.loc[list(zip(z["step"], z["uav"], strict=True))]
    ground = np.sqrt(np.maximum(z["range"].to_numpy() ** 2 - at["altitude"].to_numpy() ** 2, 0))
    np.testing.assert_allclose(
        z["x"], at["x"].to_numpy() + ground * np.cos(z["bearing"]), rtol=1e-9, atol=1e-9
    )
    np.testing.assert_allclose(
        z["y"], at["y"].to_numpy() + ground * np.sin(z["bearing"]), rtol=1e-9, atol=1e-9
    )
    # a true detection lies near its target: within 5 sigma-ish of the sensor, far less
    # than the field; clutter is anywhere in the disk
    targets = pd.read_parquet(out / "targets.parquet").set_index(["step", "target"])
    assert "best_x" not in targets.columns
    true = z[~z["clutter"]]
    where = targets.loc[list(zip(true["step"], true["origin"], strict=True))]
    miss = np.hypot(true["x"].to_numpy() - where["x"], true["y"].to_numpy() - where["y"])
    assert np.median(miss) < 10.0


def schema_unit(path, column):
    return pa_parquet.read_schema(path).field(column).metadata[b"unit"]


def test_the_dataset_of_a_tracked_run_has_slots_and_scans(tmp_path, saved):
    path, result = saved
    trace = result.trace
    nc = tmp_path / "run.nc"
    uavtrack.io.to_xarray(path).to_netcdf(nc, engine="h5netcdf")
    K, Z = trace.label.shape[2], trace.scan_valid.shape[2]
    with xr.open_dataset(nc, engine="h5netcdf") as ds:
        assert ds.sizes["slot"] == K and ds.sizes["measurement"] == Z
        assert ds["estimate"].dims == ("step", "uav", "slot", "state")
        assert ds["observed"].dims == ("step", "uav", "target")
        np.testing.assert_array_equal(ds["label"].values, trace.label)
        np.testing.assert_array_equal(ds["status"].values, trace.status)
        np.testing.assert_array_equal(ds["scan_origin"].values, trace.scan_origin)
        assert ds["scan_range"].attrs["units"] == "m"
        e = ds["estimate"].sel(state="vx", uav=2, slot=3).values
        np.testing.assert_allclose(e, trace.mean[:, 2, 3, 2], rtol=1e-12)
        assert int(ds["scan_valid"].sum()) == int(trace.scan_valid.sum())
