"""Command line: ``uavtrack run``, ``uavtrack params``.

Bad input of any kind ends with one line ``uavtrack: error: ...`` on stderr and exit
code 2, and leaves no partial output file.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from enum import Enum
from pathlib import Path
from typing import Annotated, Any

import typer
from typer.exceptions import TyperException

from .config import Scenario, ScenarioError, parse_value

app = typer.Typer(
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    help="Distributed multi-UAV cooperative multi-target tracking.",
)


class MethodName(str, Enum):
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


def atomic_write(path: Path, write) -> None:
    """Call ``write(file)`` on a temporary file beside `path`, then rename it into place."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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

    from .simulation import simulate

    scenario = load_scenario(config, set_)
    if trace is not None:
        writable_target(trace, "--trace")
    result = simulate(scenario, method.value, seed=seed, trace=trace is not None)
    if trace is not None:
        atomic_write(trace, lambda f: np.savez_compressed(f, **result.trace.arrays()))
    summary = result.summary()
    if as_json:
        summary["scenario"] = scenario.model_dump()
        typer.echo(json.dumps(summary))
        return
    from rich.console import Console
    from rich.table import Table

    from rich.markup import escape

    table = Table(title=f"uavtrack run: {summary['method']}, seed {seed}", show_header=False)
    table.add_row("observation rate", f"{summary['observation_rate']:.4f}")
    for j, rate in enumerate(summary["per_target"]):
        table.add_row(f"  target {j}", f"{rate:.4f}")
    table.add_row(escape("position RMSE [m]"), f"{summary['rmse']:.2f}")
    table.add_row("NEES (4 if consistent)", f"{summary['nees']:.2f}")
    table.add_row("consensus rounds per UAV", f"{summary['rounds']:.2f}")
    table.add_row("messages per step", f"{summary['messages']:.2f}")
    table.add_row(escape("decision time per UAV [ms]"), f"{1e3 * summary['decision_time']:.3f}")
    Console().print(table)
    if trace is not None:
        typer.echo(f"trace written to {trace}")


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
    from rich.console import Console
    from rich.table import Table

    table = Table("field", "value", "unit, source")
    from rich.markup import escape

    for name, value, doc in scenario.describe():
        table.add_row(name, escape(str(value)), escape(doc))
    Console(width=160).print(table)


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit code (2 for any bad input)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        app(args=argv or ["--help"], prog_name="uavtrack", standalone_mode=False)
    except TyperException as exc:  # usage errors: unknown option, bad value, ...
        return fail(exc.format_message())
    except ScenarioError as exc:
        return fail(str(exc))
    except typer.Abort:
        return fail("interrupted")
    except typer.Exit as exc:
        return exc.exit_code
    return 0


def fail(message: str) -> int:
    message = " ".join(message.split()).replace("Value error, ", "")
    print(f"uavtrack: error: {message}", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
