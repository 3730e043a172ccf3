"""`uavtrack reproduce`, `uavtrack sweep` and `uavtrack animate`."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from contextlib import contextmanager
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from .._files import check_output, check_outputs, write_json, write_text
from ..errors import Interrupted, ScenarioError, UsageError
from ..limits import MAX_TRIALS
from .app import (
    DISTRIBUTED,
    ConfigOpt,
    ForceOpt,
    MethodName,
    MethodOpt,
    SetOpt,
    TeamOpt,
    TrialStepsOpt,
    app,
    chosen_methods,
    console,
    load_scenario,
    method_name,
    parse_overrides,
    steps_bar,
    with_steps,
)

if TYPE_CHECKING:
    from ..config import Scenario
    from ..experiments.protocol import Experiment


class EngineName(StrEnum):
    local = "local"
    dask = "dask"


WorkersOpt = Annotated[
    int | None,
    typer.Option(
        min=1, metavar="N", help="parallel workers, at most the cores available [the cores]"
    ),
]
EngineOpt = Annotated[
    EngineName,
    typer.Option(metavar="ENGINE", help="local (worker processes) or dask (a Dask cluster)"),
]
AddressOpt = Annotated[
    str | None,
    typer.Option(
        metavar="ADDRESS",
        help="Dask scheduler address, with --engine dask [a LocalCluster of --workers]",
    ),
]
SeedOpt = Annotated[
    int, typer.Option(min=0, metavar="N", help="experiment seed (trial t uses its t-th child)")
]
ProgressOpt = Annotated[
    bool | None,
    typer.Option(
        "--progress/--no-progress",
        help="show progress [a bar on a terminal, a line a minute elsewhere]",
    ),
]
StepsOpt = Annotated[int | None, typer.Option(min=1, metavar="N", help="steps per trial [500]")]

# the options of every experiment command (`experiments.protocol`), declared once; each
# command's help names its profile
OutOpt = Annotated[
    Path | None,
    typer.Option(
        "--out",
        metavar="DIR",
        help="results folder [results/COMMAND; results/COMMAND-quick with --quick]",
    ),
]
TrialsOpt = Annotated[
    int | None,
    typer.Option(
        min=1, max=MAX_TRIALS, metavar="N", help="trials per cell and method [the profile's]"
    ),
]
ProfileStepsOpt = Annotated[
    int | None, typer.Option("--steps", min=1, metavar="N", help="steps per trial [the profile's]")
]
QuickOpt = Annotated[
    bool, typer.Option("--quick", help="the small profile, for smoke tests (in the help above)")
]


def note(message: str) -> None:
    print(f"uavtrack: note: {message}", file=sys.stderr)


@contextmanager
def run_jobs(plan, out: Path, manifest: dict, engine, workers, address, progress, outputs=()):
    """Execute a plan into `out`; yields (results by job key, info) with the folder locked,
    so the caller writes its summary, figures and report under the same lock. `outputs`:
    the files the caller will write in `out`, checked before any job runs.

    Raises Interrupted on Ctrl-C and RunError when jobs failed; finished jobs are kept.
    """
    import time

    from .._process import available_memory
    from ..errors import RunError
    from ..experiments.jobs import unique
    from ..experiments.store import Store, check_scheduler, execute, resolve_workers
    from ..simulation import check_memory, memory_estimate

    jobs = unique(j for group in plan.values() for j in group)
    if address and engine != EngineName.dask:
        raise UsageError("--address needs --engine dask")
    check_outputs(out, ["summary.json", "report.md", *outputs])
    if address:
        check_scheduler(address)  # before anything is written
    workers, capped = resolve_workers(workers)
    if capped:
        note(capped)
    for job in jobs:  # refuse what cannot fit before any work
        check_memory(job.scenario, job.count)
    largest = max(sum(memory_estimate(j.scenario, j.count).values()) for j in jobs)
    fits = max(1, int(0.9 * available_memory() // max(largest, 1)))
    if workers > fits:
        note(f"{workers} workers would not fit in memory; using {fits}")
        workers = fits
    start = time.perf_counter()
    with Store(out, manifest) as store:
        try:
            skipped, failed = execute(jobs, store, engine.value, workers, address, progress)
        except KeyboardInterrupt:
            saved = sum(store.done(job) for job in jobs)
            raise Interrupted(
                f"{saved} of {len(jobs)} jobs are saved in {store.raw}; "
                "run the same command again to finish"
            ) from None
        except RunError as exc:
            saved = sum(store.done(job) for job in jobs)
            raise RunError(
                f"{exc}; {saved} of {len(jobs)} jobs are saved in {store.raw}; "
                "run the same command again to finish"
            ) from None
        for key, reason in store.set_aside:
            note(f"job file {key}.json was set aside in {store.failed} ({reason}) and recomputed")
        if failed:
            for job in failed:
                print(
                    f"uavtrack: job {job.key} failed (see {store.failed / job.key}.json)",
                    file=sys.stderr,
                )
            raise RunError(
                f"{len(failed)} of {len(jobs)} jobs failed; the others are saved in "
                f"{store.raw}; run the same command again to retry"
            )
        info = {
            "seconds": time.perf_counter() - start,
            "compute_seconds": sum(store.seconds(job) for job in jobs),
            "jobs_run": len(jobs) - skipped,
            "jobs_skipped": skipped,
            "engine": engine.value,
            "workers": workers,
            "command": "uavtrack " + " ".join(sys.argv[1:]),
        }
        yield {job.key: store.load(job) for job in jobs}, info


def sized(profile, trials: int | None, steps: int | None):
    """A profile with the --trials and --steps asked for (its job chunks no larger)."""
    from dataclasses import replace

    asked = {k: v for k, v in (("trials", trials), ("steps", steps)) if v is not None}
    profile = replace(profile, **asked)
    return replace(profile, chunk=min(profile.chunk, profile.trials))


def manifest_of(kind: str, seed: int, profile, scenario) -> dict:
    """What an experiment folder records it was made with."""
    return {"kind": kind, "seed": seed, "plan": profile.to_dict(), "scenario": scenario.to_dict()}


def run_experiment(
    experiment: Experiment,
    scenario: Scenario,
    options: dict[str, Any],
    before: Callable[[Scenario], dict[str, Any]] | None = None,
) -> tuple[dict[str, Any], Path, dict[str, Any]]:
    """The body every experiment command shares (`experiments.protocol.Experiment`): size
    the profile from --quick, --trials and --steps, plan the jobs, run them into the
    folder (results/NAME unless --out), and write summary.json, the figures and
    report.md. `before(scenario)` adds to the summary what is measured before the jobs
    (a dict). `options`: the command's quick, trials, steps, config, set_, seed, out,
    engine, workers, address and progress. Returns the summary, the folder and the run's
    info."""
    o, kind = options, experiment.NAME
    steps = explicit_steps(o["config"], o["set_"], o["steps"])
    quick = o["quick"]
    profile = sized(
        experiment.Profile.quick() if quick else experiment.Profile(), o["trials"], steps
    )
    out = o["out"] or Path("results") / (f"{kind}-quick" if quick else kind)
    scenario = scenario.with_overrides({"steps": profile.steps}, origin="--steps")
    seed = o["seed"]
    jobs = experiment.plan(scenario, profile, seed)
    refuse_any(jobs)
    manifest = manifest_of(kind, seed, profile, scenario)
    measured = before(scenario) if before is not None else {}
    run = run_jobs(jobs, out, manifest, o["engine"], o["workers"], o["address"], o["progress"],
                   experiment.figures(jobs))  # fmt: skip
    with run as (results, info):
        info["seed"] = seed
        summary = experiment.summarize(jobs, results, profile, scenario)
        summary.update(measured)
        summary["settings"] = {"profile": profile.to_dict(), "seed": seed, **info}
        write_json(out / "summary.json", summary)
        experiment.figure(summary, out)
        write_text(out / "report.md", experiment.report(summary, scenario, info))
    return summary, out, info


def refuse_any(jobs: dict[str, list[Any]]) -> None:
    """Every job's scenario and method checked before any work: a pair a method does not
    run yet (`simulation.refusal`) stops the command in one line, naming its cell."""
    from ..methods import get
    from ..simulation import refusal

    for job in (j for group in jobs.values() for j in group):
        why = refusal(job.scenario, get(job.method))
        if why is not None:
            raise ScenarioError(f"{job.label or 'the base'}, {job.method}: {why}")


def explicit_steps(config: Path | None, set_: list[str] | None, steps: int | None) -> int | None:
    """Steps asked for by ``--steps``, ``--set steps=`` or the config file, in that order;
    two of them that disagree are refused."""
    given = {}
    if steps is not None:
        given["--steps"] = steps
    overrides = parse_overrides(set_ or [])
    if "steps" in overrides:
        given["--set steps"] = overrides["steps"]
    from ..config import read_toml
    from ..config.scenario import config_file

    if config is not None and "steps" in read_toml(config_file(config)):
        given[f"{config} steps"] = read_toml(config_file(config))["steps"]
    values = list(given.items())
    for (name, value), (other, was) in zip(values[1:], values, strict=False):
        if value != was:
            raise ScenarioError(f"{other} = {was!r} and {name} = {value!r} disagree; give one")
    return values[0][1] if values else None


@app.command()
def reproduce(
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            metavar="DIR",
            help="results folder [results/reproduce; results/reproduce-quick with --quick]",
        ),
    ] = None,
    trials: Annotated[
        int | None,
        typer.Option(min=1, max=MAX_TRIALS, metavar="N", help="trials per configuration [50]"),
    ] = None,
    steps: StepsOpt = None,
    workers: WorkersOpt = None,
    engine: EngineOpt = EngineName.local,
    address: AddressOpt = None,
    quick: Annotated[
        bool, typer.Option("--quick", help="small profile for smoke tests: 4 trials x 60 steps")
    ] = False,
    sensitivity: Annotated[
        bool,
        typer.Option(
            "--sensitivity",
            help=(
                "also move each assumed parameter to a low and a high value, and read eq. 15 "
                "as printed (all methods, same trials), and report whether the paper's "
                "conclusions hold (report.md, sensitivity.png); 114 more jobs, about three "
                "times the plain run, in the same folder, reusing what is done"
            ),
        ),
    ] = False,
    seed: SeedOpt = 0,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    team: TeamOpt = None,
    progress: ProgressOpt = None,
) -> None:
    """Run every experiment of the paper's Section 7 (Figures 5 to 9) into a folder,
    with the uncalibrated first guess beside the defaults."""
    from ..experiments import figures, report
    from ..experiments.reproduce import Profile, reproduce_plan, summarize_reproduction

    scenario = load_scenario(config, set_, team)
    steps = explicit_steps(config, set_, steps)
    profile = sized(Profile.quick() if quick else Profile(), trials, steps)
    out = out or Path("results") / ("reproduce-quick" if quick else "reproduce")
    scenario = scenario.with_overrides({"steps": profile.steps}, origin="--steps")
    plan = reproduce_plan(scenario, profile, seed, sensitivity)
    manifest = manifest_of("reproduce", seed, profile, scenario)
    pictures = [f"fig{k}.png" for k in range(5, 10)] + ["sensitivity.png"]
    with run_jobs(plan, out, manifest, engine, workers, address, progress, pictures) as (
        results,
        info,
    ):
        info["seed"] = seed
        summary = summarize_reproduction(plan, results, profile, scenario)
        summary["settings"] = {"profile": profile.to_dict(), "seed": seed, **info}
        write_json(out / "summary.json", summary)
        figures.reproduction_figures(summary, out)
        if "sensitivity" not in summary:  # an earlier run's chart would not match the report
            (out / "sensitivity.png").unlink(missing_ok=True)
        write_text(out / "report.md", report.reproduction(summary, scenario, info))
    _print_reproduction(summary, out, info)


def _print_reproduction(summary: dict, out: Path, info: dict) -> None:
    from rich.markup import escape
    from rich.table import Table

    from ..experiments.statistics import ci, pm

    table = Table(title="Fig. 5: overall observation rate (mean ± std)")
    for col in ("method", "ours", "paper", "distributed − this method, paired [95% CI]"):
        table.add_column(col)
    for m, r in summary["compare"].items():
        p = summary["paper"][m]
        pair = summary["paired"].get(f"distributed - {m}")
        diff = "" if pair is None else ci(pair)
        table.add_row(m, pm(r["mean"], r["std"]), pm(p["mean"], p["std"]), escape(diff))
    console().print(table)
    if "sensitivity" in summary:
        from ..experiments.report import sensitivity_verdicts

        trials = summary["sensitivity"]["base"]["distributed - centralized"]["trials"]
        typer.echo(
            "Sensitivity: each assumed parameter at a low and a high value"
            + (f" ({trials} trials each: mostly noise below 20)" if trials < 20 else "")
        )
        for claim, fails in sensitivity_verdicts(summary["sensitivity"]):
            typer.echo(f"  {claim} fails at: {'; '.join(fails) if fails else 'no setting'}")
    more = ", sensitivity.png" if "sensitivity" in summary else ""
    typer.echo(
        f"wrote {out}/summary.json, report.md, fig5.png ... fig9.png{more} "
        f"({info['jobs_run']} jobs run, {info['jobs_skipped']} reused, "
        f"{info['seconds']:.1f} s)"
    )


@app.command()
def sweep(
    field: Annotated[str, typer.Argument(metavar="FIELD", help="scenario field, dotted")],
    values: Annotated[
        list[str],
        typer.Argument(
            metavar="VALUE... [FIELD VALUE...]...",
            help="values to try, read as TOML; negative ones after --. Another field and "
            "its values make a grid: every combination of the values",
        ),
    ],
    methods: Annotated[
        list[MethodName] | None,
        typer.Option(
            "--method",
            metavar="METHOD",
            parser=method_name,
            help="a method to run (repeatable), or policy:FILE [the paper's three]",
        ),
    ] = None,
    trials: Annotated[
        int,
        typer.Option(
            min=1, max=MAX_TRIALS, metavar="N", help="trials per value (or cell) and method"
        ),
    ] = 20,
    steps: StepsOpt = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out", metavar="DIR", help="results folder [results/sweep-FIELD[-FIELD...]]"
        ),
    ] = None,
    workers: WorkersOpt = None,
    engine: EngineOpt = EngineName.local,
    address: AddressOpt = None,
    seed: SeedOpt = 0,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    team: TeamOpt = None,
    progress: ProgressOpt = None,
) -> None:
    """Vary one scenario field, or several as a grid (comm_range 25 50 faults.loss 0 0.2:
    four cells); every method on the same trials in every cell."""
    from ..config import parse_value
    from ..experiments.jobs import sweep_axes, sweep_plan

    scenario = load_scenario(config, set_, team)
    steps = explicit_steps(config, set_, steps)
    if steps is not None:
        scenario = scenario.with_overrides({"steps": steps}, origin="--steps")
    texts = parse_sweep(scenario, [field, *values])
    for name in texts:
        if name in parse_overrides(set_ or []):
            raise UsageError(f"sweep sets {name} itself; do not --set {name} too")
        if team is not None and name in ("n_uavs", "n_targets"):
            raise UsageError(f"--team sets n_uavs and n_targets; do not sweep {name} too")
        if name == "steps" and steps is not None:
            raise UsageError("sweep steps: --steps and --set steps do not apply; sweep one of them")
    raw: dict[str, Sequence[Any]] = {
        name: [parse_value(v, where=f"sweep value {name}") for v in given]
        for name, given in texts.items()
    }
    axes = sweep_axes(scenario, raw)
    names = chosen_methods(methods)
    plan = sweep_plan(scenario, axes, names, trials, chunk=10, seed=seed)  # every cell checked
    refuse_any(plan)  # and every method on it
    out = out or Path("results") / ("sweep-" + "-".join(axes))
    one = len(axes) == 1
    manifest = {
        "kind": "sweep",
        "seed": seed,
        "scenario": scenario.to_dict(),
        "plan": ({"field": field, "values": axes[field]} if one else {"fields": axes})
        | {"methods": names, "trials": trials},
    }
    from ..experiments import figures, report
    from ..experiments.jobs import summarize_sweep
    from ..experiments.statistics import TRACK_METRICS

    with run_jobs(plan, out, manifest, engine, workers, address, progress, ["sweep.png"]) as (
        results,
        info,
    ):
        info["seed"] = seed
        tracked = scenario.tracker.unlabelled
        summary = summarize_sweep(plan, results, axes, names, TRACK_METRICS if tracked else ())
        summary["units"] = {name: scenario.unit(name) for name in axes}
        if one:
            summary["unit"] = summary["units"][field]
        summary["settings"] = info
        write_json(out / "summary.json", summary)
        figures.sweep_figure(summary, out / "sweep.png")
        write_text(out / "report.md", report.sweep(summary, scenario, info))

    from rich.markup import escape
    from rich.table import Table

    from ..experiments.statistics import level_text, pm

    what = field if one else " x ".join(axes)
    table = Table(title=f"observation rate against {what} (mean ± std, {trials} trials)")
    for name in axes:
        unit = summary["units"][name]
        table.add_column(escape(f"{name} [{unit}]" if unit else name))
    for m in names:
        table.add_column(m)
    for k, cell in enumerate(summary["cells"]):
        rows = (summary["methods"][m][k] for m in names)
        table.add_row(*map(level_text, cell), *(pm(r["mean"], r["std"]) for r in rows))
    console().print(table)
    typer.echo(
        f"wrote {out}/summary.json, report.md, sweep.png ({info['jobs_run']} jobs run, "
        f"{info['jobs_skipped']} reused, {info['seconds']:.1f} s)"
    )


def parse_sweep(scenario, tokens: list[str]) -> dict[str, list[str]]:
    """``FIELD VALUE... [FIELD VALUE...]...`` -> ``{FIELD: [VALUE, ...], ...}``: a token that
    names a scenario field starts the next field's values. A word that is neither a field
    nor a value of the field before it is refused, with the field it was likely meant as."""
    from ..config import closest, flatten, parse_value, set_dotted

    data = scenario.model_dump()
    fields = flatten(data)
    set_dotted(data, tokens[0], None)  # the first must be a field: refused by name if not
    axes: dict[str, list[str]] = {}
    current = tokens[0]
    for token in tokens:
        if token.startswith("--"):
            raise UsageError(
                f"sweep: {token!r} came after '--', where only values go; put options before '--'"
            )
        if token in fields:
            if token in axes:
                raise UsageError(
                    f"sweep: {token} is given twice; give each field once, with all its values"
                )
            axes[current := token] = []
            continue
        meant = closest(token, data) if isinstance(parse_value(token), str) else None
        if meant is not None:
            try:
                scenario.with_overrides({current: parse_value(token)})
            except ScenarioError:
                raise UsageError(
                    f"sweep: {token!r} is neither a value of {current} nor a scenario field; "
                    f"did you mean {meant}?"
                ) from None
        axes[current].append(token)
    for name, given in axes.items():
        if not given:
            raise ScenarioError(f"sweep {name}: give at least one value")
    return axes


@app.command()
def animate(
    out: Annotated[Path, typer.Option("--out", metavar="FILE", help="GIF file to write")],
    config: ConfigOpt = None,
    method: MethodOpt = DISTRIBUTED,
    seed: Annotated[int, typer.Option(min=0, metavar="N", help="random seed of the trial")] = 0,
    set_: SetOpt = None,
    team: TeamOpt = None,
    steps: TrialStepsOpt = None,
    every: Annotated[int, typer.Option(min=1, metavar="K", help="draw every K-th step")] = 2,
    fps: Annotated[
        int, typer.Option(min=1, max=60, metavar="F", help="frames per second, 1 to 60")
    ] = 10,
    force: ForceOpt = False,
) -> None:
    """Animate one trial like the paper's Figure 4, as a GIF."""
    from .._progress import bar
    from ..simulation import simulate
    from ..viz import scene

    if out.suffix.lower() != ".gif":
        raise UsageError(f"--out must name a .gif file, got {out}")
    check_output(out, "--out", force)
    scenario = with_steps(load_scenario(config, set_, team), steps, set_)
    with steps_bar(scenario) as advance:
        result = simulate(scenario, method.value, seed=seed, progress=lambda _: advance(1))
    frames = len(scene.animation_frames(scenario.steps, every))
    with bar(frames, "frames", "frames") as advance:
        scene.animate(
            result.trace,
            scenario,
            out,
            every=every,
            fps=fps,
            title=f"{method.value}, seed {seed}",
            progress=advance,
        )
    typer.echo(f"wrote {out} ({frames} frames, observation rate {result.observation_rate:.3f})")


def refuse_set(scenario, fields: tuple[str, ...], command: str, what: str) -> None:
    """Refuse a base scenario that sets any of `fields` (names or "group." prefixes),
    which `command` sets itself."""
    from ..errors import UsageError
    from ..experiments.jobs import difference

    set_here = {
        k: v for k, v in difference(type(scenario)(), scenario).items() if k.startswith(fields)
    }
    if set_here:
        shown = ", ".join(f"{k}={v}" for k, v in set_here.items())
        raise UsageError(
            f"{command} sets {what} itself; leave them at their defaults in the base "
            f"scenario (got {shown})"
        )
