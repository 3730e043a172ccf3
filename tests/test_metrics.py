"""The NEES as a distribution: the tally's median and fraction inside the 95 % chi-square(4)
interval, against numpy on a trace's samples and against chi-square(4) itself."""

import json
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

import uavtrack
from uavtrack import cli, estimation
from uavtrack.metrics import (
    NEES_BINS_PER_DECADE,
    NEES_DECADES,
    NeesSpread,
    Tally,
    nees_interval,
)

RESOLUTION = 10 ** (1 / (2 * NEES_BINS_PER_DECADE))
"""The factor within which a median read from the histogram lies of numpy's."""


def inside(q):
    low, high = stats.chi2.ppf(0.025, 4), stats.chi2.ppf(0.975, 4)
    return int(np.count_nonzero((q >= low) & (q <= high)))


def test_the_interval_is_chi_square_4_at_95_percent():
    low, high = nees_interval()
    assert low == pytest.approx(stats.chi2.ppf(0.025, 4), rel=1e-12)
    assert high == pytest.approx(stats.chi2.ppf(0.975, 4), rel=1e-12)
    assert nees_interval(2, 0.99) == pytest.approx(stats.chi2.ppf([0.005, 0.995], 2), rel=1e-12)


@pytest.mark.parametrize("n", [1, 2, 7, 1000, 1001])
def test_the_histograms_median_is_numpys_within_its_resolution(n, rng):
    # samples over twelve decades, odd and even counts
    q = 10 ** rng.uniform(-5, 7, (3, n))
    spread = NeesSpread(3)
    spread.add(q[:, : n // 2])
    spread.add(q[:, n // 2 :])  # in two parts: the counts add up
    median = spread.median()
    for b in range(3):
        ratio = median[b] / np.median(q[b])
        assert 1 / RESOLUTION <= ratio <= RESOLUTION
    assert np.array_equal(spread.samples, [n, n, n])
    assert np.array_equal(spread.inside, [inside(q[b]) for b in range(3)])


def test_samples_outside_the_range_or_masked_out():
    low, high = (10.0**d for d in NEES_DECADES)
    spread = NeesSpread(2)
    q = np.array([[low / 10, 3.0, -1e-15, 5.0, 8.0], [high * 10, np.nan, np.inf, 3.0, 7.0]])
    spread.add(q, counted=np.array([[True, True, True, True, False], [True] * 5]))
    assert np.array_equal(spread.samples, [4, 5])
    assert np.array_equal(spread.inside, [2, 2])
    # -1e-15 and low / 10 below the range count as its edge: the middle two are low and 3
    assert spread.median()[0] == pytest.approx((low + 3.0) / 2, rel=RESOLUTION - 1)
    assert spread.median()[1] == high  # 3, 7, then three beyond the range (NaN too): its edge
    assert np.isnan(NeesSpread(1).median()).all() and np.isnan(NeesSpread(1).inside_fraction())


def test_the_memory_does_not_grow_with_the_samples(rng):
    spread = NeesSpread(2)
    shape = spread.counts.shape
    spread.add(rng.chisquare(4, (2, 10**5)))
    assert spread.counts.shape == shape == (2, (NEES_DECADES[1] - NEES_DECADES[0]) * 400 + 2)


@pytest.mark.parametrize("failures", [(), ((1, 5), (3, 30))])
def test_the_tallys_median_and_inside_fraction_are_those_of_the_trace(short, failures):
    scenario = short.with_overrides({"faults.failures": [list(f) for f in failures]})
    r = uavtrack.simulate(scenario, "distributed", seed=3)
    tr = r.trace
    alive = np.broadcast_to(tr.alive[..., None], tr.mean.shape[:-1])  # (T, Nu, Nt)
    q = estimation.nees(tr.mean, tr.cov, tr.targets[:, None])[alive]
    assert len(q) == tr.alive.sum() * short.n_targets and (len(q) < 1200) == bool(failures)
    assert r.nees == pytest.approx(q.mean(), rel=1e-9)
    assert 1 / RESOLUTION <= r.nees_median / np.median(q) <= RESOLUTION
    assert r.nees_inside * len(q) == pytest.approx(inside(q), abs=1e-9)
    # the team's best: the most confident living UAV's estimate (lowest index on ties)
    conf = np.where(tr.alive[..., None], 1.0 / np.trace(tr.cov, axis1=-2, axis2=-1), -np.inf)
    best = np.argmax(conf, axis=1)
    steps, targets = np.meshgrid(np.arange(short.steps), np.arange(short.n_targets), indexing="ij")
    qb = estimation.nees(tr.mean[steps, best, targets], tr.cov[steps, best, targets], tr.targets)
    assert r.nees_best == pytest.approx(qb.mean(), rel=1e-9)
    assert 1 / RESOLUTION <= r.nees_best_median / np.median(qb) <= RESOLUTION
    assert r.nees_best_inside * qb.size == pytest.approx(inside(qb), abs=1e-9)


def consistent_cycle(rng, truth, n_uavs, alive):
    """A cycle whose every estimate errs by a draw of its own covariance: NEES ~ chi2(4)."""
    B, Nt = truth.shape[:2]
    A = rng.normal(size=(B, n_uavs, Nt, 4, 4))
    cov = A @ np.swapaxes(A, -1, -2) + 0.5 * np.eye(4)
    error = (np.linalg.cholesky(cov) @ rng.normal(size=(B, n_uavs, Nt, 4, 1)))[..., 0]
    zeros = np.zeros((B, n_uavs))
    return SimpleNamespace(
        alive=alive,
        mean=np.where(alive[..., None, None], truth[:, None] - error, np.nan),
        cov=cov,
        observed=np.zeros((B, n_uavs, Nt), dtype=bool),
        confidence=None,
        rounds=zeros,
        messages=np.zeros(B),
        delivered=np.zeros(B),
        bytes=np.zeros((B, n_uavs), dtype=np.int64),
        node_bytes=np.zeros(B, dtype=np.int64),
        conflicts=np.zeros(B),
        decision_time_ms=zeros + np.nan,
        decision_wall_ms=zeros + np.nan,
    )


def test_a_consistent_estimators_nees_is_inside_its_interval_95_percent_of_the_time(rng):
    B, Nu, Nt, T = 2, 3, 5, 400
    tally = Tally(batch=B, n_uavs=Nu, n_targets=Nt)
    alive = np.ones((B, Nu), dtype=bool)
    for k in range(T):
        if k == T // 2:
            alive[1, 2] = False  # a failed UAV's NaN estimates count in nothing
        truth = rng.uniform(0, 100, (B, Nt, 4))
        tally.add(consistent_cycle(rng, truth, Nu, alive.copy()), truth)
    s = tally.summary()
    n = np.array([T * Nu * Nt, T * Nu * Nt - (T // 2) * Nt])
    assert np.array_equal(tally.spread["nees"].samples, n)
    for b in range(B):
        for fraction, count in ((s["nees_inside"][b], n[b]), (s["nees_best_inside"][b], T * Nt)):
            low, high = stats.binom.interval(0.99, count, 0.95)
            assert low / count <= fraction <= high / count
        # the median of chi2(4), 3.357, within the 99 % order-statistic interval of the sample's
        for median, count in ((s["nees_median"][b], n[b]), (s["nees_best_median"][b], T * Nt)):
            lo, hi = stats.binom.interval(0.99, count, 0.5)
            band = stats.chi2.ppf([lo / count, hi / count], 4)
            assert band[0] / RESOLUTION <= median <= band[1] * RESOLUTION
        assert s["nees"][b] == pytest.approx(4.0, abs=0.25)


def test_the_run_commands_json_carries_the_distribution(capsys):
    code = cli.main(["run", "--set", "steps=30", "--json", "--seed", "2"])
    out, err = capsys.readouterr()
    assert code == 0, err
    data = json.loads(out)
    r = uavtrack.simulate(uavtrack.Scenario(steps=30), seed=2, trace=False)
    for name in ("nees_median", "nees_inside", "nees_best_median", "nees_best_inside"):
        assert data[name] == pytest.approx(getattr(r, name), rel=1e-12), name
    assert 0 < data["nees_inside"] <= 1 and data["nees_median"] > 0
    code = cli.main(["run", "--set", "steps=10"])
    out, _ = capsys.readouterr()
    assert (
        code == 0
        and "NEES median" in out
        and "NEES inside its 95% interval" in " ".join(out.split())
    )
