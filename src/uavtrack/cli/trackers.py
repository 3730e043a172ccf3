"""`uavtrack trackers`: the paper's tracker against the IMM and covariance intersection."""

from __future__ import annotations

from pathlib import Path

import typer

from .app import ConfigOpt, SetOpt, TeamOpt, app, console, load_scenario
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
    refuse_set,
    run_experiment,
)


@app.command()
def trackers(
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
    team: TeamOpt = None,
    progress: ProgressOpt = None,
) -> None:
    """The distributed method with the paper's tracker (cv + max_consensus), the IMM,
    covariance intersection and both, on the paper's and on manoeuvring targets:
    observation rate, RMSE, NEES against its band, OSPA; into a folder.

    Profile: 50 trials of 500 steps; --quick: 2 trials of 60 steps."""
    from ..experiments import trackers as experiment

    scenario = load_scenario(config, set_, team)
    refuse_set(
        scenario,
        ("target.motion", "tracker.", "fusion.rule"),
        "trackers",
        "target.motion, the tracker and fusion.rule",
    )
    summary, out, info = run_experiment(
        experiment,
        scenario,
        dict(locals()),  # the command's options, by name
    )
    _print(summary, out, info)


def _print(summary: dict, out: Path, info: dict) -> None:
    from rich.table import Table

    table = Table(title="trackers (distributed, mean over trials)")
    columns = ("motion", "tracker", "rate", "RMSE best", "NEES", "median", "inside 95%")
    for col in (*columns, "NEES best", "OSPA all"):
        table.add_column(col, justify="left" if col in ("motion", "tracker") else "right")
    for motion, rows in summary["motions"].items():
        for k, (tracker, r) in enumerate(rows.items()):
            table.add_row(
                motion if k == 0 else "",
                tracker,
                f"{r['mean']:.3f}",
                f"{r['rmse_best']['mean']:.2f}",
                f"{r['nees']['mean']:.2f}",
                f"{r['nees_median']['mean']:.2f}",
                f"{r['nees_inside']['mean']:.3f}",
                f"{r['nees_best']['mean']:.2f}",
                f"{r['ospa']['mean']:.2f}",
            )
    console().print(table)
    typer.echo(
        f"wrote {out}/summary.json, report.md, trackers.png ({info['jobs_run']} jobs run, "
        f"{info['jobs_skipped']} reused, {info['seconds']:.1f} s)"
    )
