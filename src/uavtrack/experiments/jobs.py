"""Monte Carlo experiments: the paper's Section 7 and parameter sweeps, as lists of jobs.

A job is a fixed chunk of trials of one scenario with one method. Trial t of an
experiment seeded with s uses `trial_seed(s, t)` whatever the method, scenario or
chunking, so

* every method sees the same targets and noise in a trial (common random numbers),
  and differences between methods are paired;
* results do not depend on how many workers run the jobs, or on which engine.

Jobs with the same scenario and method are the same job, so the r_C = 50 m point of
Fig. 8 is Fig. 5's distributed run, computed once.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import registry
from .config import Scenario, ScenarioError, flatten
from .metrics import METRICS, mean_std, sorted_rates
from .simulation import run, trial_seed

METHOD_NAMES = tuple(registry.BUILT_IN)
"""The paper's method and its baselines, which the reproduction compares."""

PAPER_FIG5 = {
    "distributed": (0.8031, 0.1262),
    "centralized": (0.8048, 0.1217),
    "greedy": (0.6664, 0.1507),
}
"""The paper's overall observation rates, mean and std over 50 trials (Sec. 7.1)."""


FIRST_GUESS = {"dt": 1.0, "uav.altitude": 500.0}
"""The two calibrated parameters at their first guess, before the calibration against
Fig. 5 (docs, "Calibration"); the reproduction runs it beside the defaults."""

SENSITIVITY: dict[str, tuple[Any, ...]] = {
    "dt": (0.25, 1.0),
    "uav.bank_angle_deg": (30.0, 60.0),
    "uav.altitude": (350.0, 500.0),
    "uav.altitude_spacing": (0.0, 10.0),
    "planner.horizon": (2, 4),
    "field_size": (150.0, 300.0),
    "uav.start_spread": (0.0, 100.0),
    "target.initial_velocity_std": (0.5, 2.0),
    "estimation.initial_position_std": (2.0, 20.0),
    "target.noise_form": ("printed",),
}
"""Every assumed parameter with a low and a high value around the default, for
`reproduce --sensitivity` (the reading of eq. 15 has one alternative). Each moves one
parameter at a time; steps stay at the profile's, so ΔT changes the mission's length."""

NEAR_CENTRALIZED = -0.03
""""Distributed within 0.03 of centralized": distributed − centralized ≥ −0.03."""
ABOVE_GREEDY = 0.05
""""Distributed well above greedy": distributed − greedy ≥ 0.05 (the paper's gap is 0.137)."""


@dataclass(frozen=True)
class Profile:
    """The size of a reproduction of Section 7."""

    trials: int = 50
    steps: int = 500
    chunk: int = 50  # a configuration's trials in one batch: numpy's per-call cost shared
    comm_ranges: tuple[float, ...] = (10, 20, 30, 40, 50, 60, 70, 80)
    half_fovs: tuple[float, ...] = (5, 6, 7, 8, 9, 10)
    timing_grid: tuple[tuple[int, int], ...] = ((3, 2), (5, 4), (8, 6), (10, 10), (20, 20))
    timing_trials: int = 3
    timing_steps: int = 100

    @classmethod
    def quick(cls) -> Profile:
        """A smoke-test profile: a few short trials, coarse grids."""
        return cls(
            trials=4,
            steps=60,
            chunk=4,
            comm_ranges=(10, 50, 80),
            half_fovs=(5, 8),
            timing_grid=((3, 2), (5, 4)),
            timing_trials=1,
            timing_steps=20,
        )

    def to_dict(self) -> dict[str, Any]:
        return {k: _plain(getattr(self, k)) for k in self.__dataclass_fields__}


def _plain(value):
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


@dataclass(frozen=True)
class Job:
    """A chunk of trials (or of timing runs) of one scenario with one method."""

    kind: str  # "trials" or "timing"
    label: str  # the scenario's difference from the base, e.g. "comm_range=10"
    method: str
    scenario: Scenario
    first: int
    count: int
    seed: int

    @property
    def key(self) -> str:
        """File-name stem, unique within an experiment folder. A label too long for a
        file name (many fields set) keeps its start and a digest of the whole."""
        span = f"t{self.first:03d}-{self.first + self.count - 1:03d}"
        label = self.label
        if len(label) > LABEL_CHARS:
            digest = hashlib.sha256(label.encode()).hexdigest()[:16]
            label = f"{label[: LABEL_CHARS - 17]}~{digest}"
        return f"{self.kind}__{label}__{self.method}__{span}"


LABEL_CHARS = 120
"""Longest label kept whole in a job's file name (file names stop at 255 bytes)."""


def run_job(job: Job) -> dict[str, Any]:
    """Execute a job; returns JSON-ready per-trial metrics (this runs on the workers).

    Trial jobs run their trials as one batch. Timing jobs run them one at a time, so
    the decision time is that of one team, not a share of a batch. A result that is not
    finite (a scenario that broke the numerics) raises instead of being saved.
    """
    seeds = [trial_seed(job.seed, t) for t in range(job.first, job.first + job.count)]
    if job.kind == "trials":
        metrics = run(job.scenario, job.method, seeds).metrics
    else:
        parts = [run(job.scenario, job.method, [s]).metrics for s in seeds]
        metrics = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    check_finite(metrics, job.key)
    return {name: np.asarray(values).tolist() for name, values in metrics.items()}


UNDEFINED_ALLOWED = (
    "rmse", "rmse_best", "nees", "nees_best", "rounds", "decision_time_ms", "decision_wall_ms",
    "ospa", "ospa_best", "gospa", "gospa_best", "gospa_missed_best",
)  # fmt: skip
"""Metrics that may be NaN: nothing to average (every UAV failed), or not measured."""


def check_finite(metrics: dict[str, np.ndarray], what: str) -> None:
    """Raise if a metric is infinite, or NaN where it cannot be undefined."""
    for name, values in metrics.items():
        values = np.asarray(values, dtype=float)
        bad = ~np.isfinite(values)
        if name in UNDEFINED_ALLOWED:
            bad &= ~np.isnan(values)
        if bad.any():
            raise FloatingPointError(f"{what}: metric {name} is not finite ({values[bad][0]})")


def label_of(overrides: dict[str, Any]) -> str:
    """Readable label of a set of overrides ('default' when empty)."""
    if not overrides:
        return "default"
    return ",".join(f"{k}={_fmt(v)}" for k, v in sorted(overrides.items()))


def difference(base: Scenario, scenario: Scenario) -> dict[str, Any]:
    """The dotted fields where `scenario` differs from `base`, with its values."""
    was, now = flatten(base.to_dict()), flatten(scenario.to_dict())
    return {k: now[k] for k in now if now[k] != was.get(k)}


def _fmt(value: Any) -> str:
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return json.dumps(value) if isinstance(value, list | dict) else str(value)


def trial_jobs(
    base: Scenario,
    overrides: dict[str, Any],
    method: str,
    trials: int,
    chunk: int,
    seed: int,
    origin: str = "override",
) -> list[Job]:
    """Jobs covering trials 0 .. trials-1 of base+overrides with one method."""
    scenario = base.with_overrides(overrides, origin=origin)
    label = label_of(difference(base, scenario))  # equal scenarios, equal labels (label_for)
    return [
        Job("trials", label, method, scenario, first, min(chunk, trials - first), seed)
        for first in range(0, trials, chunk)
    ]


def label_for(base: Scenario, overrides: dict[str, Any]) -> str:
    """The label of base+overrides as `trial_jobs` gives it: only the fields that differ
    from `base` (an override equal to the base's value leaves no trace, "default")."""
    return label_of(difference(base, base.with_overrides(overrides)))


def sweep_values(base: Scenario, field: str, values: Sequence[Any]) -> list[Any]:
    """The values of a sweep as the scenario holds them (10 -> 10.0 for a float field).

    Each value is validated, its error naming the sweep; two values that are equal once
    validated (``10`` and ``10.0``) are refused, as they would be one configuration.
    """
    return sweep_axes(base, {field: values})[field]


def sweep_axes(base: Scenario, axes: dict[str, Sequence[Any]]) -> dict[str, list[Any]]:
    """The values of each swept field as the scenario holds them (10 -> 10.0 for a float
    field), validated: one field's values one by one, a grid's cell by cell (a value may
    need another field's: ``n_uavs 3 uav.altitudes "[400, 410, 420]"``), each error naming
    the value or the cell. Two values of a field that are equal once validated (``10`` and
    ``10.0``) are refused, as they would be one configuration."""
    for field, values in axes.items():
        if not values:
            raise ScenarioError(f"sweep {field}: give at least one value")
    held: dict[str, list[Any]] = {field: [None] * len(values) for field, values in axes.items()}
    places = itertools.product(*(range(len(v)) for v in axes.values()))
    for cell, place in zip(sweep_cells(axes), places, strict=True):
        where = "value" if len(axes) == 1 else "cell"
        scenario = base.with_overrides(cell, origin=f"sweep {where} {cell_text(cell, repr)}")
        for field, k in zip(axes, place, strict=True):
            value = scenario.value(field)
            held[field][k] = list(value) if isinstance(value, tuple) else value
    for field, values in axes.items():
        out = held[field]
        for k, value in enumerate(out):
            if value in out[:k]:
                first, raw = values[out.index(value)], values[k]
                same = (
                    f"{raw!r} is given twice,"
                    if repr(first) == repr(raw)
                    else f"{first!r} and {raw!r} are"
                )
                raise ScenarioError(
                    f"sweep {field}: {same} the same value once read ({value!r}); "
                    "give each value once"
                )
    return held


def reproduce_plan(
    base: Scenario, profile: Profile, seed: int = 0, sensitivity: bool = False
) -> dict[str, list[Job]]:
    """Every experiment of the paper's Section 7 as jobs, grouped by experiment, with the
    uncalibrated first guess and, if asked, the one-at-a-time sensitivity study."""
    base = base.with_overrides({"steps": profile.steps})
    tj = lambda over, method: trial_jobs(base, over, method, profile.trials, profile.chunk, seed)  # noqa: E731
    plan = {
        "compare": [j for m in METHOD_NAMES for j in tj({}, m)],
        "first_guess": [j for m in METHOD_NAMES for j in tj(FIRST_GUESS, m)],
        "comm_range": [
            j for r in profile.comm_ranges for j in tj({"comm_range": r}, "distributed")
        ],
        "fov": [
            j for a in profile.half_fovs for j in tj({"sensor.half_fov_deg": a}, "distributed")
        ],
        "timing": [],
    }
    for nu, nt in profile.timing_grid:
        scenario = resized(base, nu, nt).with_overrides({"steps": profile.timing_steps})
        for m in METHOD_NAMES:
            plan["timing"].append(
                Job(
                    "timing",
                    label_of({"n_uavs": nu, "n_targets": nt}),
                    m,
                    scenario,
                    0,
                    profile.timing_trials,
                    seed,
                )
            )
    if sensitivity:
        plan["sensitivity"] = [
            j
            for field, values in SENSITIVITY.items()
            for value in values
            for m in METHOD_NAMES
            for j in tj({field: value}, m)
        ]
    return plan


def resized(base: Scenario, n_uavs: int, n_targets: int) -> Scenario:
    """`base` with another team size, keeping the spread of its altitudes."""
    heights = base.altitudes()
    spread = max(heights) - min(heights)
    spacing = spread / (n_uavs - 1) if n_uavs > 1 else 0.0
    return base.with_overrides(
        {
            "n_uavs": n_uavs,
            "n_targets": n_targets,
            "uav.altitudes": None,
            "uav.altitude": (max(heights) + min(heights)) / 2,
            "uav.altitude_spacing": spacing,
        }
    )


def sweep_cells(axes: dict[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """Every combination of the swept values, the last field varying fastest:
    ``{"a": [1, 2], "b": [0, 5]}`` -> ``[{a: 1, b: 0}, {a: 1, b: 5}, {a: 2, b: 0}, ...]``."""
    return [dict(zip(axes, combo, strict=True)) for combo in itertools.product(*axes.values())]


def cell_text(cell: dict[str, Any], shown: Callable[[Any], str] | None = None) -> str:
    """``comm_range=50, faults.loss=0.2``: a cell, its values shown by `shown` (as in
    labels by default; `repr` for values as given)."""
    return ", ".join(f"{k}={(shown or _fmt)(v)}" for k, v in cell.items())


def sweep_plan(
    base: Scenario,
    axes: dict[str, Sequence[Any]],
    methods: Sequence[str],
    trials: int,
    chunk: int = 10,
    seed: int = 0,
) -> dict[str, list[Job]]:
    """One field over several values, or a grid of several fields (every combination):
    each method on the same trials in every cell. A cell the scenario refuses (values
    that cannot go together) is refused here, before any work."""
    axes = sweep_axes(base, axes)
    jobs, seen = [], {}
    for cell in sweep_cells(axes):
        for m in methods:
            jobs += trial_jobs(
                base, cell, m, trials, chunk, seed, origin=f"sweep cell {cell_text(cell)}"
            )
        label = jobs[-1].label
        if label in seen:
            raise ScenarioError(
                f"sweep: the cells {seen[label]} and {cell_text(cell)} are the same scenario; "
                "drop one of the values"
            )
        seen[label] = cell_text(cell)
    return {"sweep": jobs}


def unique(jobs: Iterable[Job]) -> list[Job]:
    """Jobs without repeats (the same key is the same computation), in first-seen order."""
    seen: dict[str, Job] = {}
    for job in jobs:
        seen.setdefault(job.key, job)
    return list(seen.values())


# ------------------------------------------------------------------ aggregation


def collect(jobs: Sequence[Job], results: dict[str, dict[str, Any]]) -> dict[tuple[str, str], dict]:
    """Per-trial metric arrays per (label, method), trials in order."""
    grouped: dict[tuple[str, str], list[tuple[int, dict]]] = {}
    for job in jobs:
        grouped.setdefault((job.label, job.method), []).append((job.first, results[job.key]))
    out = {}
    for key, parts in grouped.items():
        parts.sort(key=lambda p: p[0])
        out[key] = {
            name: np.concatenate([np.asarray(p[name]) for _, p in parts]) for name in parts[0][1]
        }
    return out


def describe(metrics: dict[str, np.ndarray]) -> dict[str, Any]:
    """Mean and std over trials of the rate, per target, sorted per target, and costs."""
    rate = np.asarray(metrics["observation_rate"], dtype=float)
    rate_mean, rate_std = mean_std(rate)
    tgt_mean, tgt_std = mean_std(metrics["per_target"])
    srt_mean, srt_std = mean_std(sorted_rates(metrics["per_target"]))
    out = {
        "trials": int(len(metrics["observation_rate"])),
        "mean": float(rate_mean),
        "std": float(rate_std),
        # the same spread over (trial, target) pairs and over (trial, step) pairs
        "std_trial_target": float(mean_std(np.ravel(metrics["per_target"]))[1]),
        "std_trial_step": float(np.sqrt(np.mean(np.square(metrics["in_view_std"])) + np.var(rate))),
        "per_target_mean": tgt_mean.tolist(),
        "per_target_std": tgt_std.tolist(),
        "sorted_mean": srt_mean.tolist(),
        "sorted_std": srt_std.tolist(),
    }
    for name in METRICS:
        if name in ("observation_rate", "per_target", "in_view_std"):
            continue
        m, s = mean_std(metrics[name])
        out[name] = {
            "mean": float(m),
            "std": float(s),
            "trials": int(np.sum(~np.isnan(np.asarray(metrics[name], dtype=float)))),
        }
    return out


def paired(a: np.ndarray, b: np.ndarray, level: float = 0.95) -> dict[str, float]:
    """Mean of the per-trial differences a - b with a t confidence interval at `level`.

    Trials where either value is undefined (NaN: an RMSE with every UAV failed) are left
    out; `trials` says how many were paired."""
    from scipy import stats  # loaded here: a command refuses bad input before this import

    diff = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    diff = diff[~np.isnan(diff)]
    n = len(diff)
    if n == 0:
        return {"mean": math.nan, "ci_low": math.nan, "ci_high": math.nan, "trials": 0}
    mean = float(diff.mean())
    if n < 2:
        return {"mean": mean, "ci_low": math.nan, "ci_high": math.nan, "trials": n}
    half = float(stats.t.ppf(0.5 + level / 2, n - 1) * diff.std(ddof=1) / math.sqrt(n))
    return {"mean": mean, "ci_low": mean - half, "ci_high": mean + half, "trials": n}


PAIRED_METRICS = (
    "observation_rate", "rmse_best", "rmse", "nees_best", "ospa_best", "gospa_best",
    "rounds", "messages",
)  # fmt: skip
"""The metrics whose paired differences `compare` reports (decision times are measured on
one trial only, so they have no interval)."""


def against_first(
    raw: dict[str, dict[str, np.ndarray]], metrics: Sequence[str] = PAIRED_METRICS
) -> dict[str, dict[str, dict[str, float]]]:
    """Paired differences of the first method against every other, on the same trials:
    ``{"distributed - greedy": {"observation_rate": paired(...), ...}, ...}``, first minus
    other, as the reproduction and `summarize_sweep` take them.

    `raw`: per-trial metrics by method, as `compare` returns them (common random numbers,
    so trial t of every method saw the same targets and noise)."""
    first, *others = raw
    return {
        f"{first} - {m}": {k: paired(raw[first][k], raw[m][k]) for k in metrics} for m in others
    }


def summarize_reproduction(
    plan: dict[str, list[Job]], results: dict[str, dict], profile: Profile, base: Scenario
) -> dict[str, Any]:
    """summary.json of a reproduction: compare, paired, comm_range, fov, timing."""
    data = {name: collect(jobs, results) for name, jobs in plan.items()}
    compare = {m: describe(data["compare"][("default", m)]) for m in METHOD_NAMES}
    rate = {m: data["compare"][("default", m)]["observation_rate"] for m in METHOD_NAMES}
    pairs = {
        f"{a} - {b}": paired(rate[a], rate[b])
        for a, b in (
            ("distributed", "centralized"),
            ("distributed", "greedy"),
            ("centralized", "greedy"),
        )
    }

    def curve(name: str, field: str, values: Sequence[Any]) -> dict[str, Any]:
        labels = [job.label for job in plan[name]]
        ordered = list(dict.fromkeys(labels))
        return {
            "field": field,
            "values": list(values),
            "distributed": [describe(data[name][(lab, "distributed")]) for lab in ordered],
        }

    timing: dict[str, Any] = {
        "grid": [list(g) for g in profile.timing_grid],
        "steps": profile.timing_steps,
        "trials": profile.timing_trials,
    }
    for m in METHOD_NAMES:  # CPU time, the figure's; wall time beside it
        cells = [
            data["timing"][(label_of({"n_uavs": nu, "n_targets": nt}), m)]
            for nu, nt in profile.timing_grid
        ]
        rows = [mean_std(cell["decision_time_ms"]) for cell in cells]
        walls = [mean_std(cell["decision_wall_ms"]) for cell in cells]
        timing[m] = {
            "mean_ms": [float(mean) for mean, _ in rows],
            "std_ms": [float(std) for _, std in rows],
            "wall_mean_ms": [float(mean) for mean, _ in walls],
            "wall_std_ms": [float(std) for _, std in walls],
        }
    out = {
        "compare": compare,
        "paired": pairs,
        "comm_range": curve("comm_range", "comm_range", profile.comm_ranges),
        "fov": curve("fov", "sensor.half_fov_deg", profile.half_fovs),
        "timing": timing,
        "paper": {m: {"mean": v[0], "std": v[1]} for m, v in PAPER_FIG5.items()},
    }
    stepped = base.with_overrides({"steps": profile.steps})  # the plan's base
    out["first_guess"] = {
        "overrides": FIRST_GUESS,
        **conclusions(
            data["first_guess"][(label_for(stepped, FIRST_GUESS), m)] for m in METHOD_NAMES
        ),
    }
    if "sensitivity" in plan:
        rows = []
        for field, values in SENSITIVITY.items():
            rows.append(
                {
                    "field": field,
                    "default": _plain(base.value(field)),
                    "values": [
                        {
                            "value": v,
                            **conclusions(
                                data["sensitivity"][(label_for(stepped, {field: v}), m)]
                                for m in METHOD_NAMES
                            ),
                        }
                        for v in values
                    ],
                }
            )
        out["sensitivity"] = {
            "base": conclusions(data["compare"][("default", m)] for m in METHOD_NAMES),
            "near_centralized": NEAR_CENTRALIZED,
            "above_greedy": ABOVE_GREEDY,
            "rows": rows,
        }
    return out


def conclusions(per_method: Iterable[dict[str, np.ndarray]]) -> dict[str, Any]:
    """Mean rates of the three methods (in METHOD_NAMES order) on the same trials, the
    two paired differences that carry the paper's conclusions, and whether each holds:
    "yes" or "no" by the mean difference, with ", CI crosses" when its 95% interval
    straddles the threshold (50 trials cannot tell the side)."""
    rate = dict(zip(METHOD_NAMES, (m["observation_rate"] for m in per_method), strict=True))

    def verdict(p: dict[str, float], threshold: float) -> str:
        holds = "yes" if p["mean"] >= threshold else "no"
        sure = p["ci_low"] >= threshold or p["ci_high"] < threshold
        return holds if sure else f"{holds}, CI crosses"

    near = paired(rate["distributed"], rate["centralized"])
    above = paired(rate["distributed"], rate["greedy"])
    return {
        "rates": {m: float(np.mean(r)) for m, r in rate.items()},
        "stds": {m: float(mean_std(r)[1]) for m, r in rate.items()},
        "distributed - centralized": near,
        "distributed - greedy": above,
        "near_centralized": verdict(near, NEAR_CENTRALIZED),
        "above_greedy": verdict(above, ABOVE_GREEDY),
    }


def summarize_sweep(
    plan: dict[str, list[Job]],
    results: dict[str, dict],
    axes: dict[str, Sequence[Any]],
    methods: Sequence[str],
) -> dict[str, Any]:
    """summary.json of a sweep: per cell (a combination of the swept values, in
    `sweep_cells` order) and method, and the paired differences of every two methods.

    ``fields`` and ``axes`` name the swept fields and their values, ``cells`` each cell's
    values in field order; a sweep of one field also keeps ``field`` and ``values``."""
    data = collect(plan["sweep"], results)
    labels = list(dict.fromkeys(job.label for job in plan["sweep"]))  # one per cell
    per_method = {m: [describe(data[(lab, m)]) for lab in labels] for m in methods}
    pairs = {}
    for k, a in enumerate(methods):
        for b in methods[k + 1 :]:
            pairs[f"{a} - {b}"] = [
                paired(data[(lab, a)]["observation_rate"], data[(lab, b)]["observation_rate"])
                for lab in labels
            ]
    cells = sweep_cells(axes)
    out: dict[str, Any] = {"fields": list(axes), "axes": {f: list(v) for f, v in axes.items()}}
    if len(axes) == 1:
        ((field, values),) = axes.items()
        out.update(field=field, values=list(values))
    out.update(cells=[list(c.values()) for c in cells], methods=per_method, paired=pairs)
    return out


# ------------------------------------------------------------------ in-process helpers


def trials(
    scenario: Scenario,
    method: str,
    n_trials: int,
    seed: int = 0,
    first: int = 0,
    chunk: int = 25,
    progress: Callable[[int], None] | None = None,
) -> dict[str, np.ndarray]:
    """Per-trial metrics of trials first .. first+n_trials-1.

    The first trial runs alone, so its decision time is measured (see
    `metrics.METRICS`); the others run in batches of `chunk`, which bounds the memory
    whatever the number of trials. Results equal one batch of them all. `progress`, if
    given, is called with the trial-steps done since its last call.
    """
    spans = [(first, 1)] + [
        (t, min(chunk, first + n_trials - t)) for t in range(first + 1, first + n_trials, chunk)
    ]
    parts = []
    for start, count in spans:
        seeds = [trial_seed(seed, t) for t in range(start, start + count)]
        done = [0]

        def advance(k: int, count: int = count, done: list = done) -> None:
            if progress is not None:
                progress((k - done[0]) * count)
                done[0] = k

        parts.append(run(scenario, method, seeds, progress=advance).metrics)
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def compare(
    scenario: Scenario,
    methods: Iterable[str],
    n_trials: int,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
) -> dict[str, dict[str, np.ndarray]]:
    """Per-trial metrics of each method on the same trials."""
    return {m: trials(scenario, m, n_trials, seed, progress=progress) for m in methods}


def summarize(metrics: dict[str, np.ndarray]) -> dict[str, object]:
    """Mean and standard deviation over trials of each metric (JSON-ready; NaN: null).

    A decision time is averaged over the trials where it was measured (`trials` says
    how many); a standard deviation needs two values.
    """
    out: dict[str, object] = {"trials": int(len(metrics["observation_rate"]))}
    for name, values in metrics.items():
        mean, std = mean_std(values)
        out[name] = {"mean": np.asarray(mean).tolist(), "std": np.asarray(std).tolist()}
        if name in ("decision_time_ms", "decision_wall_ms"):
            out[name]["trials"] = int(np.sum(~np.isnan(np.asarray(values, dtype=float))))
    return out
