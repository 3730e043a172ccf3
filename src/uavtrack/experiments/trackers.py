"""Trackers, measured (`uavtrack trackers`): the paper's filter and fusion against the
IMM and covariance intersection, on the paper's targets and on manoeuvring ones.

Every tracker runs the distributed method on the same trials (common random numbers),
so differences between trackers are paired. Consistency is judged by the mean NEES
against its 95% chi-square band: for n independent 4-D errors of a consistent
estimator, n times the mean NEES is chi-square with 4n degrees of freedom; and by the
NEES's distribution: its median (3.36 for chi-square(4)) and the fraction of the samples
inside the 95% interval of chi-square(4) (0.95), each a trial's, averaged over trials.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ..config import Scenario
from . import protocol
from .jobs import Job, collect, difference, label_of, trial_jobs, unique
from .statistics import ci, ci95, describe, nees_band, paired, pm

MOTIONS = ("ncv", "manoeuvring")


TRACKERS = {
    "cv + max_consensus": {},
    "imm + max_consensus": {"tracker.model": "imm"},
    "cv + covariance_intersection": {"fusion.rule": "covariance_intersection"},
    "imm + covariance_intersection": {
        "tracker.model": "imm",
        "fusion.rule": "covariance_intersection",
    },
    "imm with turn modes + covariance_intersection": {
        "tracker.model": "imm",
        "fusion.rule": "covariance_intersection",
        "tracker.manoeuvre_std": [2.3],
        "tracker.turn_rates_deg": [8.0],
        "tracker.transition": [
            [0.95, 0.01, 0.02, 0.02],
            [0.30, 0.40, 0.15, 0.15],
            [0.10, 0.05, 0.85, 0.00],
            [0.10, 0.05, 0.00, 0.85],
        ],
    },
}
"""The trackers: the paper's (first), the three others, and the IMM whose manoeuvre
mode is a pair of coordinated turns at +-8 deg/s (the targets' turns, up to 15 deg/s,
average 7.5) instead of a 0.5 m/s^2 noise mode: the measurement behind the default
mode set."""


METHOD = "distributed"


@dataclass(frozen=True)
class Profile(protocol.Profile):
    """The size of a trackers run (--quick: 2 trials of 60 steps)."""

    chunk: int = 25
    QUICK: ClassVar[tuple[int, int, int]] = (2, 60, 2)


def overrides(motion: str, tracker: str) -> dict[str, Any]:
    return {"target.motion": motion, **TRACKERS[tracker]}


def plan(base: Scenario, profile: Profile, seed: int = 0) -> dict[str, list[Job]]:
    """Every job, grouped by target motion."""
    base = base.with_overrides({"steps": profile.steps})
    return {
        motion: [
            job
            for tracker in TRACKERS
            for job in trial_jobs(
                base, overrides(motion, tracker), METHOD, profile.trials, profile.chunk, seed
            )
        ]
        for motion in MOTIONS
    }


def summarize(
    jobs: dict[str, list[Job]], results: dict[str, dict], profile: Profile, base: Scenario
) -> dict[str, Any]:
    """summary.json: per motion and tracker the metrics, the NEES bands, and the paired
    differences against the paper's tracker."""
    base = base.with_overrides({"steps": profile.steps})
    data = collect(unique(j for group in jobs.values() for j in group), results)
    paper = next(iter(TRACKERS))

    def metrics(motion: str, tracker: str) -> dict[str, np.ndarray]:
        scenario = base.with_overrides(overrides(motion, tracker))
        return data[(label_of(difference(base, scenario)), METHOD)]

    out: dict[str, Any] = {"motions": {}}
    pairs_per_trial = base.steps * base.n_uavs * base.n_targets
    best_per_trial = base.steps * base.n_targets
    for motion in MOTIONS:
        rows = {}
        for tracker in TRACKERS:
            m = metrics(motion, tracker)
            trials = len(m["observation_rate"])
            entry = describe(m) | {"ci95": ci95(m["observation_rate"])}
            entry["nees_band"] = nees_band(pairs_per_trial * trials)
            entry["nees_best_band"] = nees_band(best_per_trial * trials)
            if tracker != paper:
                reference = metrics(motion, paper)
                entry["against_paper"] = {
                    name: paired(m[name], reference[name])
                    for name in ("observation_rate", "rmse_best", "nees", "nees_best", "ospa")
                }
            rows[tracker] = entry
        out["motions"][motion] = rows
    out["samples"] = {"nees": pairs_per_trial, "nees_best": best_per_trial, "per": "trial"}
    return out


NAME = "trackers"
"""The command, and the results folder's name."""


def figures(jobs: dict[str, list[Job]]) -> list[str]:
    """The one figure it draws."""
    return ["trackers.png"]


def figure(summary: dict[str, Any], out: Path) -> None:
    """trackers.png: mean NEES (log scale, with the consistent value 4) and the team's
    best RMSE per tracker, on both target motions."""
    path = out / "trackers.png"
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4))
    names = list(TRACKERS)
    width = 0.38
    for k, motion in enumerate(MOTIONS):
        rows = summary["motions"][motion]
        x = np.arange(len(names)) + (k - 0.5) * width
        for ax, key in zip(axes, ("nees", "rmse_best", "observation_rate"), strict=True):
            if key == "observation_rate":
                values = [rows[t]["mean"] for t in names]
                errors = [rows[t]["ci95"] for t in names]
            else:
                values = [rows[t][key]["mean"] for t in names]
                errors = None
            ax.bar(x, values, width, yerr=errors, capsize=3, label=f"{motion} targets")
    axes[0].axhline(4.0, color="black", linewidth=1, linestyle="--", label="consistent (4)")
    axes[0].set_yscale("log")
    axes[0].set_title("mean NEES, every UAV's fused estimate")
    axes[1].set_title("RMSE of the team's best estimate [m]")
    axes[2].set_title("observation rate (95% CI)")
    axes[2].set_ylim(0, 1)
    labels = ["\n".join(textwrap.wrap(n.replace("_", " "), 13)) for n in names]
    for ax in axes:
        ax.set_xticks(np.arange(len(names)), labels, fontsize=7.5)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(summary: dict[str, Any], scenario: Scenario, info: dict[str, Any]) -> str:
    """report.md of `uavtrack trackers`."""
    first = summary["motions"][MOTIONS[0]]
    trials = next(iter(first.values()))["trials"]
    out = [
        *protocol.header(
            "Trackers: the paper's filter and fusion against the IMM and covariance intersection",
            trials,
            "target motion and tracker",
            scenario,
            info,
            ", the distributed method",
        ),  # fmt: skip
        "",
        "NEES over every estimate (walls and manoeuvres included): every UAV's fused "
        "estimate (`nees`) and the team's best (`nees_best`), with the 95% band of the mean "
        "of that many independent 4-D errors of a consistent estimator (successive "
        "estimates are correlated, so the band is narrower than their spread warrants). "
        "Its distribution, every UAV's estimate: the median of a trial's samples (3.36 for "
        "a consistent estimator) and the fraction of them inside the 95% interval of "
        "chi-square(4), [0.484, 11.14] (0.95), each averaged over the trials.",
        "",
    ]
    for motion in MOTIONS:
        rows = summary["motions"][motion]
        out += [
            f"## {motion} targets",
            "",
            "| tracker | observation rate | RMSE best [m] | NEES (band) | NEES median | "
            "NEES inside 95% | NEES best (band) | OSPA every UAV [m] | rate − paper's | "
            "RMSE best − paper's |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for tracker, r in rows.items():
            band, best_band = r["nees_band"], r["nees_best_band"]
            against = r.get("against_paper")
            out.append(
                f"| {tracker} | {pm(r['mean'], r['std'], 3)} | "
                f"{pm(r['rmse_best']['mean'], r['rmse_best']['std'], 2)} | "
                f"{r['nees']['mean']:.2f} ({band[0]:.3f}–{band[1]:.3f}) | "
                f"{r['nees_median']['mean']:.2f} | {r['nees_inside']['mean']:.3f} | "
                f"{r['nees_best']['mean']:.2f} ({best_band[0]:.3f}–{best_band[1]:.3f}) | "
                f"{r['ospa']['mean']:.2f} | "
                + (
                    f"{ci(against['observation_rate'])} | {ci(against['rmse_best'])} |"
                    if against
                    else " | |"
                )
            )
        out.append("")
    out += ["![trackers](trackers.png)", ""]
    return "\n".join(out)
