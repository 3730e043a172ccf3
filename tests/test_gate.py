"""The measurement gate (`uavtrack.robust.gate`, ``robust.gate``): its test statistic, its
threshold, what it admits, and that the simulator and the agents run it alike."""

import numpy as np
import pytest
from scipy import stats

import uavtrack
from uavtrack.robust import gate


def test_the_threshold_is_the_chi_square_quantile_with_two_degrees_of_freedom():
    for p in (0.9, 0.99, 0.9999):
        assert gate.threshold(p) == pytest.approx(stats.chi2.ppf(p, 2), rel=1e-12)


def test_the_distance_is_the_innovation_mahalanobis_distance(rng):
    mean = rng.normal(size=(50, 4)) * 5
    a = rng.normal(size=(50, 4, 4))
    cov = a @ np.swapaxes(a, -1, -2) + np.eye(4)
    z = rng.normal(size=(50, 2)) * 5
    b = rng.normal(size=(50, 2, 2))
    R = b @ np.swapaxes(b, -1, -2) + 0.5 * np.eye(2)
    nu = z - mean[:, :2]
    S = cov[:, :2, :2] + R
    expected = np.einsum("ki,kij,kj->k", nu, np.linalg.inv(S), nu)
    assert np.allclose(gate.distance(mean, cov, z, R), expected, rtol=1e-10)


def test_honest_innovations_pass_the_gate_at_its_probability(rng):
    # z = H x + v with v ~ N(0, R) and x ~ N(mean, P): the statistic is chi-square(2)
    n = 200_000
    P = np.diag([4.0, 1.0, 0.5, 0.5])
    R = np.array([[2.0, 0.3], [0.3, 0.5]])
    truth = rng.multivariate_normal(np.zeros(4), P, size=n)
    z = truth[:, :2] + rng.multivariate_normal(np.zeros(2), R, size=n)
    d2 = gate.distance(
        np.zeros((n, 4)), np.broadcast_to(P, (n, 4, 4)), z, np.broadcast_to(R, (n, 2, 2))
    )
    for p in (0.9, 0.99):
        passed = (d2 <= gate.threshold(p)).mean()
        assert passed == pytest.approx(p, abs=5 * np.sqrt(p * (1 - p) / n))


def test_what_a_uav_measured_recently_and_the_initial_cue():
    observed = np.array([[[True, False, False]]])
    last = gate.seen(None, observed, 5)  # the cue of every target counts at step 0
    assert last.tolist() == [[[5, 0, 0]]]
    assert gate.recent(None, 3, 8, (1, 1, 3)).all() and not gate.recent(None, 9, 8, (1, 1, 3)).any()
    assert gate.recent(last, 9, 8, (1, 1, 3)).tolist() == [[[True, False, False]]]
    z, R = np.zeros((1, 2)), np.eye(2)[None]
    measured = gate.Measured.of(observed, z, R, gate.recent(last, 5, 8, (1, 1, 3)))
    assert measured.recent.tolist() == [[[False, True, True]]]  # not the one measured now


def test_a_sender_caught_on_one_target_is_believed_on_none_that_round():
    from uavtrack import network

    links = network.links(np.ones((1, 2, 2), dtype=bool), "dense")
    mine = np.zeros((1, 2, 2, 4))
    cov = np.broadcast_to(np.eye(4), (1, 2, 2, 4, 4))
    offered = mine.copy()
    offered[0, 1, 0, :2] = 100.0  # sender 1 lies about target 0 only
    observed = np.array([[[True, False], [False, False]]])  # receiver 0 measures target 0
    z = np.zeros((1, 2, 2, 2))
    R = np.broadcast_to(np.eye(2), (1, 2, 2, 2, 2))
    measured = gate.Measured(observed, z, R, np.zeros((1, 2, 2), dtype=bool))
    mask = gate.admitted(links, (mine, cov), (offered, cov), measured, gate.threshold(0.9999))
    assert mask[0, 0, 1].tolist() == [False, False]  # receiver 0 takes nothing from 1
    assert mask[0, 0, 0].tolist() == [True, True]  # its own stays
    assert mask[0, 1].all()  # receiver 1 measured nothing: everything


def test_the_gate_is_off_by_default_and_on_changes_the_paper_s_run():
    base = uavtrack.Scenario(steps=60)
    assert base.robust.gate is None
    off = uavtrack.simulate(base, "distributed", seed=3)
    on = uavtrack.simulate(base.with_overrides({"robust.gate": 0.9}), "distributed", seed=3)
    assert not np.array_equal(on.trace.mean, off.trace.mean)
