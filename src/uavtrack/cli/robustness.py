"""`uavtrack robustness`: every method under every fault (the paper's Sec. 8, measured)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..limits import MAX_TRIALS
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
    WorkersOpt,
    refuse_set,
    run_experiment,
)


@app.command()
def robustness(
    out: OutOpt = None,
    trials: Annotated[
        int | None, typer.Option(min=1, max=MAX_TRIALS, metavar="N", help="trials per point [50]")
    ] = None,
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
    """Every method under message loss, bursts, delay, a round budget, UAV failures and
    position error, with and without the robustness options, into a folder.

    Profile: 50 trials of 500 steps; --quick: 4 trials of 60 steps."""
    from ..experiments import robustness as experiment

    scenario = load_scenario(config, set_, team)
    refuse_set(scenario, ("faults.", "robust."), "robustness", "the faults and the robust options")
    summary, out, info = run_experiment(
        experiment,
        scenario,
        dict(locals()),  # the command's options, by name
    )
    _print(summary, out, info)


def _print(summary: dict, out: Path, info: dict) -> None:
    from rich.table import Table

    from ..experiments.statistics import level_text

    table = Table(title="observation rate under faults (mean over trials)")
    for col in ("fault", "level", "distributed", "robust", "centralized", "greedy"):
        table.add_column(col, justify="left" if col == "fault" else "right")
    for name, fault in summary["faults"].items():
        fixed = ", ".join(f"{f.split('.')[-1]} {v}" for f, v in fault.get("fixed", {}).items())
        label = f"{name} (at {fixed})" if fixed else name  # the burst rows run at 30% loss
        for k, level in enumerate(fault["levels"]):
            table.add_row(
                label if k == 0 else "",
                level_text(level),
                *(f"{fault['series'][s][k]['mean']:.3f}" for s in fault["series"]),
            )
    console().print(table)
    typer.echo(
        f"wrote {out}/summary.json, report.md, fault_*.png ({info['jobs_run']} jobs run, "
        f"{info['jobs_skipped']} reused, {info['seconds']:.1f} s)"
    )
