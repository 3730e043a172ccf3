import errno
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from PIL import Image

import uavtrack
from uavtrack import cli

from .processes import alive, children_of


def run_cli(capsys, *args):
    code = cli.main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("repro") / "quick"
    code = cli.main(["reproduce", "--quick", "--out", str(out), "--no-progress", "--workers", "2"])
    assert code == 0
    return out


@pytest.mark.integration
def test_reproduce_quick_writes_everything(quick):
    summary = json.loads((quick / "summary.json").read_text())
    assert set(summary) >= {"compare", "comm_range", "fov", "timing", "paired"}
    for m in ("distributed", "centralized", "greedy"):
        assert 0.0 <= summary["compare"][m]["mean"] <= 1.0 and summary["compare"][m]["std"] >= 0
        assert summary["compare"][m]["trials"] == 4
    assert summary["comm_range"]["values"] == [10, 50, 80]
    assert len(summary["fov"]["distributed"]) == 2
    assert set(summary["timing"]) >= {"grid", "distributed", "centralized", "greedy"}
    for k in range(5, 10):
        with Image.open(quick / f"fig{k}.png") as im:
            assert im.size[0] > 500 and im.size[1] > 300
    report = (quick / "report.md").read_text()
    assert (
        "0.8031 ± 0.1262" in report and "0.8048 ± 0.1217" in report and "0.6664 ± 0.1507" in report
    )
    assert "95% confidence interval" in report and "`dt` | 0.5 |" in report
    assert json.loads((quick / "manifest.json").read_text())["kind"] == "reproduce"
    assert len(list((quick / "raw").glob("*.json"))) == 15
    # the first guess before calibration, beside the defaults, on the same trials
    first = summary["first_guess"]
    assert first["overrides"] == {"dt": 1.0, "uav.altitude": 500.0}
    assert set(first["rates"]) == {"distributed", "centralized", "greedy"}
    assert "conditional on two calibrated values" in report and "first guess" in report
    assert "σ over (trial, step)" in report


@pytest.mark.integration
def test_reproduce_again_reuses_every_job(quick, capsys):
    before = (quick / "summary.json").read_text()
    code, out, _ = run_cli(capsys, "reproduce", "--quick", "--out", str(quick), "--no-progress")
    assert code == 0 and "0 jobs run, 15 reused" in out
    after = json.loads((quick / "summary.json").read_text())
    assert (
        after["compare"]["distributed"]["mean"]
        == json.loads(before)["compare"]["distributed"]["mean"]
    )


@pytest.mark.slow  # 35 s; the base-value test runs the sensitivity end to end, smaller
@pytest.mark.integration
def test_sensitivity_adds_its_jobs_to_the_same_folder(quick, capsys):
    from uavtrack.experiments.reproduce import SENSITIVITY

    code, out, _ = run_cli(
        capsys, "reproduce", "--quick", "--sensitivity", "--out", str(quick), "--no-progress"
    )
    n_values = sum(len(v) for v in SENSITIVITY.values())
    assert code == 0 and f"{n_values * 3} jobs run, 15 reused" in out
    sens = json.loads((quick / "summary.json").read_text())["sensitivity"]
    assert [r["field"] for r in sens["rows"]] == list(SENSITIVITY)
    base = sens["base"]["rates"]
    compare = json.loads((quick / "summary.json").read_text())["compare"]
    assert base["greedy"] == pytest.approx(compare["greedy"]["mean"])
    for row in sens["rows"]:
        for entry in row["values"]:
            p = entry["distributed - greedy"]
            r = entry["rates"]
            assert p["mean"] == pytest.approx(r["distributed"] - r["greedy"])
            assert entry["near_centralized"].split(",")[0] in ("yes", "no")
    report = (quick / "report.md").read_text()
    assert "## Sensitivity of the conclusions" in report and "| `dt` (0.5) | 0.25 |" in report
    for claim in ("distributed within 0.03 of centralized", "distributed well above greedy"):
        said = next(line for line in out.splitlines() if line.strip().startswith(claim))
        written = next(line for line in report.splitlines() if line.startswith(f"*{claim}*"))
        assert said.split("fails at: ")[1] == written.split("fails at: ")[1].rstrip(".").replace(
            "`", ""
        )
    with Image.open(quick / "sensitivity.png") as im:
        assert im.size[0] > 800
    # without the flag the report leaves the section out, and nothing is recomputed
    code, out, _ = run_cli(capsys, "reproduce", "--quick", "--out", str(quick), "--no-progress")
    assert code == 0 and "0 jobs run, 15 reused" in out
    assert "## Sensitivity" not in (quick / "report.md").read_text()
    assert not (quick / "sensitivity.png").exists()  # no chart left that the report lacks


@pytest.mark.integration
def test_a_base_value_equal_to_a_planned_one_is_reported(tmp_path, capsys):
    # dt = 1.0 is the first guess's, field_size = 300 a sensitivity value: their runs are
    # the default's, and the report says so rather than failing
    out = tmp_path / "same"
    code, _, err = run_cli(
        capsys, "reproduce", "--quick", "--trials", "2", "--steps", "20", "--sensitivity",
        "--set", "dt=1.0", "--set", "field_size=300", "--out", str(out), "--no-progress",
    )  # fmt: skip
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    rows = {r["field"]: r for r in summary["sensitivity"]["rows"]}
    assert summary["first_guess"]["rates"]["greedy"] != summary["compare"]["greedy"]["mean"]
    high = rows["field_size"]["values"][1]
    assert high["value"] == 300 and high["rates"] == summary["sensitivity"]["base"]["rates"]


@pytest.mark.integration
def test_reproduce_refuses_a_different_scenario(quick, capsys):
    code, _, err = run_cli(capsys, "reproduce", "--quick", "--out", str(quick), "--set", "dt=1.0")
    assert code == 2 and "different scenario (dt 0.5, now 1.0)" in err


def test_sweep(tmp_path, capsys):
    out = tmp_path / "sweep"
    code, stdout, err = run_cli(
        capsys,
        "sweep",
        "planner.horizon",
        "2",
        "3",
        "--trials",
        "2",
        "--set",
        "steps=20",
        "--method",
        "distributed",
        "--method",
        "greedy",
        "--out",
        str(out),
        "--no-progress",
        "--workers",
        "1",
    )
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["field"] == "planner.horizon" and summary["values"] == [2, 3]
    assert list(summary["methods"]) == ["distributed", "greedy"]
    assert list(summary["paired"]) == ["distributed - greedy"]
    assert (out / "sweep.png").stat().st_size > 10_000 and "| 3 |" in (
        out / "report.md"
    ).read_text()


def test_a_sweep_of_two_fields_is_a_grid_of_every_combination(tmp_path, capsys):
    out = tmp_path / "grid"
    args = ["sweep", "comm_range", "0", "80", "faults.loss", "0", "0.3", "--trials", "2",
            "--steps", "20", "--method", "distributed", "--method", "greedy", "--out", str(out),
            "--no-progress", "--workers", "1"]  # fmt: skip
    code, stdout, err = run_cli(capsys, *args)
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["fields"] == ["comm_range", "faults.loss"]
    assert summary["cells"] == [[0.0, 0.0], [0.0, 0.3], [80.0, 0.0], [80.0, 0.3]]
    assert "field" not in summary and summary["units"] == {"comm_range": "m", "faults.loss": ""}
    seeds = [uavtrack.trial_seed(0, t) for t in range(2)]
    for k, (comm_range, loss) in enumerate(summary["cells"]):
        scenario = uavtrack.Scenario(steps=20, comm_range=comm_range, faults={"loss": loss})
        rates = {
            m: uavtrack.run(scenario, m, seeds).metrics["observation_rate"]
            for m in ("distributed", "greedy")
        }
        for m, rate in rates.items():  # each cell is that scenario, on the same trials
            assert summary["methods"][m][k]["mean"] == pytest.approx(rate.mean(), rel=1e-12)
        pair = summary["paired"]["distributed - greedy"][k]
        assert pair["mean"] == pytest.approx((rates["distributed"] - rates["greedy"]).mean())
    # no radio: distributed decides exactly as greedy, whatever the loss
    assert summary["paired"]["distributed - greedy"][0]["mean"] == 0
    assert summary["paired"]["distributed - greedy"][1]["mean"] == 0
    report = (out / "report.md").read_text()
    assert "# Sweep of `comm_range` × `faults.loss`" in report
    assert "| comm_range [m] | faults.loss | distributed | greedy |" in report
    assert "| 80 | 0.3 |" in report and report.count("| 0 | 0 |") == 2  # rates and pairs
    with Image.open(out / "sweep.png") as im:
        assert im.size[0] > im.size[1]  # a panel per loss, side by side
    assert "8 jobs run, 0 reused" in stdout
    capsys.readouterr()
    code, stdout, _ = run_cli(capsys, *args)
    assert code == 0 and "0 jobs run, 8 reused" in stdout
    assert json.loads((out / "summary.json").read_text())["methods"] == summary["methods"]


@pytest.mark.parametrize(
    "tokens,message",
    [
        (["comm_range", "25", "faults.los", "0"],
         "sweep: 'faults.los' is neither a value of comm_range nor a scenario field; "
         "did you mean faults.loss?"),
        (["comm_range", "25", "comm_range", "30"], "sweep: comm_range is given twice"),
        (["comm_range", "25", "faults.loss"], "sweep faults.loss: give at least one value"),
        (["comm_range", "25", "--set", "comm_range=30"],
         "sweep sets comm_range itself; do not --set comm_range too"),
        (["n_uavs", "2", "uav.altitudes", "[400.0, 410.0, 420.0]"],
         "sweep cell n_uavs=2, uav.altitudes=[400.0, 410.0, 420.0]: uav.altitudes has 3 "
         "entries but n_uavs is 2"),
    ],
)  # fmt: skip
def test_a_grid_is_refused_before_any_work(tmp_path, capsys, tokens, message):
    out = tmp_path / "s"
    code, _, err = run_cli(capsys, "sweep", *tokens, "--out", str(out))
    assert code == 2 and message in err and err.count("\n") == 1 and not out.exists()


@pytest.mark.integration
def test_a_wrong_sweep_is_refused_before_the_experiment_modules_load():
    code = (
        "import sys\n"
        "from uavtrack import cli\n"
        "assert cli.main(['sweep', 'comm_rang', '1', '2']) == 2\n"
        "assert cli.main(['sweep', 'comm_range', 'abc']) == 2\n"
        "heavy = ('scipy.stats', 'matplotlib', 'uavtrack.experiments.figures')\n"
        "heavy = [m for m in heavy if m in sys.modules]\n"
        "print(heavy)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "[]\n" and "did you mean comm_range?" in proc.stderr


EXPERIMENTS = (
    "bandwidth", "realistic", "separation", "sensing", "robustness", "trackers", "flight",
)  # fmt: skip
"""The commands built on `experiments.protocol.Experiment`."""


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_each_experiment_command_implements_the_protocol_and_names_its_profile(name, capsys):
    import importlib
    import inspect

    from uavtrack.experiments import protocol

    module = importlib.import_module(f"uavtrack.experiments.{name}")
    assert module.NAME == name
    assert issubclass(module.Profile, protocol.Profile)
    for part in ("plan", "summarize", "figures", "figure", "report"):
        declared = inspect.signature(getattr(protocol.Experiment, part)).parameters
        given = inspect.signature(getattr(module, part)).parameters
        assert len(given) == len(declared) - 1, part  # less self
    full, quick = module.Profile(), module.Profile.quick()
    assert quick.trials < full.trials and quick.steps < full.steps
    code, out, _ = run_cli(capsys, name, "--help")
    said = " ".join(out.split())  # the help is wrapped to the terminal
    assert code == 0
    assert f"Profile: {full.trials} trials of {full.steps} steps" in said
    assert f"--quick: {quick.trials} trials of {quick.steps} steps" in said
    for option in ("--out", "--trials", "--steps", "--quick", "--workers"):
        assert option in said


@pytest.mark.parametrize(
    "args,message",
    [
        (["sweep", "bogus", "1"], "unknown scenario field 'bogus'"),
        (["sweep", "comm_range", "abc"], "comm_range: Input should be a valid number"),
        (["sweep", "n_uavs", "0", "3"], "n_uavs: Input should be greater than or equal to 1"),
        (["reproduce", "--trials", "0"], "--trials"),
        (["reproduce", "--engine", "spark"], "'spark' is not one of"),
        (["reproduce", "--address", "tcp://127.0.0.1:1"], "--address needs --engine dask"),
        (["animate", "--out", "x.mp4"], "--out must name a .gif file"),
        (["animate"], "Missing option '--out'"),
    ],
)
def test_bad_experiment_input(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    code, _, err = run_cli(capsys, *args)
    assert code == 2 and message in err and err.count("\n") == 1
    assert not any(tmp_path.iterdir())


def test_animate(tmp_path, capsys):
    out = tmp_path / "run.gif"
    code, stdout, err = run_cli(
        capsys,
        "animate",
        "--out",
        str(out),
        "--set",
        "steps=12",
        "--every",
        "3",
        "--method",
        "centralized",
    )
    assert code == 0, err
    with Image.open(out) as im:
        assert im.n_frames == 5  # steps 0, 3, 6, 9 and the last, 11
    assert [p.name for p in tmp_path.iterdir()] == ["run.gif"]


def tiny_sweep(out, *extra):
    return [
        "sweep",
        "comm_range",
        "10",
        "50",
        "--trials",
        "2",
        "--steps",
        "15",
        "--method",
        "distributed",
        "--out",
        str(out),
        "--no-progress",
        "--workers",
        "1",
        *extra,
    ]


def test_tampered_job_files_are_set_aside_and_recomputed(tmp_path, capsys):
    out = tmp_path / "s"
    assert cli.main(tiny_sweep(out)) == 0
    clean = json.loads((out / "summary.json").read_text())
    files = sorted((out / "raw").glob("*.json"))
    edited, truncated, empty = files[0], files[1], files[0]
    record = json.loads(edited.read_text())
    record["metrics"]["observation_rate"] = [1.0, 1.0]  # a hand edit
    edited.write_text(json.dumps(record))
    truncated.write_text(truncated.read_text()[:40])
    capsys.readouterr()
    code, _, err = run_cli(capsys, *tiny_sweep(out))
    assert code == 0, err
    assert err.count("set aside") == 2 and "checksum" in err and "unreadable" in err
    again = json.loads((out / "summary.json").read_text())
    assert again["methods"] == clean["methods"]  # the edit did not reach the results
    assert {p.name for p in (out / "failed").glob("*.rejected.json")} == {
        f"{edited.stem}.rejected.json",
        f"{truncated.stem}.rejected.json",
    }
    kept = json.loads((out / "failed" / f"{edited.stem}.rejected.json").read_text())
    assert "checksum" in kept["reason"] and json.loads(kept["content"]) == record
    empty.write_text("")
    code, _, err = run_cli(capsys, *tiny_sweep(out))
    assert code == 0 and "set aside" in err and "Traceback" not in err


def test_a_job_file_of_another_seed_is_not_used(tmp_path, capsys):
    one, two = tmp_path / "one", tmp_path / "two"
    assert cli.main(tiny_sweep(one)) == 0
    assert cli.main(tiny_sweep(two, "--seed", "1")) == 0
    name = sorted((one / "raw").glob("*.json"))[0].name
    shutil.copy(two / "raw" / name, one / "raw" / name)  # same job key, other seed
    capsys.readouterr()
    code, _, err = run_cli(capsys, *tiny_sweep(one))
    assert code == 0 and "made for another seed (1, this job has 0)" in err


def test_a_second_run_on_a_locked_folder_is_refused(tmp_path, capsys):
    from uavtrack.experiments import store

    out = tmp_path / "s"
    with store.Store(out, {"kind": "sweep"}):
        code, _, err = run_cli(capsys, *tiny_sweep(out))
    assert code == 2 and f"{out} is in use by another uavtrack run (pid {os.getpid()})" in err
    assert err.count("\n") == 1


@pytest.mark.parametrize(
    "values,message",
    [
        (["dt", "0.5", "0.5"], "0.5 is given twice"),
        (["comm_range", "10", "10.0", "80"], "10 and 10.0 are the same value once read (10.0)"),
    ],
)
def test_sweep_refuses_repeated_values_before_any_work(tmp_path, capsys, values, message):
    out = tmp_path / "s"
    code, _, err = run_cli(capsys, "sweep", *values, "--out", str(out))
    assert code == 2 and message in err and not out.exists()


@pytest.mark.integration
def test_one_trial_writes_valid_json_with_nulls(tmp_path, capsys):
    out = tmp_path / "one"
    code, _, err = run_cli(
        capsys, "reproduce", "--quick", "--trials", "1", "--out", str(out), "--no-progress"
    )
    assert code == 0, err

    def refuse(constant):
        raise ValueError(constant)

    summary = json.loads((out / "summary.json").read_text(), parse_constant=refuse)
    assert summary["compare"]["distributed"]["std"] is None
    assert summary["paired"]["distributed - greedy"]["ci_low"] is None
    report = (out / "report.md").read_text()
    assert "needs at least two trials" in report and "± n/a" in report


@pytest.mark.parametrize("where", ["file", "proc", "raw-unwritable"])
def test_unusable_output_folders_are_refused_before_any_work(tmp_path, capsys, where):
    if where == "file":
        out = tmp_path / "f"
        out.write_text("mine")
    elif where == "proc":
        out = Path("/proc/uavtrack-results")
    else:
        out = tmp_path / "s"
        assert cli.main(tiny_sweep(out)) == 0
        shutil.rmtree(out / "raw")
        (out / "raw").symlink_to("/proc/self/fdinfo")  # a folder nobody may write in
    capsys.readouterr()
    code, _, err = run_cli(capsys, *tiny_sweep(out))
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    expected = {
        "file": "exists and is not a folder",
        "proc": "cannot create it",
        "raw-unwritable": "cannot write in it",
    }[where]
    assert f"results folder {out}" in err and expected in err
    if where == "file":
        assert out.read_text() == "mine"


def test_animate_into_a_folder_is_refused(tmp_path, capsys):
    folder = tmp_path / "movie.gif"
    folder.mkdir()
    code, _, err = run_cli(capsys, "animate", "--out", str(folder), "--set", "steps=5")
    assert code == 2 and "is a directory" in err and not any(folder.iterdir())


def test_a_full_disk_ends_the_run_in_one_line(tmp_path, capsys, monkeypatch):
    from uavtrack import _files

    def full(path, text):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(_files, "write_text", full)
    code, _, err = run_cli(capsys, *tiny_sweep(tmp_path / "s"))
    assert code == 1 and err.count("\n") == 1
    assert "No space left on device" in err and err.startswith("uavtrack: error: cannot write")


def test_a_job_with_non_finite_results_fails_instead_of_being_saved(tmp_path, capsys, monkeypatch):
    from uavtrack.experiments import jobs

    real = jobs.run

    def broken(*args, **kwargs):
        result = real(*args, **kwargs)
        result.metrics["observation_rate"][:] = float("nan")
        return result

    monkeypatch.setattr(jobs, "run", broken)
    out = tmp_path / "s"
    code, _, err = run_cli(capsys, *tiny_sweep(out))
    assert code == 1 and "jobs failed" in err
    assert not list((out / "raw").glob("*.json"))
    record = json.loads(next((out / "failed").glob("*.json")).read_text())
    assert "metric observation_rate is not finite" in record["error"]


@pytest.mark.integration
def test_unreachable_dask_scheduler_is_one_line(tmp_path, capsys):
    pytest.importorskip("dask.distributed")
    code, _, err = run_cli(
        capsys, *tiny_sweep(tmp_path / "s", "--engine", "dask", "--address", "tcp://127.0.0.1:9")
    )
    assert code == 2 and err.count("\n") == 1
    assert "--address tcp://127.0.0.1:9: no Dask scheduler answers there" in err


@pytest.mark.integration
def test_workers_are_capped_at_the_cores(tmp_path, capsys):
    code, _, err = run_cli(capsys, *tiny_sweep(tmp_path / "s", "--workers", "1000"))
    assert code == 0 and "--workers 1000 capped at" in err
    summary = json.loads((tmp_path / "s" / "summary.json").read_text())
    assert summary["settings"]["workers"] <= os.cpu_count()


@pytest.mark.integration
def test_workers_exit_with_a_killed_parent(tmp_path):
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "uavtrack.cli",
            "reproduce",
            "--quick",
            "--trials",
            "40",
            "--workers",
            "2",
            "--out",
            str(tmp_path / "r"),
            "--no-progress",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    # the bounds only stop a test that would hang: a loaded machine takes its time to
    # start the workers, and the kernel's parent-death signal ends them at once
    deadline = time.monotonic() + 300
    workers = []
    while time.monotonic() < deadline and len(workers) < 2:
        time.sleep(0.2)
        workers = children_of(proc.pid)
    assert len(workers) >= 2, "no worker processes started"
    proc.kill()
    proc.wait()
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and any(alive(w) for w in workers):
        time.sleep(0.2)
    assert not any(alive(w) for w in workers)


@pytest.mark.integration
def test_reproduce_applies_set_steps(tmp_path, capsys):
    out = tmp_path / "r"
    code, _, err = run_cli(
        capsys,
        "reproduce",
        "--quick",
        "--trials",
        "2",
        "--set",
        "steps=7",
        "--out",
        str(out),
        "--no-progress",
    )
    assert code == 0, err
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["plan"]["steps"] == 7 and manifest["scenario"]["steps"] == 7
    code, _, err = run_cli(
        capsys, "reproduce", "--quick", "--steps", "8", "--set", "steps=7", "--out", str(out)
    )
    assert code == 2 and "disagree" in err


def test_sweep_of_negative_values_and_messages_name_the_sweep(tmp_path, capsys):
    code, _, err = run_cli(
        capsys,
        "sweep",
        "--trials",
        "2",
        "--steps",
        "10",
        "--method",
        "greedy",
        "--out",
        str(tmp_path / "s"),
        "--no-progress",
        "--workers",
        "1",
        "uav.altitude_spacing",
        "--",
        "-5",
        "0",
        "5",
    )
    assert code == 0, err
    summary = json.loads((tmp_path / "s" / "summary.json").read_text())
    assert summary["values"] == [-5.0, 0.0, 5.0] and summary["unit"] == "m"
    code, _, err = run_cli(capsys, "sweep", "dt", "--", "-1")
    assert code == 2 and err.startswith("uavtrack: error: sweep value dt=-1: dt:")
    assert "--set" not in err
    code, _, err = run_cli(capsys, "sweep", "dt", "--", "0.5", "--trials", "2")
    assert code == 2 and "put options before '--'" in err


@pytest.mark.integration
def test_robustness_writes_a_figure_per_fault_and_a_report(tmp_path, capsys):
    out = tmp_path / "r"
    code, stdout, err = run_cli(
        capsys,
        "robustness",
        "--quick",
        "--trials",
        "2",
        "--steps",
        "12",
        "--out",
        str(out),
        "--no-progress",
    )
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    names = ("loss", "burst", "delay", "round_budget", "failure_rate", "position_std")
    assert tuple(summary["faults"]) == names
    for name in names:
        fault = summary["faults"][name]
        assert set(fault["series"]) == {"distributed", "robust", "centralized", "greedy"}
        assert len(fault["series"]["distributed"]) == len(fault["levels"])
        # the first level is "no fault": every fault's first row is the same runs
        first = fault["series"]["greedy"][0]["mean"]
        assert first == summary["faults"]["loss"]["series"]["greedy"][0]["mean"] or name == "burst"
        with Image.open(out / f"fault_{name}.png") as im:
            assert im.size[0] > 500
    assert set(summary["ablation"]) == set(names)
    report = (out / "report.md").read_text()
    assert "## loss: `faults.loss`" in report and "Which mechanism helps" in report
    assert "fault" in stdout and "robust" in stdout
    assert "burst (at loss 0.3)" in stdout  # its rows run at 30% loss, and say so


def test_sweep_of_a_fault_field(tmp_path, capsys):
    code, stdout, err = run_cli(
        capsys,
        "sweep",
        "faults.round_budget",
        "none",
        "1",
        "--trials",
        "2",
        "--steps",
        "15",
        "--out",
        str(tmp_path / "s"),
        "--no-progress",
        "--workers",
        "1",
    )
    assert code == 0, err
    summary = json.loads((tmp_path / "s" / "summary.json").read_text())
    assert summary["values"] == [None, 1] and summary["unit"] == "rounds"
    assert len(summary["paired"]["distributed - greedy"]) == 2
    assert "none" in stdout


def test_robustness_refuses_faults_in_the_base_scenario(tmp_path, capsys):
    code, _, err = run_cli(
        capsys, "robustness", "--quick", "--set", "robust.stale=true", "--out", str(tmp_path / "r")
    )
    assert code == 2 and "robust.stale=True" in err and not (tmp_path / "r").exists()


def test_an_output_that_cannot_be_written_is_refused_before_any_job_runs(tmp_path, capsys):
    out = tmp_path / "s"
    code, _, err = run_cli(capsys, *tiny_sweep(out))
    assert code == 0, err
    raw = sorted((out / "raw").glob("*.json"))
    raw[0].unlink()  # a job to compute again on resume
    (out / "summary.json").unlink()
    (out / "summary.json").mkdir()
    code, _, err = run_cli(capsys, *tiny_sweep(out))
    assert code == 2 and "summary.json exists and is not a regular file" in err
    assert not raw[0].exists()  # refused before the missing job was computed
    assert sorted((out / "raw").glob("*.json")) == raw[1:]


def test_a_full_disk_under_the_results_folder_names_the_folder(tmp_path, capsys, monkeypatch):
    import errno

    from uavtrack.experiments import store

    def full(fd, data, offset):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(store.os, "pwrite", full)
    code, out, err = run_cli(capsys, *tiny_sweep(tmp_path / "s"))
    assert code == 2 and out == ""
    assert err.strip() == (
        f"uavtrack: error: results folder {tmp_path / 's'}: cannot write in it "
        "(No space left on device)"
    )
