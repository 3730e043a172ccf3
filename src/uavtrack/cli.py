"""Command line: ``uavtrack run``, ``uavtrack params``.

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

from .config import Scenario, ScenarioError, parse_value
from .files import replacing

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

    from .simulation import simulate

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
    from .experiments import compare as run_compare
    from .experiments import summarize

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


class EngineName(StrEnum):
    local = "local"
    dask = "dask"


OutOpt = Annotated[Path | None, typer.Option("--out", help="results folder")]
WorkersOpt = Annotated[
    int | None, typer.Option(min=1, help="parallel workers (default: the cores available)")
]
EngineOpt = Annotated[EngineName, typer.Option(help="local processes (joblib) or a Dask cluster")]
AddressOpt = Annotated[
    str | None,
    typer.Option(help="Dask scheduler address (with --engine dask; default: a LocalCluster)"),
]
SeedOpt = Annotated[int, typer.Option(min=0, help="experiment seed (trial t uses its t-th child)")]
ProgressOpt = Annotated[bool, typer.Option("--progress/--no-progress", help="show a progress bar")]


def run_jobs(plan, out: Path, manifest: dict, engine, workers, address, progress) -> tuple:
    """Execute a plan into `out`; returns (results by job key, info) or exits 1 on failures."""
    import time

    from .experiments import unique
    from .runner import EngineError, Store, default_workers, execute

    jobs = unique(j for group in plan.values() for j in group)
    if address and engine != EngineName.dask:
        raise ScenarioError("--address needs --engine dask")
    store = Store(out, manifest)
    start = time.perf_counter()
    workers = workers or default_workers()
    try:
        skipped, failed = execute(jobs, store, engine.value, workers, address, progress)
    except KeyboardInterrupt:
        saved = sum(store.done(job) for job in jobs)
        print(
            f"uavtrack: interrupted; {saved} of {len(jobs)} jobs are saved in {store.raw}; "
            "run the same command again to finish",
            file=sys.stderr,
        )
        raise typer.Exit(130) from None
    except EngineError as exc:
        saved = sum(store.done(job) for job in jobs)
        print(
            f"uavtrack: {exc}; {saved} of {len(jobs)} jobs are saved in {store.raw}; "
            "run the same command again to finish",
            file=sys.stderr,
        )
        raise typer.Exit(1) from None
    if failed:
        for job in failed:
            print(
                f"uavtrack: job {job.key} failed (see {store.failed / job.key}.json)",
                file=sys.stderr,
            )
        print(
            f"uavtrack: {len(failed)} of {len(jobs)} jobs failed; the others are saved in "
            f"{store.raw}; run the same command again to retry",
            file=sys.stderr,
        )
        raise typer.Exit(1)
    info = {
        "seconds": time.perf_counter() - start,
        "jobs_run": len(jobs) - skipped,
        "jobs_skipped": skipped,
        "engine": engine.value,
        "workers": workers,
        "command": "uavtrack " + " ".join(sys.argv[1:]),
    }
    return {job.key: store.load(job) for job in jobs}, info


@app.command()
def reproduce(
    out: OutOpt = None,
    trials: Annotated[int | None, typer.Option(min=1, help="trials per configuration [50]")] = None,
    steps: Annotated[int | None, typer.Option(min=1, help="steps per trial [500]")] = None,
    workers: WorkersOpt = None,
    engine: EngineOpt = EngineName.local,
    address: AddressOpt = None,
    quick: Annotated[bool, typer.Option(help="small profile for smoke tests")] = False,
    seed: SeedOpt = 0,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    progress: ProgressOpt = True,
) -> None:
    """Every experiment of the paper's Section 7: Figs. 5-9, summary.json and report.md."""
    from dataclasses import replace

    from . import plots, report
    from .experiments import Profile, reproduce_plan, summarize_reproduction
    from .files import write_json, write_text

    profile = Profile.quick() if quick else Profile()
    profile = replace(
        profile, **{k: v for k, v in (("trials", trials), ("steps", steps)) if v is not None}
    )
    profile = replace(profile, chunk=min(profile.chunk, profile.trials))
    out = out or Path("results") / ("reproduce-quick" if quick else "reproduce")
    scenario = load_scenario(config, set_).with_overrides({"steps": profile.steps})
    plan = reproduce_plan(scenario, profile, seed)
    manifest = {
        "kind": "reproduce",
        "seed": seed,
        "plan": profile.to_dict(),
        "scenario": scenario.model_dump(),
    }
    results, info = run_jobs(plan, out, manifest, engine, workers, address, progress)
    info["seed"] = seed
    summary = summarize_reproduction(plan, results, profile, scenario)
    summary["settings"] = {"profile": profile.to_dict(), "seed": seed, **info}
    write_json(out / "summary.json", summary)
    plots.reproduction_figures(summary, out)
    write_text(out / "report.md", report.reproduction(summary, scenario, info))
    _print_reproduction(summary, out, info)


def _print_reproduction(summary: dict, out: Path, info: dict) -> None:
    from rich.table import Table

    table = Table(title="Fig. 5: overall observation rate (mean ± std)")
    for col in ("method", "ours", "paper", "paired difference to distributed [95% CI]"):
        table.add_column(col)
    for m, r in summary["compare"].items():
        p = summary["paper"][m]
        pair = summary["paired"].get(f"distributed - {m}")
        diff = (
            ""
            if pair is None
            else (f"{-pair['mean']:+.4f} [{-pair['ci_high']:+.4f}, {-pair['ci_low']:+.4f}]")
        )
        table.add_row(
            m, f"{r['mean']:.4f} ± {r['std']:.4f}", f"{p['mean']:.4f} ± {p['std']:.4f}", diff
        )
    console().print(table)
    typer.echo(
        f"wrote {out}/summary.json, report.md, fig5.png ... fig9.png "
        f"({info['jobs_run']} jobs run, {info['jobs_skipped']} reused, "
        f"{info['seconds']:.1f} s)"
    )


@app.command()
def sweep(
    field: Annotated[str, typer.Argument(help="scenario field, dotted for nested ones")],
    values: Annotated[list[str], typer.Argument(help="values to try (read as TOML)")],
    methods: Annotated[
        list[MethodName] | None, typer.Option("--method", help="methods (repeatable) [all]")
    ] = None,
    trials: Annotated[int, typer.Option(min=1, help="trials per value and method")] = 20,
    out: OutOpt = None,
    workers: WorkersOpt = None,
    engine: EngineOpt = EngineName.local,
    address: AddressOpt = None,
    seed: SeedOpt = 0,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    progress: ProgressOpt = True,
) -> None:
    """Vary one scenario field; every method on the same trials at every value."""
    from . import plots, report
    from .experiments import summarize_sweep, sweep_plan
    from .files import write_json, write_text

    scenario = load_scenario(config, set_)
    parsed = [parse_value(v) for v in values]
    names = [m.value for m in (methods or list(MethodName))]
    plan = sweep_plan(scenario, field, parsed, names, trials, chunk=10, seed=seed)
    out = out or Path("results") / f"sweep-{field}"
    manifest = {
        "kind": "sweep",
        "seed": seed,
        "scenario": scenario.model_dump(),
        "plan": {"field": field, "values": parsed, "methods": names, "trials": trials},
    }
    results, info = run_jobs(plan, out, manifest, engine, workers, address, progress)
    info["seed"] = seed
    summary = summarize_sweep(plan, results, field, parsed, names)
    summary["settings"] = info
    write_json(out / "summary.json", summary)
    plots.sweep_figure(summary, out / "sweep.png")
    write_text(out / "report.md", report.sweep(summary, scenario, info))

    from rich.table import Table

    table = Table(title=f"observation rate against {field} (mean ± std, {trials} trials)")
    table.add_column(field)
    for m in names:
        table.add_column(m)
    for k, v in enumerate(parsed):
        table.add_row(
            str(v),
            *(
                f"{summary['methods'][m][k]['mean']:.4f} ± {summary['methods'][m][k]['std']:.4f}"
                for m in names
            ),
        )
    console().print(table)
    typer.echo(f"wrote {out}/summary.json, report.md, sweep.png ({info['seconds']:.1f} s)")


@app.command()
def animate(
    out: Annotated[Path, typer.Option("--out", help="GIF file to write")],
    config: ConfigOpt = None,
    method: Annotated[MethodName, typer.Option(help="decision method")] = MethodName.distributed,
    seed: Annotated[int, typer.Option(min=0, help="random seed of the trial")] = 0,
    set_: SetOpt = None,
    every: Annotated[int, typer.Option(min=1, help="draw every k-th step")] = 2,
    fps: Annotated[int, typer.Option(min=1, max=60, help="frames per second")] = 10,
) -> None:
    """Animate one trial like the paper's Fig. 4 (GIF, Pillow writer)."""
    from . import plots
    from .simulation import simulate

    if out.suffix.lower() != ".gif":
        raise ScenarioError(f"--out must name a .gif file, got {out}")
    writable_target(out, "--out")
    scenario = load_scenario(config, set_)
    result = simulate(scenario, method.value, seed=seed)
    frames = plots.animate(
        result.trace, scenario, out, every=every, fps=fps, title=f"{method.value}, seed {seed}"
    )
    typer.echo(f"wrote {out} ({frames} frames, observation rate {result.observation_rate:.3f})")


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


if __name__ == "__main__":
    sys.exit(main())
