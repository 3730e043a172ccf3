"""`uavtrack sensing` and `uavtrack run` with tracks, from the command line."""

import json

import numpy as np
import pandas as pd
import pytest

from uavtrack import cli
from uavtrack.experiments import sensing


def test_run_with_tracks_shows_the_track_scores(capsys):
    code = cli.main(
        ["run", "--set", "tracker.association=gnn", "--set", "sensor.clutter_rate=1",
         "--set", "steps=30", "--json"]
    )  # fmt: skip
    out, err = capsys.readouterr()
    assert code == 0, err
    summary = json.loads(out)
    assert summary["gospa"] >= 0 and 0 <= summary["siap_completeness"] <= 1
    assert summary["rmse"] is None or np.isnan(summary["rmse"])  # no estimate per target
    code = cli.main(["run", "--set", "tracker.association=jpda", "--set", "steps=10"])
    out, _ = capsys.readouterr()
    assert code == 0 and "unassigned confirmed tracks per target and step" in out
    assert "duplicates (a target followed twice)" in out and "label purity" in out


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--set", "tracker.association=jdpa"], "tracker.association"),
        (["--set", "tracker.confirm=[3,2]", "--set", "tracker.association=gnn"], "confirm"),
        (["--set", "tracker.max_tracks=9"], "tracker.max_tracks needs"),
        (["--set", "sensor.clutter_rate=-1"], "sensor.clutter_rate"),
    ],
)
def test_bad_track_settings_are_refused_in_one_line(args, named, capsys):
    code = cli.main(["run", *args])
    _, err = capsys.readouterr()
    assert code == 2
    assert named in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_sensing_refuses_a_base_that_sets_what_it_sweeps(tmp_path, capsys):
    out = tmp_path / "s"
    code = cli.main(["sensing", "--quick", "--set", "sensor.clutter_rate=1", "--out", str(out)])
    _, err = capsys.readouterr()
    assert code == 2 and "sensing sets" in err
    assert not out.exists()


@pytest.mark.integration
def test_uavtrack_sensing_writes_its_tables_and_figure_and_resumes(tmp_path, capsys):
    from PIL import Image

    out = tmp_path / "s"
    args = ["sensing", "--quick", "--steps", "20", "--out", str(out), "--no-progress"]
    code = cli.main(args)
    _, err = capsys.readouterr()
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary["methods"]) == list(sensing.METHODS)
    rows = pd.DataFrame(
        [
            {"method": m, **{k: v for k, v in e.items() if isinstance(v, float | int | str)}}
            for m, cells in summary["methods"].items()
            for e in cells.values()
        ]
    )
    # known per P_D, every tracked cell, the unbriefed one and the births one
    assert len(rows) == 3 * (3 + 3 * 3 * 2 + 2)
    assert (rows["association"] == "jpda-unbriefed").sum() == 3
    assert (rows["association"] == "jpda-births").sum() == 3
    for method, cells in summary["methods"].items():
        for key, e in cells.items():
            if e["association"] == "known":
                continue
            if e["association"] == "jpda-births":  # another truth: no known to pair with
                assert "against_known" not in e
                continue
            known = cells[f"pd={e['pd']:g} clutter=0 known"]
            diff = e["against_known"]["observation_rate"]["mean"]  # paired on the trials
            rate, base = e["observation_rate"]["mean"], known["observation_rate"]["mean"]
            assert diff == pytest.approx(rate - base, abs=1e-12), (method, key)
    goals = summary["goals"]
    assert len(goals) == 20 and all(isinstance(g["met"], bool) for g in goals)
    value = {g["goal"]: g["value"] for g in goals}
    for method in ("distributed", "centralized"):  # the worst cell, recomputed
        cells = summary["methods"][method]
        worst = min(
            cells[f"pd={p:g} clutter={c:g} jpda"]["observation_rate"]["mean"]
            - cells[f"pd={p:g} clutter={c:g} gnn"]["observation_rate"]["mean"]
            for p in sensing.DETECTION
            for c in sensing.CLUTTER
        )  # fmt: skip
        assert value[f"{method}: jpda minus gnn rate, worst cell"] == pytest.approx(worst)
    goal = summary["methods"]["distributed"]["pd=0.9 clutter=2 jpda"]
    assert value["label purity (distributed)"] == goal["label_purity"]["mean"]
    for end, what in (("unbriefed", "unbriefed"), ("births", "unbriefed, births")):
        cold = summary["methods"]["distributed"][f"pd=0.9 clutter=2 jpda-{end}"]
        name = f"{what} (distributed): steps for the team to confirm a target in view, median"
        assert value[name] == cold["time_to_confirm_team"]["mean"]
    parity = [g for g in goals if g["goal"].startswith("P_D 1, no clutter")]
    cells = summary["methods"]["distributed"]
    for g, association in zip(parity, sensing.ASSOCIATIONS, strict=True):
        diff = cells[f"pd=1 clutter=0 {association}"]["against_known"]["observation_rate"]
        assert g["value"] == pytest.approx(abs(diff["mean"])) and g["met"] == (g["value"] <= 0.005)
    report = (out / "report.md").read_text()
    assert "## Goals" in report and "| 0.9 | 2 | jpda |" in report
    with Image.open(out / "sensing.png") as im:
        assert im.size[0] > 1000
    code = cli.main(args)  # resumes: every job is done
    out_text, _ = capsys.readouterr()
    assert code == 0 and "0 jobs run" in out_text
