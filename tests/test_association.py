import datetime
import itertools

import numpy as np
import pytest
from scipy.stats import chi2, multivariate_normal

from uavtrack import estimation
from uavtrack.tracks import association as assoc

ORDER = [0, 2, 1, 3]  # (x, y, vx, vy) <-> Stone Soup's (x, vx, y, vy); its own inverse
T0 = datetime.datetime(2024, 1, 1)


def _scenes(rng, P, K=5, pd=0.9, spread=4.0, clutter=3):
    """P rows of up to 4 present tracks close together (so that they share measurements),
    each detected with probability pd, plus up to `clutter` false measurements near and
    between them; rows padded to the most measurements, slots and measurements shuffled."""
    mean, cov = np.zeros((P, K, 4)), np.tile(np.eye(4), (P, K, 1, 1))
    present = np.zeros((P, K), dtype=bool)
    rows = []
    for p in range(P):
        centre = rng.uniform(-100, 100, 2)
        slots = rng.choice(K, size=rng.integers(1, 5), replace=False)
        present[p, slots] = True
        zs, Rs = [], []
        for k in slots:
            L = np.tril(rng.normal(size=(4, 4))) * 0.3
            L[np.diag_indices(4)] = np.abs(L[np.diag_indices(4)]) + [2.0, 2.0, 0.5, 0.5]
            cov[p, k] = L @ L.T
            mean[p, k, :2] = centre + rng.normal(0, spread, 2)
            mean[p, k, 2:] = rng.normal(0, 2, 2)
            if rng.random() < pd:
                R = _spd2(rng)
                truth = rng.multivariate_normal(mean[p, k, :2], cov[p, k, :2, :2])
                zs.append(rng.multivariate_normal(truth, R))
                Rs.append(R)
        for _ in range(rng.integers(0, clutter + 1)):
            zs.append(centre + rng.uniform(-2 * spread, 2 * spread, 2))
            Rs.append(_spd2(rng))
        order = rng.permutation(len(zs))
        rows.append(([zs[i] for i in order], [Rs[i] for i in order]))
    Z = max(1, max(len(zs) for zs, _ in rows))
    z, R = np.zeros((P, Z, 2)), np.tile(np.eye(2), (P, Z, 1, 1))
    valid = np.zeros((P, Z), dtype=bool)
    for p, (zs, Rs) in enumerate(rows):
        if zs:
            z[p, : len(zs)], R[p, : len(zs)], valid[p, : len(zs)] = zs, Rs, True
    return mean, cov, present, z, R, valid


def _spd2(rng):
    A = rng.normal(size=(2, 2))
    return A @ A.T * 0.5 + np.diag(rng.uniform(0.5, 3.0, 2))


def _associate(mean, cov, present, z, R, valid, pd, density, pg, max_events=100_000):
    inn = assoc.innovations(mean, cov, z, R)
    gated = assoc.gate(inn.d2, present, valid, pg)
    take = assoc.gnn(inn, gated, pd, density, pg)
    beta = assoc.jpda(inn, gated, pd, density, pg, max_events=max_events)
    return gated, take, beta


def _stonesoup_row(mean, cov, present, z, R, valid, pd, density, pg):
    """Stone Soup on one row: GNN's associations (K,), JPDA's beta (K, Z + 1) and its
    posteriors (PDAUpdater, Gaussian mixture reduction), in our orders."""
    from stonesoup.dataassociator.neighbour import GlobalNearestNeighbour
    from stonesoup.dataassociator.probability import JPDA
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import KalmanUpdater
    from stonesoup.updater.probability import PDAUpdater

    still = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.0), ConstantVelocity(0.0)])
    hypothesiser = PDAHypothesiser(
        predictor=KalmanPredictor(still),
        updater=KalmanUpdater(measurement_model=None),
        clutter_spatial_density=density,
        prob_detect=pd,
        prob_gate=pg,
    )
    slots = np.flatnonzero(present)
    tracks = {
        k: Track([GaussianState(mean[k][ORDER], cov[k][np.ix_(ORDER, ORDER)], timestamp=T0)])
        for k in slots
    }
    detections = {
        j: Detection(
            z[j][:, None],
            timestamp=T0,
            measurement_model=LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=R[j]),
        )
        for j in np.flatnonzero(valid)
    }

    def index(measurement):
        return next((j for j, d in detections.items() if d is measurement), -1)

    K, Z = present.shape[0], valid.shape[0]
    take = np.full(K, -1)
    gnn = GlobalNearestNeighbour(hypothesiser).associate(
        set(tracks.values()), set(detections.values()), T0
    )
    for k, track in tracks.items():
        take[k] = index(gnn[track].measurement)
    beta = np.zeros((K, Z + 1))
    beta[:, 0] = 1.0
    post_mean, post_cov = mean.copy(), cov.copy()
    jpda = JPDA(hypothesiser).associate(set(tracks.values()), set(detections.values()), T0)
    updater = PDAUpdater(measurement_model=None, gm_method=True)
    for k, track in tracks.items():
        beta[k, 0] = 0.0
        for hypothesis in jpda[track]:
            beta[k, 1 + index(hypothesis.measurement) if hypothesis else 0] = float(
                hypothesis.probability
            )
        posterior = updater.update(jpda[track])
        post_mean[k] = np.asarray(posterior.state_vector, dtype=float).ravel()[ORDER]
        post_cov[k] = np.asarray(posterior.covar, dtype=float)[np.ix_(ORDER, ORDER)]
    return take, beta, post_mean, post_cov


# ------------------------------------------------------------------------ the oracle


@pytest.mark.parametrize(
    ("seed", "pd", "density", "pg"),
    [(1, 0.9, 1e-3, 0.99), (2, 0.6, 1e-2, 0.95), (3, 0.95, 1e-4, 0.99), (4, 0.8, 3e-2, 0.9)],
)
@pytest.mark.parametrize("together", [True, False])
def test_gnn_and_jpda_equal_stone_soup_on_random_scenes(
    seed, pd, density, pg, together, monkeypatch
):
    pytest.importorskip("stonesoup")
    if not together:  # every cluster enumerated alone on its gated pairs
        monkeypatch.setattr(assoc, "_complete", lambda n, m: None)
    rng = np.random.default_rng(seed)
    mean, cov, present, z, R, valid = _scenes(rng, P=12, pd=pd)
    gated, take, beta = _associate(mean, cov, present, z, R, valid, pd, density, pg)
    post_mean, post_cov = assoc.pda_update(mean, cov, z, R, beta)
    # the scenes hold clusters of several tracks and tracks with several measurements
    assert (gated.sum(axis=1) >= 2).any() and (gated.sum(axis=2) >= 2).any()
    for p in range(len(mean)):
        s_take, s_beta, s_mean, s_cov = _stonesoup_row(
            mean[p], cov[p], present[p], z[p], R[p], valid[p], pd, density, pg
        )
        assert np.array_equal(take[p], s_take)
        np.testing.assert_allclose(beta[p], s_beta, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(post_mean[p], s_mean, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(post_cov[p], s_cov, rtol=1e-9, atol=1e-9)


def test_innovations_and_gate_are_the_gaussian_and_its_chi_square_quantile():
    rng = np.random.default_rng(5)
    mean, cov, present, z, R, valid = _scenes(rng, P=3)
    inn = assoc.innovations(mean, cov, z, R)
    for p, k, j in itertools.product(range(3), range(mean.shape[1]), range(z.shape[1])):
        S = cov[p, k, :2, :2] + R[p, j]
        nu = z[p, j] - mean[p, k, :2]
        assert inn.d2[p, k, j] == pytest.approx(nu @ np.linalg.solve(S, nu), rel=1e-10)
        expected = multivariate_normal(mean[p, k, :2], S).logpdf(z[p, j])
        assert inn.log_lik[p, k, j] == pytest.approx(expected, rel=1e-10, abs=1e-10)
    for pg in (0.5, 0.9, 0.99, 0.999):  # chi-square(2) has the closed form -2 log(1 - P_G)
        assert assoc.threshold(pg) == pytest.approx(-2 * np.log1p(-pg), rel=1e-12)
        assert assoc.threshold(pg, 4) == pytest.approx(chi2.ppf(pg, 4), rel=1e-12)
    gated = assoc.gate(inn.d2, present, valid, 0.99)
    expected = (inn.d2 <= chi2.ppf(0.99, 2)) & present[:, :, None] & valid[:, None, :]
    assert np.array_equal(gated, expected)


# ------------------------------------------------------------------------ closed cases


def _separated(rng, P=4, K=6):
    """Tracks 100 m apart, each with one measurement near it (in a shuffled order), and an
    empty last slot."""
    mean = np.zeros((P, K, 4))
    mean[:, :, :2] = np.arange(K)[None, :, None] * 100.0 + rng.normal(0, 1, (P, K, 2))
    cov = np.tile(np.diag([4.0, 4.0, 1.0, 1.0]), (P, K, 1, 1))
    present = np.ones((P, K), dtype=bool)
    present[:, -1] = False
    order = np.array([rng.permutation(K - 1) for _ in range(P)])  # the track of measurement j
    z = np.take_along_axis(mean[:, :-1, :2], order[..., None], axis=1)
    z += rng.normal(0, 1, z.shape)
    R = np.tile(np.eye(2), (P, K - 1, 1, 1))
    valid = np.ones((P, K - 1), dtype=bool)
    return mean, cov, present, z, R, valid, np.argsort(order, axis=1)


def test_perfect_sensor_and_separated_tracks_take_their_own_measurement():
    rng = np.random.default_rng(6)
    mean, cov, present, z, R, valid, own = _separated(rng)
    P, K = present.shape
    _, take, beta = _associate(mean, cov, present, z, R, valid, 1.0, 0.0, 0.99)
    assert np.array_equal(take[:, :-1], own) and (take[:, -1] == -1).all()
    hit = np.zeros_like(beta)
    hit[np.arange(P)[:, None], np.arange(K - 1)[None], 1 + own] = 1.0
    hit[:, -1, 0] = 1.0  # an empty slot is missed
    np.testing.assert_allclose(beta, hit, rtol=0, atol=1e-12)
    gated = assoc.gate(assoc.innovations(mean, cov, z, R).d2, present, valid, 0.99)
    assert not assoc.unused_gnn(take, valid).any() and not assoc.unused_jpda(gated, valid).any()


def test_a_track_alone_with_its_measurement_has_the_pda_weights():
    rng = np.random.default_rng(16)
    mean, cov, present, z, R, valid, own = _separated(rng)
    pd, density, pg = 0.7, 2e-3, 0.95
    _, take, beta = _associate(mean, cov, present, z, R, valid, pd, density, pg)
    for p, k in itertools.product(range(present.shape[0]), range(present.shape[1] - 1)):
        j = own[p, k]
        w = pd * multivariate_normal(mean[p, k, :2], cov[p, k, :2, :2] + R[p, j]).pdf(z[p, j])
        w /= density
        assert beta[p, k, 1 + j] == pytest.approx(w / (1 - pd * pg + w), rel=1e-10)
        assert beta[p, k, 0] == pytest.approx((1 - pd * pg) / (1 - pd * pg + w), rel=1e-10)
        assert take[p, k] == (j if w >= 1 - pd * pg else -1)


def test_an_undetectable_track_takes_nothing_and_changes_nothing_else():
    rng = np.random.default_rng(7)
    mean, cov, present, z, R, valid = _scenes(rng, P=20, pd=1.0, spread=2.0)
    pd = np.full(present.shape, 0.9)
    first = np.argmax(present, axis=1)
    pd[np.arange(20), first] = 0.0
    _, take, beta = _associate(mean, cov, present, z, R, valid, pd, 1e-3, 0.99)
    absent = present.copy()
    absent[np.arange(20), first] = False
    _, take_, beta_ = _associate(mean, cov, absent, z, R, valid, pd, 1e-3, 0.99)
    assert (take[np.arange(20), first] == -1).all()
    assert np.array_equal(take, take_)
    np.testing.assert_allclose(beta, beta_, rtol=1e-12, atol=1e-15)


def test_unused_measurements_are_those_no_track_took_or_could_have_produced():
    take = np.array([[2, -1, 0]])
    valid = np.array([[True, True, True, False]])
    assert assoc.unused_gnn(take, valid).tolist() == [[False, True, False, False]]
    gated = np.zeros((1, 3, 4), dtype=bool)
    gated[0, 0, 1] = True  # track 0 may have produced measurement 1
    gated[0, 2, 3] = True  # an invalid measurement is never counted
    assert assoc.unused_jpda(gated, valid).tolist() == [[True, False, True, False]]


# ------------------------------------------------------------------------ invariances


@pytest.mark.parametrize("axis", ["measurements", "slots"])
def test_reordering_measurements_or_slots_reorders_the_result_and_nothing_else(axis):
    rng = np.random.default_rng(8)
    mean, cov, present, z, R, valid = _scenes(rng, P=30, spread=2.0)
    args = (0.8, 5e-3, 0.99)
    gated, take, beta = _associate(mean, cov, present, z, R, valid, *args)
    assert (gated.sum(axis=1) >= 2).any()  # clusters of several tracks among the rows
    post = assoc.pda_update(mean, cov, z, R, beta)
    gnn_post = assoc.assigned_update(mean, cov, z, R, take)
    if axis == "measurements":
        perm = rng.permutation(z.shape[1])
        inverse = np.argsort(perm)
        _, take_, beta_ = _associate(
            mean, cov, present, z[:, perm], R[:, perm], valid[:, perm], *args
        )
        assert np.array_equal(take_, np.where(take >= 0, inverse[take], -1))
        np.testing.assert_allclose(beta_, beta[:, :, np.r_[0, 1 + perm]], rtol=1e-12, atol=1e-15)
        post_ = assoc.pda_update(mean, cov, z[:, perm], R[:, perm], beta_)
        gnn_post_ = assoc.assigned_update(mean, cov, z[:, perm], R[:, perm], take_)
    else:
        perm = rng.permutation(mean.shape[1])
        m, c = mean[:, perm], cov[:, perm]
        _, take_, beta_ = _associate(m, c, present[:, perm], z, R, valid, *args)
        assert np.array_equal(take_, take[:, perm])
        np.testing.assert_allclose(beta_, beta[:, perm], rtol=1e-12, atol=1e-15)
        post_ = tuple(x[:, np.argsort(perm)] for x in assoc.pda_update(m, c, z, R, beta_))
        gnn_post_ = tuple(x[:, np.argsort(perm)] for x in assoc.assigned_update(m, c, z, R, take_))
    for a, b in zip((*post, *gnn_post), (*post_, *gnn_post_), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def test_a_batch_of_rows_gives_what_each_row_gives_alone():
    rng = np.random.default_rng(9)
    mean, cov, present, z, R, valid = _scenes(rng, P=25, spread=2.0)
    pd = rng.uniform(0.5, 1.0, present.shape)
    density = rng.uniform(1e-4, 1e-2, 25)
    gated, take, beta = _associate(mean, cov, present, z, R, valid, pd, density, 0.95)
    assert (gated.sum(axis=1) >= 2).any()  # clusters of several tracks among the rows
    post = assoc.pda_update(mean, cov, z, R, beta)
    for p in range(25):
        one = slice(p, p + 1)
        _, take1, beta1 = _associate(
            mean[one], cov[one], present[one], z[one], R[one], valid[one], pd[one],
            density[one], 0.95,
        )  # fmt: skip
        assert np.array_equal(take1[0], take[p])
        np.testing.assert_allclose(beta1[0], beta[p], rtol=1e-12, atol=1e-15)
        post1 = assoc.pda_update(mean[one], cov[one], z[one], R[one], beta1)
        np.testing.assert_allclose(post1[0][0], post[0][p], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(post1[1][0], post[1][p], rtol=1e-12, atol=1e-12)


# ------------------------------------------------------------------------ posteriors


def test_pda_update_on_one_hypothesis_is_the_kalman_update_or_the_prediction():
    rng = np.random.default_rng(10)
    mean, cov, present, z, R, valid = _scenes(rng, P=6)
    P, K, Z = mean.shape[0], mean.shape[1], z.shape[1]
    pick = rng.integers(-1, Z, (P, K))  # -1: all on the miss
    beta = np.zeros((P, K, Z + 1))
    beta[np.arange(P)[:, None], np.arange(K)[None], pick + 1] = 1.0
    post_mean, post_cov = assoc.pda_update(mean, cov, z, R, beta)
    gnn_mean, gnn_cov = assoc.assigned_update(mean, cov, z, R, pick)
    for p, k in itertools.product(range(P), range(K)):
        j = pick[p, k]
        if j < 0:
            want = mean[p, k], cov[p, k]
        else:
            want = estimation.update(mean[p, k], cov[p, k], z[p, j], R[p, j])
        for got in ((post_mean[p, k], post_cov[p, k]), (gnn_mean[p, k], gnn_cov[p, k])):
            np.testing.assert_allclose(got[0], want[0], rtol=1e-15, atol=0)
            np.testing.assert_allclose(got[1], want[1], rtol=1e-15, atol=0)


def test_pda_update_is_the_mixture_mean_and_covariance():
    rng = np.random.default_rng(11)
    mean, cov, present, z, R, valid = _scenes(rng, P=3)
    Z = z.shape[1]
    beta = rng.dirichlet(np.ones(Z + 1), size=mean.shape[:2])
    post_mean, post_cov = assoc.pda_update(mean, cov, z, R, beta)
    p, k = 1, 2
    parts = [(mean[p, k], cov[p, k])] + [
        estimation.update(mean[p, k], cov[p, k], z[p, j], R[p, j]) for j in range(Z)
    ]
    # a sample of the mixture has these first two moments
    x = sum(b * m for b, (m, _) in zip(beta[p, k], parts, strict=True))
    second = sum(b * (c + np.outer(m, m)) for b, (m, c) in zip(beta[p, k], parts, strict=True))
    np.testing.assert_allclose(post_mean[p, k], x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(post_cov[p, k], second - np.outer(x, x), rtol=1e-8, atol=1e-8)


# ------------------------------------------------------------------------ large clusters


def _cluster(links, rng, spread=1.5):
    """One row whose gating graph is `links` (tracks x measurements): each measurement sits
    at the mean of the tracks it links, the others far away."""
    n, m = links.shape
    mean = np.zeros((1, n, 4))
    mean[0, :, :2] = rng.normal(0, 1, (n, 2)) * 100.0
    cov = np.tile(np.diag([9.0, 9.0, 1.0, 1.0]), (1, n, 1, 1))
    z = np.zeros((1, m, 2))
    for j in range(m):
        z[0, j] = mean[0, links[:, j], :2].mean(axis=0) + rng.normal(0, spread, 2)
    R = np.tile(np.eye(2), (1, m, 1, 1))
    inn = assoc.innovations(mean, cov, z, R)
    gated = np.zeros((1, n, m), dtype=bool)
    gated[0] = links
    return mean, cov, z, R, inn, gated


def test_a_tree_shaped_cluster_beyond_max_events_is_still_exact():
    rng = np.random.default_rng(12)
    links = np.zeros((2, 3), dtype=bool)  # k0 - j1 - k1, plus one own measurement each
    links[0, [0, 1]] = links[1, [1, 2]] = True
    n_events = sum(
        len({j for j in c if j >= 0}) == sum(j >= 0 for j in c)
        for c in itertools.product(*[[-1, *np.flatnonzero(row)] for row in links])
    )
    assert n_events == 8
    *_, inn, gated = _cluster(links, rng)
    exact = assoc.jpda(inn, gated, 0.9, 1e-3, 0.99, max_events=n_events)
    propagated = assoc.jpda(inn, gated, 0.9, 1e-3, 0.99, max_events=n_events - 1)
    np.testing.assert_allclose(propagated, exact, rtol=1e-9, atol=1e-12)


def test_a_cyclic_cluster_beyond_max_events_gets_loopy_belief_propagation():
    pytest.importorskip("stonesoup")
    from stonesoup.dataassociator.probability import JPDAwithLBP

    rng = np.random.default_rng(13)
    links = np.ones((3, 3), dtype=bool)  # every track gated to every measurement: 34 events
    mean, cov, z, R, inn, gated = _cluster(links, rng, spread=0.0)
    mean[0, :, :2] = mean[0, 0, :2] + rng.normal(0, 2, (3, 2))  # close: all gated
    z[0] = mean[0, 0, :2] + rng.normal(0, 2, (3, 2))
    inn = assoc.innovations(mean, cov, z, R)
    gated = assoc.gate(inn.d2, np.ones((1, 3), bool), np.ones((1, 3), bool), 0.999)
    assert gated.all()
    args = (0.9, 2e-3, 0.999)
    exact = assoc.jpda(inn, gated, *args, max_events=34)
    lbp = assoc.jpda(inn, gated, *args, max_events=33)
    assert np.abs(lbp - exact).max() > 1e-4  # the approximation, not the enumeration
    np.testing.assert_allclose(lbp.sum(axis=2), 1.0, rtol=1e-12)
    # its fixed point: beta_kj / beta_k0 = psi_kj nu_kj with the messages of Williams & Lau
    _, lmiss, ldet = assoc._log_weights(inn, gated, *args)
    psi = np.exp(ldet[0] - lmiss[0][:, None])
    nu = lbp[0, :, 1:] / lbp[0, :, :1] / psi
    s = 1 + (psi * nu).sum(axis=1, keepdims=True)
    mu = psi / (s - psi * nu)
    np.testing.assert_allclose(nu, 1 / (1 + mu.sum(axis=0, keepdims=True) - mu), rtol=1e-10)
    # and Stone Soup's loopy belief propagation, within its stopping tolerance (delta 1e-3)
    s_beta = _stonesoup_lbp(mean[0], cov[0], z[0], R[0], *args, JPDAwithLBP)
    np.testing.assert_allclose(lbp[0], s_beta, rtol=2e-3, atol=1e-4)


def _stonesoup_lbp(mean, cov, z, R, pd, density, pg, associator):
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import KalmanUpdater

    still = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.0), ConstantVelocity(0.0)])
    hypothesiser = PDAHypothesiser(
        predictor=KalmanPredictor(still),
        updater=KalmanUpdater(measurement_model=None),
        clutter_spatial_density=density,
        prob_detect=pd,
        prob_gate=pg,
    )
    tracks = [
        Track([GaussianState(m[ORDER], c[np.ix_(ORDER, ORDER)], timestamp=T0)])
        for m, c in zip(mean, cov, strict=True)
    ]
    detections = [
        Detection(
            zj[:, None],
            timestamp=T0,
            measurement_model=LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=Rj),
        )
        for zj, Rj in zip(z, R, strict=True)
    ]
    out = associator(hypothesiser).associate(set(tracks), set(detections), T0)
    beta = np.zeros((len(tracks), len(detections) + 1))
    for k, track in enumerate(tracks):
        for hypothesis in out[track]:
            j = next((1 + i for i, d in enumerate(detections) if d is hypothesis.measurement), 0)
            beta[k, j] = float(hypothesis.probability)
    return beta


# ------------------------------------------------------------------------ bad input


def test_bad_arguments_name_what_is_wrong():
    rng = np.random.default_rng(14)
    mean, cov, present, z, R, valid = _scenes(rng, P=2)
    inn = assoc.innovations(mean, cov, z, R)
    gated = assoc.gate(inn.d2, present, valid, 0.99)
    with pytest.raises(ValueError, match="gate_probability"):
        assoc.threshold(1.0)
    with pytest.raises(ValueError, match="pd"):
        assoc.gnn(inn, gated, 1.5, 1e-3, 0.99)
    with pytest.raises(ValueError, match="density"):
        assoc.jpda(inn, gated, 0.9, -1.0, 0.99)
    with pytest.raises(ValueError, match="max_events"):
        assoc.jpda(inn, gated, 0.9, 1e-3, 0.99, max_events=0)


def test_components_number_as_scipy_does():
    """The JPDA's clusters come from `components`: the same count and numbering as
    scipy's connected_components on random graphs, isolated nodes and repeated edges
    included."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(1)
    for _ in range(500):
        n, e = int(rng.integers(1, 40)), int(rng.integers(0, 60))
        a, b = rng.integers(0, n, e), rng.integers(0, n, e)
        count, label = connected_components(
            coo_matrix((np.ones(e), (a, b)), shape=(n, n)), directed=False
        )
        ours = assoc.components(a, b, n)
        assert ours[0] == count and np.array_equal(ours[1], label)
