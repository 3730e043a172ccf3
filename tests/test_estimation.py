import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from uavtrack import SensorModel, estimation, sensing, world


def test_transition_and_process_noise_match_eqs_14_15_at_unit_step():
    A = estimation.transition(1.0)
    assert np.array_equal(A, [[1, 0, 1, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1]])
    s1, s2 = 0.16, 0.3
    Q = estimation.process_noise(1.0, s1, s2)
    # eq. (15) as printed, in the order (x, vx, y, vy), permuted to (x, y, vx, vy)
    printed = np.array(
        [
            [s1**2 / 4, s1**2 / 2, 0, 0],
            [s1**2 / 2, s1**2, 0, 0],
            [0, 0, s2**2 / 4, s2**2 / 2],
            [0, 0, s2**2 / 2, s2**2],
        ]
    )
    order = [0, 2, 1, 3]
    assert np.allclose(Q, printed[np.ix_(order, order)])


@pytest.mark.parametrize("dt", [0.25, 0.5, 2.0])
def test_printed_noise_form_is_the_printed_matrix_at_any_step(dt):
    from uavtrack import Scenario

    s1, s2 = 0.16, 0.3
    scenario = Scenario(dt=dt, target={"sigma_1": s1, "sigma_2": s2, "noise_form": "printed"})
    Q = estimation.process_noise(dt, *scenario.acceleration_std())
    for pos, vel, s in ((0, 2, s1), (1, 3, s2)):  # sigma^2 [[dT^2/4, dT/2], [dT/2, 1]]
        block = Q[np.ix_([pos, vel], [pos, vel])]
        assert np.allclose(block, s**2 * np.array([[dt**2 / 4, dt / 2], [dt / 2, 1.0]]))
    # the acceleration reading: a quarter of the variance at dT = 0.5 s, dT^2 in general
    plain = Scenario(dt=dt, target={"sigma_1": s1, "sigma_2": s2})
    assert np.allclose(estimation.process_noise(dt, *plain.acceleration_std()), Q * dt**2)


def test_noise_forms_agree_at_unit_step_and_move_the_truth_otherwise():
    from uavtrack import Scenario, simulate

    one = [
        simulate(Scenario(dt=1.0, steps=40, target={"noise_form": form}), seed=3)
        for form in ("acceleration", "printed")
    ]
    assert np.array_equal(one[0].trace.targets, one[1].trace.targets)
    assert one[0].observation_rate == one[1].observation_rate
    half = [
        simulate(Scenario(dt=0.5, steps=40, target={"noise_form": form}), seed=3).trace.targets
        for form in ("acceleration", "printed")
    ]
    # the same draws scaled by 1/dT: the velocity changes double (before any wall)
    dv = [np.diff(t[:5, :, 2:], axis=0) for t in half]
    assert np.all(np.abs(dv[0]) > 0)
    assert np.allclose(np.abs(dv[1]), 2 * np.abs(dv[0]))


def test_update_hand_computed():
    # prior P = diag(4, 4, 1, 1) predicted with dT = 1 and Q = 0:
    # per axis P(k|k-1) = [[5, 1], [1, 1]]; R = I -> S = 6, K = [5/6, 1/6]
    A, Q = estimation.transition(1.0), np.zeros((4, 4))
    mean, cov = estimation.predict(
        np.array([1.0, 2.0, 1.0, -1.0]), np.diag([4.0, 4.0, 1.0, 1.0]), A, Q
    )
    assert np.allclose(mean, [2.0, 1.0, 1.0, -1.0])
    z = np.array([3.2, 0.4])
    post_mean, post_cov = estimation.update(mean, cov, z, np.eye(2))
    # innovation (1.2, -0.6)
    assert np.allclose(
        post_mean, [2 + 5 / 6 * 1.2, 1 - 5 / 6 * 0.6, 1 + 1 / 6 * 1.2, -1 - 1 / 6 * 0.6]
    )
    # P+ = P - K S K^T: [[5 - 25/6, 1 - 5/6], [., 1 - 1/6]]
    axis = np.array([[5 / 6, 1 / 6], [1 / 6, 5 / 6]])
    assert np.allclose(post_cov[np.ix_([0, 2], [0, 2])], axis)
    assert np.allclose(post_cov[np.ix_([1, 3], [1, 3])], axis)
    assert np.allclose(post_cov[np.ix_([0, 2], [1, 3])], 0.0)


def spd(draw, n, scale):
    m = np.array(draw(st.lists(st.floats(-1, 1), min_size=n * n, max_size=n * n))).reshape(n, n)
    return scale * (m @ m.T + 0.1 * np.eye(n))


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_update_equals_information_form(data):
    P = spd(data.draw, 4, data.draw(st.floats(0.1, 100)))
    R = spd(data.draw, 2, data.draw(st.floats(0.01, 100)))
    mean = np.array(data.draw(st.lists(st.floats(-50, 50), min_size=4, max_size=4)))
    z = np.array(data.draw(st.lists(st.floats(-50, 50), min_size=2, max_size=2)))
    post_mean, post_cov = estimation.update(mean, P, z, R)
    H = np.eye(2, 4)
    info = np.linalg.inv(P) + H.T @ np.linalg.inv(R) @ H
    assert np.allclose(np.linalg.inv(post_cov), info, rtol=1e-6, atol=1e-8 * np.abs(info).max())
    info_mean = np.linalg.solve(info, np.linalg.solve(P, mean) + H.T @ np.linalg.solve(R, z))
    assert np.allclose(post_mean, info_mean, rtol=1e-6, atol=1e-6)
    assert np.allclose(post_cov, post_cov.T)
    assert (np.linalg.eigvalsh(post_cov) > 0).all()


def test_filter_step_updates_only_observed_pairs(rng):
    mean = rng.normal(size=(2, 3, 4))
    cov = np.broadcast_to(np.diag([4.0, 4.0, 1.0, 1.0]), (2, 3, 4, 4)).copy()
    observed = np.array([[True, False, False], [False, False, True]])
    z = rng.normal(size=(2, 2))
    R = np.broadcast_to(np.eye(2), (2, 2, 2))
    A, Q = estimation.transition(1.0), estimation.process_noise(1.0, 0.16, 0.16)
    new_mean, new_cov = estimation.filter_step(mean, cov, observed, z, R, A, Q)
    pred_mean, pred_cov = estimation.predict(mean, cov, A, Q)
    assert np.array_equal(new_mean[~observed], pred_mean[~observed])
    assert np.array_equal(new_cov[~observed], pred_cov[~observed])
    m, P = estimation.update(pred_mean[0, 0], pred_cov[0, 0], z[0], R[0])
    assert np.allclose(new_mean[0, 0], m) and np.allclose(new_cov[0, 0], P)
    m, P = estimation.update(pred_mean[1, 2], pred_cov[1, 2], z[1], R[1])
    assert np.allclose(new_mean[1, 2], m) and np.allclose(new_cov[1, 2], P)


def test_confidence_is_inverse_trace():
    cov = np.diag([1.0, 2.0, 3.0, 4.0])
    assert estimation.confidence(cov) == pytest.approx(0.1)


def nees_runs(n_runs, steps, ground_range=30.0, altitude=500.0):
    """NEES of the paper's filter (converted range-bearing measurements, eq. 5-12 and
    23-25) tracking an NCV target (sigma = 0.16) seen every step from a UAV circling it
    at a 30 m ground range, 500 m up (the geometry of an orbiting tracker)."""
    sensor = SensorModel()
    A, Q = estimation.transition(1.0), estimation.process_noise(1.0, 0.16, 0.16)
    P0 = np.diag([25.0, 25.0, 1.0, 1.0])
    out = np.empty((n_runs, steps))
    for run in range(n_runs):
        rng = np.random.default_rng([2024, run])
        x = np.array([1e4, 1e4, *rng.normal(0, 1, 2)])
        mean, cov = x + rng.multivariate_normal(np.zeros(4), P0), P0
        for k in range(steps):
            if k:
                x = world.move_targets(x, rng.normal(0, 0.16, 2), 1.0, 2e4)
                mean, cov = estimation.predict(mean, cov, A, Q)
            uav = np.array(
                [
                    x[0] + ground_range * np.cos(0.65 * k),
                    x[1] + ground_range * np.sin(0.65 * k),
                    altitude,
                ]
            )
            zc, R = sensing.convert(
                uav, sensing.measure(uav, x, sensor, rng.standard_normal(2)), sensor
            )
            mean, cov = estimation.update(mean, cov, zc, R)
            out[run, k] = estimation.nees(mean, cov, x)
    return out


def test_nees_inside_chi_square_band():
    n_runs, steps = 60, 40
    runs = nees_runs(n_runs, steps)
    q = runs.mean(axis=0)  # average over runs, per step
    lo, hi = chi2.ppf([0.025, 0.975], 4 * n_runs) / n_runs
    inside = (q > lo) & (q < hi)
    # a consistent filter is inside the 95% band at ~95% of steps; allow a few misses
    assert inside.mean() >= 0.85, (q.round(2), lo, hi)
    overall = runs.mean()
    lo_all, hi_all = chi2.ppf([0.005, 0.995], 4 * n_runs) / n_runs
    assert lo_all < overall < hi_all


@settings(max_examples=50, deadline=None)
@given(st.data())
def test_nees_closed_form_equals_solve(data):
    P = spd(data.draw, 4, data.draw(st.floats(0.01, 100)))
    e = np.array(data.draw(st.lists(st.floats(-20, 20), min_size=4, max_size=4)))
    expected = e @ np.linalg.solve(P, e)
    assert estimation.nees(np.zeros(4), P, e) == pytest.approx(expected, rel=1e-7, abs=1e-9)
    stacked = estimation.nees(np.zeros((3, 4)), np.stack([P] * 3), np.stack([e] * 3))
    assert stacked.shape == (3,) and np.allclose(stacked, expected, rtol=1e-7, atol=1e-9)


def test_a_filter_step_refuses_a_transition_without_its_noise_or_the_reverse():
    mean, cov = np.zeros((1, 4)), np.eye(4)[None]
    nothing = (np.zeros(1, dtype=bool), np.zeros((0, 2)), np.zeros((0, 2, 2)))
    A, Q = estimation.transition(1.0), estimation.process_noise(1.0, 1.0, 1.0)
    for pair in ((A, None), (None, Q)):
        with pytest.raises(ValueError, match="A and Q are given together, or neither"):
            estimation.filter_step(mean, cov, *nothing, *pair)
