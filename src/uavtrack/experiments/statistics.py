"""Every statistic and number format of the experiments, in one place: the mean and
spread over trials (`describe`, `summarize`), paired differences with t intervals
(`paired`, `against_first`), the 95% half-width (`ci95`), the NEES chi-square band, and
the formatters the reports and the command line print them with.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..metrics import METRICS, mean_std, sorted_rates


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

TRACK_METRICS = (
    "gospa", "gospa_localisation", "gospa_missed", "gospa_false",
    "unassigned_tracks_per_target", "duplicate_tracks", "stale_tracks", "never_tracks",
    "switches", "siap_completeness", "siap_ambiguity", "siap_spuriousness", "gospa_team",
    "label_purity", "ospa2", "ospa2_team",
)  # fmt: skip
"""The track metrics of a run with tracks (``tracker.association`` gnn or jpda), which a
comparison and a sweep report beside the observation rate."""

TRACK_PAIRED_METRICS = ("observation_rate", *TRACK_METRICS, "rounds", "messages")
"""The metrics whose paired differences `compare` reports with tracks, in place of the
per-target estimate metrics, which a track set does not have."""


def paired_metrics(tracked: bool) -> tuple[str, ...]:
    """The metrics a comparison pairs: `TRACK_PAIRED_METRICS` with tracks, else
    `PAIRED_METRICS`."""
    return TRACK_PAIRED_METRICS if tracked else PAIRED_METRICS


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


def summarize(metrics: dict[str, np.ndarray]) -> dict[str, object]:
    """Mean and standard deviation over trials of each metric (JSON-ready; NaN: null).

    A decision time is averaged over the trials where it was measured (`trials` says
    how many); a standard deviation needs two values.
    """
    out: dict[str, object] = {"trials": int(len(metrics["observation_rate"]))}
    for name, values in metrics.items():
        mean, std = mean_std(values)
        entry: dict[str, object] = {
            "mean": np.asarray(mean).tolist(),
            "std": np.asarray(std).tolist(),
        }
        if name in ("decision_time_ms", "decision_wall_ms"):
            entry["trials"] = int(np.sum(~np.isnan(np.asarray(values, dtype=float))))
        out[name] = entry
    return out


def _missing(value: float | None) -> bool:
    return value is None or value != value  # None or NaN


def pm(mean: float | None, std: float | None, digits: int = 4) -> str:
    """``mean ± std``; n/a for what could not be computed."""
    if _missing(mean):
        return "n/a"
    spread = "n/a" if _missing(std) else f"{std:.{digits}f}"
    return f"{mean:.{digits}f} ± {spread}"


def ci(p: dict[str, float], negate: bool = False, digits: int = 4) -> str:
    """``mean [low, high]`` of a paired difference (of its negation if `negate`)."""
    mean, low, high = p["mean"], p["ci_low"], p["ci_high"]
    if negate:
        mean, low, high = -mean, -high, -low
    if _missing(mean):
        return "n/a"
    if _missing(low) or _missing(high):
        return f"{signed(mean, digits)} [n/a]"
    return f"{signed(mean, digits)} [{signed(low, digits)}, {signed(high, digits)}]"


def signed(x: float, digits: int = 4) -> str:
    """x with its sign, and +0 rather than -0 for what rounds to zero."""
    text = f"{x:+.{digits}f}"
    return "+" + text[1:] if float(text) == 0 else text


def number(value: float | None, digits: int = 2) -> str:
    return "n/a" if _missing(value) else f"{value:.{digits}f}"


def level_text(value: Any) -> str:
    """A level or swept value as text: none for an unset field, numbers without noise."""
    if value is None:
        return "none"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def ci95(values: np.ndarray) -> float:
    """Half-width of the 95% t confidence interval of the mean (NaN for one value)."""
    from scipy import stats  # loaded here: a command refuses bad input before this import

    values = np.asarray(values, dtype=float)
    n = len(values)
    if n < 2:
        return float("nan")
    return float(stats.t.ppf(0.975, n - 1) * values.std(ddof=1) / np.sqrt(n))


def nees_band(samples: float, dim: int = 4, level: float = 0.95) -> tuple[float, float]:
    """The band of the mean NEES of `samples` independent `dim`-D errors of a consistent
    estimator: chi-square(dim x samples) quantiles divided by samples."""
    from scipy import stats  # loaded here: a command refuses bad input before this import

    low, high = stats.chi2.ppf([(1 - level) / 2, (1 + level) / 2], dim * samples)
    return float(low / samples), float(high / samples)
