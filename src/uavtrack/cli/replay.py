"""`uavtrack replay`: recorded scans through the trackers and the team (the io extra)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._files import check_distinct, check_new_folder, check_output, new_folder
from ..errors import RunError, UsageError
from .app import (
    DISTRIBUTED,
    BagOpt,
    ConfigOpt,
    ForceOpt,
    MethodOpt,
    SeedOpt,
    SetOpt,
    app,
    check_bag,
    load_scenario,
    parse_overrides,
    show,
    source_of,
    steps_bar,
)

SET_BY_RECORDING = {"n_uavs", "n_targets", "steps", "tracker.briefing"}
"""Scenario fields a replay takes from the recording (`replay.scenario_for`)."""


@app.command()
def replay(
    source: Annotated[
        Path,
        typer.Argument(
            metavar="FOLDER",
            help="a recording: a folder of tables (uavs, measurements; links, briefing, "
            "targets if known), Parquet or CSV, such as `uavtrack export TRACE --out FOLDER` "
            "writes, or a ROS 2 bag of /uav_<i>/odom and /uav_<i>/radar_scan, such as "
            "`uavtrack run --bag FOLDER` writes with tracks (schema: docs, Replay recorded "
            "scans)",
        ),
    ],
    config: ConfigOpt = None,
    method: MethodOpt = DISTRIBUTED,
    seed: SeedOpt = 0,
    set_: SetOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="print one JSON object")] = False,
    trace: Annotated[
        Path | None,
        typer.Option("--trace", metavar="FILE", help="write the per-step trace to FILE (.npz)"),
    ] = None,
    tables: Annotated[
        Path | None,
        typer.Option(
            "--tables",
            metavar="FOLDER",
            help="write the tracks and the rest of the trace as Parquet tables to a new FOLDER "
            "(as uavtrack export: a recording too, with its briefing and scenario.toml)",
        ),
    ] = None,
    bag: BagOpt = None,
    force: ForceOpt = False,
) -> None:
    """Run the trackers, the team's agreement and its assignment on recorded scans.

    The scenario is --config, else the folder's scenario.toml, else the defaults; the
    recording sets the team, the steps and the briefing. --seed draws the radio's faults.
    """
    from ..io.replay import replay as run_replay

    source = source.expanduser()
    check_distinct({"--trace": trace, "--tables": tables, "--bag": bag})
    if trace is not None:
        check_output(trace, "--trace", force)
    if tables is not None:
        check_new_folder(tables, "--tables", "the tables", force)
    check_bag(bag, force)
    record, scenario, given = recorded(source, config, set_, "FOLDER")
    with steps_bar(scenario) as advance:
        result = run_replay(record, scenario, method.value, seed, progress=lambda _: advance(1))
    if tables is not None:
        _write_tables(result, tables, record)
    import numpy as np  # not at import: a command's help loads no numpy

    assert result.trace is not None
    label, status = result.trace.label, result.trace.status
    confirmed = (status == 2).sum(axis=-1).mean()
    rows = [
        ("recording", f"{source}: {record.sensors} sensors, {record.steps} steps, "
                      f"{int(record.valid.sum())} measurements"),
        ("confirmed tracks per UAV and step", f"{confirmed:.2f}"),
        ("team labels held confirmed", f"{np.unique(label[status == 2]).size}"),
        ("truth", "given: scores against it" if record.targets is not None
                  else "none: no score against it"),
    ]  # fmt: skip
    if tables is not None:
        rows.append(("tables written to", str(tables)))
    source_text = source_of(given, set_, None)
    show(result, scenario, seed, as_json, trace, title="uavtrack replay", rows=rows,
         source=source_text, bag=bag, extra={"recording": str(source)},
         truth=record.targets is not None)  # fmt: skip


def recorded(source: Path, config: Path | None, set_: list[str] | None, option: str):
    """The recording at `source` (tables or a bag), the scenario it replays with (--config,
    else the folder's scenario.toml, else the defaults; then --set, then the recording's
    team, steps and briefing) and the config file read. `option` names `source` in errors."""
    try:
        from ..io import recording
    except ImportError as exc:
        raise UsageError(f"{option}: {exc}") from None
    from ..io.replay import scenario_for

    source = source.expanduser()
    if not source.is_dir():
        raise UsageError(f"{option}: {source} is not a folder of tables or a ROS 2 bag")
    settled = sorted(SET_BY_RECORDING & parse_overrides(set_ or []).keys())
    if settled:
        raise UsageError(f"--set {settled[0]}: the recording sets it; leave it out")
    given = config if config is not None else _folder_config(source)
    scenario = load_scenario(given, set_, None)
    if recording.is_bag(source):
        record = recording.from_bag(source, scenario)
    else:
        record = recording.read(source, scenario)
    return record, scenario_for(record, scenario), given


def _folder_config(folder: Path) -> Path | None:
    path = folder / "scenario.toml"
    return path if path.is_file() else None


def _write_tables(result, out: Path, record) -> None:
    """The replay's tables as `uavtrack export` writes a run's (a recording too: its
    briefing, the recording's, and its scenario)."""
    from ..io import tables

    frames = tables.to_frames(result)
    if record.prior is not None:
        frames["briefing"] = tables.briefing_frame(*record.prior)
    try:
        with new_folder(out) as folder:
            folder.mkdir()
            for name, frame in frames.items():
                tables.write_table(frame, folder / f"{name}.parquet", "parquet")
            (folder / "scenario.toml").write_text(result.scenario.to_toml(), encoding="utf-8")
    except OSError as exc:
        raise RunError(f"cannot write the tables {out}: {exc.strerror or exc}") from None
