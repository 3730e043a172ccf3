"""The sensor as it really is: detections, clutter and unlabelled scans (`tracks.scan`)."""

import numpy as np
import pytest
from scipy import stats

import uavtrack
from uavtrack import sensing
from uavtrack.config import SensorModel
from uavtrack.tracks import scan


def _poisson_interval(mean: float, n: int, level: float = 0.99) -> tuple[float, float]:
    """The `level` interval of the mean of n Poisson(mean) counts."""
    lo, hi = stats.poisson.interval(level, mean * n)
    return lo / n, hi / n


def test_detections_are_bernoulli_of_the_detection_probability():
    rngs = [np.random.default_rng(s) for s in range(4)]
    observed = np.ones((4, 5, 6), dtype=bool)
    observed[:, :, 5] = False  # out of view: never detected
    hits = sum(scan.detected(rngs, observed, 0.7) for _ in range(200))
    assert not hits[:, :, 5].any()
    n = 4 * 5 * 5 * 200
    lo, hi = stats.binom.interval(0.99, n, 0.7)
    assert lo <= hits[:, :, :5].sum() <= hi


def test_a_perfect_detector_draws_nothing():
    rng = np.random.default_rng(1)
    before = rng.bit_generator.state
    observed = np.ones((1, 2, 3), dtype=bool)
    assert scan.detected([rng], observed, 1.0) is observed
    assert rng.bit_generator.state == before


def test_clutter_is_poisson_and_uniform_over_the_disk():
    sensor = SensorModel(clutter_rate=2.5)
    rng = np.random.default_rng(3)
    uavs = np.array([[0.0, 0.0, 425.0, 15.0, 0.0], [100.0, 50.0, 500.0, 15.0, 1.0]])
    scans = [scan.clutter(rng, uavs, np.array([True, True]), sensor) for _ in range(2000)]
    counts = np.array([np.bincount(owner, minlength=2) for owner, _ in scans])
    lo, hi = _poisson_interval(2.5, counts.size)
    assert lo <= counts.mean() <= hi
    # the ground positions: slant range and bearing back to the ground, against the disk
    owner = np.concatenate([o for o, _ in scans])
    polar = np.concatenate([p for _, p in scans])
    h = uavs[owner, 2]
    r = np.sqrt(np.maximum(polar[:, 0] ** 2 - h**2, 0.0))
    radius = sensing.observation_radius(h, sensor)
    # uniform over the disk: (r / r_O)^2 is uniform on [0, 1]; near the nadir a range
    # std of 0.2 m moves the ground range by metres, so the test looks between 0.25 and 0.8
    u = (r / radius) ** 2
    middle = u[(u > 0.25) & (u < 0.8)]
    assert stats.kstest((middle - 0.25) / 0.55, "uniform").pvalue > 1e-3
    lo, hi = stats.binom.interval(0.99, u.size, 0.55)
    assert lo - 0.02 * u.size <= middle.size <= hi + 0.02 * u.size
    # and the bearing uniform around the UAV
    bearing = np.mod(polar[:, 1], 2 * np.pi) / (2 * np.pi)
    assert stats.kstest(bearing, "uniform").pvalue > 1e-3


def test_a_failed_uav_sees_no_clutter():
    sensor = SensorModel(clutter_rate=5.0)
    rng = np.random.default_rng(0)
    uavs = np.zeros((2, 5))
    uavs[:, 2] = 425.0
    owner, polar = scan.clutter(rng, uavs, np.array([False, True]), sensor)
    assert (owner == 1).all() and polar.shape == (owner.size, 2)


def test_assemble_keeps_every_measurement_and_shuffles_by_row():
    detected = np.zeros((2, 3, 4), dtype=bool)
    detected[0, 0, [1, 3]] = True
    detected[1, 2, 0] = True
    polar = np.array([[1.0, 0.1], [3.0, 0.3], [10.0, 1.0]])
    false = [
        (np.array([0, 1]), np.array([[7.0, 0.7], [8.0, 0.8]])),
        (np.zeros(0, int), np.zeros((0, 2))),
    ]
    rngs = [np.random.default_rng(0), np.random.default_rng(1)]
    raw, valid, origin = scan.assemble(rngs, detected, polar, false, shuffle=True)
    assert raw.shape == (2, 3, 3, 2)
    assert valid.sum(axis=-1).tolist() == [[3, 1, 0], [0, 0, 1]]
    row = {tuple(x) for x in raw[0, 0][valid[0, 0]]}
    assert row == {(1.0, 0.1), (3.0, 0.3), (7.0, 0.7)}
    assert sorted(origin[0, 0][valid[0, 0]].tolist()) == [scan.CLUTTER, 1, 3]
    assert (origin[~valid] == scan.NONE).all()
    # each origin stays with its measurement through the shuffle
    for z, o in zip(raw[0, 0][valid[0, 0]], origin[0, 0][valid[0, 0]], strict=True):
        assert {1: 1.0, 3: 3.0, scan.CLUTTER: 7.0}[int(o)] == z[0]


def test_the_shuffle_moves_the_order():
    detected = np.ones((1, 1, 6), dtype=bool)
    polar = np.arange(12.0).reshape(6, 2)
    nothing = [(np.zeros(0, int), np.zeros((0, 2)))]
    orders = {
        tuple(scan.assemble([np.random.default_rng(s)], detected, polar, nothing, True)[2][0, 0])
        for s in range(20)
    }
    assert len(orders) > 10


@pytest.mark.parametrize("association", ["known", "gnn"])
def test_the_paper_draws_are_the_same_whatever_the_sensor(association):
    """Missed detections and clutter draw from their own stream: the targets' paths and
    the UAVs' start are the paper's at any detection probability and clutter rate."""
    base = uavtrack.Scenario(steps=5)
    other = base.with_overrides(
        {
            "sensor.detection_probability": 0.5,
            "sensor.clutter_rate": 3.0,
            "tracker.association": association,
        }
    )
    a, b = uavtrack.simulate(base, seed=4), uavtrack.simulate(other, seed=4)
    np.testing.assert_array_equal(a.trace.targets, b.trace.targets)
    np.testing.assert_array_equal(a.trace.uavs[0], b.trace.uavs[0])
