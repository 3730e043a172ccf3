"""`uavtrack sensing`: missed detections, clutter and unknown association, for the three
methods, paired against known association."""

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
def sensing(
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
    """The three methods at detection probability 1, 0.9, 0.7 x clutter 0, 2, 10 per scan
    x association gnn, jpda, each paired with known association on the same trials, and
    at 0.9 and 2 jpda without a briefing (jpda-unbriefed) and without a briefing with
    targets that come and go (jpda-births: target.stay 200, target.away 100; another
    truth, so unpaired): observation rate, GOSPA, OSPA(2) and the team picture's,
    duplicate, stale and never-followed tracks, label purity, switches, the team's time
    to confirm, SIAP, NEES; into a folder.

    Profile: 50 trials of 500 steps; --quick: 2 trials of 60 steps."""
    from ..experiments import sensing as experiment

    scenario = load_scenario(config, set_, team)
    refuse_set(
        scenario,
        ("sensor.detection_probability", "sensor.clutter_rate", "tracker.association"),
        "sensing",
        "the detection probability, the clutter rate and the association",
    )
    summary, out, info = run_experiment(
        experiment,
        scenario,
        dict(locals()),  # the command's options, by name
    )
    _print(summary, out, info)


def _print(summary: dict, out: Path, info: dict) -> None:
    from rich.table import Table

    table = Table(title="sensing (mean over trials)")
    for col in ("method", "P_D", "clutter", "assoc.", "rate", "− known", "GOSPA", "dup/tgt"):
        table.add_column(col, justify="left" if col in ("method", "assoc.") else "right")
    for method, rows in summary["methods"].items():
        for k, e in enumerate(rows.values()):
            against = e.get("against_known")
            false = e["duplicate_tracks"]["mean"]
            table.add_row(
                method if k == 0 else "",
                f"{e['pd']:g}",
                f"{e['clutter']:g}",
                e["association"],
                f"{e['observation_rate']['mean']:.3f}",
                f"{against['observation_rate']['mean']:+.3f}" if against else "",
                f"{e['gospa']['mean']:.2f}",
                "" if false is None or false != false else f"{false:.3f}",
            )
    console().print(table)
    met = sum(g["met"] for g in summary["goals"])
    typer.echo(
        f"goals met: {met} of {len(summary['goals'])} (report.md); wrote {out}/summary.json, "
        f"report.md, sensing.png ({info['jobs_run']} jobs run, {info['jobs_skipped']} reused, "
        f"{info['seconds']:.1f} s)"
    )
