"""`uavtrack separation`: collision avoidance at one altitude, paired with and without
the filter, from the command line."""

import json

import pandas as pd
import pytest

from uavtrack import cli
from uavtrack.experiments import separation


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--set", "planner.avoidance=none"], "planner.avoidance"),
        (["--set", 'uav.dynamics="jsbsim"'], "uav.dynamics"),
        (["--config", "one-altitud"], "one-altitude"),
        (["--set", "uav.separation=-3"], "uav.separation"),
    ],
)
def test_separation_refuses_bad_input_in_one_line_and_writes_nothing(tmp_path, args, named, capsys):
    out = tmp_path / "s"
    code = cli.main(["separation", "--quick", *args, "--out", str(out)])
    _, err = capsys.readouterr()
    assert code == 2 and named in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.integration  # JSBSim aircraft and worker processes
@pytest.mark.slow  # 25 s, most of it JSBSim's 20 x 16 teams; its refusals run by default
def test_uavtrack_separation_writes_its_tables_and_figure_and_resumes(tmp_path, capsys):
    from PIL import Image

    out = tmp_path / "s"
    args = ["separation", "--quick", "--steps", "30", "--out", str(out), "--no-progress"]
    code = cli.main(args)
    _, err = capsys.readouterr()
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary["methods"]) == list(separation.METHODS)
    rows = pd.DataFrame(
        [
            {"method": m, "cell": c, "rate_none": e["none"]["observation_rate"]["mean"],
             "rate_filter": e["loiter"]["observation_rate"]["mean"], "cost": e["cost"]["mean"],
             "losses_filter": e["loiter"]["losses_total"], "dynamics": e["dynamics"],
             "radio": e["radio"]}
            for m, cells in summary["methods"].items()
            for c, e in cells.items()
        ]
    )  # fmt: skip
    assert len(rows) == 3 * len(separation.TEAMS) * len(separation.CELLS)
    # the cost is the paired difference of the same trials: the difference of the means
    assert (rows["cost"] - (rows["rate_none"] - rows["rate_filter"])).abs().max() < 1e-12
    # within the sound range the unicycle's guarantee holds for every method and team
    # (with the slow backup too, at its own, smaller sound range)
    sound = rows[(rows["dynamics"] == "unicycle") & rows["radio"].str.startswith("sound")]
    assert len(sound) == 2 * 3 * len(separation.TEAMS)
    assert (sound["losses_filter"] == 0).all()
    assert summary["sound_range"] >= 161.0
    goals = summary["goals"]
    assert len(goals) == 18 and all(isinstance(g["met"], bool) for g in goals)
    assert [g["met"] for g in goals if "losses with" in g["goal"]] == [True] * 8
    report = (out / "report.md").read_text()
    assert "## Goals" in report and "| 20x16 | jsbsim | sound |" in report
    with Image.open(out / "separation.png") as im:
        assert im.size[0] > 1000
    code = cli.main(args)  # resumes: every job is done
    out_text, _ = capsys.readouterr()
    assert code == 0 and "0 jobs run" in out_text
