"""The interacting multiple model filter against filterpy's IMMEstimator (an oracle from
the test extras), and the facts a wrong mixing step would break."""

import numpy as np
import pytest

from uavtrack import estimation

filterpy = pytest.importorskip("filterpy.kalman")

DT = 0.5
A = estimation.transition(DT)
QS = np.stack([estimation.process_noise(DT, 0.16, 0.16), estimation.process_noise(DT, 2.0, 2.0)])
T = np.array([[0.95, 0.05], [0.10, 0.90]])


def measurements(rng, steps=40):
    """A target that goes straight, turns hard, then stops; noisy positions, and each
    step's R (a distance-dependent sensor gives each its own)."""
    x, out = np.array([0.0, 0.0, 3.0, 1.0]), []
    for k in range(steps):
        if 15 <= k < 25:  # a 0.3 rad/s turn
            c, s = np.cos(0.3 * DT), np.sin(0.3 * DT)
            x[2:] = [c * x[2] - s * x[3], s * x[2] + c * x[3]]
        if k >= 32:
            x[2:] *= 0.3  # stopping
        x[:2] += DT * x[2:]
        L = rng.normal(size=(2, 2)) * 0.3
        R = L @ L.T + np.eye(2) * rng.uniform(0.2, 2.0)
        out.append((x[:2] + rng.multivariate_normal(np.zeros(2), R), R, rng.random() < 0.8))
    return out


def filterpy_imm(mean0, cov0, prob0, motions=(A, A), noises=QS, transition=T):
    """filterpy's IMM of Kalman filters with these motions and noises."""
    filters = []
    for F, Q in zip(motions, noises, strict=True):
        f = filterpy.KalmanFilter(dim_x=4, dim_z=2)
        f.x, f.P, f.F, f.Q = mean0.copy(), cov0.copy(), F.copy(), Q.copy()
        f.H = np.hstack([np.eye(2), np.zeros((2, 2))])
        filters.append(f)
    return filterpy.IMMEstimator(filters, prob0.copy(), transition.copy())


def update_both(oracle, ours, z, R):
    """Update filterpy's IMM and ours with one measurement; the posteriors (mode
    probabilities, combined mean and covariance) must agree to 1e-9."""
    for f in oracle.filters:
        f.R = R.copy()
    oracle.update(z)
    ours = estimation.imm_update(ours, np.array([True]), z[None], R[None])
    mean, cov = estimation.combine(ours)
    assert np.allclose(ours.prob[0], oracle.mu, rtol=1e-9, atol=1e-12)
    assert np.allclose(mean[0], oracle.x, rtol=1e-9, atol=1e-9)
    assert np.allclose(cov[0], oracle.P, rtol=1e-9, atol=1e-9)
    return ours


def test_the_imm_equals_filterpys_on_the_same_measurements(rng):
    mean0, cov0, prob0 = (
        np.array([1.0, -1.0, 0.0, 0.0]),
        np.diag([25.0, 25, 1, 1]),
        np.array([0.9, 0.1]),
    )
    oracle = filterpy_imm(mean0, cov0, prob0)
    ours = estimation.imm_start(mean0[None], cov0[None], prob0)
    for z, R, seen in measurements(rng):
        oracle.predict()
        ours = estimation.imm_predict(ours, T, A, QS)
        for j, f in enumerate(oracle.filters):  # the mixed, predicted modes
            assert np.allclose(ours.mean[0, j], f.x, rtol=1e-9, atol=1e-9)
            assert np.allclose(ours.cov[0, j], f.P, rtol=1e-9, atol=1e-9)
        assert np.allclose(ours.prob[0], oracle.cbar, rtol=1e-9, atol=1e-12)
        if not seen:  # no measurement: filterpy's IMM has no "skip"; ours keeps the prior
            mean, cov = estimation.combine(ours)
            oracle.mu = oracle.cbar.copy()
            oracle._compute_mixing_probabilities()
            oracle._compute_state_estimate()
            assert np.allclose(mean[0], oracle.x, rtol=1e-9, atol=1e-9)
            continue
        ours = update_both(oracle, ours, z, R)
    assert ours.prob[0, 1] > 0.3  # the stop made the manoeuvre mode likely at the end


def test_the_imm_is_batched_over_any_leading_axes(rng):
    # a (2, 3) stack of filters, some observing: each equals its own run alone
    mean = rng.normal(size=(2, 3, 4))
    cov = np.broadcast_to(np.diag([4.0, 4, 1, 1]), (2, 3, 4, 4)).copy()
    modes = estimation.imm_start(mean, cov, np.array([0.7, 0.3]))
    observed = np.array([[True, False, True], [False, True, True]])
    z, R = rng.normal(size=(4, 2)), np.broadcast_to(np.eye(2), (4, 2, 2))
    both = estimation.imm_update(estimation.imm_predict(modes, T, A, QS), observed, z, R)
    for n, (b, i) in enumerate(zip(*np.nonzero(observed), strict=True)):
        alone = estimation.imm_start(mean[b, i][None], cov[b, i][None], np.array([0.7, 0.3]))
        alone = estimation.imm_update(
            estimation.imm_predict(alone, T, A, QS), np.array([True]), z[n][None], R[n][None]
        )
        assert np.array_equal(both.mean[b, i], alone.mean[0])
        assert np.array_equal(both.prob[b, i], alone.prob[0])
    # an unobserved pair keeps its prediction: mu = c-bar
    predicted = estimation.imm_predict(modes, T, A, QS)
    assert np.array_equal(both.prob[0, 1], predicted.prob[0, 1])


def test_identical_modes_make_the_imm_a_kalman_filter(rng):
    # with Q_1 = Q_2, mixing changes nothing and the IMM is the Kalman filter exactly
    Q = np.stack([QS[0], QS[0]])
    mean, cov = np.array([[0.0, 0.0, 1.0, 0.0]]), np.diag([25.0, 25, 1, 1])[None]
    modes = estimation.imm_start(mean, cov, np.array([0.5, 0.5]))
    for z, R, _ in measurements(rng, 10):
        chain = modes.prob @ T  # equal likelihoods: only the Markov chain moves them
        modes = estimation.imm_update(
            estimation.imm_predict(modes, T, A, Q), np.array([True]), z[None], R[None]
        )
        mean, cov = estimation.predict(mean, cov, A, QS[0])
        mean, cov = estimation.update(mean, cov, z[None], R[None])
        combined = estimation.combine(modes)
        assert np.allclose(combined[0], mean, rtol=1e-10, atol=1e-10)
        assert np.allclose(combined[1], cov, rtol=1e-10, atol=1e-10)
        assert np.allclose(modes.prob, chain, rtol=1e-12)


def test_the_combined_covariance_holds_the_spread_of_the_modes():
    modes = estimation.Modes(
        np.array([[[0.0, 0, 0, 0], [2.0, 0, 0, 0]]]),
        np.broadcast_to(np.eye(4), (1, 2, 4, 4)).copy(),
        np.array([[0.5, 0.5]]),
    )
    mean, cov = estimation.combine(modes)
    assert np.allclose(mean, [[1.0, 0, 0, 0]])
    assert cov[0, 0, 0] == pytest.approx(1.0 + 1.0)  # P plus the squared distance to the mean
    assert np.allclose(cov[0, 1:, 1:], np.eye(3))


# ---------------------------------------------------------------- in the cycle


import uavtrack  # noqa: E402
from uavtrack import Scenario  # noqa: E402
from uavtrack.testing import assert_same_trace  # noqa: E402

IMM = {"tracker.model": "imm"}


def test_the_tracker_restarts_the_modes_only_where_fusion_changed_the_estimate(rng):
    tracker = estimation.Tracker.of(DT, (0.16, 0.16), Scenario().with_overrides(IMM).tracker)
    mean = rng.normal(size=(1, 2, 3, 4))
    cov = np.broadcast_to(np.diag([4.0, 4, 1, 1]), (1, 2, 3, 4, 4)).copy()
    mean, cov, modes = tracker.start(mean, cov)
    modes = estimation.Modes(modes.mean + rng.normal(size=modes.mean.shape), modes.cov, modes.prob)
    own = estimation.combine(modes)
    fused_mean, fused_cov = own[0].copy(), own[1].copy()
    fused_mean[0, 1, 2] += 3.0  # one pair adopted another estimate
    fused_cov[0, 1, 2] *= 2.0
    _, _, closed = tracker.close(*own, modes, fused_mean, fused_cov)
    kept = estimation.imm_predict(modes, tracker.transition_matrix, tracker.A, tracker.mode_Q)
    reset = estimation.Modes(
        np.broadcast_to(fused_mean[0, 1, 2], modes.mean[0, 1, 2].shape)[None, None, None],
        np.broadcast_to(fused_cov[0, 1, 2], modes.cov[0, 1, 2].shape)[None, None, None],
        modes.prob[0, 1, 2][None, None, None],
    )
    alone = estimation.imm_predict(reset, tracker.transition_matrix, tracker.A, tracker.mode_Q)
    changed = np.zeros((1, 2, 3), dtype=bool)
    changed[0, 1, 2] = True
    assert np.array_equal(closed.mean[~changed], kept.mean[~changed])
    assert np.allclose(closed.mean[0, 1, 2], alone.mean[0, 0, 0])
    assert np.array_equal(closed.prob[0, 1, 2], kept.prob[0, 1, 2])  # probabilities kept


def test_the_stationary_distribution_is_the_chains():
    p = estimation._stationary(np.array(Scenario().tracker.transition))
    assert np.allclose(p @ np.array(Scenario().tracker.transition), p) and p.sum() == 1


@pytest.mark.parametrize(
    "overrides",
    [
        IMM,
        {"fusion.rule": "covariance_intersection"},
        {**IMM, "fusion.rule": "covariance_intersection"},
    ],
    ids=["imm", "ci", "imm+ci"],
)
def test_the_agent_form_runs_the_same_tracker(overrides):
    pytest.importorskip("msgspec")
    from uavtrack.agents import run_swarm

    for faults in ({}, {"faults.loss": 0.3, "faults.delay": 1}):
        scenario = Scenario(steps=10).with_overrides({**overrides, **faults})
        swarm = run_swarm(scenario, "distributed", seed=3, transport="memory")
        assert_same_trace(swarm.result.trace, uavtrack.simulate(scenario, seed=3).trace)


def test_the_defaults_are_the_papers_tracker():
    # the tracker of the defaults is the Kalman filter: no modes anywhere
    state, _, _ = uavtrack.simulation.initial_state(Scenario(), [np.random.SeedSequence(0)])
    assert state.modes is None
    imm, _, _ = uavtrack.simulation.initial_state(
        Scenario().with_overrides(IMM), [np.random.SeedSequence(0)]
    )
    assert imm.modes.mean.shape == (1, 5, 4, 3, 4)
    assert np.array_equal(imm.mean, state.mean) and np.allclose(imm.cov, state.cov)


@pytest.mark.integration
def test_uavtrack_trackers_writes_its_table_and_figure(tmp_path, capsys):
    import json

    from PIL import Image

    from uavtrack import cli
    from uavtrack.experiments import trackers

    out = tmp_path / "t"
    code = cli.main(["trackers", "--quick", "--out", str(out), "--no-progress"])
    _, err = capsys.readouterr()
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary["motions"]) == ["ncv", "manoeuvring"]
    for rows in summary["motions"].values():
        assert list(rows) == list(trackers.TRACKERS)
        paper = rows["cv + max_consensus"]
        for name, row in rows.items():
            low, high = row["nees_band"]
            assert low < 4 < high  # the band of a consistent estimator's mean NEES
            assert 0 <= row["nees_inside"]["mean"] <= 1 and row["nees_median"]["mean"] > 0
            if name != "cv + max_consensus":  # paired on the same trials
                diff = row["against_paper"]["rmse_best"]["mean"]
                assert diff == pytest.approx(row["rmse_best"]["mean"] - paper["rmse_best"]["mean"])
    report = (out / "report.md").read_text()
    assert "| imm + covariance_intersection |" in report
    assert "| NEES median | NEES inside 95% |" in report
    with Image.open(out / "trackers.png") as im:
        assert im.size[0] > 1000
    code = cli.main(
        ["trackers", "--quick", "--set", "tracker.model=imm", "--out", str(tmp_path / "x")]
    )
    _, err = capsys.readouterr()
    assert code == 2 and "trackers sets target.motion" in err and not (tmp_path / "x").exists()


def test_the_nees_band_is_chi_square():
    from uavtrack.experiments.statistics import nees_band

    low, high = nees_band(1)  # one 4-D error: the chi-square(4) quantiles
    assert (low, high) == pytest.approx((0.4844, 11.1433), abs=1e-4)
    low, high = nees_band(10_000)
    assert 3.9 < low < 4 < high < 4.1


def test_the_environment_runs_the_same_tracker():
    pytest.importorskip("pettingzoo")
    from uavtrack.env import parallel_env

    scenario = Scenario(steps=8).with_overrides(
        {**IMM, "fusion.rule": "covariance_intersection", "target.motion": "manoeuvring"}
    )
    env = parallel_env(scenario=scenario)
    env.reset(seed=4)
    while env.agents:
        env.step({})
    assert_same_trace(env.result().trace, uavtrack.simulate(scenario, seed=4).trace)


def test_a_turn_mode_predicts_a_coordinated_turn_exactly():
    omega, x = np.radians(12.0), np.array([3.0, -2.0, 2.0, 1.0])
    F = estimation.turn_transition(DT, omega)
    speed, heading = np.hypot(2.0, 1.0), np.arctan2(1.0, 2.0)
    # the exact arc: the centre is at distance v / omega to the left of the velocity
    centre = x[:2] + speed / omega * np.array([-np.sin(heading), np.cos(heading)])
    after = F @ x
    assert np.hypot(*(after[:2] - centre)) == pytest.approx(speed / omega)
    assert np.arctan2(after[3], after[2]) == pytest.approx(heading + omega * DT)
    assert np.array_equal(estimation.turn_transition(DT, 0.0), A)


def test_the_imm_with_turn_modes_equals_filterpys(rng):
    omega = np.radians(10.0)
    motions = [A, estimation.turn_transition(DT, omega), estimation.turn_transition(DT, -omega)]
    noises = np.stack([QS[0]] * 3)
    T3 = np.array([[0.9, 0.05, 0.05], [0.1, 0.85, 0.05], [0.1, 0.05, 0.85]])
    mean0, cov0, prob0 = np.zeros(4), np.diag([25.0, 25, 1, 1]), np.array([0.8, 0.1, 0.1])
    oracle = filterpy_imm(mean0, cov0, prob0, motions, noises, T3)
    ours = estimation.imm_start(mean0[None], cov0[None], prob0)
    for z, R, _ in measurements(rng, 30):
        oracle.predict()
        ours = estimation.imm_predict(ours, T3, np.stack(motions), noises)
        ours = update_both(oracle, ours, z, R)


def test_turn_rates_add_two_modes_each():
    s = Scenario().with_overrides(
        {
            **IMM,
            "tracker.manoeuvre_std": [2.0],
            "tracker.turn_rates_deg": [10.0],
            "tracker.transition": [
                [0.9, 0.04, 0.03, 0.03],
                [0.2, 0.7, 0.05, 0.05],
                [0.1, 0.05, 0.85, 0.0],
                [0.1, 0.05, 0.0, 0.85],
            ],
        }
    )
    tracker = estimation.Tracker.of(s.dt, s.acceleration_std(), s.tracker)
    assert tracker.mode_A.shape == (4, 4, 4)
    assert np.allclose(tracker.mode_A[2], estimation.turn_transition(s.dt, np.radians(10.0)))
    assert np.allclose(tracker.mode_A[3], estimation.turn_transition(s.dt, np.radians(-10.0)))
    with pytest.raises(uavtrack.ScenarioError, match="transition must be 5 x 5"):
        Scenario().with_overrides({**IMM, "tracker.turn_rates_deg": [10.0]})
