"""The search that chose the default time step and altitude (README, "Calibration").

Only parameters the paper does not give are varied; the score is the distance of the
three methods' mean observation rates from the paper's Fig. 5. Takes a few minutes on
two cores.

    python examples/calibrate_defaults.py
"""

import itertools
import json

from joblib import Parallel, delayed

import uavtrack
from uavtrack.experiments.jobs import trials

PAPER = {"distributed": 0.8031, "centralized": 0.8048, "greedy": 0.6664}
BASE = {"dt": 1.0, "uav.altitude": 500.0}  # the first guess


def score(overrides, n_trials):
    scenario = uavtrack.Scenario().with_overrides(overrides)
    means = {m: float(trials(scenario, m, n_trials)["observation_rate"].mean()) for m in PAPER}
    distance = sum((means[m] - PAPER[m]) ** 2 for m in PAPER) ** 0.5
    return distance, overrides, means


def search(grid, n_trials):
    rows = Parallel(n_jobs=-1)(delayed(score)(g, n_trials) for g in grid)
    for distance, overrides, means in sorted(rows, key=lambda r: r[0]):
        shown = "  ".join(f"{m[:4]} {v:.3f}" for m, v in means.items())
        print(f"{distance:.3f}  {json.dumps(overrides):80s} {shown}")
    print()


if __name__ == "__main__":
    print("one factor at a time around the first guess, 30 trials")
    factors = {
        "field_size": [100, 150, 250, 300],
        "target.initial_velocity_std": [0.0, 0.5, 2.0],
        "uav.bank_angle_deg": [30, 60],
        "uav.altitude": [350, 700],
        "dt": [0.5, 2.0],
        "planner.horizon": [2, 4],
        "uav.start_spread": [0, 100],
        "uav.altitude_spacing": [0, 10],
    }
    search([BASE] + [{**BASE, k: v} for k, vs in factors.items() for v in vs], 30)
    print("grid, 30 trials")
    keys = ["dt", "target.initial_velocity_std", "uav.altitude", "field_size"]
    search(
        [
            dict(zip(keys, v, strict=True))
            for v in itertools.product([0.5, 0.75], [1.0, 2.0, 3.0], [400, 500], [200, 300])
        ],
        30,
    )
    print("refinement, 50 trials")
    keys = ["dt", "target.initial_velocity_std", "uav.altitude"]
    search(
        [
            dict(zip(keys, v, strict=True))
            for v in itertools.product([0.5], [1.0, 1.5], [425, 450, 475])
        ],
        50,
    )
