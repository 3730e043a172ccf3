"""Collision avoidance at one altitude (`uavtrack separation`): the three methods with and
without the avoidance filter (``planner.avoidance``), on the paper's team and on a 20 x 16
team, with the unicycle of eq. (1) and with JSBSim aircraft.

The base is the scenario given (by default the preset ``one-altitude``: the whole team at
one altitude, ``uav.separation`` 10 m). Every cell runs with and without the filter on
the same trials (common random numbers), so each filtered run is paired with its
unfiltered twin, trial by trial. The radio is the base's (the paper's r_C = 50 m) and the
*sound* range above which the filter's guarantee holds (`avoidance.sound_range`); JSBSim
runs at the sound range only, where the unicycle's guarantee holds and what remains is
the aircraft's own flight: with the filter's model of eq. (1), and with the model
measured of the aircraft (``planner.avoidance_model = "measured"``, `airspace.response`)
at its own sound range, in calm air and in a steady wind (`WIND`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..airspace import avoidance
from ..config import Scenario
from . import protocol
from .jobs import Job, collect, difference, label_of, trial_jobs, unique
from .statistics import ci95, describe, paired

METHODS = ("distributed", "centralized", "greedy")
TEAMS = ((5, 4), (20, 16))
"""The paper's team and a larger one at the same density (`Scenario.scaled`)."""
CELLS = (
    ("unicycle", "paper"),
    ("unicycle", "sound"),
    ("unicycle", "paper, slow"),
    ("unicycle", "sound, slow"),
    ("jsbsim", "sound"),
    ("jsbsim", "sound, measured"),
    ("jsbsim, wind", "sound"),
    ("jsbsim, wind", "sound, measured"),
)
"""(dynamics, radio) of each cell, run with and without the filter for every team."""

WIND = 5.0
"""``wind.speed`` of the cells "jsbsim, wind" [m/s], from the default direction."""
FLOWN = 0.05
"""The goal's largest cost of the filter with JSBSim aircraft (paired)."""

SCORED = (
    "observation_rate", "separation_losses", "separation_min", "conflict_time", "messages",
    "rmse_best", "ospa_best",
)  # fmt: skip
"""The metrics the summary keeps per cell (mean and std over the trials)."""

COST = 0.03
"""The goal's largest cost of the filter in observation rate (paired), on the unicycle."""
SLOW = 10.0
"""``uav.min_speed`` of the cells "slow" [m/s]: the filter may slow a UAV to it, and its
backup loiter flies at it (radius 10.3 m against 23.0 m at 15 m/s). Assumed: two thirds
of the paper's 15 m/s, above the stall speed of a small fixed-wing UAV that cruises at
15 m/s (8 to 10 m/s for a 2 m wingspan)."""
FEWER = 0.95
"""The goal at the paper's radio: the filter removes at least this share of the losses."""


@dataclass(frozen=True)
class Profile(protocol.Profile):
    """The size of a separation run (--quick: 2 trials of 40 steps)."""


def sound(base: Scenario) -> float:
    """The sound radio range of the base [m], rounded up to the metre."""
    return float(math.ceil(avoidance.sound_range_in(base)))


def team_of(base: Scenario, team: tuple[int, int]) -> Scenario:
    """The base grown to a team (the paper's size is the base itself)."""
    if (base.n_uavs, base.n_targets) == team:
        return base
    return base.scaled(*team)


def overrides(
    base: Scenario, team: tuple[int, int], dynamics: str, radio: str, avoid: bool
) -> dict[str, Any]:
    """The fields of one run against the base."""
    scenario = team_of(base, team)
    out = difference(base, scenario)
    out["uav.dynamics"] = dynamics.split(",")[0]
    if dynamics.endswith("wind"):
        out["wind.speed"] = WIND
    slow, measured = radio.endswith("slow"), radio.endswith("measured")
    if radio.startswith("paper"):
        out["comm_range"] = base.comm_range
    else:  # the filter's sound range, with the slow backup or the measured model if flown
        filtered = base.with_overrides({**out, "planner.avoidance": "loiter"})
        if slow:
            filtered = filtered.with_overrides({"uav.min_speed": SLOW})
        if measured:
            filtered = filtered.with_overrides({"planner.avoidance_model": "measured"})
        out["comm_range"] = sound(filtered)
    out["planner.avoidance"] = "loiter" if avoid else "none"
    if slow and avoid:  # the unfiltered twin flies at one speed (min_speed needs the filter)
        out["uav.min_speed"] = SLOW
    if measured and avoid:
        out["planner.avoidance_model"] = "measured"
    return out


def runs() -> list[tuple[tuple[int, int], str, str, bool]]:
    """Every (team, dynamics, radio, avoidance) run."""
    return [(t, d, r, a) for t in TEAMS for d, r in CELLS for a in (False, True)]


def plan(base: Scenario, profile: Profile, seed: int = 0) -> dict[str, list[Job]]:
    """Every job, grouped by method."""
    base = base.with_overrides({"steps": profile.steps})
    return {
        method: [
            job
            for team, dynamics, radio, avoid in runs()
            for job in trial_jobs(
                base,
                overrides(base, team, dynamics, radio, avoid),
                method,
                profile.trials,
                profile.chunk,
                seed,
            )
        ]
        for method in METHODS
    }


def key(team: tuple[int, int], dynamics: str, radio: str) -> str:
    return f"{team[0]}x{team[1]} {dynamics} {radio}"


def summarize(
    jobs: dict[str, list[Job]], results: dict[str, dict], profile: Profile, base: Scenario
) -> dict[str, Any]:
    """summary.json: per method and cell the metrics with and without the filter, the
    filtered run paired with the unfiltered one, and the goals."""
    base = base.with_overrides({"steps": profile.steps})
    data = collect(unique(j for group in jobs.values() for j in group), results)

    def metrics(method: str, team, dynamics: str, radio: str, avoid: bool) -> dict:
        scenario = base.with_overrides(overrides(base, team, dynamics, radio, avoid))
        return data[(label_of(difference(base, scenario)), method)]

    out: dict[str, Any] = {"methods": {}, "sound_range": sound(base)}
    for method in METHODS:
        rows: dict[str, Any] = {}
        for team in TEAMS:
            for dynamics, radio in CELLS:
                entry: dict[str, Any] = {"team": f"{team[0]}x{team[1]}", "dynamics": dynamics}
                entry["radio"] = radio
                sides = {}
                for avoid in (False, True):
                    m = metrics(method, team, dynamics, radio, avoid)
                    d = describe(m)
                    side: dict[str, Any] = {"trials": d["trials"]}
                    side["ci95"] = ci95(m["observation_rate"])
                    for name in SCORED:
                        side[name] = (
                            {"mean": d["mean"], "std": d["std"]}
                            if name == "observation_rate"
                            else d[name]
                        )
                    losses = np.asarray(m["separation_losses"], dtype=float)
                    side["losses_total"] = float(losses.sum())
                    side["trials_with_losses"] = int((losses > 0).sum())
                    closest = np.asarray(m["separation_min"], dtype=float)
                    side["closest"] = (
                        float(np.nanmin(closest)) if np.isfinite(closest).any() else None
                    )
                    sides[avoid] = (side, m)
                entry["none"], entry["loiter"] = sides[False][0], sides[True][0]
                entry["cost"] = paired(
                    sides[False][1]["observation_rate"], sides[True][1]["observation_rate"]
                )
                rows[key(team, dynamics, radio)] = entry
        out["methods"][method] = rows
    out["goals"] = goals(out)
    return out


def goals(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """The issue's goals for the paper's method on the unicycle at the sound range, and
    the counts without the filter, each with its measured value and whether it holds."""
    rows = summary["methods"]["distributed"]
    out = []
    for team in TEAMS:
        name = f"{team[0]}x{team[1]}"
        for radio, how in (("sound", ""), ("sound, slow", f", slow backup ({SLOW:g} m/s)")):
            e = rows[key(team, "unicycle", radio)]
            out.append((f"{name}{how}: losses with the filter (all trials)",
                        e["loiter"]["losses_total"], "==", 0.0))  # fmt: skip
            out.append((f"{name}{how}: cost in observation rate (paired)",
                        e["cost"]["mean"], "<=", COST))  # fmt: skip
        e = rows[key(team, "unicycle", "paper, slow")]
        before = e["none"]["losses_total"]
        fewer = 1.0 - e["loiter"]["losses_total"] / before if before else 1.0
        out.append((f"{name}, slow backup, the paper's radio: share of losses removed",
                    fewer, ">=", FEWER))  # fmt: skip
        for dynamics, how in (("jsbsim", "calm"), ("jsbsim, wind", f"wind {WIND:g} m/s")):
            e = rows[key(team, dynamics, "sound, measured")]
            out.append((f"{name}, JSBSim, {how}, measured model: losses with the filter",
                        e["loiter"]["losses_total"], "==", 0.0))  # fmt: skip
            out.append((f"{name}, JSBSim, {how}, measured model: cost (paired)",
                        e["cost"]["mean"], "<=", FLOWN))  # fmt: skip
    holds = {"==": np.equal, "<=": np.less_equal, ">=": np.greater_equal}
    return [
        {"goal": goal, "value": value, "op": op, "bound": bound,
         "met": bool(np.isfinite(value) and holds[op](value, bound))}
        for goal, value, op, bound in out
    ]  # fmt: skip


NAME = "separation"
"""The command, and the results folder's name."""


def figures(jobs: dict[str, list[Job]]) -> list[str]:
    """The one figure it draws."""
    return ["separation.png"]


def figure(summary: dict[str, Any], out: Path) -> None:
    """separation.png: per cell, the observation rate with and without the filter for each
    method (95 % CI), and the losses per trial (log scale)."""
    path = out / "separation.png"
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cells = list(summary["methods"]["distributed"])
    fig, axes = plt.subplots(2, 1, figsize=(12, 8), sharex=True)
    colours = {"distributed": "tab:blue", "centralized": "tab:green", "greedy": "tab:red"}
    width = 0.13
    x = np.arange(len(cells))
    for k, method in enumerate(METHODS):
        rows = summary["methods"][method]
        for j, side in enumerate(("none", "loiter")):
            at = x + (2 * k + j - 2.5) * width
            rate = [rows[c][side]["observation_rate"]["mean"] for c in cells]
            err = [rows[c][side]["ci95"] for c in cells]
            losses = [max(rows[c][side]["separation_losses"]["mean"], 1e-2) for c in cells]
            style = {"color": colours[method], "alpha": 0.45 if side == "none" else 1.0}
            label = f"{method}, {'no avoidance' if side == 'none' else 'loiter filter'}"
            axes[0].bar(at, rate, width, yerr=err, capsize=2, label=label, **style)
            axes[1].bar(at, losses, width, **style)
    axes[0].set_ylabel("observation rate (95% CI)")
    axes[0].set_ylim(0.0, 1.25)
    axes[0].legend(fontsize=7, ncol=3, loc="upper center")
    axes[1].set_ylabel("losses of separation per trial")
    axes[1].set_yscale("log")
    axes[1].set_xticks(x, [c.replace(" ", "\n") for c in cells], fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3, axis="y")
    axes[1].set_title("0 losses drawn at 0.01", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(summary: dict[str, Any], scenario: Scenario, info: dict[str, Any]) -> str:
    """report.md of `uavtrack separation`."""
    first = next(iter(summary["methods"]["distributed"].values()))
    out = [
        *protocol.header(
            "Separation: collision avoidance at one altitude",
            first["none"]["trials"],
            "cell, side and method",
            scenario,
            info,
        ),  # fmt: skip
        "",
        f"Separation {avoidance.minimum(scenario):g} m between UAVs closer than "
        f"{scenario.uav.vertical_separation:g} m in altitude. Radio: the scenario's r_C "
        f"= {scenario.comm_range:g} m (paper) and the sound range "
        f"{summary['sound_range']:g} m, above which the filter's guarantee holds "
        "(`airspace.avoidance`). Slow: the filter may slow a UAV to "
        f"`uav.min_speed` = {SLOW:g} m/s and its backup loiter flies at it, at the paper's "
        "radio and at that backup's own sound range. Measured: with JSBSim aircraft, the "
        "filter predicts their flight by the tables `airspace.response` measures of them "
        "(``planner.avoidance_model = measured``), with the margin their errors need, at "
        "its own sound range. Wind: "
        f"{WIND:g} m/s steady. Each filtered run is paired trial by "
        "trial with the same trials unfiltered; cost = unfiltered minus filtered "
        "observation rate.",
        "",
        "## Goals (distributed)",
        "",
        "| goal | measured | bound | met |",
        "|---|---|---|---|",
    ]
    for g in summary["goals"]:
        out.append(
            f"| {g['goal']} | {g['value']:.4g} | {g['op']} {g['bound']:g} | "
            f"{'yes' if g['met'] else '**no**'} |"
        )
    out.append("")
    for method in METHODS:
        out += [
            f"## {method}",
            "",
            "| team | dynamics | radio | rate, none | rate, filter | cost (95% CI) | "
            "losses per trial, none | losses per trial, filter | trials with losses, "
            "filter | closest [m], filter |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for e in summary["methods"][method].values():
            none, loiter, cost = e["none"], e["loiter"], e["cost"]
            closest = "–" if loiter["closest"] is None else f"{loiter['closest']:.1f}"
            out.append(
                f"| {e['team']} | {e['dynamics']} | {e['radio']} | "
                f"{none['observation_rate']['mean']:.3f} | "
                f"{loiter['observation_rate']['mean']:.3f} | "
                f"{cost['mean']:+.3f} ({cost['ci_low']:+.3f}, {cost['ci_high']:+.3f}) | "
                f"{none['separation_losses']['mean']:.2f} | "
                f"{loiter['separation_losses']['mean']:.2f} | "
                f"{loiter['trials_with_losses']} of {loiter['trials']} | {closest} |"
            )
        out.append("")
    out += ["![separation](separation.png)", ""]
    return "\n".join(out)
