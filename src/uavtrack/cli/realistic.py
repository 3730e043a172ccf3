"""`uavtrack realistic`: the three methods in the realistic preset, with the robust
options and with one realism removed at a time, paired."""

from __future__ import annotations

from pathlib import Path

import typer

from .app import SetOpt, app, console, load_scenario
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


@app.command()
def realistic(
    out: OutOpt = None,
    trials: TrialsOpt = None,
    steps: ProfileStepsOpt = None,
    quick: QuickOpt = False,
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
    from its oracle-sensor rate; into a folder. --set changes the preset for every cell.

    Profile: 50 trials of 200 steps; --quick: 2 trials of 30 steps."""
    from ..experiments import realistic as experiment

    config = Path("realistic")  # the shipped preset, by name
    scenario = load_scenario(config, set_)
    for method in experiment.METHODS:  # every cell, checked before any work
        for variant in experiment.variants():
            experiment.scenario_of(scenario, method, variant)
    options = dict(locals())  # the command's options, by name
    summary, out, info = run_experiment(experiment, scenario, options)
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
