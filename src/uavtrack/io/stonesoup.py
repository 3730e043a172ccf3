"""A run in Stone Soup's types, for its metrics and plotters (stonesoup, a test
dependency; ``pip install stonesoup``).

Stone Soup orders a constant-velocity state (x, vx, y, vy); uavtrack's is (x, y, vx, vy):
the conversion reorders the states and covariances. Timestamps are `trace.EPOCH` (or
`start`) plus the step times k dt.
"""

from __future__ import annotations

import datetime as _dt

import numpy as np

from ..errors import UsageError
from ..metrics import team_best
from ..simulation import Trace
from . import trace as trace_file
from .trace import EPOCH

ORDER = [0, 2, 1, 3]
"""uavtrack's (x, y, vx, vy) read in Stone Soup's order (x, vx, y, vy)."""

POSITION = (0, 2)
"""Where x and y lie in a Stone Soup state: the mapping its metrics measure on."""

__all__ = ["EPOCH", "ORDER", "POSITION", "to_stonesoup"]


def to_stonesoup(
    source, dt: float | None = None, tracks: str = "best", start: _dt.datetime = EPOCH
):
    """A trial's truth and estimates in Stone Soup's types, in one call: `source` is a
    trace file's path, a `Result` with a trace, a `TraceFile`, or a bare `Trace` with its
    step `dt` [s].

    Returns (truths, tracks) as sets: the true targets as `GroundTruthPath`s (id
    ``target-j``) and the estimates as `Track`s of `GaussianState`s (Stone Soup's state
    order, x, vx, y, vy), with ``metadata`` saying whose they are:

    * ``tracks="best"``: one track per target from the team's best estimate (id
      ``best-j``, metadata ``{"target": j}``): at each step the estimate of the most
      confident living UAV (1/trace P), absent at steps where every UAV has failed.
      Stone Soup's OSPA and GOSPA on these tracks and the truths, per step, averaged over
      the steps, are uavtrack's ``ospa_best`` and ``gospa_best``.
    * ``tracks="uavs"``: one track per UAV and target from that UAV's fused estimate
      (id ``uav-i-target-j``, metadata ``{"uav": i, "target": j}``), with no state at
      the steps after the UAV fails. A UAV's estimates are one set: uavtrack's per-UAV
      ``ospa`` and ``gospa`` evaluate each UAV's Nt tracks alone against the truths at
      each step, and average over the living UAVs and the steps (compare every UAV's
      tracks at once and the Nu Nt estimates of Nt targets count as false tracks). Split
      the set by ``track.metadata["uav"]`` to reproduce them.
    """
    try:
        from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
        from stonesoup.types.state import GaussianState
        from stonesoup.types.track import Track
    except ImportError as exc:
        raise ImportError(f"to_stonesoup needs stonesoup: pip install stonesoup ({exc})") from None

    if tracks not in ("best", "uavs"):
        raise UsageError(f"tracks must be 'best' or 'uavs', got {tracks!r}")
    if isinstance(source, Trace):
        if dt is None:
            raise UsageError("a bare Trace needs its step dt: to_stonesoup(trace, dt)")
        trace = source
    else:
        if dt is not None:
            raise UsageError("dt goes with a bare Trace; this source has its own")
        saved = trace_file.load(source)
        trace, dt = saved.trace, saved.dt
        saved.scenario.refuse_tracks("to_stonesoup")
    if trace.label is not None:  # a bare Trace of tracks
        raise UsageError("to_stonesoup does not take a trace of tracks (gnn or jpda) yet")
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
            out.add(Track(states, id=f"best-{j}", init_metadata={"target": j}))
    else:
        for i in range(trace.uavs.shape[1]):
            for j in range(Nt):
                states = [
                    gaussian(trace.mean[k, i, j], trace.cov[k, i, j], k)
                    for k in range(T)
                    if trace.alive[k, i]
                ]
                out.add(
                    Track(states, id=f"uav-{i}-target-{j}", init_metadata={"uav": i, "target": j})
                )
    return truths, out
