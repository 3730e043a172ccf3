"""Command line: ``uavtrack run | compare | reproduce | sweep | animate | bench | params``.

Bad input of any kind ends with one line ``uavtrack: error: ...`` on stderr and exit
code 2, and leaves no partial output file.
"""

from __future__ import annotations

import json
import os
import sys
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer
from typer.exceptions import TyperException

from ..config import Scenario, ScenarioError, parse_value
from ..files import replacing

app = typer.Typer(
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    help="Distributed multi-UAV cooperative multi-target tracking.",
)


class MethodName(StrEnum):
    distributed = "distributed"
    centralized = "centralized"
    greedy = "greedy"


ConfigOpt = Annotated[
    Path | None,
    typer.Option("--config", help="scenario TOML file (missing fields keep their defaults)"),
]
SetOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--set",
        metavar="FIELD=VALUE",
        help="override a scenario field, dotted for nested ones (sensor.half_fov_deg=10)",
    ),
]


def load_scenario(config: Path | None, overrides: list[str] | None) -> Scenario:
    """The scenario from an optional TOML file and FIELD=VALUE overrides."""
    scenario = Scenario.from_toml(config) if config is not None else Scenario()
    return scenario.with_overrides(parse_overrides(overrides or []))


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """``["a.b=1", "c=[1, 2]"]`` -> ``{"a.b": 1, "c": [1, 2]}`` (values read as TOML)."""
    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise ScenarioError(f"--set expects FIELD=VALUE, got {item!r}")
        out[name.strip()] = parse_value(text.strip())
    return out


def writable_target(path: Path, option: str) -> Path:
    """Check early that an output file can be created, before any long computation."""
    parent = path.expanduser().resolve().parent
    if not parent.is_dir():
        raise ScenarioError(f"{option}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise ScenarioError(f"{option}: directory {parent} is not writable")
    return path


@app.command()
def run(
    config: ConfigOpt = None,
    method: Annotated[MethodName, typer.Option(help="decision method")] = MethodName.distributed,
    seed: Annotated[int, typer.Option(min=0, help="random seed of the trial")] = 0,
    set_: SetOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="print one JSON object")] = False,
    trace: Annotated[
        Path | None, typer.Option("--trace", help="write the per-step trace to this .npz file")
    ] = None,
) -> None:
    """Simulate one trial and print its metrics."""
    import numpy as np

    from ..simulation import simulate

    scenario = load_scenario(config, set_)
    if trace is not None:
        writable_target(trace, "--trace")
    result = simulate(scenario, method.value, seed=seed, trace=trace is not None)
    if trace is not None:
        with replacing(trace) as tmp:
            np.savez_compressed(tmp, **result.trace.arrays())
    summary = result.summary()
    if as_json:
        summary["scenario"] = scenario.model_dump()
        typer.echo(json.dumps(summary))
        return
    from rich.markup import escape
    from rich.table import Table

    table = Table(title=f"uavtrack run: {summary['method']}, seed {seed}", show_header=False)
    table.add_row("observation rate", f"{summary['observation_rate']:.4f}")
    for j, rate in enumerate(summary["per_target"]):
        table.add_row(f"  target {j}", f"{rate:.4f}")
    table.add_row(escape("position RMSE [m]"), f"{summary['rmse']:.2f}")
    table.add_row("NEES (4 if consistent)", f"{summary['nees']:.2f}")
    table.add_row("consensus rounds per UAV", f"{summary['rounds']:.2f}")
    table.add_row("messages per step", f"{summary['messages']:.2f}")
    table.add_row(escape("decision time per UAV [ms]"), f"{1e3 * summary['decision_time']:.3f}")
    console().print(table)
    if trace is not None:
        typer.echo(f"trace written to {trace}")


@app.command()
def compare(
    config: ConfigOpt = None,
    methods: Annotated[
        list[MethodName] | None, typer.Option("--method", help="methods to compare (repeatable)")
    ] = None,
    trials: Annotated[int, typer.Option(min=1, help="Monte Carlo trials per method")] = 50,
    seed: Annotated[int, typer.Option(min=0, help="experiment seed")] = 0,
    set_: SetOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="print one JSON object")] = False,
) -> None:
    """Run the methods on the same trials; mean and std of each metric."""
    from ..experiments import compare as run_compare
    from ..experiments import summarize

    scenario = load_scenario(config, set_)
    names = [m.value for m in (methods or list(MethodName))]
    results = {m: summarize(v) for m, v in run_compare(scenario, names, trials, seed).items()}
    if as_json:
        typer.echo(
            json.dumps(
                {
                    "trials": trials,
                    "seed": seed,
                    "methods": results,
                    "scenario": scenario.model_dump(),
                }
            )
        )
        return
    from rich.markup import escape
    from rich.table import Table

    table = Table(title=f"{trials} trials, seed {seed}")
    for col in (
        "method",
        "observation rate",
        "per target",
        "RMSE [m]",
        "NEES",
        "rounds",
        "messages",
        "decision [ms]",
    ):
        table.add_column(
            escape(col), justify="left" if col in ("method", "per target") else "right"
        )
    for name, r in results.items():
        table.add_row(
            name,
            f"{r['observation_rate']['mean']:.4f} ± {r['observation_rate']['std']:.4f}",
            " ".join(f"{x:.3f}" for x in r["per_target"]["mean"]),
            f"{r['rmse']['mean']:.1f}",
            f"{r['nees']['mean']:.1f}",
            f"{r['rounds']['mean']:.2f}",
            f"{r['messages']['mean']:.1f}",
            f"{1e3 * r['decision_time']['mean']:.3f}",
        )
    console().print(table)


@app.command()
def params(
    config: ConfigOpt = None,
    set_: SetOpt = None,
    toml: Annotated[bool, typer.Option("--toml", help="print the scenario as TOML")] = False,
) -> None:
    """Show every scenario parameter with its value, unit and source."""
    scenario = load_scenario(config, set_)
    if toml:
        typer.echo(scenario.to_toml(), nl=False)
        return
    from rich.table import Table

    table = Table("field", "value", "unit, source")
    from rich.markup import escape

    for name, value, doc in scenario.describe():
        table.add_row(name, escape(str(value)), escape(doc))
    console(160).print(table)


def console(width: int = 120):
    """A rich console; wide when printing to a file or pipe (rich would use 80 columns)."""
    from rich.console import Console

    return Console() if sys.stdout.isatty() else Console(width=width)


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit code (2 for any bad input)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        # without standalone mode typer returns exit codes (typer.Exit, Ctrl-C -> 130)
        code = app(args=argv or ["--help"], prog_name="uavtrack", standalone_mode=False)
    except TyperException as exc:  # usage errors: unknown option, bad value, ...
        return fail(exc.format_message())
    except ScenarioError as exc:
        return fail(str(exc))
    except typer.Abort:
        fail("interrupted; finished jobs are kept, run the same command again to finish")
        return 130
    except typer.Exit as exc:
        return exc.exit_code
    return code if isinstance(code, int) else 0


def fail(message: str) -> int:
    message = " ".join(message.split()).replace("Value error, ", "")
    print(f"uavtrack: error: {message}", file=sys.stderr)
    return 2


# the other commands register themselves on `app`
from . import benchmark, experiments  # noqa: E402, F401
