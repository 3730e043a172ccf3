"""`uavtrack bandwidth`: the three methods on a radio of limited capacity, with and
without the compact encoding and the event trigger, paired."""

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


@app.command()
def bandwidth(
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
    """The three methods on a radio of 1 kbit/s to 1 Mbit/s and unlimited (the channel
    shared by each UAV's neighbourhood), distributed and greedy also with the compact
    encoding, the event trigger and both: observation rate, bytes per UAV and step, the
    cost paired against the unlimited paper exchange, and the capacity that keeps 95 %
    of it; into a folder.

    Profile: 50 trials of 500 steps; --quick: 2 trials of 40 steps."""
    from ..errors import UsageError
    from ..experiments import bandwidth as experiment

    mine = ("radio.bandwidth_bps", "radio.encoding", "fusion.trigger", "fusion.refresh")
    given = [k for k in parse_overrides(set_ or []) if k in mine]
    if given:
        raise UsageError(
            f"bandwidth sets {given[0]} itself (it runs every capacity from 1 kbit/s to 1 "
            "Mbit/s and unlimited, with and without the compact encoding and the trigger); "
            "leave it out of --set"
        )
    scenario = load_scenario(config, set_)
    options = dict(locals())  # the command's options, by name
    summary, out, info = run_experiment(experiment, scenario, options)
    _print(summary, out, info)


def _print(summary: dict, out: Path, info: dict) -> None:
    from rich.table import Table

    from ..experiments.bandwidth import BANDWIDTHS, name

    table = Table(title="bandwidth: observation rate (bytes per UAV and step)")
    table.add_column("method, variant", no_wrap=True, min_width=24)
    for b in BANDWIDTHS:
        table.add_column(name(b), justify="right")
    for method, rows in summary["methods"].items():
        for variant, row in rows.items():
            cells = [row[name(b)] for b in BANDWIDTHS]
            table.add_row(
                f"{method}, {variant}",
                *(f"{c['observation_rate']['mean']:.3f} ({c['bytes']['mean']:.0f})" for c in cells),
            )
    console().print(table)
    met = sum(g["met"] for g in summary["goals"])
    typer.echo(
        f"goals met: {met} of {len(summary['goals'])} (report.md); wrote {out}/summary.json, "
        f"report.md, bandwidth.png ({info['jobs_run']} jobs run, {info['jobs_skipped']} "
        f"reused, {info['seconds']:.1f} s)"
    )
