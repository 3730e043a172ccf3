"""`uavtrack reproduce`, `uavtrack sweep` and `uavtrack animate`."""

from __future__ import annotations

import sys
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from ..config import ScenarioError, parse_value
from ..files import write_json, write_text
from . import ConfigOpt, MethodName, SetOpt, app, console, load_scenario, writable_target


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

    from ..experiments import unique
    from ..runner import EngineError, Store, default_workers, execute

    jobs = unique(j for group in plan.values() for j in group)
    if address and engine != EngineName.dask:
        raise ScenarioError("--address needs --engine dask")
    store = Store(out, manifest)
    start = time.perf_counter()
    workers = workers or default_workers()
    try:
        skipped, failed = execute(jobs, store, engine.value, workers, address, progress)
    except (KeyboardInterrupt, EngineError) as exc:
        interrupted = isinstance(exc, KeyboardInterrupt)
        saved = sum(store.done(job) for job in jobs)
        print(
            f"uavtrack: {'interrupted' if interrupted else exc}; {saved} of {len(jobs)} jobs "
            f"are saved in {store.raw}; run the same command again to finish",
            file=sys.stderr,
        )
        raise typer.Exit(130 if interrupted else 1) from None
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
    """Run every experiment of the paper's Section 7 (Figures 5 to 9) into a folder."""
    from dataclasses import replace

    from .. import plots, report
    from ..experiments import Profile, reproduce_plan, summarize_reproduction

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
    from .. import plots, report
    from ..experiments import summarize_sweep, sweep_plan

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
    """Animate one trial like the paper's Figure 4, as a GIF."""
    from .. import plots
    from ..simulation import simulate

    if out.suffix.lower() != ".gif":
        raise ScenarioError(f"--out must name a .gif file, got {out}")
    writable_target(out, "--out")
    scenario = load_scenario(config, set_)
    result = simulate(scenario, method.value, seed=seed)
    frames = plots.animate(
        result.trace, scenario, out, every=every, fps=fps, title=f"{method.value}, seed {seed}"
    )
    typer.echo(f"wrote {out} ({frames} frames, observation rate {result.observation_rate:.3f})")
