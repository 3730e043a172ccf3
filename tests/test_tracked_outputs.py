"""The outside formats of a run of tracks (tracker.association gnn or jpda), each read
back by an independent library: the tables by pandas, pyarrow and xarray, the tracks by
Stone Soup, the bag by rosbags, the recording by Rerun's reader."""

import datetime

import numpy as np
import pytest

import uavtrack
import uavtrack.io
from uavtrack import cli
from uavtrack.errors import UsageError

pd = pytest.importorskip("pandas")
xr = pytest.importorskip("xarray")
pa_parquet = pytest.importorskip("pyarrow.parquet")
pytest.importorskip("h5netcdf")

SEED = 2
"""A seed whose run has every kind of track: false ones (SIAP spuriousness > 0), births."""

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
        ["run", "--seed", str(SEED), "--trace", str(path), "--set", "tracker.association=jpda",
         "--set", "sensor.detection_probability=0.9", "--set", "sensor.clutter_rate=2",
         "--set", "steps=30", "--set", "faults.failures=[[1, 12]]"]
    )  # fmt: skip
    assert code == 0
    return path, uavtrack.simulate(TRACKED, seed=SEED, trace=True)


def test_the_tables_of_a_tracked_run_hold_its_tracks_and_measurements(tmp_path, saved, capsys):
    path, result = saved
    trace = result.trace
    out = tmp_path / "tables"
    assert cli.main(["export", str(path), "--out", str(out)]) == 0
    assert "tracks" in capsys.readouterr().out
    names = sorted(p.name for p in out.iterdir())
    tables = ("steps", "uavs", "targets", "tracks", "measurements", "briefing")
    assert names == sorted([f"{n}.parquet" for n in tables] + ["scenario.toml"])  # no pairs
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


def test_stone_soup_scores_the_tracks_by_label_as_uavtrack_does(saved):
    """Each UAV's confirmed tracks by label, scored by Stone Soup's GOSPA (alpha 2, no
    switching penalty, on the positions) per step, averaged over the steps the UAV
    lives and then over the UAVs, are uavtrack's gospa of the run."""
    pytest.importorskip("stonesoup")
    from stonesoup.measures import Euclidean
    from stonesoup.metricgenerator.ospametric import GOSPAMetric
    from stonesoup.types.detection import Clutter, TrueDetection

    from uavtrack.io.stonesoup import POSITION

    path, result = saved
    trace = result.trace
    e = TRACKED.evaluation
    truths, per_uav = uavtrack.io.to_stonesoup(path, tracks="uavs")
    confirmed = (trace.status == 2) & trace.alive[..., None]
    expected = {
        (int(i), int(trace.label[k, i, s])) for k, i, s in zip(*np.nonzero(confirmed), strict=True)
    }
    assert {(t.metadata["uav"], t.metadata["label"]) for t in per_uav} == expected
    for track in per_uav:  # one state per step the UAV holds the label confirmed
        i, label = track.metadata["uav"], track.metadata["label"]
        k, s = np.nonzero(confirmed[:, i] & (trace.label[:, i] == label))
        assert len(track) == len(k) and track.id == f"uav-{i}-label-{label}"
        for state, k_, s_ in zip(track.states, k, s, strict=True):
            x, y, vx, vy = trace.mean[k_, i, s_]
            np.testing.assert_allclose(state.state_vector.ravel(), [x, vx, y, vy], rtol=1e-12)
            assert (state.timestamp - uavtrack.io.stonesoup.EPOCH).total_seconds() == 0.5 * k_
    gospa = GOSPAMetric(c=e.ospa_cutoff, p=e.ospa_order, measure=Euclidean(mapping=POSITION))
    times = sorted({state.timestamp for path_ in truths for state in path_})
    per_row = []
    for i in range(TRACKED.n_uavs):
        mine = [t for t in per_uav if t.metadata["uav"] == i]
        stamps = [{s.timestamp: s for s in t} for t in mine]
        values = [
            gospa.compute_gospa_metric([s[t] for s in stamps if t in s], [p[t] for p in truths])[
                0
            ].value["distance"]
            for k, t in enumerate(times)
            if trace.alive[k, i]
        ]
        per_row.append(np.mean(values))
    assert len(per_row) == 5 and trace.alive[:, 1].sum() == 12
    assert np.mean(per_row) == pytest.approx(result.gospa, rel=1e-9)

    # the team's tracks: one per label, each step the most confident holder's state
    _, team = uavtrack.io.to_stonesoup(result, tracks="best")
    assert {t.metadata["label"] for t in team} == {label for _, label in expected}
    track = max(team, key=len)
    label = track.metadata["label"]
    spread = np.where(
        confirmed & (trace.label == label), np.trace(trace.cov, axis1=-2, axis2=-1), np.inf
    )
    held = np.flatnonzero(np.isfinite(spread).any(axis=(1, 2)))
    assert len(track) == len(held)
    for state, k in zip(track.states, held, strict=True):
        i, s = np.unravel_index(np.argmin(spread[k]), spread[k].shape)
        np.testing.assert_allclose(state.covar[0, 0], trace.cov[k, i, s, 0, 0], rtol=1e-12)
    # Stone Soup's GOSPA of the team's tracks per step, averaged: uavtrack's gospa_team
    stamps = [{s.timestamp: s for s in t} for t in team]
    values = [
        gospa.compute_gospa_metric([s[t] for s in stamps if t in s], [p[t] for p in truths])[
            0
        ].value["distance"]
        for t in times
    ]
    assert np.mean(values) == pytest.approx(result.gospa_team, rel=1e-9)
    assert result.gospa_team < result.gospa  # the team's picture beats a UAV's own

    # the scans as a detector yields them: true detections of the truths, and clutter
    scans = uavtrack.io.to_detections(path, truths=truths)
    assert len(scans) == 30
    found = [d for _, detections in scans for d in detections]
    assert len(found) == int(trace.scan_valid.sum())
    clutter = [d for d in found if isinstance(d, Clutter)]
    assert len(clutter) == int((trace.scan_origin == -1).sum()) > 0
    true = [d for d in found if isinstance(d, TrueDetection)]
    assert len(true) + len(clutter) == len(found)
    ids = {p.id: p for p in truths}
    for d in true:
        assert d.groundtruth_path is ids[f"target-{d.metadata['origin']}"]
        target = d.groundtruth_path[d.timestamp].state_vector.ravel()
        assert np.hypot(*(d.state_vector.ravel() - target[[0, 2]])) < 100.0
    with pytest.raises(UsageError, match="scans of a run of tracks"):
        uavtrack.io.to_detections(uavtrack.simulate(uavtrack.Scenario(steps=3), trace=True))


def test_the_bag_of_a_tracked_run_holds_tracks_by_label_and_the_scans(tmp_path, saved, capsys):
    pytest.importorskip("rosbags")
    from rosbags.highlevel import AnyReader

    path, result = saved
    trace = result.trace
    bag = tmp_path / "bag"
    code = cli.main(
        ["run", "--seed", str(SEED), "--bag", str(bag), "--set", "tracker.association=jpda",
         "--set", "sensor.detection_probability=0.9", "--set", "sensor.clutter_rate=2",
         "--set", "steps=30", "--set", "faults.failures=[[1, 12]]"]
    )  # fmt: skip
    assert code == 0, capsys.readouterr().err
    with AnyReader([bag]) as reader:
        topics = {c.topic for c in reader.connections}
        assert not any(t.startswith("/team/target_") for t in topics)
        assert "/team/estimates" not in topics

        def read(topic):
            chosen = [c for c in reader.connections if c.topic == topic]
            return [
                (t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages(chosen)
            ]

        for i in (1, 3):
            tracks = read(f"/uav_{i}/tracks")
            failed = int(not trace.alive[-1, i])
            assert len(tracks) == int(trace.alive[:, i].sum()) + failed  # UAV 1 fails at 12
            if failed:  # at its failure, a DELETEALL alone: its tracks leave the view
                t, msg = tracks.pop()
                assert t == 12 * 500_000_000 and [x.action for x in msg.markers] == [3]
                t, msg = read(f"/uav_{i}/scan")[-1]
                assert t == 12 * 500_000_000 and [x.action for x in msg.markers] == [3]
            for t, msg in tracks:
                k = t // 500_000_000
                assert msg.markers[0].action == 3  # DELETEALL: the last step's tracks go
                lifetimes = {(x.lifetime.sec, x.lifetime.nanosec) for x in msg.markers[1:]}
                assert lifetimes <= {(1, 0)}  # two steps of 0.5 s: they go by themselves
                ellipses = [x for x in msg.markers if x.ns in ("tentative", "confirmed")]
                held = np.flatnonzero(trace.status[k, i] > 0)
                assert [x.id for x in ellipses] == trace.label[k, i, held].tolist()
                assert [x.ns for x in ellipses] == [
                    ("", "tentative", "confirmed")[s] for s in trace.status[k, i, held]
                ]
                for x, s in zip(ellipses, held, strict=True):
                    mean, P = trace.mean[k, i, s], trace.cov[k, i, s, :2, :2]
                    assert (x.pose.position.x, x.pose.position.y) == tuple(mean[:2])
                    axes = np.sort(np.linalg.eigvalsh(P))[::-1]  # 2-sigma diameters
                    np.testing.assert_allclose([x.scale.x, x.scale.y], 4 * np.sqrt(axes), rtol=1e-9)
                texts = [x for x in msg.markers if x.ns == "label"]
                assert [x.text for x in texts] == [f"L{x.id}" for x in ellipses]
            scans = read(f"/uav_{i}/scan")
            assert len(scans) == len(tracks) + failed
            scans = scans[: len(tracks)]
            for t, msg in scans:
                k = t // 500_000_000
                spots = {x.ns: [(p.x, p.y) for p in x.points] for x in msg.markers}
                valid, origin = trace.scan_valid[k, i], trace.scan_origin[k, i]
                for ns, chosen in (("detections", origin >= 0), ("clutter", origin == -1)):
                    expect = [tuple(z) for z in trace.scan_z[k, i][valid & chosen]]
                    assert spots[ns] == expect
        # the assignment lines end at each UAV's own estimate of the track it follows
        t, msg = read("/team/assignments")[20]
        ends = [(p.x, p.y) for p in msg.markers[0].points][1::2]
        followed = [
            tuple(
                trace.mean[
                    20, i, np.flatnonzero(trace.label[20, i] == trace.assignment[20, i])[0], :2
                ]
            )
            for i in np.flatnonzero(trace.alive[20] & (trace.assignment[20] >= 0))
        ]
        assert ends == followed and len(ends) > 0


def test_a_recording_of_a_tracked_run_draws_tracks_by_label_and_the_scans(tmp_path, saved):
    """Through the command line: each track at its estimate with its team label as class
    id and text, tentative ones apart; true detections and clutter apart."""
    pytest.importorskip("rerun")
    from uavtrack.viz import rerun

    from .test_viewer import column, contents

    _, result = saved
    trace = result.trace
    path = tmp_path / "run.rrd"
    code = cli.main(
        ["run", "--seed", str(SEED), "--rerun", str(path), "--set", "tracker.association=jpda",
         "--set", "sensor.detection_probability=0.9", "--set", "sensor.clutter_rate=2",
         "--set", "steps=30", "--set", "faults.failures=[[1, 12]]"]
    )  # fmt: skip
    assert code == 0
    dynamic, static = contents(path)
    assert set(dynamic) | (static - {"__properties"}) == set(rerun.ENTITIES + rerun.TRACK_ENTITIES)
    T, Nu, K = trace.label.shape
    held = ((trace.status > 0) & trace.alive[..., None]).reshape(T, Nu * K)
    where = column(path, "world/tracks", "positions")
    ids = column(path, "world/tracks", "class_ids")
    labels = column(path, "world/tracks", "labels")
    for k in (0, 11, 12, 29):
        drawn = np.isfinite(np.array(where[k], dtype=float)).all(axis=1)
        np.testing.assert_array_equal(drawn, held[k])  # UAV 1's go when it fails at 12
        n = np.flatnonzero(held[k])
        i, s = np.divmod(n, K)
        np.testing.assert_allclose(
            np.array(where[k], dtype=float)[n, :2], trace.mean[k, i, s, :2], rtol=1e-6
        )  # float32
        assert [ids[k][m] for m in n] == trace.label[k, i, s].tolist()
        names = [labels[k][m] for m in n]
        tentative = trace.status[k, i, s] == 1
        assert names == [
            f"L{label}" + (" (tentative)" if t else "")
            for label, t in zip(trace.label[k, i, s], tentative, strict=True)
        ]
    assert any(" (tentative)" in x for k in where for x in labels[k])
    for entity, chosen in (
        ("world/scan/detections", trace.scan_origin >= 0),
        ("world/scan/clutter", trace.scan_origin == -1),
    ):
        spots = column(path, entity, "positions")
        seen = (chosen & trace.scan_valid & trace.alive[..., None]).reshape(T, -1)
        counts = [int(np.isfinite(np.array(spots[k], float)).all(axis=1).sum()) for k in range(T)]
        assert counts == seen.sum(axis=1).tolist()
    assert sum(counts) > 0
    # a UAV's estimate is its own of the track it follows
    centers = column(path, "world/estimates/ellipses", "centers")
    k = 20
    for i in np.flatnonzero(trace.alive[k] & (trace.assignment[k] >= 0)):
        s = np.flatnonzero(trace.label[k, i] == trace.assignment[k, i])[0]
        np.testing.assert_allclose(centers[k][i][:2], trace.mean[k, i, s, :2], rtol=1e-6)


class PerStep:
    """A track-to-truth associator for Stone Soup's metrics: at each step, each track to
    its nearest truth closer than `threshold` (`TrackToTruth`'s rule at one step, with
    nothing carried between steps). Stone Soup's own `TrackToTruth` at
    consec_pairs_confirm = consec_misses_end = 1 makes the same associations but cannot
    hold one of a single step (its TimeRange asks start < end, a ValueError), so a run of
    steps in a row with one truth is a TimeRangeAssociation from its first step to its
    last plus 1 us: it holds those steps and no other (the next is dT later; a track
    absent at a step, a label deleted and adopted back, ends a run)."""

    def __init__(self, threshold: float) -> None:
        self.threshold = threshold

    def associate_tracks(self, tracks, truths):
        from stonesoup.types.association import AssociationSet, TimeRangeAssociation
        from stonesoup.types.time import TimeRange

        from uavtrack.io.stonesoup import POSITION

        truths = list(truths)
        at = [{s.timestamp: s.state_vector.ravel()[list(POSITION)] for s in t} for t in truths]
        out = set()
        for track in tracks:
            runs: list[list] = []  # [truth, first, last] of each run of steps
            for state in sorted(track, key=lambda s: s.timestamp):
                where = state.state_vector.ravel()[list(POSITION)]
                best, nearest = self.threshold, None
                for truth, states in zip(truths, at, strict=True):
                    there = states.get(state.timestamp)
                    if there is not None and float(np.hypot(*(where - there))) < best:
                        best, nearest = float(np.hypot(*(where - there))), truth
                step = datetime.timedelta(seconds=TRACKED.dt)
                if nearest is None:
                    runs.append([None, None, None])
                elif runs and runs[-1][0] is nearest and state.timestamp - runs[-1][2] == step:
                    runs[-1][2] = state.timestamp  # a run is steps in a row: a gap ends it
                else:
                    runs.append([nearest, state.timestamp, state.timestamp])
            for truth, first, last in runs:
                if truth is not None:
                    end = last + datetime.timedelta(microseconds=1)
                    out.add(TimeRangeAssociation((track, truth), TimeRange(first, end)))
        return AssociationSet(out)


def test_stone_soups_siap_on_the_exported_tracks_is_uavtracks(saved):
    """Stone Soup's SIAPMetrics on each UAV's exported tracks and the truth of the steps
    it lived, with the per-step association (`PerStep`), gives each UAV's completeness,
    ambiguity and spuriousness; their means over the UAVs are uavtrack's siap_* of the
    run to 1e-12."""
    pytest.importorskip("stonesoup")
    from stonesoup.measures import Euclidean
    from stonesoup.metricgenerator.manager import MultiManager
    from stonesoup.metricgenerator.tracktotruthmetrics import SIAPMetrics
    from stonesoup.types.groundtruth import GroundTruthPath

    from uavtrack.io.stonesoup import EPOCH, POSITION

    path, result = saved
    trace = result.trace
    truths, per_uav = uavtrack.io.to_stonesoup(path, tracks="uavs")
    names = ("Completeness", "Ambiguity", "Spuriousness")
    theirs = {name: [] for name in names}
    for i in range(TRACKED.n_uavs):
        lived = {EPOCH + datetime.timedelta(seconds=0.5 * int(k)) for k in np.flatnonzero(
            trace.alive[:, i])}  # fmt: skip
        seen = {GroundTruthPath([s for s in t if s.timestamp in lived], id=t.id) for t in truths}
        mine = {t for t in per_uav if t.metadata["uav"] == i}
        siap = SIAPMetrics(
            position_measure=Euclidean(POSITION), velocity_measure=Euclidean(POSITION)
        )
        manager = MultiManager([siap], PerStep(TRACKED.evaluation.ospa_cutoff))
        manager.add_data({"groundtruth_paths": seen, "tracks": mine})
        values = {m.title: m.value for m in manager.generate_metrics()["siap_generator"].values()}
        for name in names:
            theirs[name].append(values[f"SIAP {name}"])
    ours = result.summary()
    assert 0 < ours["siap_completeness"] < 1 and ours["siap_spuriousness"] > 0
    for name in names:
        assert ours[f"siap_{name.lower()}"] == pytest.approx(np.mean(theirs[name]), rel=1e-12)
