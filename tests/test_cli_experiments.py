import json

import pytest
from PIL import Image

from uavtrack import cli


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
    assert len(list((quick / "raw").glob("*.json"))) == 18


def test_reproduce_again_reuses_every_job(quick, capsys):
    before = (quick / "summary.json").read_text()
    code, out, _ = run_cli(capsys, "reproduce", "--quick", "--out", str(quick), "--no-progress")
    assert code == 0 and "0 jobs run, 18 reused" in out
    after = json.loads((quick / "summary.json").read_text())
    assert (
        after["compare"]["distributed"]["mean"]
        == json.loads(before)["compare"]["distributed"]["mean"]
    )


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
        assert im.n_frames == 4
    assert [p.name for p in tmp_path.iterdir()] == ["run.gif"]
