import numpy as np
import pytest
from scipy import stats

import uavtrack
from uavtrack.experiments import robustness, statistics
from uavtrack.experiments.jobs import unique


def test_plan_shares_equal_configurations_and_covers_every_series():
    profile = robustness.Profile()
    plan = robustness.plan(uavtrack.Scenario(), profile)
    jobs = unique(j for group in plan.values() for j in group)
    assert len({j.key for j in jobs}) == len(jobs)
    # no-fault runs are shared by every fault; a burst of length 1 is independent loss
    no_fault = {j.key for j in plan["loss"] if j.label == "default"}
    for name in ("delay", "round_budget", "failure_rate", "position_std"):
        assert no_fault <= {j.key for j in plan[name]}
    burst_one = {j.key for j in plan["burst"] if "burst_length" not in j.label and "0.3" in j.label}
    assert burst_one and burst_one <= {j.key for j in plan["loss"]}
    methods = {j.method for j in jobs}
    assert methods == {"distributed", "centralized", "greedy"}
    robust = [j for j in jobs if "robust.stale=True" in j.label]
    assert robust and all(j.method == "distributed" for j in robust)
    assert all(j.count == profile.chunk for j in jobs)


def test_ci95_is_the_t_interval(rng):
    values = rng.normal(0.7, 0.05, 12)
    low, high = stats.t.interval(0.95, 11, loc=values.mean(), scale=stats.sem(values))
    assert statistics.ci95(values) == pytest.approx((high - low) / 2)
    assert np.isnan(statistics.ci95(values[:1]))


def test_series_settings():
    assert robustness.series_method("robust") == ("distributed", robustness.ROBUST)
    assert robustness.series_method("greedy") == ("greedy", {})
    scenario = uavtrack.Scenario().with_overrides(robustness.ROBUST)
    assert scenario.robust.stale and scenario.robust.extra_rounds == 2
