"""OSPA and GOSPA: metric facts, and Stone Soup's metric generators as an oracle."""

import datetime

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uavtrack.metrics import gospa, ospa

stonesoup = pytest.importorskip("stonesoup")
from stonesoup.metricgenerator.ospametric import GOSPAMetric, OSPAMetric  # noqa: E402
from stonesoup.types.state import State  # noqa: E402

NOW = datetime.datetime(2026, 1, 1)


def states(points):
    return [State(np.asarray(x, dtype=float).reshape(-1, 1), timestamp=NOW) for x in points]


def random_sets(rng, m, n, d=2, scale=30.0):
    return rng.uniform(0, scale, (m, d)), rng.uniform(0, scale, (n, d))


@pytest.mark.parametrize("p", [1.0, 2.0, 3.0])
def test_gospa_equals_stone_soup_with_its_parts(p):
    rng = np.random.default_rng(1)
    for _ in range(40):
        m, n = rng.integers(0, 7, 2)
        X, Y = random_sets(rng, m, n)
        c = rng.uniform(2.0, 20.0)
        ours = gospa(X, Y, c, p)
        theirs, _ = GOSPAMetric(c=c, p=p).compute_gospa_metric(states(Y), states(X))
        value = theirs.value
        assert ours.distance == pytest.approx(value["distance"], abs=1e-9, rel=1e-12)
        for part in ("localisation", "missed", "false"):
            assert getattr(ours, part) == pytest.approx(value[part], abs=1e-9, rel=1e-12)
        total = ours.localisation + ours.missed + ours.false
        assert total == pytest.approx(ours.distance**p, rel=1e-12, abs=1e-12)


def test_ospa_equals_stone_soup_at_p_1():
    rng = np.random.default_rng(2)
    for _ in range(40):
        m, n = rng.integers(1, 7, 2)
        X, Y = random_sets(rng, m, n)
        c = rng.uniform(2.0, 20.0)
        theirs = OSPAMetric(c=c, p=1).compute_OSPA_distance(states(Y), states(X)).value
        assert ospa(X, Y, c, 1) == pytest.approx(theirs, abs=1e-9, rel=1e-12)


def test_ospa_takes_the_optimal_matching_where_stone_soup_matches_plain_distances():
    # plain distances prefer the matching (0, 4) (sum 4 < 4.1), the squares prefer
    # (2.05, 2.05) (8.4 < 16): OSPA of order 2 is sqrt(8.405 / 2) = 2.05
    X = np.array([[0.0, 0.0], [0.45, 2.0]])
    Y = np.array([[0.0, 0.0], [0.45, -2.0]])
    ours = ospa(X, Y, c=10.0, p=2)
    assert ours == pytest.approx(np.hypot(0.45, 2.0))
    theirs = OSPAMetric(c=10.0, p=2).compute_OSPA_distance(states(Y), states(X)).value
    assert theirs == pytest.approx(np.sqrt(16 / 2)) and theirs > ours + 0.7


def test_edge_cases():
    empty = np.zeros((0, 2))
    three = np.ones((3, 2))
    assert ospa(empty, empty, 5.0) == 0.0 and gospa(empty, empty, 5.0).distance == 0.0
    assert ospa(empty, three, 5.0, 2) == 5.0  # every point unmatched: the cut-off
    g = gospa(three, empty, 4.0, 2)
    assert g.missed == 3 * 16 / 2 and g.false == 0 and g.distance == pytest.approx(np.sqrt(24))
    g = gospa(np.zeros((1, 2)), np.array([[100.0, 0.0]]), 4.0, 1)  # too far to be a pair
    assert (g.localisation, g.missed, g.false, g.distance) == (0.0, 2.0, 2.0, 4.0)
    assert np.isnan(gospa(three, three + 1, 4.0, alpha=1).missed)


def test_broadcasting_equals_one_pair_at_a_time():
    rng = np.random.default_rng(3)
    X = rng.uniform(0, 30, (4, 3, 5, 2))
    Y = rng.uniform(0, 30, (3, 6, 2))  # broadcast over the first axis
    d = ospa(X, Y, 12.0, 2)
    g = gospa(X, Y, 12.0, 2)
    assert d.shape == g.distance.shape == (4, 3)
    for i in range(4):
        for j in range(3):
            assert d[i, j] == ospa(X[i, j], Y[j], 12.0, 2)
            assert g.missed[i, j] == gospa(X[i, j], Y[j], 12.0, 2).missed


point_sets = st.integers(0, 5).flatmap(
    lambda m: st.lists(
        st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=m, max_size=m
    ).map(lambda pts: np.array(pts, dtype=float).reshape(-1, 2))
)


@settings(max_examples=150, deadline=None)
@given(point_sets, point_sets, point_sets, st.floats(0.5, 40), st.sampled_from([1.0, 2.0, 3.5]))
def test_ospa_and_gospa_are_metrics(X, Y, Z, c, p):
    for distance in (lambda a, b: ospa(a, b, c, p), lambda a, b: gospa(a, b, c, p).distance):
        xy, yx = distance(X, Y), distance(Y, X)
        assert xy == pytest.approx(yx, abs=1e-9)  # symmetric
        assert distance(X, X) == pytest.approx(0.0, abs=1e-9)
        assert xy <= distance(X, Z) + distance(Z, Y) + 1e-9  # triangle inequality
    assert 0 <= ospa(X, Y, c, p) <= c + 1e-9  # OSPA is bounded by its cut-off


@pytest.mark.parametrize(
    "call,message",
    [
        (lambda: ospa(np.zeros((2, 2)), np.zeros((2, 3)), 1.0), "same d"),
        (lambda: ospa(np.zeros(2), np.zeros((2, 2)), 1.0), "point sets"),
        (lambda: ospa(np.zeros((2, 2)), np.zeros((2, 2)), 0.0), "cut-off c"),
        (lambda: ospa(np.full((8, 2), np.nan), np.zeros((8, 2)), 1.0), "finite"),
        (lambda: gospa(np.zeros((2, 2)), np.zeros((2, 2)), 1.0, p=0.5), "order p"),
        (lambda: gospa(np.zeros((2, 2)), np.zeros((2, 2)), 1.0, alpha=3), "alpha"),
    ],
)
def test_bad_arguments_name_the_problem(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_all_matchings_at_once_equal_the_assignment_solver(monkeypatch):
    from uavtrack import metrics

    rng = np.random.default_rng(4)
    X = rng.uniform(0, 20, (30, 5, 2))
    Y = rng.uniform(0, 20, (30, 5, 2))
    fast = gospa(X, Y, 8.0, 2)
    monkeypatch.setattr(metrics, "SMALL_SETS", 0)
    slow = gospa(X, Y, 8.0, 2)
    for a, b in zip(fast, slow, strict=True):
        assert np.allclose(a, b, rtol=1e-12, atol=1e-12)
