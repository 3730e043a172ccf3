"""The plain-Python assignment solver against scipy's (the oracle) and brute force."""

import itertools
import math

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

from uavtrack import assignment
from uavtrack.numerics import chisquare, lsap


def problems(seed: int, count: int):
    """Random (n, m) matrices, many with ties: small integers, two values that round
    when shifted, normal draws, and forbidden (inf) entries."""
    rng = np.random.default_rng(seed)
    for t in range(count):
        n, m = (int(x) for x in rng.integers(1, 8, size=2))
        kind = t % 5
        if kind == 0:
            cost = rng.integers(0, 3, (n, m)).astype(float)
        elif kind == 1:
            cost = rng.normal(size=(n, m))
        elif kind == 2:
            cost = np.round(rng.normal(size=(n, m)), 1)
            cost[rng.random((n, m)) < 0.3] = np.inf
        elif kind == 3:
            cost = rng.integers(0, 2, (n, m)).astype(float) * 0.1 + 0.2
        else:
            cost = np.full((n, m), rng.normal())
        yield cost, bool(t % 3 == 0)


def test_equals_scipy_ties_included():
    for cost, maximize in problems(0, 4000):
        if maximize:
            cost = -cost  # forbidden pairs stay forbidden
        try:
            want = linear_sum_assignment(cost, maximize=maximize)
        except ValueError as error:
            with pytest.raises(ValueError, match=str(error)):
                lsap.solve_lists(cost.tolist(), maximize)
            continue
        rows, cols = lsap.solve_lists(cost.tolist(), maximize)
        np.testing.assert_array_equal(rows, want[0])
        np.testing.assert_array_equal(cols, want[1])


def test_optimal_against_brute_force():
    rng = np.random.default_rng(1)
    for _ in range(300):
        n, m = (int(x) for x in rng.integers(1, 6, size=2))
        cost = rng.normal(size=(n, m))
        rows, cols = lsap.solve(cost)
        assert len(set(cols.tolist())) == len(cols) == min(n, m)
        if n <= m:
            best = min(
                sum(cost[i, c] for i, c in enumerate(p))
                for p in itertools.permutations(range(m), n)
            )
        else:
            best = min(
                sum(cost[r, j] for j, r in enumerate(p))
                for p in itertools.permutations(range(n), m)
            )
        assert cost[rows, cols].sum() == pytest.approx(best, abs=1e-12)


def test_bad_input_and_large_problems():
    with pytest.raises(ValueError, match="invalid numeric entries"):
        lsap.solve(np.array([[1.0, np.nan]]))
    with pytest.raises(ValueError, match="infeasible"):
        lsap.solve(np.array([[np.inf, np.inf], [1.0, 2.0]]))
    with pytest.raises(ValueError, match="2-d"):
        lsap.solve(np.zeros(3))
    rows, cols = lsap.solve(np.zeros((0, 3)))
    assert rows.size == cols.size == 0
    big = np.random.default_rng(2).normal(size=(30, 40))  # past SMALL: scipy's solver
    assert not lsap.small(30, 40) and lsap.small(5, 20)
    want = linear_sum_assignment(big)
    got = lsap.solve(big)
    np.testing.assert_array_equal(got[1], want[1])
    # the same problem in plain Python, whatever its size
    np.testing.assert_array_equal(lsap.solve_lists(big.tolist())[1], want[1])


def test_auction_solver_uses_it_for_small_problems():
    rng = np.random.default_rng(3)
    for _ in range(200):
        bids = rng.integers(0, 3, (4, 6)).astype(float)  # ties everywhere
        rows, cols = assignment.linear_sum_assignment(bids, maximize=True)
        want = linear_sum_assignment(bids, maximize=True)
        np.testing.assert_array_equal(cols, want[1])


@pytest.mark.parametrize("dof", [1, 2, 3, 4, 5, 6, 9])
def test_chisquare_quantiles_equal_scipy(dof):
    for p in (1e-6, 0.001, 0.025, 0.3, 0.5, 0.9, 0.95, 0.975, 0.99, 0.9999, 1 - 1e-7):
        assert chisquare.ppf(p, dof) == pytest.approx(chi2.ppf(p, dof), rel=1e-13)
    for x in (1e-3, 0.1, 1.0, 3.0, 7.0, 20.0, 60.0):
        assert chisquare.cdf(x, dof) == pytest.approx(chi2.cdf(x, dof), rel=1e-13)
        assert chisquare.sf(x, dof) == pytest.approx(chi2.sf(x, dof), rel=1e-13)
    assert chisquare.ppf(0.9, 2) == pytest.approx(-2.0 * math.log(0.1), rel=1e-15)


def test_chisquare_bad_input():
    for dof in (0, 1.5, -2):
        with pytest.raises(ValueError, match="degrees of freedom"):
            chisquare.cdf(1.0, dof)
    for p in (0.0, 1.0, 1.2):
        with pytest.raises(ValueError, match="probability"):
            chisquare.ppf(p, 4)


@pytest.mark.integration  # two fresh interpreters: whether scipy.optimize gets loaded
def test_a_long_tracked_run_loads_the_compiled_solver_and_scores_the_same():
    import json
    import subprocess
    import sys

    code = (
        "import json, sys, uavtrack\n"
        "from uavtrack.numerics import lsap\n"
        "lsap.IMPORT_SECONDS = float(sys.argv[1])\n"
        "s = uavtrack.Scenario(steps=200, tracker={'association': 'jpda'})\n"
        "m = uavtrack.run(s, 'distributed', [0, 1, 2, 3]).metrics\n"
        "print(json.dumps({'loaded': 'scipy.optimize' in sys.modules,\n"
        "    **{k: m[k].tolist() for k in ('gospa', 'switches', 'label_purity')}}))\n"
    )
    runs = [
        json.loads(
            subprocess.run(
                [sys.executable, "-c", code, limit], capture_output=True, text=True, check=True
            ).stdout
        )
        for limit in ("0.5", "1e9")  # as shipped; never worth it
    ]
    assert runs[0].pop("loaded") and not runs[1].pop("loaded")
    assert runs[0] == runs[1]  # the same answers, ties included
