"""Covariance intersection: Stone Soup's Chernoff (CI) updater as an oracle, and the
consistency CI promises whatever the correlation of what it fuses."""

import numpy as np
import pytest

from uavtrack import fusion


def spd(rng, n=4, scale=1.0):
    L = rng.normal(size=(n, n)) * scale
    return L @ L.T + n * scale**2 * np.eye(n) * 0.1


def test_two_estimates_equal_stone_soups_chernoff_update(rng):
    pytest.importorskip("stonesoup")
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.types.detection import GaussianDetection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.prediction import GaussianStatePrediction
    from stonesoup.updater.chernoff import ChernoffUpdater

    for _ in range(5):
        a, b = rng.normal(size=4) * 5, rng.normal(size=4) * 5
        A, B = spd(rng, scale=2.0), spd(rng, scale=1.0)
        weight = fusion.fast_weights(np.stack([A, B]), np.array([True, True]))
        mean, cov = fusion.intersect(np.stack([a, b]), np.stack([A, B]), weight)
        # Stone Soup fuses a measurement (a, A) with weight omega into a prediction (b, B)
        model = LinearGaussian(ndim_state=4, mapping=(0, 1, 2, 3), noise_covar=A)
        detection = GaussianDetection(a.reshape(4, 1), A, measurement_model=model)
        prediction = GaussianStatePrediction(b.reshape(4, 1), B)
        posterior = ChernoffUpdater(measurement_model=model, omega=weight[0]).update(
            SingleHypothesis(prediction, detection)
        )
        assert np.allclose(mean, np.ravel(posterior.state_vector), rtol=1e-9, atol=1e-9)
        assert np.allclose(cov, posterior.covar, rtol=1e-9, atol=1e-9)


def test_the_fast_weights_follow_the_confidence():
    cov = np.stack([np.eye(4), 3 * np.eye(4), 2 * np.eye(4)])
    weight = fusion.fast_weights(cov, np.array([True, True, False]))
    # 1/tr: 1/4 and 1/12, normalised; an absent estimate takes no part
    assert np.allclose(weight, [0.75, 0.25, 0.0])


def test_intersection_of_an_estimate_with_itself_is_itself(rng):
    x, P = rng.normal(size=4), spd(rng)
    mean, cov = fusion.intersect(np.stack([x, x, x]), np.stack([P, P, P]), np.full(3, 1 / 3))
    assert np.allclose(mean, x) and np.allclose(cov, P)  # no information is counted twice


def test_fusing_correlated_estimates_stays_consistent(rng):
    # two estimates sharing most of their error (a common prior): the naive independent
    # fusion is overconfident, CI is not (mean NEES of the fused estimate at most 4)
    n, shared, own = 20000, np.diag([4.0, 4, 1, 1]), np.diag([1.0, 1, 0.25, 0.25])
    common = rng.multivariate_normal(np.zeros(4), shared, n)
    a = common + rng.multivariate_normal(np.zeros(4), own, n)
    b = common + rng.multivariate_normal(np.zeros(4), own, n)
    P = np.broadcast_to(shared + own, (n, 2, 4, 4))
    weight = fusion.fast_weights(P, np.ones((n, 2), dtype=bool))
    mean, cov = fusion.intersect(np.stack([a, b], axis=1), P, weight)
    e = -mean  # the truth is 0
    nees = np.einsum("ni,ni->n", e, np.linalg.solve(cov, e[..., None])[..., 0])
    assert nees.mean() <= 4.0
    naive = np.linalg.inv(2 * np.linalg.inv(shared + own))  # as if independent
    naive_nees = np.einsum("ni,ij,nj->n", e, np.linalg.inv(naive), e)
    assert naive_nees.mean() > 6.0  # what max-consensus-free averaging would claim


def test_a_round_is_the_same_in_the_dense_and_the_edge_form(rng):
    from uavtrack import network

    B, n, m = 2, 7, 3
    adjacency = rng.random((B, n, n)) < 0.4
    adjacency |= np.swapaxes(adjacency, 1, 2)
    adjacency |= np.eye(n, dtype=bool)

    def tuples():
        cov = np.stack([spd(rng) for _ in range(B * n * m)]).reshape(B, n, m, 4, 4)
        return fusion.Estimates(
            mean=rng.normal(size=(B, n, m, 4)), cov=cov, stamp=np.zeros((B, n, m))
        )

    own, offered = tuples(), tuples()  # with delay: what was offered is not the current one
    dense = fusion.intersect_round(own, offered, network.links(adjacency, "dense"))
    edges = fusion.intersect_round(own, offered, network.links(adjacency, "edges"))
    for name in ("mean", "cov", "gamma"):
        assert np.allclose(getattr(dense, name), getattr(edges, name), rtol=1e-10, atol=1e-12)
    # receiver 0 of trial 0: the n-way intersection of its own and its neighbours' offers
    heard = np.flatnonzero(adjacency[0, 0])
    mean = np.stack([own.mean[0, 0] if q == 0 else offered.mean[0, q] for q in heard], 1)
    cov = np.stack([own.cov[0, 0] if q == 0 else offered.cov[0, q] for q in heard], 1)
    x, P = fusion.intersect(mean, cov, fusion.fast_weights(cov, np.ones(mean.shape[:2], bool)))
    assert np.allclose(dense.mean[0, 0], x) and np.allclose(dense.cov[0, 0], P)


@pytest.mark.parametrize("form", ["dense", "edges"])
def test_a_round_of_tuples_without_confidence_fuses_only_what_is_admitted(rng, form):
    # tuples that carry no "gamma" (all finite, then): the admitted mask alone decides
    from uavtrack import network

    B, n, m = 1, 4, 2
    links = network.links(np.ones((B, n, n), dtype=bool), form)
    cov = np.stack([spd(rng) for _ in range(B * n * m)]).reshape(B, n, m, 4, 4)
    own = fusion.Estimates(mean=rng.normal(size=(B, n, m, 4)), cov=cov)
    t, i, q = links.pairs()
    admitted = np.broadcast_to((i == q)[..., None], np.broadcast(t, i, q).shape + (m,))
    out = fusion.intersect_round(own, own, links, admitted)  # each admits only its own
    assert np.allclose(out.mean, own.mean, rtol=1e-10, atol=1e-12)
    assert np.allclose(out.cov, own.cov, rtol=1e-10, atol=1e-12)
