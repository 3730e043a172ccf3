"""Monte Carlo experiments: many trials of a scenario per method.

Trial t of an experiment seeded with s uses `trial_seed(s, t)`, whatever the method,
so every method sees the same targets and noise in a trial (common random numbers)
and differences between methods are paired.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from .config import Scenario
from .metrics import mean_std
from .simulation import run, trial_seed


def trials(
    scenario: Scenario, method: str, n_trials: int, seed: int = 0, first: int = 0
) -> dict[str, np.ndarray]:
    """Per-trial metrics of trials first .. first+n_trials-1, run as one batch."""
    seeds = [trial_seed(seed, t) for t in range(first, first + n_trials)]
    return run(scenario, method, seeds).metrics


def compare(
    scenario: Scenario, methods: Iterable[str], n_trials: int, seed: int = 0
) -> dict[str, dict[str, np.ndarray]]:
    """Per-trial metrics of each method on the same trials."""
    return {m: trials(scenario, m, n_trials, seed) for m in methods}


def summarize(metrics: dict[str, np.ndarray]) -> dict[str, object]:
    """Mean and standard deviation over trials of each metric (JSON-ready)."""
    out: dict[str, object] = {"trials": int(len(metrics["observation_rate"]))}
    for name, values in metrics.items():
        mean, std = mean_std(values)
        out[name] = {"mean": np.asarray(mean).tolist(), "std": np.asarray(std).tolist()}
    return out
