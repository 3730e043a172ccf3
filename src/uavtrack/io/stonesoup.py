"""A run in Stone Soup's types, for its metrics and plotters (stonesoup, a test
dependency; ``pip install stonesoup``).

Stone Soup orders a constant-velocity state (x, vx, y, vy); uavtrack's is (x, y, vx, vy):
the conversion reorders the states and covariances. Timestamps are `start` plus the
step times k dt.
"""

from __future__ import annotations

import datetime as _dt

import numpy as np

from ..errors import UsageError
from ..metrics import team_best

ORDER = [0, 2, 1, 3]
"""uavtrack's (x, y, vx, vy) read in Stone Soup's order (x, vx, y, vy)."""

POSITION = (0, 2)
"""Where x and y lie in a Stone Soup state: the mapping its metrics measure on."""

EPOCH = _dt.datetime(2000, 1, 1)


def to_stonesoup(trace, dt: float, tracks: str = "best", start: _dt.datetime = EPOCH):
    """The true targets as `GroundTruthPath`s (id ``target-j``) and the estimates as
    `Track`s of `GaussianState`s: ``tracks="best"`` one per target from the team's best
    estimate (id ``best-j``; the metrics' ``*_best``), ``"uavs"`` one per UAV and target
    from its fused estimate (id ``uav-i-target-j``; steps after the UAV fails left out).
    Returns (truths, tracks) as sets."""
    try:
        from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
        from stonesoup.types.state import GaussianState
        from stonesoup.types.track import Track
    except ImportError as exc:
        raise ImportError(f"to_stonesoup needs stonesoup: pip install stonesoup ({exc})") from None

    if tracks not in ("best", "uavs"):
        raise UsageError(f"tracks must be 'best' or 'uavs', got {tracks!r}")
    T, Nt = trace.targets.shape[:2]
    times = [start + _dt.timedelta(seconds=k * dt) for k in range(T)]
    truths = set()
    for j in range(Nt):
        states = [
            GroundTruthState(trace.targets[k, j, ORDER], timestamp=times[k]) for k in range(T)
        ]
        truths.add(GroundTruthPath(states, id=f"target-{j}"))

    def gaussian(mean, cov, k):
        return GaussianState(mean[ORDER], cov[np.ix_(ORDER, ORDER)], timestamp=times[k])

    out = set()
    if tracks == "best":
        best = team_best(trace.mean, trace.cov, trace.alive)[0]
        for j in range(Nt):
            states = [
                gaussian(trace.mean[k, best[k, j], j], trace.cov[k, best[k, j], j], k)
                for k in range(T)
                if best[k, j] >= 0
            ]
            out.add(Track(states, id=f"best-{j}"))
    else:
        for i in range(trace.uavs.shape[1]):
            for j in range(Nt):
                states = [
                    gaussian(trace.mean[k, i, j], trace.cov[k, i, j], k)
                    for k in range(T)
                    if trace.alive[k, i]
                ]
                out.add(Track(states, id=f"uav-{i}-target-{j}"))
    return truths, out
