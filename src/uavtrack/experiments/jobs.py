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
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import Scenario, ScenarioError, flatten
from ..limits import MAX_TRIALS
from ..simulation import run, trial_seed
from .statistics import describe, paired


@dataclass(frozen=True, kw_only=True)
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
        return f"{self.kind}__{label}__{_file_safe(self.method)}__{span}"


def _file_safe(name: str) -> str:
    """A method's name as a file name's part: itself, or with a character a file name
    cannot hold (a policy file's path) replaced and a digest of the whole added."""
    safe = re.sub(r"[^A-Za-z0-9._=+-]", "_", name)
    if safe == name:
        return name
    return f"{safe[-60:]}~{hashlib.sha256(name.encode()).hexdigest()[:12]}"


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
    "ospa", "ospa_best", "gospa", "gospa_best", "gospa_missed_best", "nees_median",
    "nees_inside", "nees_best_median", "nees_best_inside", "gospa_localisation",
    "gospa_missed", "gospa_false", "switches", "fragmentations", "unassigned_tracks",
    "unassigned_tracks_per_target", "duplicate_tracks", "stale_tracks", "never_tracks",
    "never_tracks_new", "gospa_team", "label_purity", "ospa2", "ospa2_team", "time_to_confirm",
    "time_to_confirm_team", "never_confirmed",
    "siap_completeness", "siap_ambiguity", "siap_spuriousness", "separation_min",
)  # fmt: skip
"""Metrics that may be NaN: nothing to average (every UAV failed), not measured, or not
defined for the run (the track metrics with known association, the per-target estimate
metrics with tracks, the closest approach of a team that never shared an altitude band)."""


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
    """Jobs covering trials 0 .. trials-1 of base+overrides with one method; more than
    `limits.MAX_TRIALS` trials are refused before a job is made."""
    if not 1 <= trials <= MAX_TRIALS:
        raise ScenarioError(f"trials {trials}: give 1 to {MAX_TRIALS:,} per configuration")
    scenario = base.with_overrides(overrides, origin=origin)
    label = label_of(difference(base, scenario))  # equal scenarios, equal labels (label_for)
    return [
        Job(
            kind="trials",
            label=label,
            method=method,
            scenario=scenario,
            first=first,
            count=min(chunk, trials - first),
            seed=seed,
        )
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


def sweep_axes(base: Scenario, axes: Mapping[str, Sequence[Any]]) -> dict[str, list[Any]]:
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


def sweep_cells(axes: Mapping[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """Every combination of the swept values, the last field varying fastest:
    ``{"a": [1, 2], "b": [0, 5]}`` -> ``[{a: 1, b: 0}, {a: 1, b: 5}, {a: 2, b: 0}, ...]``."""
    return [dict(zip(axes, combo, strict=True)) for combo in itertools.product(*axes.values())]


def cell_text(cell: dict[str, Any], shown: Callable[[Any], str] | None = None) -> str:
    """``comm_range=50, faults.loss=0.2``: a cell, its values shown by `shown` (as in
    labels by default; `repr` for values as given)."""
    return ", ".join(f"{k}={(shown or _fmt)(v)}" for k, v in cell.items())


def sweep_plan(
    base: Scenario,
    axes: Mapping[str, Sequence[Any]],
    methods: Sequence[str],
    trials: int,
    chunk: int = 10,
    seed: int = 0,
) -> dict[str, list[Job]]:
    """One field over several values, or a grid of several fields (every combination):
    each method on the same trials in every cell. A cell the scenario refuses (values
    that cannot go together) is refused here, before any work."""
    held = sweep_axes(base, axes)
    jobs, seen = [], {}
    for cell in sweep_cells(held):
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


def summarize_sweep(
    plan: dict[str, list[Job]],
    results: dict[str, dict],
    axes: Mapping[str, Sequence[Any]],
    methods: Sequence[str],
    more: Sequence[str] = (),
) -> dict[str, Any]:
    """summary.json of a sweep: per cell (a combination of the swept values, in
    `sweep_cells` order) and method, and the paired differences of every two methods in
    observation rate (``paired``) and in each metric of `more` (``paired_metrics``:
    metric -> pair -> per cell; with tracks, `statistics.TRACK_METRICS`).

    ``fields`` and ``axes`` name the swept fields and their values, ``cells`` each cell's
    values in field order; a sweep of one field also keeps ``field`` and ``values``."""
    data = collect(plan["sweep"], results)
    labels = list(dict.fromkeys(job.label for job in plan["sweep"]))  # one per cell
    per_method = {m: [describe(data[(lab, m)]) for lab in labels] for m in methods}
    by_metric: dict[str, dict[str, list]] = {name: {} for name in ("observation_rate", *more)}
    for k, a in enumerate(methods):
        for b in methods[k + 1 :]:
            for name, pairs_of in by_metric.items():
                pairs_of[f"{a} - {b}"] = [
                    paired(data[(lab, a)][name], data[(lab, b)][name]) for lab in labels
                ]
    pairs = by_metric.pop("observation_rate")
    cells = sweep_cells(axes)
    out: dict[str, Any] = {"fields": list(axes), "axes": {f: list(v) for f, v in axes.items()}}
    if len(axes) == 1:
        ((field, values),) = axes.items()
        out.update(field=field, values=list(values))
    out.update(cells=[list(c.values()) for c in cells], methods=per_method, paired=pairs)
    if more:
        out["paired_metrics"] = by_metric
    return out


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
