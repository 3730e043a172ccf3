"""The bench's own correctness checks (it refuses to time things that disagree).

No timing is asserted here; speed is measured by `uavtrack bench`.
"""

import json

import pytest

from uavtrack.experiments import bench


def test_kalman_equals_filterpy():
    pytest.importorskip("filterpy")
    result = bench.kalman_case(20, repeats=1)
    assert result["equal_outputs"] and result["unit"] == "filter" and result["speedup"] > 0


def test_planner_choices_equal_both_references():
    results = bench.planner_case(4, 3, repeats=1)
    assert [r["equal_choices"] for r in results] == [True, True]


def test_plain_sequence_loop_is_an_exhaustive_search():
    scenario = bench.team(3, 2, steps=5)
    trace = bench.simulate(scenario, "greedy", seed=0).trace
    args = (scenario.sensor, 0.7, 3, scenario.dt)
    value, first = bench.plan_by_sequence(trace.uavs[-1], trace.mean[-1], *args)
    reference = bench.planning.plan_exhaustive(trace.uavs[-1], trace.mean[-1], *args)
    assert (first == reference.action).all()
    assert value == pytest.approx(reference.value, rel=1e-12)


def test_batched_equals_one_at_a_time_in_bench():
    assert bench.batch_case(3, 15, repeats=1)["equal_results"]


def test_cycle_cases_report_each_method():
    rows = bench.cycle_cases([(3, 2)], ("distributed", "greedy"), repeats=1)
    assert [r["method"] for r in rows] == ["distributed", "greedy"]
    assert all(r["median_s"] > 0 and r["real_time_factor"] > 0 for r in rows)


def test_team_keeps_altitude_spread():
    assert bench.team(100, 100).altitudes()[0] == pytest.approx(415.0)


def test_bench_json_is_written_atomically(tmp_path, monkeypatch):
    # the command with a stand-in for the (long) measurements
    from uavtrack import cli

    monkeypatch.setattr(
        bench,
        "bench",
        lambda quick, progress=None: {
            "machine": {"cores": 2, "blas_threads": "1 (environment)"},
            "quick": quick,
            "cases": [bench.case("x", 2e-3, 4e-3, unit="call")],
        },
    )
    out = tmp_path / "b.json"
    assert cli.main(["bench", "--quick", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["cases"][0]["speedup"] == pytest.approx(2.0)
    assert data["cases"][0]["median_s"] == pytest.approx(2e-3)


def test_mid_run_state_is_the_runs_state():
    # k steps of `mid_run` are the first k steps of a run with the same seed
    import numpy as np

    scenario = bench.Scenario(steps=6).scaled(12, 12)
    state, targets, _ = bench.mid_run(scenario, k=5)
    trace = bench.simulate(scenario, "distributed", seed=bench.trial_seed(0, 0)).trace
    assert state.k == 5
    assert np.array_equal(state.uavs[0], trace.uavs[5])
    assert np.array_equal(targets[0], trace.targets[5])
    assert np.array_equal(state.target[0], trace.assignment[4])


@pytest.mark.integration
def test_run_case_reports_its_memory_peak_beside_the_estimate():
    row = bench.run_case(12, 12, steps=5)
    assert row["unit"] == "step" and row["steps"] == 5
    # the process's peak holds Python and the libraries: above the run's own estimate
    assert row["peak_bytes"] > row["estimate_bytes"] > 0


def test_scaling_figure_needs_scaled_cases(tmp_path):
    from uavtrack.experiments import figures

    rows = bench.cycle_cases([(4, 4), (8, 8)], ("distributed",), repeats=1, scaled=True)
    assert [r["scaled"] for r in rows] == [True, True]
    figures.scaling_figure(rows, tmp_path / "s.png")
    assert (tmp_path / "s.png").stat().st_size > 0
    with pytest.raises(ValueError, match="no scaled decision-cycle cases"):
        figures.scaling_figure(
            bench.cycle_cases([(3, 2)], ("greedy",), repeats=1), tmp_path / "t.png"
        )
    assert not (tmp_path / "t.png").exists()
