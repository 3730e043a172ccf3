"""`uavtrack separation`: collision avoidance at one altitude, for the three methods with
and without the avoidance filter, paired."""

from __future__ import annotations

from pathlib import Path

import typer

from .app import ConfigOpt, SetOpt, app, console, load_scenario, parse_overrides
from .experiments import (
    AddressOpt,
    EngineName,
    EngineOpt,
    OutOpt,
    ProfileStepsOpt,
    ProgressOpt,
    QuickOpt,
    SeedOpt,
    TrialsOpt,
    WorkersOpt,
    run_experiment,
)

PRESET = "one-altitude"
"""The base when no --config is given."""


@app.command()
def separation(
    out: OutOpt = None,
    trials: TrialsOpt = None,
    steps: ProfileStepsOpt = None,
    quick: QuickOpt = False,
    workers: WorkersOpt = None,
    engine: EngineOpt = EngineName.local,
    address: AddressOpt = None,
    seed: SeedOpt = 0,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    progress: ProgressOpt = None,
) -> None:
    """The three methods at one altitude with and without the avoidance filter, on the
    paper's team and on 20 x 16, with the paper's radio and the range where the filter's
    guarantee holds, unicycle and JSBSim: losses of separation, closest approach and the
    filter's cost in observation rate, paired; into a folder. The base is the preset
    one-altitude unless --config gives another.

    Profile: 50 trials of 500 steps; --quick: 2 trials of 40 steps."""
    from ..errors import UsageError
    from ..experiments import separation as experiment

    given = [k for k in parse_overrides(set_ or []) if k in ("planner.avoidance", "uav.dynamics")]
    if given:
        raise UsageError(
            f"separation sets {given[0]} itself (with and without the filter, unicycle and "
            "JSBSim); leave it out of --set"
        )
    config = config if config is not None else Path(PRESET)
    scenario = load_scenario(config, set_)
    options = dict(locals())  # the command's options, by name
    options["config"] = config
    summary, out, info = run_experiment(experiment, scenario, options)
    _print(summary, out, info)


def _print(summary: dict, out: Path, info: dict) -> None:
    from rich.table import Table

    table = Table(title="separation (mean over trials)")
    for col in ("method", "cell", "rate", "filter", "cost", "losses", "filter losses"):
        table.add_column(col, justify="left" if col in ("method", "cell") else "right")
    for method, rows in summary["methods"].items():
        for k, (cell, e) in enumerate(rows.items()):
            none, loiter = e["none"], e["loiter"]
            table.add_row(
                method if k == 0 else "",
                cell,
                f"{none['observation_rate']['mean']:.3f}",
                f"{loiter['observation_rate']['mean']:.3f}",
                f"{e['cost']['mean']:+.3f}",
                f"{none['separation_losses']['mean']:.2f}",
                f"{loiter['separation_losses']['mean']:.2f}",
            )
    console().print(table)
    met = sum(g["met"] for g in summary["goals"])
    typer.echo(
        f"goals met: {met} of {len(summary['goals'])} (report.md); wrote {out}/summary.json, "
        f"report.md, separation.png ({info['jobs_run']} jobs run, {info['jobs_skipped']} "
        f"reused, {info['seconds']:.1f} s)"
    )
