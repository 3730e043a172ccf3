"""Rerun recordings: what a saved run holds, read back from the file."""

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

import uavtrack

pytest.importorskip("rerun")
from rerun.chunk import RrdReader  # noqa: E402

from uavtrack.viz import rerun  # noqa: E402

from .test_files import on_a_small_disk  # noqa: E402


def contents(path):
    """entity path -> {step: instances} of the positions-like column, and the statics."""
    out, static = {}, set()
    for chunk in RrdReader(path).store().stream():
        entity = chunk.entity_path.lstrip("/")
        if chunk.is_static:
            static.add(entity)
            continue
        batch = chunk.to_record_batch()
        data = [n for n in batch.schema.names if n not in ("rerun.controls.RowId", "step")]
        main = next(
            (n for n in data if n.split(":")[-1] in ("positions", "centers", "origins", "strips")),
            data[0],
        )
        rows = batch.column(main).to_pylist()
        steps = out.setdefault(entity, {})
        for step, row in zip(batch.column("step").to_pylist(), rows, strict=True):
            steps[step] = steps.get(step, 0) + (len(row) if isinstance(row, list) else 1)
    return out, static


def test_a_saved_recording_holds_every_entity_for_every_step(tmp_path):
    scenario = uavtrack.Scenario(steps=25, faults={"failures": [[3, 10]]})
    result = uavtrack.simulate(scenario, seed=2)
    path = tmp_path / "run.rrd"
    rerun.save(result.trace, scenario, path)
    dynamic, static = contents(path)
    assert set(dynamic) | (static - {"__properties"}) == set(rerun.ENTITIES)
    assert static - {"__properties"} == {"world/field", "world/targets/paths"}
    for entity, steps in dynamic.items():
        assert sorted(steps) == list(range(25)), entity
    assert [dynamic["world/targets"][k] for k in range(25)] == [4] * 25
    # UAV 3 fails at step 10: every UAV keeps its instance, UAV 3 stays where it fell
    assert [dynamic["world/uavs"][k] for k in range(25)] == [5] * 25
    uavs = column(path, "world/uavs", "positions")
    labels = column(path, "world/uavs", "labels")
    for k in (5, 15, 24):
        assert np.allclose(uavs[k], result.trace.uavs[k, :, :3], atol=1e-4)  # float32
        assert labels[k][3] == ("U3" if k < 10 else "U3 (failed)") and labels[k][4] == "U4"
    tracking = (result.trace.assignment >= 0) & result.trace.alive
    centers = column(path, "world/estimates/ellipses", "centers")
    drawn = [
        int(np.isfinite(np.array(centers[k], dtype=float)).all(axis=1).sum()) for k in range(25)
    ]
    assert drawn == list(tracking.sum(1))  # what a UAV no longer has is NaN: not drawn
    links = np.triu(uavtrack.network.adjacency(result.trace.uavs, scenario.comm_range))
    links &= result.trace.alive[:, :, None] & result.trace.alive[:, None, :]
    assert [dynamic["world/links"].get(k, 0) for k in range(25)] == list(links.sum(axis=(1, 2)))


def column(path, entity, name):
    """step -> the rows of one component column of an entity."""
    for chunk in RrdReader(path).store().stream():
        if chunk.entity_path.lstrip("/") == entity and not chunk.is_static:
            batch = chunk.to_record_batch()
            wanted = next(n for n in batch.schema.names if n.split(":")[-1] == name)
            steps = batch.column("step").to_pylist()
            return dict(zip(steps, batch.column(wanted).to_pylist(), strict=True))
    raise KeyError(entity)


def test_recordings_of_different_runs_have_different_ids_and_a_top_view(tmp_path):
    a, b = uavtrack.Scenario(steps=3), uavtrack.Scenario(steps=3, comm_range=80)
    assert rerun.recording_id("distributed-0", a) != rerun.recording_id("distributed-0", b)
    rerun.save(uavtrack.simulate(a, seed=0).trace, a, tmp_path / "a.rrd", "distributed-0")
    reader = RrdReader(tmp_path / "a.rrd")
    assert [r.recording_id for r in reader.recordings()] == [f"distributed-0-{a.digest()}"]
    assert len(reader.blueprints()) == 1  # the default layout travels with the file
    above = rerun.blueprint(a).root_container.contents[0]
    assert above.name == "field from above" and "EyeControls3D" in above.properties


def test_one_entity_per_kind_whatever_the_team(tmp_path):
    kinds = []
    for team in ((3, 2), (40, 30)):
        scenario = uavtrack.Scenario(steps=4).scaled(*team)
        result = uavtrack.simulate(scenario, seed=0)
        rerun.save(result.trace, scenario, tmp_path / "r.rrd")
        dynamic, static = contents(tmp_path / "r.rrd")
        kinds.append(set(dynamic) | static)
        assert dynamic["world/uavs"][3] == team[0]
    assert kinds[0] == kinds[1]


def cli(*args, display=False):
    env = {**os.environ, "DISPLAY": "", "WAYLAND_DISPLAY": ""} if not display else None
    return subprocess.run(
        [sys.executable, "-m", "uavtrack.cli", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )


@pytest.mark.integration
def test_run_writes_a_recording_and_refuses_bad_names(tmp_path):
    out = cli("run", "--set", "steps=15", "--rerun", str(tmp_path / "a.rrd"), "--json")
    assert out.returncode == 0 and "Rerun recording written" in out.stderr
    assert sorted(contents(tmp_path / "a.rrd")[0]["world/uavs"]) == list(range(15))
    bad = cli("run", "--rerun", str(tmp_path / "a.txt"))
    assert bad.returncode == 2 and bad.stderr.strip().endswith("should end in .rrd")
    missing = cli("run", "--rerun", str(tmp_path / "no" / "a.rrd"))
    assert missing.returncode == 2 and "does not exist" in missing.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.rrd"]


@pytest.mark.integration
def test_run_rerun_without_a_file_needs_a_display_and_says_so(tmp_path):
    out = cli("run", "--set", "steps=5", "--rerun", "--json")  # --json is not the file
    assert out.returncode == 2 and out.stdout == ""  # refused before any work
    assert out.stderr.count("\n") == 1
    assert "needs a display" in out.stderr and "--rerun FILE.rrd" in out.stderr


@pytest.mark.integration
@pytest.mark.parametrize("room", [20_000, 40_000])
def test_a_recording_on_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, room):
    proc = on_a_small_disk(
        tmp_path, room, "-m", "uavtrack.cli", "run", "--steps", 20, "--rerun", "x.rrd"
    )
    assert proc.returncode == 1 and proc.stdout == "", proc.stderr[-2000:]
    assert proc.stderr == "uavtrack: error: cannot write x.rrd: File too large\n"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.integration
def test_a_recording_with_rerun_turned_off_is_refused_in_one_line(tmp_path):
    out = subprocess.run(
        [sys.executable, "-m", "uavtrack.cli", "run", "--steps", "3", "--rerun", "x.rrd"],
        cwd=tmp_path, env={**os.environ, "RERUN": "off"}, capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.count("\n") == 1 and "Rerun is turned off here" in out.stderr
    assert list(tmp_path.iterdir()) == []


def test_each_metric_has_a_view_on_its_own_scale(tmp_path):
    scenario = uavtrack.Scenario(steps=8)
    rerun.save(uavtrack.simulate(scenario, seed=1).trace, scenario, tmp_path / "m.rrd")
    reader = RrdReader(tmp_path / "m.rrd")
    views, ranges = {}, {}
    for chunk in reader.stream(store=reader.blueprints()[0]):  # the layout, read back
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if "ViewBlueprint:class_identifier" in names:
            kind = batch.column("ViewBlueprint:class_identifier").to_pylist()[0]
            origin = batch.column("ViewBlueprint:space_origin").to_pylist()[0][0]
            views[chunk.entity_path] = (kind, origin)
        if "ScalarAxis:range" in names:
            view = chunk.entity_path.rsplit("/", 1)[0]
            ranges[view] = batch.column("ScalarAxis:range").to_pylist()[0][0]
    series = {origin: view for view, (kind, origin) in views.items() if "TimeSeries" in kind}
    metrics = {e for e in rerun.ENTITIES if e.startswith("metrics/")}
    assert set(series) == metrics  # one view per metric, none shared
    assert ranges == {series["metrics/observation_rate"]: [0.0, 1.0]}  # a share: [0, 1]


@pytest.mark.integration
def test_the_viz_extra_reads_a_recording_back(tmp_path):
    import tomllib
    from pathlib import Path

    project = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    extra = project["project"]["optional-dependencies"]["viz"]
    viz = {re.split("[<>=!~; ]", requirement)[0] for requirement in extra}
    assert {"rerun-sdk", "pyarrow"} <= viz  # Rerun writes, pyarrow holds what it reads back
    scenario = uavtrack.Scenario(steps=12)
    trace = uavtrack.simulate(scenario, seed=4).trace
    rerun.save(trace, scenario, tmp_path / "r.rrd")
    # read back with the viz extra alone: no pandas, polars or datafusion
    code = (
        "import sys, json\n"
        "for name in ('pandas', 'polars', 'datafusion'):\n"
        "    sys.modules[name] = None\n"
        "from rerun.chunk import RrdReader\n"
        "for chunk in RrdReader(sys.argv[1]).store().stream():\n"
        "    if chunk.entity_path == '/metrics/observation_rate':\n"
        "        batch = chunk.to_record_batch()\n"
        "        column = next(n for n in batch.schema.names if n.endswith(':scalars'))\n"
        "        rows = zip(batch.column('step').to_pylist(), batch.column(column).to_pylist())\n"
        "        print(json.dumps(sorted((k, v[0]) for k, v in rows)))\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "r.rrd")], capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    steps, rates = zip(*json.loads(proc.stdout), strict=True)
    assert list(steps) == list(range(12))
    running = np.cumsum(trace.observed.any(axis=1).mean(axis=1)) / np.arange(1, 13)
    assert np.allclose(rates, running, rtol=1e-12, atol=0)


def test_a_recording_of_a_team_that_all_failed_warns_of_nothing(tmp_path):
    import warnings

    failures = [[i, 0] for i in range(5)]
    scenario = uavtrack.Scenario(steps=6, faults={"failures": failures})
    trace = uavtrack.simulate(scenario, seed=0).trace
    assert not trace.alive.any()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rerun.save(trace, scenario, tmp_path / "x.rrd")
    assert (tmp_path / "x.rrd").stat().st_size > 0


def test_targets_that_come_and_go_are_drawn_while_present(tmp_path):
    """With target.stay a target away is not drawn (NaN) and each stay has its own path
    and name: T0, then T0.1 for the next target in place 0."""
    scenario = uavtrack.Scenario(steps=40).with_overrides(
        {"tracker.association": "jpda", "target.stay": 8, "target.away": 4}
    )
    result = uavtrack.simulate(scenario, seed=4)
    path = tmp_path / "run.rrd"
    rerun.save(result.trace, scenario, path)
    here = ~np.isnan(result.trace.targets[..., 0])
    points = column(path, "world/targets", "positions")
    labels = column(path, "world/targets", "labels")
    for k in range(40):
        drawn = np.isfinite(np.array(points[k], dtype=float)).all(axis=1)
        assert drawn.tolist() == here[k].tolist()
    entered = (here[1:] & ~here[:-1]).sum(axis=0)  # new targets per place
    names = {
        name for k in range(40) for name, shown in zip(labels[k], here[k], strict=True) if shown
    }
    assert len(names) == 4 + entered.sum()
    assert "T0" in names and (entered[0] == 0 or "T0.1" in names)
