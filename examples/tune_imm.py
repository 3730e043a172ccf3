"""The search behind the IMM's default modes (README, "manoeuvring targets, IMM filters").

    python examples/tune_imm.py            # about 4 minutes on 2 cores

Runs imm + covariance intersection, distributed, on 16 trials of each target motion
(trial seeds 0..15 of seed 0) for each candidate mode set, and prints the mean
observation rate, the team's best RMSE (mean and median over trials) and the mean NEES
of every UAV's estimate and of the team's best.
"""

from __future__ import annotations

import numpy as np
from joblib import Parallel, delayed

import uavtrack
from uavtrack.experiments.trackers import TRACKERS

STICKY = [[0.95, 0.04, 0.01], [0.10, 0.85, 0.05], [0.30, 0.30, 0.40]]
CANDIDATES = {
    "first guess: 1 and 5 m/s^2": {
        "tracker.manoeuvre_std": [1.0, 5.0],
        "tracker.transition": [[0.90, 0.08, 0.02], [0.15, 0.80, 0.05], [0.30, 0.30, 0.40]],
    },
    "0.5 and 2.0 m/s^2": {"tracker.manoeuvre_std": [0.5, 2.0], "tracker.transition": STICKY},
    "0.5 and 2.3 m/s^2 (the default)": {},
    "0.5 and 2.6 m/s^2": {"tracker.manoeuvre_std": [0.5, 2.6], "tracker.transition": STICKY},
    "turns at +-8 deg/s and 2.3 m/s^2": {
        k: v
        for k, v in TRACKERS["imm with turn modes + covariance_intersection"].items()
        if k.startswith("tracker.") and k != "tracker.model"
    },
}
TRIALS = 16


def one(name: str, overrides: dict, motion: str, trial: int) -> tuple:
    scenario = uavtrack.Scenario().with_overrides(
        {
            "target.motion": motion,
            "tracker.model": "imm",
            "fusion.rule": "covariance_intersection",
            **overrides,
        }
    )
    r = uavtrack.simulate(scenario, seed=uavtrack.trial_seed(0, trial), trace=False)
    return name, motion, r.observation_rate, r.rmse_best, r.nees, r.nees_best


def main() -> None:
    runs = Parallel(n_jobs=2)(
        delayed(one)(name, overrides, motion, t)
        for name, overrides in CANDIDATES.items()
        for motion in ("ncv", "manoeuvring")
        for t in range(TRIALS)
    )
    rows: dict[tuple, list] = {}
    for name, motion, *values in runs:
        rows.setdefault((name, motion), []).append(values)
    for (name, motion), values in rows.items():
        v = np.array(values)
        print(
            f"{name:34s} {motion:11s} rate {v[:, 0].mean():.3f}  RMSE best {v[:, 1].mean():5.2f} "
            f"(median {np.median(v[:, 1]):.2f})  NEES {v[:, 2].mean():.2f}  "
            f"NEES best {v[:, 3].mean():.2f}"
        )


if __name__ == "__main__":
    main()
