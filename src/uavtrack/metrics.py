"""Performance measures (paper Sec. 7) accumulated step by step over a batch of trials.

Every per-trial metric is listed once in `METRICS` with its unit and meaning; the
command line, the JSON output and the reports read their labels from there.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .estimation import confidence, nees

METRICS: dict[str, tuple[str, str]] = {
    "observation_rate": (
        "",
        "mean over targets of the fraction of steps at which the target's true position "
        "lies inside at least one UAV's observation disk (Sec. 7)",
    ),
    "per_target": ("", "observation rate of each target, numbered from 0"),
    "rmse": (
        "m",
        "position RMSE of every UAV's fused estimate of every target, including the stale "
        "estimates of UAVs cut off from the team",
    ),
    "rmse_best": (
        "m",
        "position RMSE of the team's best estimate: per target, the estimate of the UAV "
        "most confident in it (highest 1/trace P)",
    ),
    "nees": (
        "",
        "NEES of every UAV's fused estimate over the 4-D state (4 when consistent), "
        "stale estimates included",
    ),
    "nees_best": ("", "NEES of the team's best estimate (4 when consistent)"),
    "rounds": ("", "consensus rounds D_i per UAV and step"),
    "messages": ("", "radio messages per step: consensus tuples (and uploads for centralized)"),
    "decision_time_ms": (
        "ms",
        "wall time per cycle of one UAV's own planning and assignment (distributed, greedy) "
        "or of the central node's for the whole team (centralized); measured only when a "
        "trial runs alone, never inside a batch, where numpy's per-call cost is shared",
    ),
}
"""Per-trial metrics: name -> (unit, meaning)."""


@dataclass
class Tally:
    """Running sums over the steps of a batch of B trials (Nu UAVs, Nt targets).

    NEES is computed in blocks of steps covering about 4000 filters: few numpy calls,
    and the block stays in cache. Decision times are kept only when `timed` (one trial
    alone); otherwise they are NaN.
    """

    batch: int
    n_uavs: int
    n_targets: int
    timed: bool = False
    steps: int = 0
    observed: np.ndarray = field(init=False)
    sums: dict[str, np.ndarray] = field(init=False)
    _pending: list = field(init=False, repr=False)
    _block: int = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.observed = np.zeros((self.batch, self.n_targets))
        names = ("squared_error", "squared_error_best", "nees", "nees_best", "rounds")
        self.sums = {name: np.zeros(self.batch) for name in names + ("messages", "decision")}
        self._pending = []
        self._block = int(np.clip(4096 // (self.batch * self.n_uavs * self.n_targets), 1, 64))

    def add(
        self,
        observed: np.ndarray,
        truth: np.ndarray,
        mean: np.ndarray,
        cov: np.ndarray,
        rounds: np.ndarray,
        messages: np.ndarray,
        decision_time: np.ndarray,
    ) -> None:
        """Add one step. observed (B, Nu, Nt); truth (B, Nt, 4); mean (B, Nu, Nt, 4);
        cov (B, Nu, Nt, 4, 4); rounds (B, Nu); messages (B,); decision_time (B, Nu) [s]."""
        self.steps += 1
        self.observed += observed.any(axis=1)
        err = mean[..., :2] - truth[:, None, :, :2]
        self.sums["squared_error"] += (err * err).sum(axis=(1, 2, 3))
        # the team's best estimate of each target: its most confident UAV (lowest on ties)
        best = np.argmax(confidence(cov), axis=1)[:, None, :]  # (B, 1, Nt)
        best_mean = np.take_along_axis(mean, best[..., None], axis=1)[:, 0]
        best_cov = np.take_along_axis(cov, best[..., None, None], axis=1)[:, 0]
        err = best_mean[..., :2] - truth[..., :2]
        self.sums["squared_error_best"] += (err * err).sum(axis=(1, 2))
        self._pending.append((mean, cov, best_mean, best_cov, truth))
        if len(self._pending) == self._block:
            self._flush()
        self.sums["rounds"] += rounds.mean(axis=1)
        self.sums["messages"] += messages
        self.sums["decision"] += decision_time.mean(axis=1)

    def _flush(self) -> None:
        if self._pending:
            mean, cov, best_mean, best_cov, truth = (
                np.stack(parts) for parts in zip(*self._pending, strict=True)
            )
            self.sums["nees"] += nees(mean, cov, truth[:, :, None]).sum(axis=(0, 2, 3))
            self.sums["nees_best"] += nees(best_mean, best_cov, truth).sum(axis=(0, 2))
            self._pending = []

    def per_target(self) -> np.ndarray:
        """Observation rate of each target, (B, Nt)."""
        return self.observed / self.steps

    def summary(self) -> dict[str, np.ndarray]:
        """Per-trial metrics of `METRICS`, each an array over the batch (per_target (B, Nt))."""
        self._flush()
        pairs = self.steps * self.n_uavs * self.n_targets
        targets = self.steps * self.n_targets
        per_target = self.per_target()
        s = self.sums
        decision = 1e3 * s["decision"] / self.steps if self.timed else np.full(self.batch, np.nan)
        return {
            "observation_rate": per_target.mean(axis=1),
            "per_target": per_target,
            "rmse": np.sqrt(s["squared_error"] / pairs),
            "rmse_best": np.sqrt(s["squared_error_best"] / targets),
            "nees": s["nees"] / pairs,
            "nees_best": s["nees_best"] / targets,
            "rounds": s["rounds"] / self.steps,
            "messages": s["messages"] / self.steps,
            "decision_time_ms": decision,
        }


def sorted_rates(per_target: np.ndarray) -> np.ndarray:
    """Each trial's target rates from lowest to highest (the paper's Fig. 6), (..., Nt)."""
    return np.sort(per_target, axis=-1)


def mean_std(values: np.ndarray, axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Mean and sample standard deviation (ddof = 1) over an axis, ignoring NaN.

    NaN marks a value that was not measured (a decision time inside a batch). With
    fewer than two values the standard deviation is undefined: NaN (null in JSON).
    """
    values = np.asarray(values, dtype=float)
    n = np.sum(~np.isnan(values), axis=axis)
    total = np.nansum(values, axis=axis)
    mean = np.where(n > 0, total / np.maximum(n, 1), np.nan)
    dev = np.where(np.isnan(values), 0.0, values - np.expand_dims(mean, axis))
    var = np.sum(dev * dev, axis=axis) / np.maximum(n - 1, 1)
    return mean, np.where(n > 1, np.sqrt(var), np.nan)
