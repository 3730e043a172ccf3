import json
import os
import pty
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import uavtrack
from uavtrack import cli


def run_cli(capsys, *args):
    code = cli.main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def test_run_json(capsys):
    code, out, err = run_cli(
        capsys, "run", "--set", "steps=30", "--json", "--method", "greedy", "--seed", "4"
    )
    assert code == 0, err
    data = json.loads(out)
    assert data["method"] == "greedy" and data["seed"] == 4
    assert set(data) >= {"observation_rate", "per_target", "rmse", "nees"}
    assert len(data["per_target"]) == 4
    assert data["observation_rate"] == pytest.approx(np.mean(data["per_target"]))
    assert data["scenario"]["steps"] == 30


def test_run_table_and_set_nested(capsys):
    code, out, _ = run_cli(
        capsys,
        "run",
        "--set",
        "steps=20",
        "--set",
        "sensor.half_fov_deg=10",
        "--set",
        "n_targets=2",
    )
    assert code == 0
    assert "observation rate" in out and "target 1" in out and "target 2" not in out


def test_config_file_and_override_precedence(capsys, tmp_path):
    config = tmp_path / "s.toml"
    config.write_text("steps = 15\nn_targets = 3\n[sensor]\nhalf_fov_deg = 8.0\n")
    code, out, _ = run_cli(capsys, "run", "--config", str(config), "--set", "n_targets=2", "--json")
    data = json.loads(out)
    assert code == 0 and data["scenario"]["steps"] == 15
    assert data["scenario"]["n_targets"] == 2 and data["scenario"]["sensor"]["half_fov_deg"] == 8.0


def test_trace_file(capsys, tmp_path):
    path = tmp_path / "t.npz"
    code, _, err = run_cli(capsys, "run", "--set", "steps=12", "--trace", str(path))
    assert code == 0, err
    with np.load(path) as npz:
        assert npz["targets"].shape == (12, 4, 4)
        assert npz["uavs"].shape == (12, 5, 5)
        assert npz["mean"].shape == (12, 5, 4, 4)
        assert npz["cov"].shape == (12, 5, 4, 4, 4)
        assert npz["observed"].shape == (12, 5, 4) and npz["observed"].dtype == bool
        assert npz["assignment"].shape == (12, 5) and npz["rounds"].shape == (12, 5)
    assert [p.name for p in tmp_path.iterdir()] == ["t.npz"]


def test_team_scales_the_scenario_before_the_overrides(capsys):
    code, out, err = run_cli(
        capsys, "run", "--team", "30x40", "--set", "steps=6", "--set", "field_size=900", "--json"
    )
    assert code == 0, err
    data = json.loads(out)["scenario"]
    expected = uavtrack.Scenario().scaled(30, 40)
    assert (data["n_uavs"], data["n_targets"], data["field_size"]) == (30, 40, 900.0)
    assert data["uav"]["altitude_spacing"] == expected.uav.altitude_spacing


BAD = [
    (["run", "--set", "foo=1"], "unknown scenario field 'foo'"),
    (["run", "--set", "sensor.fov=1"], "unknown scenario field 'sensor.fov'"),
    (["run", "--set", "n_uavs=abc"], "n_uavs: Input should be a valid integer"),
    (["run", "--set", "comm_range=-10"], "comm_range: Input should be greater than or equal to 0"),
    (["run", "--set", "n_uavs=0"], "n_uavs: Input should be greater than or equal to 1"),
    (
        ["run", "--set", "sensor.half_fov_deg=90"],
        "sensor.half_fov_deg: Input should be less than 90",
    ),
    (["run", "--set", "steps"], "--set expects FIELD=VALUE"),
    (["run", "--method", "best"], "'best' is not one of"),
    (["run", "--seed", "-3"], "--seed"),
    (["run", "--config", "/nonexistent/s.toml"], "cannot read config file"),
    (["run", "--bogus"], "No such option: --bogus"),
    (["nocommand"], "No such command"),
    (["run", "--team", "300"], "--team expects NxM"),
    (["sweep", "dt", "1", "--team", "0x4"], "--team expects NxM"),
    (["params", "--team", "9x9", "--set", "n_targets=3"], "do not --set n_targets too"),
    (["sweep", "n_uavs", "10", "30", "--team", "20x20"], "do not sweep n_uavs too"),
    (["run", "--set", "n_uavs=300", "--set", "n_targets=300"], "--team 300x300"),
    (["sweep", "comm_range", "50", "--trials", "100000000"], "less than or equal to 100000"),
    (["run", "--team", "9" * 5000 + "x3"], "--team expects NxM"),
    (["sensing", "--trials", "100001"], "less than or equal to 100000"),
    (["compare", "--trials", "100001"], "less than or equal to 100000"),
]


@pytest.mark.parametrize("args,message", BAD)
def test_bad_input_exits_2_with_one_line(capsys, tmp_path, args, message):
    trace = tmp_path / "out.npz"
    code, out, err = run_cli(capsys, *args, *(["--trace", str(trace)] if args[0] == "run" else []))
    assert code == 2
    assert message in err
    assert err.count("\n") == 1 and err.startswith("uavtrack: error: ")
    assert "Traceback" not in err + out
    assert not any(tmp_path.iterdir())  # nothing half-written


def test_malformed_config_file(capsys, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[sensor\nk_d = 1\n")
    code, _, err = run_cli(capsys, "run", "--config", str(bad))
    assert code == 2 and "not valid TOML" in err and err.count("\n") == 1
    typo = tmp_path / "typo.toml"
    typo.write_text("n_uav = 3\n")
    code, _, err = run_cli(capsys, "run", "--config", str(typo))
    assert code == 2 and "unknown field 'n_uav'" in err


HOSTILE_CONFIGS = {
    "tables nested 3000 deep": ("a = " + "{b = " * 3000 + "1" + "}" * 3000, "nested deeper"),
    "arrays nested 3000 deep": ("a = " + "[" * 3000 + "]" * 3000, "nested deeper"),
    "a header 3000 keys deep": ("[" + ".".join(["a"] * 3000) + "]\nx = 1", "nested deeper"),
    "a 5000-digit integer": ("steps = " + "9" * 5000, "a number of more than 4300 digits"),
}


@pytest.mark.parametrize("name", list(HOSTILE_CONFIGS))
def test_a_hostile_config_file_or_value_is_refused_in_one_line(capsys, tmp_path, name):
    text, message = HOSTILE_CONFIGS[name]
    config = tmp_path / "hostile.toml"
    config.write_text(text)
    trace = tmp_path / "t.npz"
    value = text.split(" = ", 1)[1] if not text.startswith("[") else None
    tries = [["--config", str(config)]] + ([["--set", f"steps={value}"]] if value else [])
    for args in tries:
        code, out, err = run_cli(capsys, "run", *args, "--trace", str(trace))
        assert code == 2 and message in err, err[:300]
        assert err.count("\n") == 1 and len(err) < 300 and "Traceback" not in err + out
    assert not trace.exists()


def test_a_config_file_is_read_up_to_a_limit(capsys, tmp_path):
    """/dev/zero and a runaway file: refused after 1 MiB, not read whole."""
    from uavtrack.config import toml

    big = tmp_path / "big.toml"
    big.write_text("# " + "x" * toml.MAX_BYTES + "\nsteps = 5\n")
    for path in (big, Path("/dev/zero")):
        if not path.exists():
            continue
        code, _, err = run_cli(capsys, "run", "--config", str(path))
        assert code == 2 and "larger than 1024 KiB" in err and err.count("\n") == 1
    small = tmp_path / "small.toml"
    small.write_text("# " + "x" * (toml.MAX_BYTES - 100) + "\nsteps = 5\n")
    assert uavtrack.Scenario.from_toml(small).steps == 5  # up to the limit, read


def test_an_error_shows_a_long_value_cut(capsys):
    code, _, err = run_cli(capsys, "run", "--set", "steps=" + "9" * 4000)
    assert code == 2 and "less than or equal to" in err and "(4000 chars)" in err
    assert len(err) < 300


def test_trace_into_missing_directory(capsys, tmp_path):
    code, _, err = run_cli(
        capsys, "run", "--set", "steps=5", "--trace", str(tmp_path / "no" / "t.npz")
    )
    assert code == 2 and "does not exist" in err


def test_params_lists_every_field(capsys, tmp_path):
    code, out, _ = run_cli(capsys, "params", "--toml", "--set", "comm_range=60")
    assert code == 0 and "comm_range = 60.0" in out and "[sensor]" in out
    lines = out.splitlines()
    # each field's unit, range and source just above it, as TOML comments
    above = lines[lines.index("comm_range = 60.0") - 1]
    assert above.startswith("# communication range r_C") and "[m]" in above
    assert "# round_budget =   (not set)" in lines
    (tmp_path / "s.toml").write_text(out)  # and it reads back as the same scenario
    import uavtrack

    again = uavtrack.Scenario.from_toml(tmp_path / "s.toml")
    assert again == uavtrack.Scenario().with_overrides({"comm_range": 60.0})


@pytest.mark.integration
def test_console_script_exit_code():
    proc = subprocess.run(
        [sys.executable, "-m", "uavtrack.cli", "run", "--set", "planner.horizon=0"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    expected = "--set: planner.horizon: Input should be greater than or equal to 2 (got 0)"
    assert proc.stderr.strip() == f"uavtrack: error: {expected}"


def cli_command(*args):
    return [sys.executable, "-m", "uavtrack.cli", *args]


@pytest.mark.parametrize("name", ["run.trace", "t", "T.NPZ"])
def test_trace_is_written_at_exactly_the_path_given(capsys, tmp_path, name):
    path = tmp_path / name
    path.write_text("earlier")  # replaced only when asked to
    code, out, err = run_cli(capsys, "run", "--set", "steps=6", "--trace", str(path), "--force")
    assert code == 0, err
    assert [p.name for p in tmp_path.iterdir()] == [name]
    with np.load(path) as npz:
        assert npz["assignment"].shape == (6, 5)


@pytest.mark.parametrize("target", ["folder", "fifo"])
def test_trace_to_a_folder_or_special_file_is_refused(capsys, tmp_path, target):
    # (a device node is refused the same way; not tried here, as a faulty build
    # would replace /dev/null)
    path = tmp_path / "t.npz"
    if target == "folder":
        path.mkdir()
    else:
        os.mkfifo(path)
    code, _, err = run_cli(capsys, "run", "--set", "steps=5", "--trace", str(path))
    assert code == 2 and err.count("\n") == 1 and "--trace" in err


@pytest.mark.parametrize(
    "setting,message",
    [
        ("n_uavs=true", "n_uavs: Input should be a valid integer (got True)"),
        ("steps=5\nn_uavs=3", "spans several lines"),
        ("uav.speed=inf", "uav.speed: Input should be a finite number"),
        ("target.sigma_1=inf", "target.sigma_1: Input should be a finite number"),
        ("field_size=inf", "field_size: Input should be a finite number"),
        ("dt=1e308", "dt: Input should be less than or equal to 10"),
        ("uav.altitudes=[400, 410, nan, 430, 440]", "uav.altitudes.2: Input should be a finite"),
        ("faults.loss=1.5", "faults.loss: Input should be less than or equal to 1"),
        ("faults.loss=-0.1", "faults.loss: Input should be greater than or equal to 0"),
        ("faults.failures=[[7, 10]]", "faults.failures names UAV 7, which does not exist"),
        ("faults.delay=0.5", "faults.delay: Input should be a valid integer"),
        ("faults.round_budget=0", "faults.round_budget: Input should be greater than or equal"),
        ("robust.stale=1", "robust.stale: Input should be a valid boolean"),
    ],
)
def test_bad_values_are_refused_before_any_work(capsys, setting, message):
    code, out, err = run_cli(capsys, "run", "--set", setting)
    assert code == 2 and message in err and err.count("\n") == 1 and not out


def test_version_and_short_help(capsys):
    code, out, _ = run_cli(capsys, "--version")
    assert code == 0 and out.strip() == f"uavtrack {uavtrack.__version__}"
    for args in (["-h"], ["run", "-h"], ["sweep", "-h"]):
        code, out, _ = run_cli(capsys, *args)
        assert code == 0 and out.startswith("Usage: uavtrack")


def test_help_texts_show_no_placeholders_and_name_default_folders(capsys):
    seen = ""
    for command in ("", "run", "compare", "params", "reproduce", "sweep", "animate", "bench"):
        code, out, _ = run_cli(capsys, *command.split(), "--help")
        assert code == 0
        for placeholder in ("<list[", "<int range>", "<path>", "<str>", "{"):
            assert placeholder not in out, (command, placeholder)
        seen += out
    assert "results/reproduce-quick" in seen and "results/sweep-FIELD" in seen
    assert "Usage: uavtrack sweep [OPTIONS] FIELD VALUE..." in seen
    for command in ("compare", "sweep", "reproduce"):
        code, out, _ = run_cli(capsys, command, "--help")
        assert "--steps N" in out, command


def test_run_table_explains_what_its_estimates_cover(capsys):
    code, out, _ = run_cli(capsys, "run", "--set", "steps=20")
    assert code == 0
    for label in (
        "target 0",
        "position RMSE, team's best estimate [m]",
        "position RMSE, every UAV's estimate [m]",
        "NEES, team's best estimate (4 if consistent)",
        "decision time per UAV and cycle [ms of CPU time]",
        "the same in wall time [ms]",
        "includes the stale ones",
    ):
        assert label in " ".join(out.split()), label
    assert "target 4" not in out


def test_json_names_the_decision_time_unit_and_is_strict(capsys):
    code, out, _ = run_cli(capsys, "run", "--set", "steps=10", "--json")
    data = json.loads(out)
    assert data["decision_time_ms"] > 0 and "decision_time" not in data
    assert data["decision_wall_ms"] > 0
    assert data["rmse_best"] <= data["rmse"]
    code, out, _ = run_cli(capsys, "compare", "--trials", "3", "--steps", "10", "--json")
    assert code == 0
    for r in json.loads(out, parse_constant=refuse_constant)["methods"].values():
        assert r["decision_time_ms"]["trials"] == 1  # trial 0, run alone
        assert r["decision_time_ms"]["mean"] > 0 and r["decision_time_ms"]["std"] is None
        assert r["observation_rate"]["std"] is not None
    code, out, _ = run_cli(capsys, "compare", "--trials", "1", "--steps", "10", "--json")
    for r in json.loads(out, parse_constant=refuse_constant)["methods"].values():
        assert r["observation_rate"]["std"] is None


def test_compare_gives_paired_differences_of_the_first_method(capsys):
    from scipy import stats

    args = ("compare", "--trials", "4", "--steps", "40", "--method", "greedy")
    code, out, err = run_cli(capsys, *args, "--method", "distributed", "--json")
    assert code == 0, err
    data = json.loads(out, parse_constant=refuse_constant)
    assert list(data["paired"]) == ["greedy - distributed"]
    pair = data["paired"]["greedy - distributed"]
    # the same trials, run again: the difference per trial, its mean and its t interval
    scenario = uavtrack.Scenario(steps=40)
    seeds = [uavtrack.trial_seed(0, t) for t in range(4)]
    rate = {m: uavtrack.run(scenario, m, seeds).metrics for m in ("distributed", "greedy")}
    for key in ("observation_rate", "rmse_best", "messages"):
        diff = rate["greedy"][key] - rate["distributed"][key]
        half = stats.t.ppf(0.975, 3) * diff.std(ddof=1) / 2
        assert pair[key]["mean"] == pytest.approx(diff.mean(), rel=1e-9, abs=1e-12)
        assert pair[key]["ci_low"] == pytest.approx(diff.mean() - half, rel=1e-9, abs=1e-12)
        assert pair[key]["ci_high"] == pytest.approx(diff.mean() + half, rel=1e-9, abs=1e-12)
        assert pair[key]["trials"] == 4
    assert pair["observation_rate"]["mean"] < 0  # greedy tracks less than the paper's method
    assert "decision_time_ms" not in pair  # measured on one trial: no interval
    code, out, _ = run_cli(capsys, *args, "--method", "distributed", "--method", "centralized")
    assert code == 0
    assert "greedy minus each other method, paired" in " ".join(out.split())  # wrapped
    assert "greedy − distributed" in out and "greedy − centralized" in out
    low, high = pair["observation_rate"]["ci_low"], pair["observation_rate"]["ci_high"]
    assert f"[{low:+.4f}, {high:+.4f}]" in out
    code, out, _ = run_cli(capsys, "compare", "--trials", "2", "--steps", "10", "--json")
    assert list(json.loads(out)["paired"]) == ["distributed - centralized", "distributed - greedy"]


TRACKED_SETS = (
    "--set", 'tracker.association="jpda"', "--set", "sensor.detection_probability=0.9",
    "--set", "sensor.clutter_rate=2",
)  # fmt: skip


def test_compare_with_tracks_shows_and_pairs_the_track_metrics(capsys):
    """With tracks the per-target estimate rows are n/a: the table shows GOSPA and its
    parts, the unassigned tracks and their kinds, the team picture, label purity, switches
    and SIAP, and --json pairs them, trial by trial."""
    from uavtrack.experiments.statistics import TRACK_METRICS

    args = ("compare", "--trials", "3", "--steps", "30", *TRACKED_SETS)
    code, out, err = run_cli(capsys, *args, "--method", "distributed", "--method", "greedy")
    assert code == 0, err
    text = " ".join(out.split())
    for label in ("GOSPA, each UAV's confirmed tracks", "its false part", "SIAP completeness",
                  "unassigned confirmed tracks per target and step", "duplicates (a target",
                  "never on a target (clutter-born)", "GOSPA, the team picture", "label purity",
                  "track switches"):  # fmt: skip
        assert text.count(label) == 2, label  # the means and the paired differences
    assert "RMSE" not in text and "n/a │" not in out  # no per-target estimate rows
    code, out, _ = run_cli(capsys, *args, "--method", "distributed", "--method", "greedy", "--json")
    data = json.loads(out, parse_constant=refuse_constant)
    pair = data["paired"]["distributed - greedy"]
    assert set(TRACK_METRICS) <= set(pair) and "rmse_best" not in pair
    scenario = uavtrack.Scenario(steps=30).with_overrides(
        {"tracker.association": "jpda", "sensor.detection_probability": 0.9,
         "sensor.clutter_rate": 2.0}
    )  # fmt: skip
    seeds = [uavtrack.trial_seed(0, t) for t in range(3)]
    runs = {m: uavtrack.run(scenario, m, seeds).metrics for m in ("distributed", "greedy")}
    for key in TRACK_METRICS:
        diff = runs["distributed"][key] - runs["greedy"][key]
        assert pair[key]["mean"] == pytest.approx(np.nanmean(diff), rel=1e-9, abs=1e-12), key
        assert data["methods"]["greedy"][key]["mean"] == pytest.approx(
            np.nanmean(runs["greedy"][key]), rel=1e-9, abs=1e-12
        )


def test_a_sweep_with_tracks_reports_and_pairs_the_track_metrics(capsys, tmp_path):
    from uavtrack.experiments.statistics import TRACK_METRICS

    out = tmp_path / "sweep"
    code, _, err = run_cli(
        capsys, "sweep", "sensor.clutter_rate", "0", "2", "--trials", "2", "--set", "steps=20",
        "--set", 'tracker.association="gnn"', "--method", "distributed", "--method", "greedy",
        "--out", str(out), "--no-progress", "--workers", "1",
    )  # fmt: skip
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary["paired_metrics"]) == list(TRACK_METRICS)
    for name in TRACK_METRICS:
        cells = summary["paired_metrics"][name]["distributed - greedy"]
        assert len(cells) == 2 and all(c["trials"] >= 1 for c in cells)
    report = (out / "report.md").read_text()
    assert "## Tracks" in report and "### SIAP spuriousness" in report
    assert "### GOSPA, each UAV's confirmed tracks [m]" in report


def test_paired_differences_leave_out_undefined_trials():
    from uavtrack.experiments.jobs import paired

    p = paired(np.array([1.0, np.nan, 3.0, 6.0]), np.array([0.0, 1.0, np.nan, 2.0]))
    assert p["trials"] == 2 and p["mean"] == pytest.approx(2.5)
    assert np.isnan(paired(np.array([np.nan]), np.array([1.0]))["mean"])


def refuse_constant(name):
    raise ValueError(f"not valid JSON: {name}")


def test_compare_steps_and_set_steps_must_agree(capsys):
    code, _, err = run_cli(capsys, "compare", "--steps", "10", "--set", "steps=20")
    assert code == 2 and "disagree" in err


def test_bench_json_to_a_folder_is_refused_at_once(capsys, tmp_path):
    code, _, err = run_cli(capsys, "bench", "--quick", "--json", str(tmp_path))
    assert code == 2 and "is a directory" in err


def test_memory_refusal_names_the_field(capsys, monkeypatch):
    from uavtrack import _process

    monkeypatch.setattr(_process, "available_memory", lambda: 20 * 2**20)
    code, _, err = run_cli(
        capsys,
        "run",
        "--set",
        "n_uavs=100",
        "--set",
        "n_targets=100",
        "--set",
        "uav.altitude_spacing=0.2",
    )
    assert code == 2 and "of memory" in err and "reduce n_uavs" in err


def handles(pid: int, signum: int, limit: float = 300.0) -> bool:
    """Wait until process `pid` catches `signum` (its SigCgt mask in /proc): an event, not
    a guess of how long a loaded machine takes to import; the limit only stops a hang."""
    end = time.monotonic() + limit
    while time.monotonic() < end:
        try:
            for line in open(f"/proc/{pid}/status"):
                if line.startswith("SigCgt:") and int(line.split()[1], 16) >> (signum - 1) & 1:
                    return True
        except OSError:
            return False
        time.sleep(0.05)
    return False


@pytest.mark.integration
@pytest.mark.parametrize(
    "sent,code,word", [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")]
)
def test_ctrl_c_or_sigterm_on_run_says_so(tmp_path, sent, code, word):
    proc = subprocess.Popen(
        cli_command("run", "--set", "steps=200000", "--trace", str(tmp_path / "t.npz")),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert handles(proc.pid, signal.SIGTERM)  # the command runs: its handler is in place
    time.sleep(1)
    proc.send_signal(sent)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == code
    assert err.strip().startswith(f"uavtrack: {word}") and err.count("\n") == 1
    assert not any(tmp_path.iterdir())


@pytest.mark.integration
def test_stdout_to_a_full_device_fails_in_one_line():
    with open("/dev/full", "w") as full:
        proc = subprocess.run(
            cli_command("params", "--toml"), stdout=full, stderr=subprocess.PIPE, text=True
        )
    assert proc.returncode == 1
    assert proc.stderr.strip() == (
        "uavtrack: error: cannot write standard output: No space left on device"
    )


@pytest.mark.integration
def test_progress_bar_on_a_terminal(tmp_path):
    leader, follower = pty.openpty()
    proc = subprocess.run(
        cli_command("compare", "--trials", "2", "--steps", "30"),
        stdout=subprocess.PIPE,
        stderr=follower,
        timeout=120,
    )
    os.close(follower)
    shown = b""
    while True:
        try:
            chunk = os.read(leader, 65536)
        except OSError:
            break
        if not chunk:
            break
        shown += chunk
    os.close(leader)
    assert proc.returncode == 0
    assert b"trial-steps" in shown and b"180/180" in shown  # 3 methods x 2 trials x 30 steps


@pytest.mark.parametrize("command", ["run", "swarm"])
def test_steps_is_taken_by_every_command_that_runs_a_trial(capsys, command):
    code, out, err = run_cli(capsys, command, "--steps", "7", "--json")
    assert code == 0, err
    assert json.loads(out)["scenario"]["steps"] == 7
    code, _, err = run_cli(capsys, command, "--steps", "7", "--set", "steps=9")
    assert code == 2 and "--steps 7 and --set steps=9 disagree" in err


@pytest.mark.parametrize(
    "args,hint",
    [
        (["sweep", "uav.altitude_spacing", "-5", "0", "5"], "put -- before the values"),
        (["run", "--set", "comm_range", "80"], "--set comm_range=80"),
        (["run", "--set", "comm_rang=80"], "did you mean comm_range?"),
        (["run", "--set", "sensor.half_fov=5"], "did you mean sensor.half_fov_deg?"),
        (["run", "--set", "half_fov_deg=5"], "did you mean sensor.half_fov_deg?"),
    ],
)
def test_refused_arguments_come_with_what_was_meant(capsys, args, hint):
    code, out, err = run_cli(capsys, *args)
    assert code == 2 and hint in err and err.count("\n") == 1 and out == ""


def test_two_outputs_at_one_path_are_refused(capsys, tmp_path):
    path = tmp_path / "x.rrd"
    code, _, err = run_cli(capsys, "run", "--rerun", str(path), "--trace", str(path))
    assert code == 2 and "name the same file" in err
    assert not path.exists()


def test_long_work_off_a_terminal_says_how_far_it_is_once_a_minute(capsys, monkeypatch):
    from uavtrack import _progress

    clock = {"now": 0.0}
    monkeypatch.setattr(_progress.time, "monotonic", lambda: clock["now"])
    monkeypatch.setattr(_progress, "on_terminal", lambda: False)
    with _progress.bar(10, "trial-steps", "trial-steps") as advance:
        for _ in range(10):
            clock["now"] += 25.0  # a step every 25 s: a line at 75 s, 150 s, 225 s
            advance(1)
    lines = capsys.readouterr().err.splitlines()
    assert lines == [
        "uavtrack: trial-steps: 3 of 10 (30%), 1 min 15 s elapsed, about 2 min 55 s left",
        "uavtrack: trial-steps: 6 of 10 (60%), 2 min 30 s elapsed, about 1 min 40 s left",
        "uavtrack: trial-steps: 9 of 10 (90%), 3 min 45 s elapsed, about 25 s left",
    ]
    with _progress.bar(10, "steps", "steps", enabled=False) as advance:
        clock["now"] += 1000
        advance(5)
    assert capsys.readouterr().err == ""


def test_a_large_team_is_summarised_and_absent_metrics_say_why(capsys):
    code, out, err = run_cli(
        capsys, "compare", "--team", "30x30", "--trials", "1", "--steps", "6", "--method",
        "greedy",
    )  # fmt: skip
    assert code == 0, err
    rows = [line for line in out.splitlines() if "target" in line and "│" in line]
    assert not any("target 29" in line for line in rows)  # not one row per target
    for place in ("lowest of 30", "median of 30", "highest of 30", "std over the 30"):
        assert any(place in line for line in rows), place
    code, out, err = run_cli(capsys, "run", "--team", "30x30", "--steps", "4")
    assert code == 0 and "n/a" in out and "not computed above 20 targets" in " ".join(out.split())


def test_the_run_table_says_the_team_and_where_the_scenario_came_from(
    capsys, tmp_path, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    Path("s.toml").write_text("comm_range = 70.0\n")
    code, out, _ = run_cli(
        capsys, "run", "--config", "s.toml", "--team", "6x5", "--set", "dt=0.4", "--steps", "5"
    )
    text = " ".join(out.split())
    assert code == 0 and "6 UAVs x 5 targets, 5 steps" in text
    assert "config s.toml, --team 6x5, --set dt=0.4" in text


def test_a_world_on_every_interface_prints_endpoints_others_can_reach():
    from uavtrack.cli.swarm import reachable

    found = reachable("tcp/0.0.0.0:7447")
    assert found and all(e.startswith("tcp/") and e.endswith(":7447") for e in found)
    assert "tcp/0.0.0.0:7447" not in found and "tcp/127.0.0.1:7447" in found
    assert reachable("tls/10.1.2.3:7447") == ["tls/10.1.2.3:7447"]


def test_every_command_that_writes_a_file_refuses_one_that_exists_unless_forced(capsys, tmp_path):
    trace, nc = tmp_path / "t.npz", tmp_path / "t.nc"
    assert run_cli(capsys, "run", "--steps", "5", "--trace", str(trace))[0] == 0
    first = trace.read_bytes()
    assert run_cli(capsys, "export", str(trace), "--out", str(nc))[0] == 0
    taken = [
        (["run", "--steps", "5", "--seed", "1", "--trace", str(trace)], "--trace"),
        (["swarm", "--steps", "2", "--trace", str(trace)], "--trace"),
        (["export", str(trace), "--out", str(nc)], "--out"),
        (["animate", "--steps", "4", "--out", str(tmp_path / "a.gif")], "--out"),
        (["bench", "--quick", "--json", str(nc)], "--json"),
    ]
    (tmp_path / "a.gif").write_bytes(b"GIF89a")
    for args, option in taken:
        code, out, err = run_cli(capsys, *args)
        assert code == 2 and err.count("\n") == 1, (args, err)
        assert f"{option}: " in err and "exists" in err and "--force to replace it" in err
    assert trace.read_bytes() == first  # nothing replaced
    code, _, err = run_cli(capsys, *taken[0][0], "--force")
    assert code == 0, err
    assert trace.read_bytes() != first  # seed 1's trace replaced seed 0's
    assert run_cli(capsys, "export", str(trace), "--out", str(nc), "--force")[0] == 0


def test_an_interrupted_command_says_what_it_left_on_disk(capsys, tmp_path, monkeypatch):
    """Ctrl-C while `run --trace --bag` writes the bag: the trace is complete on disk,
    the bag is not there, and the message says both."""
    from uavtrack.io import bag as bag_module

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(bag_module, "write_bag", interrupted)
    trace, bag = tmp_path / "t.npz", tmp_path / "bag"
    code, _, err = run_cli(capsys, "run", "--steps", "5", "--trace", str(trace), "--bag", str(bag))
    assert code == 130
    assert "no partial file was left; written whole before it: " + str(trace) in err, err
    assert trace.is_file() and not bag.exists()
    uavtrack.io.trace.read(trace)  # whole: it reads back
