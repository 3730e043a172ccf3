"""Sensing as it really is (`uavtrack sensing`): missed detections, clutter and unknown
association, for the paper's method and its baselines.

Every cell of P_D {1, 0.9, 0.7} x clutter {0, 2, 10} per scan x association {gnn, jpda}
runs the three methods on the same trials (common random numbers), and so does known
association at each P_D (clutter does not reach a UAV that knows each measurement's
target, so one known run per P_D serves every clutter level). The missed detections of
a trial are the same draws with every association (`tracks.scan.Draws`), so each tracked
run is paired with the known-association run of its method and P_D, trial by trial.

The observation rate stays defined on the truth; GOSPA compares each UAV's estimates
with the truth in both (with known association its estimate of every target, with tracks
its confirmed tracks), so its ratio says what unknown association costs in estimation.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ..config import Scenario
from . import protocol
from .jobs import Job, collect, difference, label_of, trial_jobs, unique
from .statistics import ci95, describe, paired

DETECTION = (1.0, 0.9, 0.7)
CLUTTER = (0.0, 2.0, 10.0)
ASSOCIATIONS = ("gnn", "jpda")
METHODS = ("distributed", "centralized", "greedy")

GOAL_CELL = (0.9, 2.0, "jpda")
"""Where the goals are measured: P_D 0.9, 2 false measurements per scan, JPDA."""

SCORED = (
    "observation_rate", "gospa", "gospa_localisation", "gospa_missed", "gospa_false",
    "switches", "fragmentations", "unassigned_tracks", "unassigned_tracks_per_target",
    "duplicate_tracks", "stale_tracks", "never_tracks", "never_tracks_new", "gospa_team",
    "label_purity", "ospa2", "ospa2_team", "time_to_confirm", "time_to_confirm_team",
    "never_confirmed", "siap_completeness", "siap_ambiguity", "siap_spuriousness", "nees",
    "nees_median", "nees_inside", "messages",
)  # fmt: skip
"""The metrics the summary keeps per cell (mean and std over the trials)."""


@dataclass(frozen=True)
class Profile(protocol.Profile):
    """The size of a sensing run (--quick: 2 trials of 60 steps)."""

    chunk: int = 25
    QUICK: ClassVar[tuple[int, int, int]] = (2, 60, 2)


UNBRIEFED = "-unbriefed"
"""A cell's association with this suffix starts with no track (``tracker.briefing``
false): the team must find the targets."""

BIRTHS = "-births"
"""A cell's association with this suffix starts with no track and its targets come and
go (`BIRTH_SETTINGS`): the team must find each new one."""

BIRTH_SETTINGS = {"target.stay": 200.0, "target.away": 100.0}
"""The births cell's targets: a stay of 200 steps on average, a place empty for 100
(in a run of 500 steps from the full set, about 0.3 of the places empty at a time and
1.4 new targets per place)."""


def overrides(pd: float, clutter: float, association: str) -> dict[str, Any]:
    """The fields of one cell (known association sees no clutter: its cell is clutter 0)."""
    out: dict[str, Any] = {"sensor.detection_probability": pd}
    if association != "known":
        rule = association.removesuffix(UNBRIEFED).removesuffix(BIRTHS)
        out |= {"sensor.clutter_rate": clutter, "tracker.association": rule}
        if association.endswith((UNBRIEFED, BIRTHS)):
            out["tracker.briefing"] = False
        if association.endswith(BIRTHS):
            out |= BIRTH_SETTINGS
    return out


def cells() -> list[tuple[float, float, str]]:
    """Every (P_D, clutter, association) run, the known ones first, the unbriefed and
    the births cells (at `GOAL_CELL`) last."""
    known = [(pd, 0.0, "known") for pd in DETECTION]
    grid = [(pd, c, a) for pd in DETECTION for c in CLUTTER for a in ASSOCIATIONS]
    pd, clutter, association = GOAL_CELL
    return known + grid + [(pd, clutter, association + end) for end in (UNBRIEFED, BIRTHS)]


def plan(base: Scenario, profile: Profile, seed: int = 0) -> dict[str, list[Job]]:
    """Every job, grouped by method."""
    base = base.with_overrides({"steps": profile.steps})
    return {
        method: [
            job
            for pd, clutter, association in cells()
            for job in trial_jobs(
                base,
                overrides(pd, clutter, association),
                method,
                profile.trials,
                profile.chunk,
                seed,
            )
        ]
        for method in METHODS
    }


def _key(pd: float, clutter: float, association: str) -> str:
    return f"pd={pd:g} clutter={clutter:g} {association}"


def summarize(
    jobs: dict[str, list[Job]], results: dict[str, dict], profile: Profile, base: Scenario
) -> dict[str, Any]:
    """summary.json: per method and cell the metrics, and each tracked cell paired with
    the known-association run of its method and P_D."""
    base = base.with_overrides({"steps": profile.steps})
    data = collect(unique(j for group in jobs.values() for j in group), results)

    def metrics(method: str, pd: float, clutter: float, association: str) -> dict:
        scenario = base.with_overrides(overrides(pd, clutter, association))
        return data[(label_of(difference(base, scenario)), method)]

    out: dict[str, Any] = {"methods": {}}
    for method in METHODS:
        rows: dict[str, Any] = {}
        for pd, clutter, association in cells():
            m = metrics(method, pd, clutter, association)
            d = describe(m)
            entry: dict[str, Any] = {
                "pd": pd,
                "clutter": clutter,
                "association": association,
                "trials": d["trials"],
                "ci95": ci95(m["observation_rate"]),
            }
            for name in SCORED:
                entry[name] = (
                    {"mean": d["mean"], "std": d["std"]} if name == "observation_rate" else d[name]
                )
            if association != "known" and not association.endswith(BIRTHS):  # same truth
                known = metrics(method, pd, 0.0, "known")
                entry["against_known"] = {
                    "observation_rate": paired(m["observation_rate"], known["observation_rate"]),
                    "gospa": paired(m["gospa"], known["gospa"]),
                    "rate_ratio": _ratio(m["observation_rate"], known["observation_rate"]),
                    "gospa_ratio": _ratio(m["gospa"], known["gospa"]),
                }
            rows[_key(pd, clutter, association)] = entry
        out["methods"][method] = rows
    out["goals"] = goals(out)
    return out


def _ratio(a: np.ndarray, b: np.ndarray) -> float:
    """The ratio of the means over the trials both define."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    both = ~(np.isnan(a) | np.isnan(b))
    return float(a[both].mean() / b[both].mean()) if both.any() and b[both].mean() else float("nan")


def goals(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """The goals at `GOAL_CELL`, each with its measured value and whether it holds."""
    key = _key(*GOAL_CELL)
    dist = summary["methods"]["distributed"][key]
    cent = summary["methods"]["centralized"][key]
    greedy = summary["methods"]["greedy"][key]
    rate = dist["observation_rate"]["mean"]
    out = [
        ("observation rate / known (distributed)", dist["against_known"]["rate_ratio"], ">=", 0.95),
        ("GOSPA / known (distributed)", dist["against_known"]["gospa_ratio"], "<=", 1.3),
        ("duplicate tracks per target and step", dist["duplicate_tracks"]["mean"], "<=", 0.02),
        ("the same, centralized", cent["duplicate_tracks"]["mean"], "<=", 0.02),
        ("never-followed tracks per target and step", dist["never_tracks"]["mean"], "<=", 0.02),
        ("the same, centralized", cent["never_tracks"]["mean"], "<=", 0.02),
        ("track switches per target and 100 steps", dist["switches"]["mean"], "<=", 1.0),
        ("team picture GOSPA / a UAV's (distributed)",
         dist["gospa_team"]["mean"] / dist["gospa"]["mean"], "<=", 0.8),
        ("label purity (distributed)", dist["label_purity"]["mean"], ">=", 0.95),
        ("centralized minus distributed rate", cent["observation_rate"]["mean"] - rate, "<=", 0.03),
        ("distributed minus greedy rate", rate - greedy["observation_rate"]["mean"], ">", 0.0),
        ("NEES inside its 95 % interval", dist["nees_inside"]["mean"], ">=", 0.85),
        ("NEES median", dist["nees_median"]["mean"], "in", (2.5, 4.5)),
    ]  # fmt: skip
    for association in ASSOCIATIONS:  # P_D 1, no clutter: the paper's rate, paired
        ideal = summary["methods"]["distributed"][_key(1.0, 0.0, association)]
        diff = ideal["against_known"]["observation_rate"]["mean"]
        name = f"P_D 1, no clutter, {association}: rate's distance from known"
        out.append((name, abs(diff), "<=", 0.005))
    slow = summary["methods"]["centralized"].get(_key(0.7, 0.0, "jpda"))
    if slow is not None:  # centralized at P_D 0.7 without clutter, against known
        diff = slow["against_known"]["observation_rate"]["mean"]
        out.append(("centralized, P_D 0.7, no clutter, jpda: rate minus known", diff, ">=", -0.05))
    for method in ("distributed", "centralized"):  # JPDA no worse than GNN, cell by cell
        cells = summary["methods"][method]
        worst = min(
            cells[_key(pd, c, "jpda")]["observation_rate"]["mean"]
            - cells[_key(pd, c, "gnn")]["observation_rate"]["mean"]
            for pd in DETECTION
            for c in CLUTTER
        )  # fmt: skip
        out.append((f"{method}: jpda minus gnn rate, worst cell", worst, ">=", -0.01))
    pd, clutter, association = GOAL_CELL
    for end, what in ((UNBRIEFED, "unbriefed"), (BIRTHS, "unbriefed, births")):
        cold = summary["methods"]["distributed"][_key(pd, clutter, association + end)]
        out.append((f"{what} (distributed): steps for the team to confirm a target in "
                    "view, median", cold["time_to_confirm_team"]["mean"], "<=", 10.0))  # fmt: skip
    checks = {
        ">=": lambda v, b: v >= b,
        "<=": lambda v, b: v <= b,
        ">": lambda v, b: v > b,
        "in": lambda v, b: b[0] <= v <= b[1],
    }
    return [
        {"goal": name, "value": value, "op": op, "bound": bound,
         "met": bool(checks[op](value, bound)) if np.isfinite(value) else False}
        for name, value, op, bound in out
    ]  # fmt: skip


NAME = "sensing"
"""The command, and the results folder's name."""


def figures(jobs: dict[str, list[Job]]) -> list[str]:
    """The one figure it draws."""
    return ["sensing.png"]


def figure(summary: dict[str, Any], out: Path) -> None:
    """sensing.png: per clutter level, the observation rate against P_D for each method
    and association (known association dotted), and GOSPA likewise."""
    path = out / "sensing.png"
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(CLUTTER), figsize=(15, 8), sharex=True, sharey="row")
    colours = {"distributed": "tab:blue", "centralized": "tab:green", "greedy": "tab:red"}
    styles = {"known": ":", "gnn": "--", "jpda": "-"}
    for col, clutter in enumerate(CLUTTER):
        for method in METHODS:
            rows = summary["methods"][method]
            for association in ("known", *ASSOCIATIONS):
                c = 0.0 if association == "known" else clutter
                entries = [rows[_key(pd, c, association)] for pd in DETECTION]
                for row, name in enumerate(("observation_rate", "gospa")):
                    values = [e[name]["mean"] for e in entries]
                    err = [e["ci95"] for e in entries] if name == "observation_rate" else None
                    axes[row, col].errorbar(
                        DETECTION, values, yerr=err, color=colours[method],
                        linestyle=styles[association], marker="o", markersize=3, capsize=2,
                        label=f"{method}, {association}",
                    )  # fmt: skip
        axes[0, col].set_title(f"clutter {clutter:g} per scan")
        axes[1, col].set_xlabel("detection probability P_D")
    axes[0, 0].set_ylabel("observation rate (95% CI)")
    axes[0, 0].set_ylim(0.0, 1.0)
    axes[1, 0].set_ylabel("GOSPA per UAV [m]")
    axes[0, 0].legend(fontsize=7, ncol=1)
    for ax in axes.ravel():
        ax.invert_xaxis()
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(summary: dict[str, Any], scenario: Scenario, info: dict[str, Any]) -> str:
    """report.md of `uavtrack sensing`."""
    first = next(iter(summary["methods"]["distributed"].values()))
    out = [
        *protocol.header(
            "Sensing: missed detections, clutter and unknown association",
            first["trials"],
            "cell and method",
            scenario,
            info,
        ),  # fmt: skip
        "",
        "Each tracked cell is paired trial by trial with known association at the same P_D "
        "(the same missed detections). GOSPA: each UAV's confirmed tracks (with known "
        "association its estimate of every target) against the truth, cut-off "
        f"{scenario.evaluation.ospa_cutoff:g} m.",
        "",
        f"## Goals (P_D {GOAL_CELL[0]:g}, clutter {GOAL_CELL[1]:g} per scan, {GOAL_CELL[2]})",
        "",
        "| goal | measured | bound | met |",
        "|---|---|---|---|",
    ]
    for g in summary["goals"]:
        bound = g["bound"]
        shown = f"in [{bound[0]:g}, {bound[1]:g}]" if g["op"] == "in" else f"{g['op']} {bound:g}"
        out.append(
            f"| {g['goal']} | {g['value']:.4g} | {shown} | {'yes' if g['met'] else '**no**'} |"
        )
    out.append("")
    for method in METHODS:
        out += [
            f"## {method}",
            "",
            "| P_D | clutter | association | rate | rate − known (95% CI) | GOSPA [m] | "
            "GOSPA / known | team GOSPA / OSPA(2) [m] | duplicate / stale / never-followed "
            "tracks per target·step | switches /100 steps | team's steps to confirm "
            "(median) | NEES median | NEES inside |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for e in summary["methods"][method].values():
            against = e.get("against_known")
            diff = against["observation_rate"] if against else None
            out.append(
                f"| {e['pd']:g} | {e['clutter']:g} | {e['association']} | "
                f"{e['observation_rate']['mean']:.3f} | "
                + (
                    f"{diff['mean']:+.3f} ({diff['ci_low']:+.3f}, {diff['ci_high']:+.3f}) | "
                    if diff
                    else " | "
                )
                + f"{e['gospa']['mean']:.2f} | "
                + (f"{against['gospa_ratio']:.2f} | " if against else " | ")
                + f"{_num(e['gospa_team'])} / {_num(e['ospa2_team'])} | "
                + f"{_num(e['duplicate_tracks'])} / {_num(e['stale_tracks'])} / "
                f"{_num(e['never_tracks'])} | {_num(e['switches'])} | "
                f"{_num(e['time_to_confirm_team'])} | {_num(e['nees_median'])} | "
                f"{_num(e['nees_inside'])} |"
            )
        out.append("")
    out += ["![sensing](sensing.png)", ""]
    return "\n".join(out)


def _num(entry: dict[str, Any]) -> str:
    value = entry["mean"]
    return "–" if value is None or not np.isfinite(value) else f"{value:.3g}"
