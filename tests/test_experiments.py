import numpy as np
import pytest
from scipy import stats

import uavtrack
from uavtrack.experiments import jobs as job_lists
from uavtrack.experiments import reproduce, statistics
from uavtrack.experiments.reproduce import Profile
from uavtrack.metrics import METRICS


def test_reproduce_plan_shares_the_default_runs():
    plan = reproduce.reproduce_plan(uavtrack.Scenario(), Profile())
    keys = {name: {j.key for j in jobs} for name, jobs in plan.items()}
    # r_C = 50 m (Fig. 8) and alpha = 5 deg (Fig. 9) are Fig. 5's distributed runs
    default = {k for k in keys["compare"] if "__distributed__" in k}
    assert default <= keys["comm_range"] and default <= keys["fov"]
    jobs = job_lists.unique(j for group in plan.values() for j in group)
    assert len(jobs) == len({j.key for j in jobs})
    trial_jobs = [j for j in jobs if j.kind == "trials"]
    # 3 methods at the defaults and at the first guess + 7 other ranges + 5 other FOVs,
    # one job of all 50 trials each
    assert len(trial_jobs) == 3 + 3 + 7 + 5
    assert {j.count for j in trial_jobs} == {50}
    assert all(j.scenario.steps == 500 for j in trial_jobs)


def test_sensitivity_moves_one_assumed_parameter_at_a_time():
    base = uavtrack.Scenario()
    plain = reproduce.reproduce_plan(base, Profile())
    plan = reproduce.reproduce_plan(base, Profile(), sensitivity=True)
    assert {k: [j.key for j in v] for k, v in plain.items()} == {
        k: [j.key for j in v] for k, v in plan.items() if k != "sensitivity"
    }
    moved = set()
    for job in plan["sensitivity"]:
        diff = job_lists.difference(base.with_overrides({"steps": 500}), job.scenario)
        assert len(diff) == 1, diff
        ((field, value),) = diff.items()
        assert value in reproduce.SENSITIVITY[field] and value != base.value(field)
        moved.add(field)
        assert "assumed" in dict((n, d) for n, _, d in base.describe())[field]
    assert moved == set(reproduce.SENSITIVITY)


def test_conclusion_verdicts_follow_the_confidence_interval():
    rng = np.random.default_rng(0)
    noise = rng.normal(0, 0.01, 50)
    greedy = {"observation_rate": np.full(50, 0.5)}
    cases = {-0.01: "yes", -0.06: "no", -0.029: "yes, CI crosses", -0.031: "no, CI crosses"}
    for gap, verdict in cases.items():
        dist = {"observation_rate": 0.8 + noise}
        cent = {"observation_rate": 0.8 - gap + noise[::-1]}
        out = reproduce.conclusions([dist, cent, greedy])
        assert out["distributed - centralized"]["mean"] == pytest.approx(gap)
        assert out["near_centralized"] == verdict
        assert out["above_greedy"] == "yes"


def test_chunks_cover_trials_exactly_once():
    jobs = job_lists.trial_jobs(uavtrack.Scenario(), {"comm_range": 20.0}, "greedy", 23, 10, 0)
    covered = [t for j in jobs for t in range(j.first, j.first + j.count)]
    assert covered == list(range(23))
    assert jobs[0].label == "comm_range=20"


def test_results_do_not_depend_on_chunking():
    scenario = uavtrack.Scenario(steps=40)
    whole = job_lists.run_job(job_lists.trial_jobs(scenario, {}, "distributed", 4, 4, 9)[0])
    parts = [
        job_lists.run_job(j) for j in job_lists.trial_jobs(scenario, {}, "distributed", 4, 2, 9)
    ]
    for name in ("observation_rate", "per_target", "rounds", "messages"):
        assert np.array_equal(np.asarray(whole[name]), np.concatenate([p[name] for p in parts]))
    assert np.allclose(whole["rmse"], np.concatenate([p["rmse"] for p in parts]), rtol=1e-12)


def test_paired_confidence_interval_matches_t_test(rng):
    a, b = rng.normal(0.8, 0.05, 30), rng.normal(0.7, 0.05, 30)
    p = statistics.paired(a, b)
    lo, hi = stats.ttest_rel(a, b).confidence_interval(0.95)
    assert p["mean"] == pytest.approx(np.mean(a - b))
    assert (p["ci_low"], p["ci_high"]) == pytest.approx((lo, hi))


def test_describe_sorted_ranks():
    metrics = {
        "observation_rate": np.array([0.5, 0.7]),
        "per_target": np.array([[0.9, 0.1], [0.6, 0.8]]),
    }
    for name in METRICS:
        if name in ("observation_rate", "per_target"):
            continue
        metrics[name] = np.zeros(2)
    metrics["decision_time_ms"] = np.array([0.5, np.nan])  # measured for trial 0 only
    d = statistics.describe(metrics)
    assert d["sorted_mean"] == pytest.approx([0.35, 0.85])
    assert d["per_target_mean"] == pytest.approx([0.75, 0.45])
    assert d["mean"] == pytest.approx(0.6) and d["std"] == pytest.approx(np.std([0.5, 0.7], ddof=1))
    assert d["decision_time_ms"]["mean"] == 0.5 and d["decision_time_ms"]["trials"] == 1
    assert np.isnan(d["decision_time_ms"]["std"])  # one value: no spread


def test_resized_team_keeps_the_altitude_spread():
    base = uavtrack.Scenario()
    big = reproduce.resized(base, 21, 30)
    assert (big.n_uavs, big.n_targets) == (21, 30)
    assert min(big.altitudes()) == pytest.approx(415.0) and max(big.altitudes()) == pytest.approx(
        435.0
    )
    assert len(set(big.altitudes())) == 21
    assert reproduce.resized(base, 5, 4) == base


def test_an_experiment_of_more_trials_than_it_can_hold_is_refused_before_planning():
    from uavtrack.experiments.jobs import trial_jobs
    from uavtrack.limits import MAX_TRIALS

    scenario = uavtrack.Scenario(steps=5)
    assert len(trial_jobs(scenario, {}, "greedy", MAX_TRIALS, 10, 0)) == MAX_TRIALS // 10
    with pytest.raises(uavtrack.ScenarioError, match="give 1 to 100,000"):
        trial_jobs(scenario, {}, "greedy", 10**8, 10, 0)
