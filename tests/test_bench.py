"""The bench's own correctness checks (it refuses to time things that disagree).

No timing is asserted here; speed is measured by `uavtrack bench`.
"""

import json
import subprocess
import sys

import pytest

from uavtrack import bench


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


def test_import_does_not_load_numpy_and_bench_pins_threads(tmp_path):
    code = (
        "import sys, uavtrack, uavtrack.cli.benchmark as cli\n"
        "assert 'numpy' not in sys.modules\n"
        "print(cli.pin_threads())\n"
        "import numpy, os\n"
        "print(os.environ['OPENBLAS_NUM_THREADS'])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["environment", "1"]


def test_bench_json_is_written_atomically(tmp_path, monkeypatch):
    # the command with a stand-in for the (long) measurements
    from uavtrack import cli

    monkeypatch.setattr(
        bench,
        "bench",
        lambda quick, progress=None: {
            "machine": {"cores": 2},
            "quick": quick,
            "cases": [bench.case("x", 2e-3, 4e-3, unit="call")],
        },
    )
    out = tmp_path / "b.json"
    assert cli.main(["bench", "--quick", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["cases"][0]["speedup"] == pytest.approx(2.0)
    assert data["cases"][0]["median_s"] == pytest.approx(2e-3)
