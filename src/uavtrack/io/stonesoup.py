"""A run in Stone Soup's types, for its metrics and plotters (stonesoup, a test
dependency; ``pip install stonesoup``).

Stone Soup orders a constant-velocity state (x, vx, y, vy); uavtrack's is (x, y, vx, vy):
the conversion reorders the states and covariances. Timestamps are `trace.EPOCH` (or
`start`) plus the step times k dt.

A run of tracks (``tracker.association`` gnn or jpda) gives tracks by team label, of
their confirmed states only (a tentative track is not yet an output of a tracker), and
its scans as Stone Soup's detections (`to_detections`).
"""

from __future__ import annotations

import datetime as _dt

import numpy as np

from ..errors import UsageError
from ..metrics import team_best
from ..records import Trace
from ..world import present, stays
from . import trace as trace_file
from .trace import EPOCH

ORDER = [0, 2, 1, 3]
"""uavtrack's (x, y, vx, vy) read in Stone Soup's order (x, vx, y, vy)."""

POSITION = (0, 2)
"""Where x and y lie in a Stone Soup state: the mapping its metrics measure on."""

__all__ = ["EPOCH", "ORDER", "POSITION", "to_detections", "to_stonesoup"]


def to_stonesoup(
    source, dt: float | None = None, tracks: str = "best", start: _dt.datetime = EPOCH
):
    """A trial's truth and estimates in Stone Soup's types, in one call: `source` is a
    trace file's path, a `Result` with a trace, a `TraceFile`, or a bare `Trace` with its
    step `dt` [s].

    Returns (truths, tracks) as sets: the true targets as `GroundTruthPath`s (id
    ``target-j``; with targets that come and go, ``target.stay``, one per stay, the n-th
    to take place j after the first ``target-j-n``) and the estimates as `Track`s of
    `GaussianState`s (Stone Soup's state order, x, vx, y, vy), with ``metadata`` saying
    whose they are:

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

    With unknown association (a trace with labels) the tracks are those of the team's
    labels, confirmed states only:

    * ``tracks="best"``: one track per team label ever confirmed (id ``label-L``,
      metadata ``{"label": L}``): at each step the confirmed estimate of the most
      confident living UAV that holds the label (1/trace P), absent at steps where none
      holds it confirmed.
    * ``tracks="uavs"``: one track per UAV and label it confirmed (id ``uav-i-label-L``,
      metadata ``{"uav": i, "label": L}``), its confirmed states while the UAV lives.
      uavtrack's ``gospa`` scores each UAV's confirmed tracks alone against the truths at
      each step, averages over the steps the UAV lives, then over the UAVs: split the set
      by ``track.metadata["uav"]`` and Stone Soup's ``GOSPAMetric`` (same c and p, alpha 2,
      no switching penalty, measured on `POSITION`) gives it again.
    """
    try:
        from stonesoup.types.state import GaussianState
        from stonesoup.types.track import Track
    except ImportError as exc:
        raise ImportError(f"to_stonesoup needs stonesoup: pip install stonesoup ({exc})") from None

    if tracks not in ("best", "uavs"):
        raise UsageError(f"tracks must be 'best' or 'uavs', got {tracks!r}")
    trace, dt = _trace_and_dt(source, dt, "to_stonesoup")
    T, Nt = trace.targets.shape[:2]
    times = [start + _dt.timedelta(seconds=k * dt) for k in range(T)]
    truths = _truths(trace, times)

    def gaussian(mean, cov, k):
        return GaussianState(mean[ORDER], cov[np.ix_(ORDER, ORDER)], timestamp=times[k])

    if trace.label is not None:
        return truths, _labelled(trace, tracks, gaussian, Track)
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


def _truths(trace: Trace, times: list[_dt.datetime]) -> set:
    """The true targets as `GroundTruthPath`s, id ``target-j``. With targets that come
    and go (``target.stay``, NaN while away), each stay in place j is its own path, the
    first ``target-j``, the n-th after it ``target-j-n``."""
    from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState

    truths = set()
    T = len(times)
    here = present(trace.targets[:T])  # (T, Nt)
    stay = stays(trace.targets)[:T]
    for j in range(trace.targets.shape[1]):
        for n in np.unique(stay[here[:, j], j]):
            steps = np.flatnonzero(here[:, j] & (stay[:, j] == n))
            states = [
                GroundTruthState(trace.targets[k, j, ORDER], timestamp=times[k]) for k in steps
            ]
            truths.add(GroundTruthPath(states, id=_path_id(j, n)))
    return truths


def _path_id(target: int, stay: int) -> str:
    """The id of a target's `GroundTruthPath`: ``target-j``, ``target-j-n`` for the n-th
    target to take place j after the first."""
    return f"target-{target}" + (f"-{stay}" if stay else "")


def _labelled(trace: Trace, tracks: str, gaussian, Track) -> set:
    """The confirmed tracks of a run of tracks by team label (see `to_stonesoup`)."""
    confirmed = (trace.status == 2) & trace.alive[..., None]  # (T, Nu, K)
    states: dict[tuple[int, ...], list] = {}
    if tracks == "uavs":
        for k, i, s in zip(*np.nonzero(confirmed), strict=True):
            key = (int(i), int(trace.label[k, i, s]))
            states.setdefault(key, []).append(gaussian(trace.mean[k, i, s], trace.cov[k, i, s], k))
        return {
            Track(found, id=f"uav-{i}-label-{label}", init_metadata={"uav": i, "label": label})
            for (i, label), found in states.items()
        }
    spread = np.trace(trace.cov, axis1=-2, axis2=-1)  # 1/confidence
    for k in range(trace.targets.shape[0]):
        best: dict[int, tuple[float, int, int]] = {}
        for i, s in zip(*np.nonzero(confirmed[k]), strict=True):
            label = int(trace.label[k, i, s])
            if label not in best or spread[k, i, s] < best[label][0]:
                best[label] = (float(spread[k, i, s]), int(i), int(s))
        for label, (_, i, s) in best.items():
            states.setdefault((label,), []).append(
                gaussian(trace.mean[k, i, s], trace.cov[k, i, s], k)
            )
    return {
        Track(found, id=f"label-{label}", init_metadata={"label": label})
        for (label,), found in states.items()
    }


def to_detections(
    source, dt: float | None = None, start: _dt.datetime = EPOCH, truths: set | None = None
) -> list[tuple[_dt.datetime, set]]:
    """A run of tracks' scans as Stone Soup's detections, as a detector yields them: a
    (timestamp, detections) pair per step. `source` as `to_stonesoup`'s.

    Each measurement is a `TrueDetection` of its target's `GroundTruthPath` (those of
    `truths`, from `to_stonesoup`, when given, so that they are the same objects; else
    new ones) or a `Clutter`, whose state vector is its ground position (x, y) [m];
    ``metadata`` holds the UAV (``uav``), the measured ``range`` [m] and ``bearing``
    [rad], and for evaluation the ``origin`` (target index, -1 clutter). No measurement
    model is attached: the conversion's covariance R depends on where the UAV believed it
    was, which the trace does not keep."""
    try:
        from stonesoup.types.detection import Clutter, TrueDetection
    except ImportError as exc:
        raise ImportError(f"to_detections needs stonesoup: pip install stonesoup ({exc})") from None

    trace, dt = _trace_and_dt(source, dt, "to_detections")
    if trace.label is None:
        raise UsageError(
            "to_detections reads the scans of a run of tracks (tracker.association gnn or "
            "jpda); this trace has none"
        )
    T = trace.targets.shape[0]
    times = [start + _dt.timedelta(seconds=k * dt) for k in range(T)]
    paths = {path.id: path for path in (truths if truths is not None else _truths(trace, times))}
    stay = stays(trace.targets)  # (T, Nt): which stay of its place each target is on
    out = []
    for k in range(T):
        found = set()
        for i, z in zip(*np.nonzero(trace.scan_valid[k]), strict=True):
            origin = int(trace.scan_origin[k, i, z])
            r, bearing = (float(v) for v in trace.scan_polar[k, i, z])
            meta = {"uav": int(i), "range": r, "bearing": bearing, "origin": origin}
            vector = trace.scan_z[k, i, z].reshape(2, 1)
            if origin >= 0:
                found.add(
                    TrueDetection(
                        vector, groundtruth_path=paths[_path_id(origin, stay[k, origin])],
                        timestamp=times[k], metadata=meta,
                    )
                )  # fmt: skip
            else:
                found.add(Clutter(vector, timestamp=times[k], metadata=meta))
        out.append((times[k], found))
    return out


def _trace_and_dt(source, dt: float | None, caller: str) -> tuple[Trace, float]:
    """The trace and its step [s]: a bare `Trace` with the dt given, or a saved run
    (a path or a result), which holds its own."""
    if isinstance(source, Trace):
        if dt is None:
            raise UsageError(f"a bare Trace needs its step dt: {caller}(trace, dt)")
        return source, dt
    if dt is not None:
        raise UsageError("dt goes with a bare Trace; this source has its own")
    saved = trace_file.load(source)
    return saved.trace, saved.dt
