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
    "in_view_std": (
        "",
        "standard deviation over the steps of the fraction of targets in view, whose mean "
        "over the steps is the observation rate (one reading of the paper's σ, see README)",
    ),
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
    "rounds": ("", "consensus rounds per UAV and step (D_i, plus robust.extra_rounds)"),
    "messages": (
        "",
        "radio messages sent per step, all protocols: beacons, D_i flooding, consensus "
        "tuples and bids (distributed), flooding and tuples (greedy), uploads and "
        "downloads (centralized); one per link into a receiver that needs it",
    ),
    "delivered": ("", "radio messages per step that arrived (messages minus those lost)"),
    "conflicts": (
        "",
        "targets per step followed by two or more UAVs while another target has none",
    ),
    "failed": ("", "UAVs failed by the end of the trial (faults)"),
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
    """Running sums over the steps of a batch of B trials (Nu UAVs, Nt targets), fed
    one `simulation.Cycle` at a time.

    Failed UAVs count in nothing: their estimates leave the RMSE and NEES, their rounds
    the mean. NEES is computed in blocks of steps covering about 4000 filters: few
    numpy calls, and the block stays in cache. Decision times are kept only when
    `timed` (one trial alone); otherwise they are NaN.
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
        names = (
            "squared_error", "squared_error_best", "nees", "nees_best", "rounds", "messages",
            "delivered", "conflicts", "decision", "decided", "pairs", "best", "alive",
            "in_view_sq",
        )  # fmt: skip
        self.sums = {name: np.zeros(self.batch) for name in names}
        self.failed = np.zeros(self.batch)
        self._pending = []
        self._block = int(np.clip(4096 // (self.batch * self.n_uavs * self.n_targets), 1, 64))

    def add(self, cycle, truth: np.ndarray) -> None:
        """Add one step: a `simulation.Cycle` and the true targets (B, Nt, 4)."""
        s = self.sums
        self.steps += 1
        alive = cycle.alive
        everyone = bool(alive.all())
        mean, cov = cycle.mean, cycle.cov
        in_view = cycle.observed.any(axis=1)
        self.observed += in_view
        s["in_view_sq"] += np.square(in_view.mean(axis=1))
        err = mean[..., :2] - truth[:, None, :, :2]
        squared = err * err
        if not everyone:
            squared = np.where(alive[:, :, None, None], squared, 0.0)
        s["squared_error"] += squared.sum(axis=(1, 2, 3))
        s["pairs"] += alive.sum(axis=1) * self.n_targets
        # the team's best estimate of each target: its most confident UAV (lowest on ties)
        gamma = confidence(cov)
        if not everyone:
            gamma = np.where(alive[..., None], gamma, -np.inf)
        best = np.argmax(gamma, axis=1)  # (B, Nt)
        anyone = alive.any(axis=1)
        b, j = np.arange(best.shape[0])[:, None], np.arange(best.shape[1])
        best_mean, best_cov = mean[b, best, j], cov[b, best, j]
        err = best_mean[..., :2] - truth[..., :2]
        s["squared_error_best"] += np.where(anyone, (err * err).sum(axis=(1, 2)), 0.0)
        s["best"] += anyone * self.n_targets
        self._pending.append((mean, cov, best_mean, best_cov, truth, None if everyone else alive))
        if len(self._pending) == self._block:
            self._flush()
        if everyone:
            s["rounds"] += cycle.rounds.mean(axis=1)
        else:
            s["rounds"] += np.where(
                anyone, (cycle.rounds * alive).sum(axis=1) / np.maximum(alive.sum(axis=1), 1), 0
            )
        s["alive"] += anyone
        s["messages"] += cycle.messages
        s["delivered"] += cycle.delivered
        s["conflicts"] += cycle.conflicts
        decision = cycle.decision_time_ms
        if not everyone:  # only the living decide
            counted = np.isfinite(decision)
            decision = np.where(counted, decision, 0.0).sum(axis=1) / np.maximum(
                counted.sum(axis=1), 1
            )
            s["decided"] += counted.any(axis=1)
        else:
            decision = decision.mean(axis=1)
            s["decided"] += 1
        s["decision"] += decision
        self.failed = (~alive).sum(axis=1).astype(float)

    def _flush(self) -> None:
        if self._pending:
            masks = [p[5] for p in self._pending]
            mean, cov, best_mean, best_cov, truth = (  # one step: no copy
                parts[0][None] if len(parts) == 1 else np.stack(parts)
                for parts in list(zip(*self._pending, strict=True))[:5]
            )
            q = nees(mean, cov, truth[:, :, None])  # (S, B, Nu, Nt)
            if any(m is not None for m in masks):
                alive = np.stack(
                    [np.ones(q.shape[1:3], dtype=bool) if m is None else m for m in masks]
                )
                q = np.where(alive[..., None], q, 0.0)
                anyone = alive.any(axis=2)  # (S, B)
                best = np.where(anyone[..., None], nees(best_mean, best_cov, truth), 0.0)
            else:
                best = nees(best_mean, best_cov, truth)
            self.sums["nees"] += q.sum(axis=(0, 2, 3))
            self.sums["nees_best"] += best.sum(axis=(0, 2))
            self._pending = []

    def per_target(self) -> np.ndarray:
        """Observation rate of each target, (B, Nt)."""
        return self.observed / self.steps

    def summary(self) -> dict[str, np.ndarray]:
        """Per-trial metrics of `METRICS`, each an array over the batch (per_target (B, Nt))."""
        self._flush()
        per_target = self.per_target()
        s = self.sums
        # nothing to average (every UAV failed from the start): NaN, not a perfect score
        pairs = np.where(s["pairs"] > 0, s["pairs"], np.nan)
        targets = np.where(s["best"] > 0, s["best"], np.nan)
        decided = np.where(s["decided"] > 0, s["decided"], np.nan)
        decision = s["decision"] / decided if self.timed else np.full(self.batch, np.nan)
        return {
            "observation_rate": per_target.mean(axis=1),
            "per_target": per_target,
            "in_view_std": np.sqrt(
                np.maximum(s["in_view_sq"] / self.steps - per_target.mean(axis=1) ** 2, 0.0)
            ),
            "rmse": np.sqrt(s["squared_error"] / pairs),
            "rmse_best": np.sqrt(s["squared_error_best"] / targets),
            "nees": s["nees"] / pairs,
            "nees_best": s["nees_best"] / targets,
            "rounds": s["rounds"] / np.where(s["alive"] > 0, s["alive"], np.nan),
            "messages": s["messages"] / self.steps,
            "delivered": s["delivered"] / self.steps,
            "conflicts": s["conflicts"] / self.steps,
            "failed": self.failed,
            "decision_time_ms": decision,
        }


def rank_names(n: int) -> list[str]:
    """Names of the places of n sorted rates: lowest, 2nd lowest, ..., highest."""
    if n == 1:
        return ["only"]
    ordinal = {2: "2nd", 3: "3rd"}
    middle = [f"{ordinal.get(k, f'{k}th')} lowest" for k in range(2, n)]
    return ["lowest", *middle, "highest"]


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
