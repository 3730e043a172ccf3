"""`uavtrack realistic`: the three methods in the realistic preset, with the robust
options and with one realism removed at a time, paired."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..limits import MAX_TRIALS
from .app import SetOpt, app, console, load_scenario
from .experiments import (
    AddressOpt,
    EngineName,
    EngineOpt,
    ProgressOpt,
    SeedOpt,
    WorkersOpt,
    run_experiment,
)


@app.command()
def realistic(
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            metavar="DIR",
            help="results folder [results/realistic; results/realistic-quick with --quick]",
        ),
    ] = None,
    trials: Annotated[
        int | None,
        typer.Option(min=1, max=MAX_TRIALS, metavar="N", help="trials per cell and method [50]"),
    ] = None,
    steps: Annotated[
        int | None, typer.Option(min=1, metavar="N", help="steps per trial [200]")
    ] = None,
    quick: Annotated[
        bool, typer.Option("--quick", help="small profile for smoke tests: 2 trials x 30 steps")
    ] = False,
    workers: WorkersOpt = None,
    engine: EngineOpt = EngineName.local,
    address: AddressOpt = None,
    seed: SeedOpt = 0,
    set_: SetOpt = None,
    progress: ProgressOpt = None,
) -> None:
    """The three methods in the realistic preset (--config realistic), with the robust
    options, and with each realism removed in turn: observation rate, separation losses,
    bytes, the gain of each removal paired with the preset, and each method's distance
    from its oracle-sensor rate; into a folder. --set changes the preset for every cell."""
    from ..experiments import realistic as experiment

    config = Path("realistic")  # the shipped preset, by name
    scenario = load_scenario(config, set_)
    for method in experiment.METHODS:  # every cell, checked before any work
        for variant in experiment.variants():
            experiment.scenario_of(scenario, method, variant)
    options = dict(locals())  # the command's options, by name
    summary, out, info = run_experiment(
        "realistic",
        experiment,
        scenario,
        options,
        lambda jobs: ["realistic.png"],
        lambda summary, out: experiment.figure(summary, out / "realistic.png"),
        experiment.report,
    )
    _print(summary, out, info)


def _print(summary: dict, out: Path, info: dict) -> None:
    from rich.table import Table

    from ..experiments.realistic import METHODS

    table = Table(title="realistic: observation rate (gain against the preset)")
    table.add_column("cell")
    for method in METHODS:
        table.add_column(method, justify="right")
    for variant in summary["variants"]:
        row = []
        for method in METHODS:
            c = summary["methods"][method]["cells"][variant]
            gain = "" if variant == "preset" else f" ({c['gain']['mean']:+.3f})"
            row.append(f"{c['observation_rate']:.3f}{gain}")
        table.add_row(variant, *row)
    console().print(table)
    d = summary["distributed_minus_greedy"]
    typer.echo(
        f"distributed - greedy in the preset: {d['mean']:+.3f} ({d['ci_low']:+.3f}, "
        f"{d['ci_high']:+.3f}); wrote {out}/summary.json, report.md, realistic.png "
        f"({info['jobs_run']} jobs run, {info['jobs_skipped']} reused, {info['seconds']:.1f} s)"
    )
