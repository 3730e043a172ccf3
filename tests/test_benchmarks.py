"""The benchmark scripts run as the documentation gives them: they print their figures
and write a file only where ``--out`` names one, so a run never replaces the published
figures (benchmarks/*-2core.json). Each runs as a copy laid out as in the checkout, so
that a script that did write its default file would write it there, not here."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration  # the benchmark scripts run as commands

ROOT = Path(__file__).resolve().parents[1]


def run(script: str, checkout: Path, *args: str) -> subprocess.CompletedProcess:
    """``python benchmarks/<script> args`` from the root of a copy of the checkout."""
    (checkout / "benchmarks").mkdir(parents=True, exist_ok=True)
    shutil.copy(ROOT / "benchmarks" / script, checkout / "benchmarks")
    path = os.pathsep.join(filter(None, [str(ROOT / "src"), os.environ.get("PYTHONPATH")]))
    return subprocess.run(
        [sys.executable, f"benchmarks/{script}", *args],
        cwd=checkout, env={**os.environ, "PYTHONPATH": path, "MPLBACKEND": "Agg"},
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip


def files_in(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


@pytest.mark.parametrize(
    "script, args",
    [("env.py", ["--steps", "1", "--repeats", "1"]), ("flight.py", ["--steps", "1"])],
)
def test_the_documented_command_writes_no_file(script, args, tmp_path):
    if script == "flight.py":
        pytest.importorskip("jsbsim")
    done = run(script, tmp_path, *args)
    assert done.returncode == 0, done.stderr
    assert "real time" in done.stdout or "agent-steps/s" in done.stdout
    assert files_in(tmp_path) == [f"benchmarks/{script}"]  # no benchmarks/*-2core.json


def test_env_benchmark_writes_its_json_only_where_asked(tmp_path):
    done = run("env.py", tmp_path, "--steps", "1", "--repeats", "1", "--out", "mine.json")
    assert done.returncode == 0, done.stderr
    assert files_in(tmp_path) == ["benchmarks/env.py", "mine.json"]
    figures = json.loads((tmp_path / "mine.json").read_text())
    assert [row["trials"] for row in figures["vector"]] == [1, 16, 64, 256]
    single = figures["single"]["agent_steps_per_wall_s"]
    for row in figures["vector"]:
        for form in ("with_paper_actions", "agents_only"):
            got = row[form]
            assert got["times_single"] == pytest.approx(got["agent_steps_per_wall_s"] / single)


def test_a_bad_out_is_refused_before_the_timings(tmp_path):
    (tmp_path / "taken").mkdir()
    done = run("env.py", tmp_path, "--out", "taken")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "--out: taken is a directory" in done.stderr.strip().splitlines()[-1]
    assert done.stdout == ""  # nothing was timed


def test_sensing_benchmark_prints_the_ratio_and_writes_only_where_asked(tmp_path):
    args = ("--steps", "5", "--team-steps", "1", "--repeats", "1")
    done = run("sensing.py", tmp_path, *args)
    assert done.returncode == 0, done.stderr
    assert "ratio" in done.stdout and files_in(tmp_path) == ["benchmarks/sensing.py"]
    done = run("sensing.py", tmp_path / "b", *args, "--out", "mine.json")
    assert done.returncode == 0, done.stderr
    figures = json.loads((tmp_path / "b" / "mine.json").read_text())
    for row in figures["results"]:
        assert row["ratio"] == pytest.approx(row["jpda_cpu_s"] / row["known_cpu_s"])
    bad = run("sensing.py", tmp_path / "c", "--steps", "0")
    assert bad.returncode == 2 and "at least 1" in bad.stderr


@pytest.mark.parametrize("method", ["distributed", "centralized", "greedy"])
def test_the_cycle_profile_finds_every_stage_of_each_method(method, tmp_path):
    # a stage function renamed or moved would leave its stage at zero and its time in
    # "other"; the noise stage is the only one a short run may not reach measurably
    done = run("profile_cycle.py", tmp_path, method, "1", "steps=20")
    assert done.returncode == 0, done.stderr
    shown = {line.split()[0]: float(line.split()[1]) for line in done.stdout.splitlines()[1:]}
    stages = set(shown) - {"total", "other", "noise"}
    assert stages == {
        "graph", "sensing", "filter", "confidence", "fusion", "planning", "auction",
        "control", "prediction", "metrics",
    }  # fmt: skip
    assert all(shown[stage] > 0 for stage in stages), shown
    assert files_in(tmp_path) == ["benchmarks/profile_cycle.py"]


def test_the_cycle_profile_names_the_stages_of_the_track_pipeline(tmp_path):
    tracked = ("tracker.association=jpda", "sensor.detection_probability=0.9")
    done = run("profile_cycle.py", tmp_path, "distributed", "1", "steps=20", *tracked)
    assert done.returncode == 0, done.stderr
    shown = {line.split()[0]: float(line.split()[1]) for line in done.stdout.splitlines()[1:]}
    assert {"scan", "tracking", "agreement", "columns", "metrics"} <= set(shown)
    assert "fusion" not in shown  # the oracle's consensus does not run
    # the named stages hold most of the cycle: "other" is the driver's share
    assert shown["other"] < 0.5 * shown["total"], shown


@pytest.mark.slow  # 25 s; test_scoring checks the scores against Stone Soup's in the default
def test_the_trackers_head_to_head_replays_the_run_and_scores_both(tmp_path):
    """uavtrack's central tracker replayed on a run's scans must give the run's tracks
    (the script stops otherwise); Stone Soup's tracker runs on the same scans; both
    are scored and the table printed, and a file written only where asked."""
    pytest.importorskip("stonesoup")
    args = ("--trials", "1", "--steps", "15")
    done = run("trackers.py", tmp_path, *args)
    assert done.returncode == 0, done.stderr
    rows = [line for line in done.stdout.splitlines() if line.startswith("| ")]
    assert [row.split(" | ")[0] for row in rows[1:]] == ["| uavtrack", "| stonesoup"]
    assert files_in(tmp_path) == ["benchmarks/trackers.py"]
    done = run("trackers.py", tmp_path / "b", *args, "--association", "gnn", "--out", "t.json")
    assert done.returncode == 0, done.stderr
    means = json.loads((tmp_path / "b" / "t.json").read_text())["means"]
    for who in ("uavtrack", "stonesoup"):  # GOSPA is its three parts (p = 1)
        m = means[who]
        assert m["gospa"] == pytest.approx(m["localisation"] + m["missed"] + m["false"])
    bad = run("trackers.py", tmp_path / "c", "--detection", "1.5")
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
