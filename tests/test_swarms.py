"""Large teams: the exact reductions (k-d tree radio, flooding on the receivers with
links, the pruned planner, the restricted auction) decide as the dense code does."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import uavtrack
from uavtrack import assignment, network

from .test_assignment import full_problem as dense_solve  # every column, no restriction


def dense(monkeypatch):
    """The code as it was before the reductions: dense radio and flooding, every bid
    scored, every auction over all targets."""
    monkeypatch.setattr(network, "SPARSE_FROM", 10**9)
    monkeypatch.setattr(assignment, "_solve", lambda bids, clock=None: dense_solve(bids))
    monkeypatch.setattr(assignment, "_restricted", lambda bids, best, clock=None: dense_solve(bids))


@settings(max_examples=8, deadline=None)
@given(
    st.integers(5, 60),
    st.integers(5, 60),
    st.integers(0, 2**16),
    st.sampled_from(["distributed", "centralized", "greedy"]),
)
def test_large_team_decides_as_the_dense_code(n_uavs, n_targets, seed, method):
    scenario = uavtrack.Scenario(steps=12).scaled(n_uavs, n_targets)
    fast = uavtrack.simulate(scenario, method, seed=seed).trace
    with pytest.MonkeyPatch.context() as mp:
        dense(mp)
        slow = uavtrack.simulate(
            scenario.with_overrides({"planner.prune": False}), method, seed=seed
        ).trace
    for name in ("targets", "uavs", "observed", "assignment", "action", "rounds", "messages"):
        assert np.array_equal(getattr(fast, name), getattr(slow, name)), name
    for name in ("mean", "cov"):
        assert np.array_equal(getattr(fast, name), getattr(slow, name)), name
    scored = ~np.isnan(fast.bids)
    assert np.array_equal(fast.bids[scored], slow.bids[scored])


def test_pruning_leaves_bids_unscored_in_a_large_team():
    scenario = uavtrack.Scenario(steps=3).scaled(60, 60)
    bids = uavtrack.simulate(scenario, "distributed", seed=1).trace.bids
    assert 0 < np.isnan(bids).mean() < 1
    unpruned = scenario.with_overrides({"planner.prune": False})
    assert not np.isnan(uavtrack.simulate(unpruned, "distributed", seed=1).trace.bids).any()


def test_pruning_is_off_where_bids_may_be_stale_or_lost():
    scenario = uavtrack.Scenario(steps=3).scaled(40, 40)
    for fault in ({"faults.loss": 0.2}, {"faults.delay": 1}):
        bids = uavtrack.simulate(scenario.with_overrides(fault), "distributed", seed=1).trace.bids
        assert not np.isnan(bids).any(), fault


def test_batch_equals_each_trial_alone_with_pruning():
    scenario = uavtrack.Scenario(steps=8).scaled(30, 30)
    seeds = [uavtrack.trial_seed(0, t) for t in range(3)]
    batch = uavtrack.run(scenario, "distributed", seeds, trace=True)
    for t, seed in enumerate(seeds):
        alone = uavtrack.simulate(scenario, "distributed", seed=seed).trace
        for name in ("assignment", "action", "uavs", "observed"):
            assert np.array_equal(getattr(batch.traces[t], name), getattr(alone, name)), name
        assert np.array_equal(batch.traces[t].bids, alone.bids, equal_nan=True)


def test_scaled_scenario_keeps_density_band_and_validates():
    base = uavtrack.Scenario()
    heights = base.altitudes()
    for n, m in [(5, 4), (20, 30), (300, 300), (1000, 1000)]:
        big = base.scaled(n, m)
        assert (big.n_uavs, big.n_targets) == (n, m)
        density = (n + m) / big.field_size**2
        assert density == pytest.approx((base.n_uavs + base.n_targets) / base.field_size**2)
        assert min(big.altitudes()) == pytest.approx(min(heights))
        assert max(big.altitudes()) == pytest.approx(max(heights))
        assert big.uav.start_spread == big.field_size
    # the default team scaled to itself changes only where the UAVs start
    same = base.scaled(base.n_uavs, base.n_targets)
    assert same.with_overrides({"uav.start_spread": base.uav.start_spread}) == base
    with pytest.raises(uavtrack.ScenarioError, match="n_uavs must be a positive integer"):
        base.scaled(0, 10)


def test_a_team_too_large_for_its_altitudes_is_told_how_to_scale():
    with pytest.raises(uavtrack.ScenarioError, match=r"altitude_spacing to .* --team 300x300"):
        uavtrack.Scenario(n_uavs=300, n_targets=300)
