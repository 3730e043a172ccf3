"""The paper's open questions (Sec. 8), measured: every method under every fault.

`uavtrack robustness` runs, for each fault of `config.FaultModel`, a range of levels
with four series on the same trials (common random numbers, so differences between
series are paired):

* ``distributed``: the paper's method as printed;
* ``robust``: the same with every robustness mechanism of `config.RobustModel` on
  (`ROBUST`): extra consensus rounds, time-stamped tuples predicted forward with silent
  neighbours dropped from the auction, and the UAV's own position error added to R;
* ``centralized`` and ``greedy``, the paper's baselines.

An ablation then runs each mechanism alone at one level of each fault, to tell which
one helps where. The experiment is a job list on the same resumable store as
`uavtrack reproduce`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np

from ..config import Scenario
from . import protocol
from .jobs import Job, collect, difference, label_of, trial_jobs, unique
from .statistics import ci95, describe, paired

ROBUST = {"robust.extra_rounds": 2, "robust.stale": True, "robust.position_noise": True}
"""The robust series: every mechanism on; 2 extra rounds (assumed: a margin of two rounds
covers the D_i a UAV underestimates when one or two flooding messages are lost)."""


MECHANISMS = {
    "extra rounds": {"robust.extra_rounds": 2},
    "stale": {"robust.stale": True},
    "position noise": {"robust.position_noise": True},
}
"""The mechanisms of the ablation, each alone."""


SERIES = ("distributed", "robust", "centralized", "greedy")


@dataclass(frozen=True, kw_only=True)
class Fault:
    """One fault of the standard set: a field swept over levels, with fixed settings.

    name: short name; field: the scenario field swept; levels: its values (the first is
    "no fault"); fixed: other fields set at every level; ablation: the level at which
    each mechanism is tried alone; xlabel: the axis label of its figure.
    """

    name: str
    field: str
    levels: tuple
    fixed: dict
    ablation: Any
    xlabel: str


FAULTS = (
    Fault(
        name="loss",
        field="faults.loss",
        levels=(0.0, 0.1, 0.2, 0.3, 0.5, 0.7),
        fixed={},
        ablation=0.5,
        xlabel="message loss probability (independent)",
    ),
    Fault(
        name="burst",
        field="faults.burst_length",
        levels=(1.0, 2.0, 5.0, 10.0, 20.0),
        fixed={"faults.loss": 0.3},
        ablation=10.0,
        xlabel="mean burst length [cycles] at 30% loss",
    ),
    Fault(
        name="delay",
        field="faults.delay",
        levels=(0, 1, 2, 4, 8),
        fixed={},
        ablation=2,
        xlabel="message delay [cycles]",
    ),
    Fault(
        name="round_budget",
        field="faults.round_budget",
        levels=(None, 3, 2, 1),
        fixed={},
        ablation=1,
        xlabel="consensus rounds per cycle (none: unlimited)",
    ),
    Fault(
        name="failure_rate",
        field="faults.failure_rate",
        levels=(0.0, 0.0001, 0.0004, 0.001, 0.002),
        fixed={},
        ablation=0.001,
        xlabel="UAV failure probability per UAV and cycle",
    ),
    Fault(
        name="position_std",
        field="faults.position_std",
        levels=(0.0, 1.0, 2.0, 5.0, 10.0),
        fixed={},
        ablation=5.0,
        xlabel="UAV position error, std per axis [m]",
    ),
)


@dataclass(frozen=True)
class Profile(protocol.Profile):
    """The size of a robustness run (--quick: 4 trials of 60 steps, three levels per
    fault)."""

    chunk: int = 25
    faults: tuple[Fault, ...] = FAULTS
    QUICK: ClassVar[tuple[int, int, int]] = (4, 60, 4)

    @classmethod
    def quick(cls) -> Self:
        """A smoke-test profile: a few short trials, three levels per fault."""
        short = tuple(
            Fault(
                name=f.name,
                field=f.field,
                levels=f.levels[:1] + f.levels[2:4],
                fixed=f.fixed,
                ablation=f.ablation,
                xlabel=f.xlabel,
            )
            for f in FAULTS
        )
        return replace(super().quick(), faults=short)

    def to_dict(self) -> dict[str, Any]:
        return {
            "trials": self.trials,
            "steps": self.steps,
            "chunk": self.chunk,
            "faults": {f.name: {"field": f.field, "levels": list(f.levels)} for f in self.faults},
        }


def series_method(series: str) -> tuple[str, dict]:
    """The method and the robustness overrides of a series."""
    if series == "robust":
        return "distributed", ROBUST
    if series in MECHANISMS:
        return "distributed", MECHANISMS[series]
    return series, {}


def plan(base: Scenario, profile: Profile, seed: int = 0) -> dict[str, list[Job]]:
    """Every job of the experiment, grouped by fault (and "ablation")."""
    base = base.with_overrides({"steps": profile.steps})
    out: dict[str, list[Job]] = {}

    def jobs(overrides: dict, series: str) -> list[Job]:
        method, extra = series_method(series)
        return trial_jobs(base, {**overrides, **extra}, method, profile.trials, profile.chunk, seed)

    for fault in profile.faults:
        out[fault.name] = [
            job
            for level in fault.levels
            for series in SERIES
            for job in jobs({**fault.fixed, fault.field: level}, series)
        ]
    out["ablation"] = [
        job
        for fault in profile.faults
        for series in ("distributed", *MECHANISMS, "robust")
        for job in jobs({**fault.fixed, fault.field: fault.ablation}, series)
    ]
    return out


def _label(base: Scenario, overrides: dict, series: str) -> tuple[str, str]:
    method, extra = series_method(series)
    scenario = base.with_overrides({**overrides, **extra})
    return label_of(difference(base, scenario)), method


def summarize(
    jobs: dict[str, list[Job]], results: dict[str, dict], profile: Profile, base: Scenario
) -> dict[str, Any]:
    """summary.json: per fault, per series and level, the observation rate and costs,
    with paired differences; the ablation; and the settings of the series."""
    base = base.with_overrides({"steps": profile.steps})
    data = collect(unique(j for group in jobs.values() for j in group), results)
    out: dict[str, Any] = {"series": {s: dict(series_method(s)[1]) for s in SERIES}}
    faults: dict[str, Any] = {}
    for fault in profile.faults:
        rows: dict[str, list] = {s: [] for s in SERIES}
        pairs: dict[str, list] = {
            "distributed - centralized": [],
            "distributed - greedy": [],
            "robust - distributed": [],
        }
        for level in fault.levels:
            over = {**fault.fixed, fault.field: level}
            rate = {}
            for s in SERIES:
                metrics = data[_label(base, over, s)]
                rows[s].append(describe(metrics) | {"ci95": ci95(metrics["observation_rate"])})
                rate[s] = metrics["observation_rate"]
            for name in pairs:
                a, b = name.split(" - ")
                pairs[name].append(paired(rate[a], rate[b]))
        faults[fault.name] = {
            "field": fault.field,
            "fixed": fault.fixed,
            "levels": list(fault.levels),
            "xlabel": fault.xlabel,
            "series": rows,
            "paired": pairs,
        }
    out["faults"] = faults
    ablation = {}
    for fault in profile.faults:
        over = {**fault.fixed, fault.field: fault.ablation}
        paper = data[_label(base, over, "distributed")]["observation_rate"]
        entry = {"field": fault.field, "level": fault.ablation, "series": {}}
        for s in ("distributed", *MECHANISMS, "robust"):
            rate = data[_label(base, over, s)]["observation_rate"]
            entry["series"][s] = {
                "mean": float(np.mean(rate)),
                "vs_paper": paired(rate, paper),
            }
        ablation[fault.name] = entry
    out["ablation"] = ablation
    return out


NAME = "robustness"
"""The command, and the results folder's name."""


def figures(jobs: dict[str, list[Job]]) -> list[str]:
    """One figure per fault (fault_<name>.png)."""
    return [f"fault_{name}.png" for name in jobs if name != "ablation"]


def figure(summary: dict[str, Any], out: Path) -> None:
    from .figures import robustness_figures

    robustness_figures(summary, out)


def report(summary: dict[str, Any], scenario: Scenario, info: dict[str, Any]) -> str:
    """report.md (`report.robustness`)."""
    from . import report as reports

    return reports.robustness(summary, scenario, info)
