"""The trace file of ``uavtrack run --trace`` and ``swarm --trace`` (.npz).

A compressed NumPy archive (read it with ``numpy.load``; no pickles) holding every array
of `simulation.Trace` under its field's name, and what made them: ``scenario`` (the
scenario as JSON text; `Scenario.from_dict(json.loads(...))` reads it back), ``method``,
``seed`` (absent when the trial had none), ``dt`` [s] and ``uavtrack`` (the version). A
failed UAV's rows of ``mean``, ``cov`` and ``bids`` are NaN from the step it fails.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._version import __version__
from ..config import Scenario, ScenarioError
from ..errors import UsageError
from ..files import write_npz
from ..simulation import RECORDED, Result, Trace

META = ("scenario", "method", "seed", "dt", "uavtrack")
"""The entries of a trace file beside the trace's arrays."""


@dataclass(frozen=True)
class TraceFile:
    """A trace read back with what made it."""

    trace: Trace
    scenario: Scenario
    method: str
    seed: int | None
    version: str

    @property
    def dt(self) -> float:
        return self.scenario.dt


def write(path: str | Path, result: Result) -> None:
    """Write `result`'s trace and its metadata to `path`, atomically."""
    if result.trace is None:
        raise ValueError("this result holds no trace: simulate(..., trace=True)")
    arrays = dict(result.trace.arrays())
    arrays["scenario"] = np.array(json.dumps(result.scenario.to_dict(), sort_keys=True))
    arrays["method"] = np.array(result.method)
    arrays["dt"] = np.array(result.scenario.dt)
    arrays["uavtrack"] = np.array(__version__)
    if result.seed is not None:
        arrays["seed"] = np.array(int(result.seed))
    write_npz(path, arrays)


def read(path: str | Path) -> TraceFile:
    """A trace file written by `write`; a one-line UsageError for anything else."""
    path = Path(path).expanduser()
    if not path.is_file():
        raise UsageError(f"{path}: no such trace file")
    if not zipfile.is_zipfile(path):
        raise UsageError(f"{path}: not a uavtrack trace file (not a NumPy .npz archive)")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise UsageError(f"{path}: not a uavtrack trace file ({exc})") from None
    names = ["targets"] + [f.name for f in RECORDED]
    missing = [n for n in names + ["scenario", "method"] if n not in arrays]
    if missing:
        older = " (written before traces carried their scenario: run it again)"
        hint = older if "scenario" in missing and len(missing) <= 2 else ""
        raise UsageError(f"{path}: not a uavtrack trace file, missing {', '.join(missing)}{hint}")
    try:
        scenario = Scenario.from_dict(json.loads(str(arrays["scenario"])), origin=str(path))
    except (json.JSONDecodeError, ScenarioError) as exc:
        raise UsageError(f"{path}: its scenario cannot be read ({exc})") from None
    trace = Trace(**{n: arrays[n] for n in names})
    seed = int(arrays["seed"]) if "seed" in arrays else None
    version = str(arrays["uavtrack"]) if "uavtrack" in arrays else "unknown"
    return TraceFile(trace, scenario, str(arrays["method"]), seed, version)
