"""The `app` of the command line, its shared options and checks, and the commands
``run``, ``compare``, ``params`` and their helpers; `main` runs a command line with its
exit codes (`uavtrack.cli`).
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from typer import core as typer_core
from typer.exceptions import TyperException

from .. import __version__, _process
from .._files import check_distinct, check_new_folder, check_output, dumps
from .._progress import bar
from ..errors import Interrupted, RunError, ScenarioError, UsageError
from ..limits import MAX_TRIALS
from ..methods import registry

if TYPE_CHECKING:
    from ..config import Scenario


def _plain_argument_help() -> None:
    """Show positional arguments as ``FIELD VALUE...`` in help, not ``{FIELD} <str>``."""
    argument = typer_core.TyperArgument
    if hasattr(argument, "display_type_rich"):
        argument.display_type_rich = lambda self, ctx: None
    if hasattr(argument, "_usage_display_name"):

        def usage(self) -> str:
            name = self.display_name_raw
            many = self.nargs != 1 and not name.endswith("...")
            return (name + ("..." if many else "")) if self.required else f"[{name}]"

        argument._usage_display_name = usage


_plain_argument_help()


def _version(value: bool) -> None:
    if value:
        typer.echo(f"uavtrack {__version__}")
        raise typer.Exit()


app = typer.Typer(
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"]},
    help="Distributed multi-UAV cooperative multi-target tracking.",
)


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", is_eager=True, callback=_version, help="Show the version and exit."
        ),
    ] = False,
) -> None:
    """Distributed multi-UAV cooperative multi-target tracking (docs: the docs/ folder)."""


class MethodName(str):
    """A --method value: a method of the registry (built-in and plugins), or
    ``policy:FILE``, a learned policy (`uavtrack.env.policy`)."""

    __slots__ = ()

    @property
    def value(self) -> str:
        return str(self)


def method_name(text: str) -> MethodName:
    """The --method `text`, checked against the registry's names and ``policy:FILE``."""
    if text in registry.names() or (text.startswith(registry.POLICY) and text != registry.POLICY):
        return MethodName(text)
    raise typer.BadParameter(f"{text!r} is not one of {', '.join(registry.names())}, policy:FILE")


DISTRIBUTED = MethodName("distributed")
"""The default --method: the paper's."""


ConfigOpt = Annotated[
    Path | None,
    typer.Option(
        "--config",
        metavar="FILE",
        help="scenario TOML file, or a shipped preset by name: one-altitude, realistic "
        "(missing fields keep their defaults)",
    ),
]
SetOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--set",
        metavar="FIELD=VALUE",
        help="override a scenario field, dotted for nested ones (sensor.half_fov_deg=10); "
        "repeatable; values are read as TOML",
    ),
]
TeamOpt = Annotated[
    str | None,
    typer.Option(
        "--team",
        metavar="NxM",
        help="grow the scenario to N UAVs and M targets at the same density "
        "(Scenario.scaled: field, altitude spacing and start area follow the team)",
    ),
]
MethodOpt = Annotated[
    MethodName,
    typer.Option(
        metavar="METHOD",
        parser=method_name,
        help=", ".join(registry.names()) + ", or policy:FILE (a learned policy)",
    ),
]
SeedOpt = Annotated[int, typer.Option(min=0, metavar="N", help="random seed of the trial")]
ForceOpt = Annotated[
    bool,
    typer.Option(
        "--force", help="replace the output files that exist (a folder is never replaced)"
    ),
]
BagOpt = Annotated[
    Path | None,
    typer.Option(
        "--bag",
        metavar="DIR",
        help="write the run as a ROS 2 bag (MCAP) in the new folder DIR (the io extra)",
    ),
]


Ros2Opt = Annotated[
    int | None,
    typer.Option(
        "--ros2",
        min=0,
        max=232,
        metavar="DOMAIN",
        help="zenoh: each UAV program also publishes its pose and estimates as ROS 2 topics "
        "in rmw_zenoh's conventions, in this ROS 2 domain (0-232; the io extra)",
    ),
]


def check_bag(bag: Path | None, force: bool = False) -> None:
    """Refuse early a bag folder that cannot be made, and a missing io extra."""
    if bag is None:
        return
    check_new_folder(bag, "--bag", "the bag", force)
    try:
        from ..io import bag as _  # noqa: F401
    except ImportError as exc:
        raise UsageError(f"--bag: {exc}") from None


TrialStepsOpt = Annotated[
    int | None,
    typer.Option("--steps", min=1, metavar="N", help="steps of the trial [the scenario's]"),
]


def load_scenario(
    config: Path | None, overrides: list[str] | None, team: str | None = None, fly: bool = True
) -> Scenario:
    """The scenario from an optional TOML file, scaled to --team NxM, then the
    FIELD=VALUE overrides; for a command that flies it (`fly`), checked to be flyable."""
    from ..config import Scenario

    changes = parse_overrides(overrides or [])
    scenario = Scenario.from_toml(config) if config is not None else Scenario()
    if team is not None:
        n_uavs, n_targets = parse_team(team)
        both = sorted({"n_uavs", "n_targets"} & changes.keys())
        if both:
            raise ScenarioError(f"--team sets n_uavs and n_targets; do not --set {both[0]} too")
        scenario = scenario.scaled(n_uavs, n_targets)
    scenario = scenario.with_overrides(changes, origin="--set")
    if fly:  # up front: JSBSim and the aircraft, before any work (`flight.check`)
        from ..flight import check

        check(scenario)
    return scenario


def source_of(config: Path | None, overrides: list[str] | None, team: str | None) -> str:
    """Where a scenario came from, in words: the defaults or a config file, then --team
    and --set."""
    parts = [f"config {config}" if config is not None else "the defaults"]
    if team is not None:
        parts.append(f"--team {team.strip()}")
    if overrides:
        parts.append("--set " + ", ".join(o.strip() for o in overrides))
    return ", ".join(parts)


def parse_team(text: str) -> tuple[int, int]:
    """``"300x300"`` -> (300, 300): UAVs and targets, each a positive integer."""
    match = re.fullmatch(r"\s*(\d{1,9})\s*[xX]\s*(\d{1,9})\s*", text)
    if not match or min(int(match[1]), int(match[2])) < 1:
        raise ScenarioError(
            "--team expects NxM, N UAVs and M targets, positive integers (300x300), got "
            + (repr(text) if len(text) <= 40 else f"{text[:28]!r}... ({len(text)} chars)")
        )
    return int(match[1]), int(match[2])


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """`config.parse_overrides`, loaded when a command runs (help loads no numpy)."""
    from ..config import parse_overrides as parsed

    return parsed(items)


def steps_bar(scenario: Scenario, trials: int = 1, label: str = "steps"):
    """Progress over trial-steps: a bar on a terminal, a line a minute elsewhere."""
    return bar(scenario.steps * trials, label, label)


RUN_ROWS = (
    ("rmse_best", "position RMSE, team's best estimate [m]", "{:.2f}"),
    ("rmse", "position RMSE, every UAV's estimate [m]", "{:.2f}"),
    ("nees_best", "NEES, team's best estimate (4 if consistent)", "{:.2f}"),
    ("nees", "NEES, every UAV's estimate (4 if consistent)", "{:.2f}"),
    ("nees_median", "NEES median, every UAV's estimate (3.36 if consistent)", "{:.2f}"),
    ("nees_inside", "NEES inside its 95% interval, every UAV's (0.95 if consistent)", "{:.3f}"),
    ("ospa_best", "OSPA, team's best estimates [m]", "{:.2f}"),
    ("ospa", "OSPA, every UAV's estimates [m]", "{:.2f}"),
    ("gospa_best", "GOSPA, team's best estimates [m]", "{:.2f}"),
    ("gospa_missed_best", "GOSPA missed targets per step, best estimates", "{:.3f}"),
    ("gospa", "GOSPA, every UAV's estimates [m] (as tracks are scored)", "{:.2f}"),
    ("rounds", "consensus rounds per UAV and step", "{:.2f}"),
    ("messages", "messages per step", "{:.2f}"),
    ("bytes", "radio bytes per UAV and step (the agent form's frames)", "{:.0f}"),
    ("decision_time_ms", "decision time per UAV and cycle [ms of CPU time]", "{:.3f}"),
    ("decision_wall_ms", "the same in wall time [ms]", "{:.3f}"),
)
TRACK_ROWS = (
    ("gospa", "GOSPA, each UAV's confirmed tracks [m]", "{:.2f}"),
    ("gospa_localisation", "  its localisation part [m^p]", "{:.2f}"),
    ("gospa_missed", "  its missed part [m^p]", "{:.2f}"),
    ("gospa_false", "  its false part [m^p]", "{:.2f}"),
    ("unassigned_tracks_per_target", "unassigned confirmed tracks per target and step", "{:.3f}"),
    ("duplicate_tracks", "  duplicates (a target followed twice)", "{:.3f}"),
    ("stale_tracks", "  stale (once on a target, now off)", "{:.3f}"),
    ("never_tracks", "  never on a target (clutter-born)", "{:.3f}"),
    ("never_tracks_new", "  new ones per UAV and 100 steps", "{:.2f}"),
    ("gospa_team", "GOSPA, the team picture (a track per label) [m]", "{:.2f}"),
    ("label_purity", "label purity (the team's label for a target)", "{:.3f}"),
    ("ospa2", "OSPA(2), each UAV's tracks over 10 steps [m]", "{:.2f}"),
    ("ospa2_team", "OSPA(2), the team picture [m]", "{:.2f}"),
    ("switches", "track switches per target and 100 steps", "{:.2f}"),
    ("fragmentations", "fragmentations per target and 100 steps", "{:.2f}"),
    ("time_to_confirm", "steps to confirm a target found anew", "{:.1f}"),
    ("time_to_confirm_team", "  by the team, median", "{:.1f}"),
    ("siap_completeness", "SIAP completeness", "{:.3f}"),
    ("siap_ambiguity", "SIAP ambiguity", "{:.3f}"),
    ("siap_spuriousness", "SIAP spuriousness", "{:.3f}"),
    ("nees", "NEES, confirmed tracks matched to a target (4 if consistent)", "{:.2f}"),
    ("nees_median", "  its median (3.36 if consistent)", "{:.2f}"),
    ("nees_inside", "  inside its 95% interval (0.95 if consistent)", "{:.3f}"),
)
"""The rows of `uavtrack run` with tracker.association gnn or jpda, in place of the
per-target estimate rows, which a track set does not have."""

TRACK_CAPTION = (
    "Tracks: each UAV's confirmed tracks against the true targets, one-to-one by the GOSPA "
    "assignment (cut-off evaluation.ospa_cutoff, order evaluation.ospa_order); a track "
    "matched to no target is unassigned: a duplicate (its nearest target within the cut-off "
    "is matched to another track), stale (it followed a target before) or never on a "
    "target; a switch is a target's matched label changing; the team picture keeps per "
    "label the most confident holder's track; SIAP "
    "associates each track with its nearest target within the cut-off."
)

FAULT_ROWS = (
    ("delivered", "messages delivered per step", "{:.2f}"),
    ("conflicts", "conflicts per step (doubled targets while one is free)", "{:.3f}"),
    ("failed", "UAVs failed by the end", "{:.0f}"),
)

SEPARATION_ROWS = (
    ("separation_losses", "losses of separation (pair-steps below uav.separation)", "{:.0f}"),
    ("separation_min", "closest two UAVs of one altitude band came [m]", "{:.2f}"),
    ("conflict_time", "time with a loss of separation [s]", "{:.1f}"),
)
"""The rows of a run with a separation to keep (``uav.separation`` > 0)."""


MANY_TARGETS = 12
"""Above this many targets, tables show the spread of the per-target rates, not each."""


def target_rows(rates: list[list[float]]) -> list[tuple[str, list[str]]]:
    """Table rows of per-target observation rates, one column per method: every target
    up to `MANY_TARGETS`, else the three lowest, the median, the three highest and the
    spread (every target is in --json)."""
    import numpy as np

    arrays = [np.asarray(r, dtype=float) for r in rates]
    n = len(arrays[0])
    if n <= MANY_TARGETS:
        return [(f"  target {j}", [f"{r[j]:.3f}" for r in arrays]) for j in range(n)]
    ordered = [np.sort(r) for r in arrays]
    picks = [
        ("lowest", 0), ("2nd lowest", 1), ("3rd lowest", 2), ("median", None),
        ("3rd highest", n - 3), ("2nd highest", n - 2), ("highest", n - 1),
    ]  # fmt: skip
    rows = [
        (
            f"  target rate, {name} of {n}",
            [f"{np.median(r) if k is None else r[k]:.3f}" for r in ordered],
        )
        for name, k in picks
    ]
    rows.append((f"  target rate, std over the {n}", [f"{np.std(r):.3f}" for r in arrays]))
    return rows


def not_computed(n_targets: int, per_uav: bool = True) -> str:
    """Why OSPA and GOSPA read n/a for this many targets ('' when they do not); per_uav:
    whether the table shows those of every UAV's estimates."""
    from ..metrics import BEST_SETS, PER_UAV_SETS

    if n_targets > BEST_SETS:
        return (
            f" OSPA and GOSPA are n/a: not computed above {BEST_SETS} targets for the best "
            f"estimates, {PER_UAV_SETS} for each UAV's (their assignments would cost more "
            "than the run)."
        )
    if n_targets > PER_UAV_SETS and per_uav:
        return (
            f" OSPA and GOSPA of every UAV's estimates are n/a: not computed above "
            f"{PER_UAV_SETS} targets (an assignment per UAV and step)."
        )
    return ""


def chosen_methods(methods: list | None) -> list[str]:
    """The methods a command runs, each loaded now so that a plugin that cannot load is
    named in one line before any work: those given with --method (once each), else the
    paper's three (installed plugins run only when named)."""
    from ..methods import get

    names = list(dict.fromkeys(m.value for m in methods)) if methods else list(registry.BUILT_IN)
    for name in names:
        get(name)
    return names


def number(fmt: str, value) -> str:
    """A metric for a table: n/a when it could not be computed (None or NaN)."""
    return "n/a" if value is None or value != value else fmt.format(value)


CAPTION = (
    "Team's best estimate: per target, the estimate of the UAV most confident in it. "
    "Every UAV's estimate includes the stale ones of UAVs cut off from the team. NEES is 4 "
    "for a consistent estimate; with the paper's filter it is higher, mostly from targets "
    "turning at the walls, which that filter cannot predict (tracker.model=imm models them). "
    "OSPA and GOSPA compare the true targets with a set of estimates as point sets "
    "(cut-off evaluation.ospa_cutoff, order evaluation.ospa_order; per UAV up to "
    "{per_uav} targets): OSPA is a mean over the targets, GOSPA a sum, so it grows with "
    "their number."
)


@app.command()
def run(
    config: ConfigOpt = None,
    method: MethodOpt = DISTRIBUTED,
    seed: SeedOpt = 0,
    set_: SetOpt = None,
    team: TeamOpt = None,
    steps: TrialStepsOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="print one JSON object")] = False,
    trace: Annotated[
        Path | None,
        typer.Option("--trace", metavar="FILE", help="write the per-step trace to FILE (.npz)"),
    ] = None,
    bag: BagOpt = None,
    force: ForceOpt = False,
    rerun: Annotated[
        str | None,
        typer.Option(
            "--rerun",
            metavar="[FILE.rrd]",
            help=(
                "log the run to Rerun: save it to FILE.rrd, or with no FILE open it in the "
                "viewer and wait until it is closed (the viz extra)"
            ),
        ),
    ] = None,
) -> None:
    """Simulate one trial and print its metrics."""
    from ..simulation import simulate

    scenario = with_steps(load_scenario(config, set_, team), steps, set_)
    check_distinct({"--trace": trace, "--rerun": rerun or None, "--bag": bag})
    if trace is not None:
        check_output(trace, "--trace", force)
    check_bag(bag, force)
    viewer = None
    if rerun is not None:
        if rerun and Path(rerun).suffix != ".rrd":
            raise UsageError(f"--rerun: {rerun} should end in .rrd")
        if rerun:
            check_output(rerun, "--rerun", force)
        elif not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise UsageError(
                "--rerun without a file opens the Rerun viewer, which needs a display; "
                "give --rerun FILE.rrd to save the recording instead"
            )
        try:
            from ..viz import rerun as viewer
        except ImportError as exc:
            raise UsageError(f"--rerun: {exc}") from None
    with steps_bar(scenario) as advance:
        result = simulate(
            scenario,
            method.value,
            seed=seed,
            trace=trace is not None or viewer is not None or bag is not None,
            progress=lambda _: advance(1),
        )
    if viewer is not None and rerun:
        viewer.save(result.trace, scenario, Path(rerun).expanduser(), f"{method.value}-{seed}")
    show(result, scenario, seed, as_json, trace, source=source_of(config, set_, team), bag=bag)
    if viewer is not None and rerun:
        typer.echo(f"Rerun recording written to {rerun}", err=as_json)
    elif viewer is not None:
        viewer.show(result.trace, scenario, f"{method.value}-{seed}")


def show(
    result,
    scenario: Scenario,
    seed: int,
    as_json: bool,
    trace: Path | None,
    extra: dict[str, Any] | None = None,
    title: str = "uavtrack run",
    rows: list[tuple[str, str]] | None = None,
    source: str = "",
    bag: Path | None = None,
    truth: bool = True,
) -> None:
    """Write the trace and the bag if asked, then print a run's metrics as a table (with
    more `rows`) or one JSON object (with `extra`, such as a swarm's traffic). Without
    `truth` (a replay of scans alone) the table leaves out what compares with it."""
    if trace is not None:
        from ..io import trace as trace_file

        trace_file.write(trace, result)
    if bag is not None:
        from ..io.bag import write_bag

        write_bag(bag, result.trace, scenario, seed=result.seed)
    summary = result.summary()
    if as_json:
        summary["scenario"] = scenario.to_dict()
        summary.update(extra or {})
        typer.echo(dumps(summary))
        return
    from rich.markup import escape
    from rich.table import Table

    from ..metrics import PER_UAV_SETS

    table = Table(
        title=f"{title}: {summary['method']}, seed {seed}",
        caption=CAPTION.format(per_uav=PER_UAV_SETS) + not_computed(scenario.n_targets),
        caption_justify="left",
        show_header=False,
    )
    team = f"{scenario.n_uavs} UAVs x {scenario.n_targets} targets, {scenario.steps} steps"
    table.add_row("team", team if truth else f"{scenario.n_uavs} UAVs, {scenario.steps} steps")
    if source:
        table.add_row("scenario from", escape(source))
    if truth:
        table.add_row("observation rate", f"{summary['observation_rate']:.4f}")
        for label, (value,) in target_rows([summary["per_target"]]):
            table.add_row(label, value)
    from ..methods import get

    central = get(summary["method"]).central
    rows_shown = RUN_ROWS
    if scenario.tracker.unlabelled:
        keep = ("rounds", "messages", "bytes", "decision_time_ms", "decision_wall_ms")
        rows_shown = TRACK_ROWS + tuple(r for r in RUN_ROWS if r[0] in keep)
        table.caption = TRACK_CAPTION
    if not truth:
        rows_shown = tuple(r for r in rows_shown if r[0] in ("rounds", "messages", "bytes"))
        table.caption = None
    for key, label, fmt in rows_shown:
        if key == "decision_time_ms" and central:
            label = "decision time per cycle, the central node's for the whole team [ms of CPU]"
        table.add_row(escape(label), number(fmt, summary[key]))
    # FaultModel's defaults are given to Field positionally, which pyright does not read
    if scenario.faults != type(scenario.faults)():
        for key, label, fmt in FAULT_ROWS:
            table.add_row(escape(label), number(fmt, summary[key]))
    if scenario.uav.separation > 0:
        for key, label, fmt in SEPARATION_ROWS:
            table.add_row(escape(label), number(fmt, summary[key]))
    for label, value in rows or []:
        table.add_row(escape(label), escape(value))
    console().print(table)
    if trace is not None:
        typer.echo(f"trace written to {trace}")
    if bag is not None:
        typer.echo(f"ROS 2 bag written to {bag}")


COMPARE_ROWS = (
    ("rmse_best", "RMSE, best estimate [m]", "{:.2f}"),
    ("rmse", "RMSE, every UAV's [m]", "{:.2f}"),
    ("nees_best", "NEES, best estimate", "{:.2f}"),
    ("ospa_best", "OSPA, best estimates [m]", "{:.2f}"),
    ("gospa_best", "GOSPA, best estimates [m]", "{:.2f}"),
    ("rounds", "rounds per UAV and step", "{:.2f}"),
    ("messages", "messages per step", "{:.1f}"),
    ("bytes", "radio bytes per UAV and step", "{:.0f}"),
    ("decision_time_ms", "decision time [ms of CPU]", "{:.3f}"),
)


@app.command()
def compare(
    config: ConfigOpt = None,
    methods: Annotated[
        list[MethodName] | None,
        typer.Option(
            "--method",
            metavar="METHOD",
            parser=method_name,
            help="a method to compare (repeatable); the first is the reference of the paired "
            "differences [the paper's three: distributed, centralized, greedy]",
        ),
    ] = None,
    trials: Annotated[
        int, typer.Option(min=1, max=MAX_TRIALS, metavar="N", help="Monte Carlo trials per method")
    ] = 50,
    steps: Annotated[
        int | None, typer.Option(min=1, metavar="N", help="steps per trial [the scenario's]")
    ] = None,
    seed: Annotated[
        int, typer.Option(min=0, metavar="N", help="experiment seed (trial t uses its t-th child)")
    ] = 0,
    set_: SetOpt = None,
    team: TeamOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="print one JSON object")] = False,
) -> None:
    """Run the methods on the same trials, in this process: mean and std of each metric,
    and the paired differences of the first method minus each other, with 95% intervals."""
    from ..experiments.jobs import compare as run_compare
    from ..experiments.statistics import against_first, paired_metrics, summarize

    scenario = with_steps(load_scenario(config, set_, team), steps, set_)
    names = chosen_methods(methods)
    tracked = scenario.tracker.unlabelled
    with steps_bar(scenario, trials * len(names), "trial-steps") as advance:
        raw = run_compare(scenario, names, trials, seed, progress=advance)
    results: dict[str, dict[str, Any]] = {m: summarize(v) for m, v in raw.items()}
    pairs = against_first(raw, paired_metrics(tracked))
    if as_json:
        typer.echo(
            dumps(
                {
                    "trials": trials,
                    "seed": seed,
                    "methods": results,
                    "paired": pairs,
                    "scenario": scenario.to_dict(),
                }
            )
        )
        return
    from rich.markup import escape
    from rich.table import Table

    from ..experiments.statistics import pm

    caption = (
        TRACK_CAPTION
        if tracked
        else "Best estimate: per target, the most confident UAV's. OSPA is a mean over "
        "the targets, GOSPA a sum." + not_computed(scenario.n_targets, per_uav=False)
    )
    table = Table(
        title=f"{trials} trials of {scenario.steps} steps, seed {seed}: mean over trials",
        caption=caption + " Decision time: trial 0, run alone.",
        caption_justify="left",
    )
    table.add_column("metric", no_wrap=True)
    for name in results:
        table.add_column(name, justify="right", no_wrap=True)
    table.add_row(
        "observation rate ± std",
        *(
            pm(r["observation_rate"]["mean"], r["observation_rate"]["std"], 3)
            for r in results.values()
        ),
    )
    for label, values in target_rows([r["per_target"]["mean"] for r in results.values()]):
        table.add_row(label, *values)
    for key, label, fmt in TRACK_COMPARE_ROWS if tracked else COMPARE_ROWS:
        table.add_row(escape(label), *(number(fmt, r[key]["mean"]) for r in results.values()))
    console().print(table)
    if pairs:
        console().print(paired_table(pairs, names[0], trials))


TRACK_COMPARE_ROWS = tuple(r for r in TRACK_ROWS if r[0] in ("gospa",) or "gospa_" in r[0]) + (
    ("unassigned_tracks_per_target", "unassigned confirmed tracks per target and step", "{:.3f}"),
    ("duplicate_tracks", "  duplicates (a target followed twice)", "{:.3f}"),
    ("stale_tracks", "  stale (once on a target, now off)", "{:.3f}"),
    ("never_tracks", "  never on a target (clutter-born)", "{:.3f}"),
    ("never_tracks_new", "  new ones per UAV and 100 steps", "{:.2f}"),
    ("switches", "track switches per target and 100 steps", "{:.2f}"),
    ("siap_completeness", "SIAP completeness", "{:.3f}"),
    ("siap_ambiguity", "SIAP ambiguity", "{:.3f}"),
    ("siap_spuriousness", "SIAP spuriousness", "{:.3f}"),
    ("label_purity", "label purity (the team's label for a target)", "{:.3f}"),
    ("ospa2", "OSPA(2), each UAV's tracks over 10 steps [m]", "{:.2f}"),
    ("ospa2_team", "OSPA(2), the team picture [m]", "{:.2f}"),
    *(r for r in COMPARE_ROWS if r[0] in ("rounds", "messages", "bytes", "decision_time_ms")),
)
"""The rows of `uavtrack compare` with tracks, in place of the per-target estimate rows."""

PAIRED_ROWS = {
    "observation_rate": ("observation rate", 4),
    **{key: (label, int(fmt[3])) for key, label, fmt in COMPARE_ROWS},  # "{:.2f}" -> 2
    **{key: (label.strip(), int(fmt[3])) for key, label, fmt in TRACK_COMPARE_ROWS},
}
"""Labels and digits of the rows of the paired-differences table (those of the means)."""


def paired_table(pairs: dict, first: str, trials: int):
    """`first` minus each other method on the same trials: mean difference [95% interval]."""
    from rich.markup import escape
    from rich.table import Table

    from ..experiments.statistics import ci

    table = Table(
        title=f"{first} minus each other method, paired on the same {trials} trials: "
        "mean [95% interval]",
        caption="An interval that excludes 0: the methods differ on this scenario "
        "(t interval over the trials; n/a with fewer than 2).",
        caption_justify="left",
    )
    table.add_column("metric", no_wrap=True)
    for name in pairs:
        table.add_column(escape(name.replace(" - ", " − ")), justify="right", no_wrap=True)
    for key in next(iter(pairs.values())):
        label, digits = PAIRED_ROWS[key]
        table.add_row(escape(label), *(ci(p[key], digits=digits) for p in pairs.values()))
    return table


def with_steps(scenario: Scenario, steps: int | None, set_: list[str] | None) -> Scenario:
    """Apply ``--steps``; refuse it when ``--set steps=...`` says something else."""
    if steps is None:
        return scenario
    given = parse_overrides(set_ or []).get("steps")
    if given is not None and given != steps:
        raise ScenarioError(f"--steps {steps} and --set steps={given} disagree; give one of them")
    return scenario.with_overrides({"steps": steps}, origin="--steps")


@app.command()
def params(
    config: ConfigOpt = None,
    set_: SetOpt = None,
    team: TeamOpt = None,
    toml: Annotated[
        bool,
        typer.Option(
            "--toml", help="print the scenario as TOML, each field's unit and range above it"
        ),
    ] = False,
) -> None:
    """Show every scenario parameter with its value, unit, range and source."""
    scenario = load_scenario(config, set_, team, fly=False)
    if toml:
        typer.echo(scenario.to_toml(comments=True), nl=False)
        return
    from rich.markup import escape
    from rich.table import Table

    table = Table("field", "value", "unit, range, source")
    for name, value, doc in scenario.describe():
        shown = (
            "not set" if value is None else str(list(value) if isinstance(value, tuple) else value)
        )
        table.add_row(name, escape(shown), escape(doc))
    console(160).print(table)


def console(width: int = 120):
    """A rich console; wide when printing to a file or pipe (rich would use 80 columns)."""
    from rich.console import Console

    return Console() if sys.stdout.isatty() else Console(width=width)


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit code (see the module docstring)."""
    from .._files import WRITTEN

    argv = _optional_values(sys.argv[1:] if argv is None else list(argv))
    WRITTEN.clear()  # what this command writes (`no_partial`)
    _terminate_as_interrupt()
    try:
        _process.check()
        # without standalone mode typer returns exit codes (typer.Exit, Ctrl-C -> 130)
        code = app(args=argv or ["--help"], prog_name="uavtrack", standalone_mode=False)
        code = code if isinstance(code, int) else 0
        if code == 130:
            return interrupted(no_partial())
        flush_stdout()  # a full or closed stdout shows here, not at interpreter exit
        return code
    except TyperException as exc:  # usage errors: unknown option, bad value, ...
        return fail(exc.format_message() + _hint(exc.format_message(), argv))
    except (UsageError, _process.ThreadsError) as exc:
        return fail(str(exc))
    except Interrupted as exc:
        return interrupted(str(exc))
    except KeyboardInterrupt:
        return interrupted(no_partial())
    except RunError as exc:
        return fail(str(exc), code=1)
    except typer.Exit as exc:
        return exc.exit_code
    except MemoryError:
        return fail("out of memory; make the scenario smaller (see uavtrack params)", code=1)
    except OSError as exc:
        return fail(os_error(exc), code=1)


def entry() -> None:
    """The console script (and ``python -m uavtrack.cli``): `main`, then exit with its code.

    An interrupted run (130, 143) has stopped its workers and left no partial file by the
    time `main` returns; it ends at once with its code. (A Ctrl-C that lands while an
    extension module initialises leaves CPython's "unhandled interrupt" mark set even
    though `main` handled it, and the interpreter would then end itself by SIGINT instead
    of with the code.)"""
    code = main()
    if code in (130, 143):
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code)
    sys.exit(code)


def _hint(message: str, argv: list[str]) -> str:
    """What a user most likely meant by an argument the parser refused, or ''."""
    if re.match(r"No such option: -\d", message):
        return (
            "; a negative value? put -- before the values, as in "
            "uavtrack sweep uav.altitude_spacing -- -5 0 5"
        )
    if message.startswith("Got unexpected extra argument"):
        for k, token in enumerate(argv[:-1]):
            if token == "--set" and "=" not in argv[k + 1]:
                name, value = argv[k + 1], argv[k + 2] if k + 2 < len(argv) else "VALUE"
                return f"; --set takes FIELD=VALUE in one word: --set {name}={value}"
    return ""


OPTIONAL_VALUES = ("--rerun",)
"""Options whose value may be left out (``--rerun`` alone opens the viewer)."""


def _optional_values(argv: list[str]) -> list[str]:
    """``--rerun`` followed by another option or nothing becomes ``--rerun=``: the parser
    would otherwise take the next option for its value."""
    out = list(argv)
    for k, token in enumerate(out):
        if token == "--":
            break
        if token in OPTIONAL_VALUES and (k + 1 == len(out) or out[k + 1].startswith("-")):
            out[k] = f"{token}="
    return out


NO_PARTIAL = "no partial file was left"


def no_partial() -> str:
    """What an interrupted command leaves: no partial file, and the files it had written
    whole before the interruption (`_files.WRITTEN`), named."""
    from .._files import WRITTEN

    if not WRITTEN:
        return NO_PARTIAL
    shown = ", ".join(str(p) for p in WRITTEN[:3]) + (" and more" if len(WRITTEN) > 3 else "")
    return f"{NO_PARTIAL}; written whole before it: {shown}"


_signal = {"terminated": False}


def _terminate_as_interrupt() -> None:
    """SIGTERM ends a command as Ctrl-C does: its cleanup runs (workers and programs it
    started are stopped, no partial file is left); the exit code is 143, not 130."""
    import signal
    import threading

    def interrupt(signum, frame):
        _signal["terminated"] = True
        raise KeyboardInterrupt

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, interrupt)


def os_error(exc: OSError) -> str:
    """An OSError as one line: what could not be done, where, and why.

    Files are written through `_files`, which names them in its errors; an error with no
    file name is the standard output's when it came from writing it (an echo, the final
    flush), else said as it is."""
    reason = exc.strerror or str(exc)
    if exc.filename is not None:
        return f"cannot write {exc.filename}: {reason}"
    if _from_stdout(exc):
        _silence_stdout()
        return f"cannot write standard output: {reason}"
    return f"a file could not be written: {reason}"


def _from_stdout(exc: BaseException) -> bool:
    """Whether `exc` was raised writing the standard output."""
    frames = []
    tb = exc.__traceback__
    while tb is not None:
        frames.append(tb.tb_frame)
        tb = tb.tb_next
    return any(
        f.f_code.co_name in ("echo", "flush_stdout") or "rich/console" in f.f_code.co_filename
        for f in frames
    )


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so Python's final flush of a broken stdout stays quiet."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError):
        pass


def flush_stdout() -> None:
    sys.stdout.flush()


def fail(message: str, code: int = 2) -> int:
    message = " ".join(message.split()).replace("Value error, ", "")
    print(f"uavtrack: error: {message}", file=sys.stderr)
    return code


def interrupted(kept: str) -> int:
    from ..experiments.store import stop_workers

    stop_workers()
    if _signal["terminated"]:  # SIGTERM: 128 + 15
        print(f"uavtrack: terminated; {kept}", file=sys.stderr)
        return 143
    print(f"uavtrack: interrupted; {kept}", file=sys.stderr)
    return 130
