"""`uavtrack flight`: the paper's comparison with every UAV a JSBSim aircraft."""

from __future__ import annotations

from pathlib import Path

import typer

from ..errors import UsageError
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
def flight(
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
    """The paper's three methods with every UAV a JSBSim aircraft (trackwing) in calm
    air, wind and turbulence, paired against the unicycle; the autopilot's bank
    tracking; into a folder.

    Conditions: unicycle; jsbsim in calm air, in a west wind of 5 and 10 m/s, in
    moderate turbulence; and the two winds with planner.wind (the planner knows the
    wind). --quick: the unicycle and the 10 m/s wind, 2 trials x 40 steps.

    Profile: 50 trials of 500 steps; --quick: 2 trials of 40 steps."""
    from ..config import Scenario, flatten, read_toml
    from ..config.scenario import config_file
    from ..experiments import flight as experiment
    from .app import parse_overrides

    own = ("wind.", "uav.dynamics", "planner.wind")
    given = [
        *parse_overrides(set_ or []),
        *(flatten(read_toml(config_file(config))) if config else {}),
    ]
    for name in given:  # before the scenario is checked, whose advice would differ
        if name.startswith(own):
            raise UsageError(
                f"flight sets uav.dynamics, planner.wind and the wind itself; do not set "
                f"{name} (its conditions are listed in uavtrack flight --help)"
            )
    Scenario().with_overrides(experiment.JSBSIM, origin="uavtrack flight")  # JSBSim there?
    scenario = load_scenario(config, set_, team)
    refuse_set(scenario, own, "flight", "uav.dynamics, planner.wind and the wind")
    options = dict(locals())  # the command's options, by name

    def autopilot(s: Scenario) -> dict:
        return {"autopilot": experiment.characterise(s, 10.0 if quick else 60.0, seed)}

    summary, out, info = run_experiment(experiment, scenario, options, before=autopilot)
    _print(summary, out, info)


def _print(summary: dict, out: Path, info: dict) -> None:
    from rich.table import Table

    table = Table(title="observation rate under real flight (mean over trials)")
    for col in ("condition", "distributed", "centralized", "greedy", "distributed - unicycle"):
        table.add_column(col, justify="left" if col == "condition" else "right")
    for name, c in summary["conditions"].items():
        against = c.get("against_unicycle", {}).get("distributed")
        table.add_row(
            name,
            *(f"{c['methods'][m]['mean']:.3f}" for m in ("distributed", "centralized", "greedy")),
            f"{against['mean']:+.3f}" if against else "",
        )
    console().print(table)
    auto = summary["autopilot"]
    typer.echo(
        f"autopilot: bank to 63% in {auto['step']['t63_s']:.2f} s, reversal in "
        f"{auto['reversal']['t63_s']:.2f} s; bank error over a cycle "
        f"{auto['tracking']['mean_error_deg']:.1f} deg on average"
    )
    typer.echo(
        f"wrote {out}/summary.json, report.md, flight.png ({info['jobs_run']} jobs run, "
        f"{info['jobs_skipped']} reused, {info['seconds']:.1f} s)"
    )
