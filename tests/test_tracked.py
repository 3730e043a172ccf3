"""Runs with unknown association (``tracker.association`` gnn, jpda): the cycle with tracks,
against the paper's run, the sensor's statistics and the forms' invariants."""

import numpy as np
import pytest
from scipy import stats

import uavtrack
from uavtrack import estimation, sensing
from uavtrack.io import trace as trace_io
from uavtrack.tracks import association
from uavtrack.tracks import scan as scans

BASE = uavtrack.Scenario(steps=60)


def _tracked(association="jpda", **more):
    return BASE.with_overrides({"tracker.association": association, **more})


def _first_ambiguous(known, tracked, scenario) -> int:
    """The first step at which a measurement of the tracked run falls outside the gate of
    its target's estimate in the known run (predicted from the step before), or inside
    the gate of another target's."""
    A = estimation.transition(scenario.dt)
    Q = estimation.process_noise(scenario.dt, *scenario.acceleration_std())
    limit = association.threshold(scenario.tracker.gate_probability)
    for k in range(1, known.mean.shape[0]):
        mean, cov = estimation.predict(known.mean[k - 1], known.cov[k - 1], A, Q)
        i, z = np.nonzero(tracked.scan_valid[k])
        j = tracked.scan_origin[k][i, z]
        zc, R = sensing.convert(known.uavs[k][i], tracked.scan_polar[k][i, z], scenario.sensor)
        S = cov[i, :, :2, :2] + R[:, None]  # (n, Nt, 2, 2): against every target
        nu = zc[:, None] - mean[i, :, :2]
        inside = np.einsum("nti,ntij,ntj->nt", nu, np.linalg.inv(S), nu) <= limit
        own = np.zeros(inside.shape, dtype=bool)
        own[np.arange(j.size), j] = True
        if (inside != own).any():
            return k
    return known.mean.shape[0]


@pytest.mark.parametrize("association", ["gnn", "jpda"])
def test_an_ideal_sensor_gives_the_paper_filters_until_a_gate_is_ambiguous(association):
    """P_D 1, no clutter: until a measurement falls outside its track's gate or inside
    another's, the tracks are the paper's filters under the targets' labels, and the
    UAVs fly the paper's run."""
    compared = 0
    for seed in (0, 1, 2):
        known = uavtrack.simulate(BASE, seed=seed).trace
        tracked = uavtrack.simulate(_tracked(association), seed=seed).trace
        n = _first_ambiguous(known, tracked, BASE)
        compared += n
        np.testing.assert_allclose(tracked.uavs[: n + 1], known.uavs[: n + 1], atol=1e-6)
        np.testing.assert_array_equal(tracked.assignment[:n], known.assignment[:n])
        assert (tracked.label[:n, :, :4] == np.arange(4)).all()
        assert (tracked.status[:n, :, 4:] == 0).all()  # nothing else was born
        np.testing.assert_allclose(tracked.mean[:n, :, :4], known.mean[:n], atol=1e-6)
    assert compared >= 40  # the comparison covers tens of steps


def test_the_order_of_a_scan_changes_nothing(monkeypatch):
    """The same measurements in another order: the same tracks, labels and flight."""
    scenario = _tracked(**{"sensor.detection_probability": 0.9, "sensor.clutter_rate": 2.0})
    first = uavtrack.simulate(scenario, seed=3).trace
    draws = scans.Draws.of

    def reordered(streams):
        d = draws(streams)
        return scans.Draws(d.detect, d.clutter, [np.random.default_rng(99) for _ in d.order])

    monkeypatch.setattr(scans.Draws, "of", staticmethod(reordered))
    second = uavtrack.simulate(scenario, seed=3).trace
    assert not np.array_equal(first.scan_origin, second.scan_origin)  # the order moved
    np.testing.assert_array_equal(first.label, second.label)
    np.testing.assert_array_equal(first.status, second.status)
    np.testing.assert_array_equal(first.assignment, second.assignment)
    np.testing.assert_allclose(second.mean, first.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(second.uavs, first.uavs, rtol=1e-9, atol=1e-9)


def test_a_batch_gives_what_each_trial_gives_alone():
    scenario = _tracked(**{"sensor.detection_probability": 0.9, "sensor.clutter_rate": 2.0})
    seeds = [uavtrack.trial_seed(0, t) for t in range(3)]
    together = uavtrack.run(scenario, "distributed", seeds).metrics
    for t, seed in enumerate(seeds):
        alone = uavtrack.run(scenario, "distributed", [seed]).metrics
        for name in ("observation_rate", "gospa", "unassigned_tracks", "switches", "messages"):
            assert together[name][t] == pytest.approx(alone[name][0], rel=1e-9, nan_ok=True)


def test_the_scans_hold_the_sensor_statistics():
    """From the traces: false measurements per living UAV and scan within the Poisson
    99 % interval of the clutter rate; detected in-view pairs within the binomial 99 %
    interval of P_D."""
    pd, rate = 0.8, 1.5
    scenario = _tracked(**{"sensor.detection_probability": pd, "sensor.clutter_rate": rate})
    scenario = scenario.with_overrides({"steps": 150})
    false = detected = in_view = scans_seen = 0
    for seed in range(4):
        t = uavtrack.simulate(scenario, seed=seed).trace
        origin, valid = t.scan_origin, t.scan_valid
        false += int((valid & (origin == scans.CLUTTER)).sum())
        scans_seen += int(t.alive.sum())
        detected += int((valid & (origin >= 0)).sum())
        in_view += int(t.observed.sum())
        # a detection is of a target in view of that UAV
        k, i, z = np.nonzero(valid & (origin >= 0))
        assert t.observed[k, i, origin[k, i, z]].all()
    lo, hi = stats.poisson.interval(0.99, rate * scans_seen)
    assert lo <= false <= hi
    lo, hi = stats.binom.interval(0.99, in_view, pd)
    assert lo <= detected <= hi


@pytest.mark.parametrize("method", ["distributed", "centralized", "greedy"])
@pytest.mark.parametrize(
    "extra",
    [
        {},
        {"tracker.model": "imm"},
        {"fusion.rule": "covariance_intersection"},
        {"faults.loss": 0.2},
    ],
)
def test_every_method_runs_with_tracks(method, extra):
    scenario = _tracked(
        **{"sensor.detection_probability": 0.9, "sensor.clutter_rate": 2.0, "steps": 40}, **extra
    )
    r = uavtrack.simulate(scenario, method, seed=5)
    t = r.trace
    assert 0.0 <= r.observation_rate <= 1.0
    for name in ("gospa", "unassigned_tracks", "siap_completeness", "nees_median"):
        assert np.isfinite(getattr(r, name)), name
    assert np.isnan(r.rmse)  # a track set has no estimate per target index
    confirmed = t.status == 2
    assert np.isfinite(t.mean[confirmed]).all() and np.isfinite(t.cov[confirmed]).all()
    for k in range(t.label.shape[0]):  # labels unique within a UAV
        for i in range(t.label.shape[1]):
            held = t.label[k, i][t.label[k, i] >= 0]
            assert held.size == np.unique(held).size
    if method == "centralized" and "faults.loss" not in extra:  # every UAV holds the node's
        assert (t.label == t.label[:, :1]).all()


def test_known_association_misses_the_same_detections():
    """P_D below 1 with known association: the filter updates only the detected pairs,
    whose draws are those of a tracked run of the same trial."""
    scenario = BASE.with_overrides({"sensor.detection_probability": 0.5})
    ideal = uavtrack.simulate(BASE, seed=2)
    missing = uavtrack.simulate(scenario, seed=2)
    assert missing.trace.observed[0].sum() == ideal.trace.observed[0].sum()  # the same truth
    assert not np.allclose(missing.trace.mean, ideal.trace.mean)
    # clutter does not reach known association
    cluttered = uavtrack.simulate(scenario.with_overrides({"sensor.clutter_rate": 5.0}), seed=2)
    np.testing.assert_array_equal(cluttered.trace.mean, missing.trace.mean)


def test_a_tracked_trace_is_written_and_read_back(tmp_path):
    r = uavtrack.simulate(_tracked(**{"sensor.clutter_rate": 1.0, "steps": 20}), seed=1)
    path = tmp_path / "t.npz"
    trace_io.write(path, r)
    back = trace_io.read(path).trace
    for name in ("label", "status", "scan_z", "scan_valid", "scan_origin", "mean", "bids"):
        np.testing.assert_array_equal(getattr(back, name), getattr(r.trace, name))
    with np.load(path) as data:  # read by numpy alone: the slots' shapes
        K = r.scenario.track_slots
        assert data["mean"].shape == (20, r.scenario.n_uavs, K, 4)
        assert data["label"].shape == (20, r.scenario.n_uavs, K)


@pytest.mark.integration
def test_importing_the_cycle_loads_no_scipy():
    """The trackers import scipy where they use it: a run of known association, and the
    command line before it refuses bad input, start without its 0.4 s."""
    import subprocess
    import sys

    code = (
        "import sys, uavtrack.simulation; "
        "print(sorted(m for m in sys.modules if m.startswith('scipy')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == "[]"
