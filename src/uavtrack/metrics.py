"""Performance measures (paper Sec. 7) accumulated step by step over a batch of trials.

* observation rate: for each target, the fraction of steps at which it is inside at
  least one UAV's observation disk; the overall rate is the mean over targets;
* position RMSE of the fused estimates (every UAV, every target, every step);
* NEES of the fused estimates, e^T P^-1 e over the 4-D state (4 when consistent);
* consensus rounds D_i and radio messages per step, decision time per UAV.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .estimation import nees


@dataclass
class Tally:
    """Running sums over the steps of a batch of B trials (Nu UAVs, Nt targets).

    NEES is computed in blocks of steps covering about 4000 filters: few numpy calls,
    and the block stays in cache.
    """

    batch: int
    n_uavs: int
    n_targets: int
    steps: int = 0
    observed: np.ndarray = field(init=False)
    squared_error: np.ndarray = field(init=False)
    nees: np.ndarray = field(init=False)
    rounds: np.ndarray = field(init=False)
    messages: np.ndarray = field(init=False)
    decision_time: np.ndarray = field(init=False)
    _pending: list = field(init=False, repr=False)
    _block: int = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.observed = np.zeros((self.batch, self.n_targets))
        self.squared_error = np.zeros(self.batch)
        self.nees = np.zeros(self.batch)
        self.rounds = np.zeros(self.batch)
        self.messages = np.zeros(self.batch)
        self.decision_time = np.zeros(self.batch)
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
        cov (B, Nu, Nt, 4, 4); rounds (B, Nu); messages (B,); decision_time (B, Nu)."""
        self.steps += 1
        self.observed += observed.any(axis=1)
        err = mean[..., :2] - truth[:, None, :, :2]
        self.squared_error += (err * err).sum(axis=(1, 2, 3))
        self._pending.append((mean, cov, truth))
        if len(self._pending) == self._block:
            self._flush()
        self.rounds += rounds.mean(axis=1)
        self.messages += messages
        self.decision_time += decision_time.mean(axis=1)

    def _flush(self) -> None:
        if self._pending:
            mean, cov, truth = (np.stack(parts) for parts in zip(*self._pending, strict=True))
            self.nees += nees(mean, cov, truth[:, :, None]).sum(axis=(0, 2, 3))
            self._pending = []

    def per_target(self) -> np.ndarray:
        """Observation rate of each target, (B, Nt)."""
        return self.observed / self.steps

    def summary(self) -> dict[str, np.ndarray]:
        """Per-trial metrics, each an array over the batch (per_target is (B, Nt))."""
        self._flush()
        pairs = self.steps * self.n_uavs * self.n_targets
        per_target = self.per_target()
        return {
            "observation_rate": per_target.mean(axis=1),
            "per_target": per_target,
            "rmse": np.sqrt(self.squared_error / pairs),
            "nees": self.nees / pairs,
            "rounds": self.rounds / self.steps,
            "messages": self.messages / self.steps,
            "decision_time": self.decision_time / self.steps,
        }


def sorted_rates(per_target: np.ndarray) -> np.ndarray:
    """Each trial's target rates from lowest to highest (the paper's Fig. 6), (..., Nt)."""
    return np.sort(per_target, axis=-1)


def mean_std(values: np.ndarray, axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Mean and sample standard deviation (ddof = 1, 0 for one value) over an axis."""
    values = np.asarray(values, dtype=float)
    n = values.shape[axis]
    std = values.std(axis=axis, ddof=1) if n > 1 else np.zeros_like(values.mean(axis=axis))
    return values.mean(axis=axis), std
