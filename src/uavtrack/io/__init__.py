"""Outside formats: the trace file (`trace`), tidy tables and xarray (`tables`, the io
extra), a results folder's job files (`results`), Stone Soup's types (`stonesoup`), ROS 2
bags and topics (`bag`, `ros2`), and the decision as MAVLink setpoints (`mavlink`); and
recorded scans in: a recording's tables or bag (`recording`, the io extra) and the cycle
run on it (`replay`).

Each conversion takes a trial in one call, as ``xarray.open_dataset`` takes a file: the
path of a trace file (``uavtrack run --trace run.npz``), a `Result` with a trace
(``simulate(..., trace=True)``) or a trace file already read (`trace.read`):

    import uavtrack.io
    ds = uavtrack.io.to_xarray("run.npz")              # a Dataset: step, uav, target
    frames = uavtrack.io.to_frames("run.npz")          # steps, uavs, targets, pairs
    truths, tracks = uavtrack.io.to_stonesoup("run.npz")   # Stone Soup's types
    scans = uavtrack.io.to_detections("run.npz")       # a run of tracks' detections
    saved = uavtrack.io.read("run.npz")                # the arrays, scenario, method, seed
    rec = uavtrack.io.read_recording("rec", scenario)   # recorded scans (uavtrack replay)

They are imported when first used, so ``import uavtrack.io`` needs no optional extra.
"""

from __future__ import annotations

from importlib import import_module

_WHERE = {
    "read": "trace",
    "to_xarray": "tables",
    "to_frames": "tables",
    "write_table": "tables",
    "results_frame": "tables",
    "to_stonesoup": "stonesoup",
    "to_detections": "stonesoup",
    "read_recording": "recording",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
