"""The trace file of ``uavtrack run --trace`` and ``swarm --trace`` (.npz).

A compressed NumPy archive (read it with ``numpy.load``; no pickles) holding every array
of `records.Trace` under its field's name, and what made them: ``scenario`` (the
scenario as JSON text; `Scenario.from_dict(json.loads(...))` reads it back), ``method``,
``seed`` (absent when the trial had none), ``dt`` [s], ``uavtrack`` (the version that
wrote it) and ``format`` (the trace format, `FORMAT`). A failed UAV's rows of ``mean``,
``cov`` and ``bids`` are NaN from the step it fails.

Which files are read: the format number, not the uavtrack version, decides. A file of
this format or of format 1 (or one without a ``format`` entry, written before the number
was stamped, whose layout is format 1) is read whatever uavtrack version wrote it; when
that version differs from the running one, `read` says so with a `TraceVersionWarning`
(the command line prints it as a note). Format 1 has no ``late`` (messages that missed
their cycle, counted from format 2): it is read as zeros, as those versions counted none.
A trace of tracks older than format 4 has no ``existence``: it is read as None.
A file of a newer format is refused, naming both versions.
"""

from __future__ import annotations

import datetime
import json
import os
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from .._files import write_npz
from ..config import Scenario, ScenarioError
from ..errors import UsageError
from ..records import RECORDED, TRACKED, Result, Trace

FORMAT = 4
"""The trace format this uavtrack writes and reads. It changes only when an array is
added, removed or changes meaning; uavtrack versions that write the same format read
each other's traces. Format 2 added ``late``, format 3 ``bytes`` and ``node_bytes``,
format 4 ``existence`` (with tracks; an older trace of tracks has none)."""

ADDED = {"late": 2, "bytes": 3, "node_bytes": 3}
"""Arrays added after format 1, with the format that added them: a file of an older
format is read with them at zero (nothing of theirs was counted then)."""

EPOCH = datetime.datetime(2000, 1, 1)
"""Where a trace's simulated clock starts when a format wants a date (netCDF's CF time
axis, Stone Soup's timestamps): step k is at EPOCH + k dt."""

META = ("scenario", "method", "seed", "dt", "uavtrack", "format")
"""The entries of a trace file beside the trace's arrays."""


class TraceVersionWarning(UserWarning):
    """A trace of this format written by another uavtrack version (read as it is)."""


@dataclass(frozen=True, kw_only=True)
class TraceFile:
    """A trace read back with what made it; `version` is the uavtrack version that
    wrote it ("unknown" for a file that does not say)."""

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
    arrays["format"] = np.array(FORMAT)
    if result.seed is not None:
        arrays["seed"] = np.array(int(result.seed))
    write_npz(path, arrays)


def read(path: str | os.PathLike[str]) -> TraceFile:
    """A trace file written by `write`; a one-line UsageError for anything else (see the
    module's documentation for which versions are read)."""
    path = Path(path).expanduser()
    if not path.is_file():
        raise UsageError(f"{path}: no such trace file")
    if not zipfile.is_zipfile(path):
        raise UsageError(f"{path}: not a uavtrack trace file (not a NumPy .npz archive)")
    try:
        with np.load(path, allow_pickle=False) as data:
            headers = _headers(path, data.zip)
            arrays = {name: data[name] for name in headers if name in META}
            scenario = _check_headers(path, headers, arrays)
            arrays.update({name: data[name] for name in headers if name not in META})
    except UsageError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise UsageError(f"{path}: not a uavtrack trace file ({exc})") from None
    version = str(arrays["uavtrack"]) if "uavtrack" in arrays else "unknown"
    written = _check_format(path, arrays.get("format"), version)
    names = ["targets"] + [f.name for f in RECORDED]
    later = [f for f in RECORDED if ADDED.get(f.name, 0) > written and f.name not in arrays]
    missing = [n for n in names + ["scenario", "method"] if n not in arrays]
    missing = [n for n in missing if n not in {f.name for f in later}]
    if missing:
        older = " (written before traces carried their scenario: run it again)"
        hint = older if "scenario" in missing and len(missing) <= 2 else ""
        raise UsageError(f"{path}: not a uavtrack trace file, missing {', '.join(missing)}{hint}")
    assert scenario is not None  # read from the headers' metadata: nothing is missing
    if later:  # arrays of a later format, not counted when the file was written
        sizes = _sizes(scenario)
        steps = arrays["targets"].shape[0] if arrays["targets"].ndim else 0
        for f in later:
            arrays[f.name] = np.zeros(_shape(f, sizes, steps), f.metadata["dtype"])
    _check_shapes(path, arrays, scenario)
    if version != __version__:
        writer = "an unknown uavtrack version" if version == "unknown" else f"uavtrack {version}"
        warnings.warn(
            f"{path} was written by {writer}; uavtrack {__version__} reads it as trace "
            f"format {written}",
            TraceVersionWarning,
            stacklevel=2,
        )
    trace = Trace(**{n: arrays[n] for n in names}, **{n: arrays[n] for n in TRACKED if n in arrays})
    seed = int(arrays["seed"]) if "seed" in arrays else None
    return TraceFile(
        trace=trace, scenario=scenario, method=str(arrays["method"]), seed=seed, version=version
    )


META_CHARS = 1 << 20
"""The longest text a trace's metadata may hold (its scenario's JSON takes a few KiB)."""


def _headers(path: Path, archive: zipfile.ZipFile) -> dict[str, tuple[np.dtype, tuple[int, ...]]]:
    """Each array's dtype and shape, read from its .npy header in the archive without
    reading its data; an entry that is not a trace's array, or whose bytes are not what
    its header declares, is refused."""
    known = {"targets", *META, *(f.name for f in RECORDED), *TRACKED}
    out = {}
    for info in archive.infolist():
        name = info.filename.removesuffix(".npy")
        if name not in known or not info.filename.endswith(".npy"):
            raise UsageError(f"{path}: not a uavtrack trace file (unknown array {name[:60]!r})")
        with archive.open(info) as file:
            major, _ = np.lib.format.read_magic(file)
            read_header = (
                np.lib.format.read_array_header_1_0
                if major == 1
                else np.lib.format.read_array_header_2_0
            )
            shape, fortran, dtype = read_header(file, max_header_size=10_000)
            start = file.tell()
        if dtype.hasobject:
            raise UsageError(f"{path}: {name} holds Python objects, not numbers")
        size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        if info.file_size != start + size:
            raise UsageError(
                f"{path}: not a uavtrack trace file ({name} holds {info.file_size - start} "
                f"bytes where its header declares {size})"
            )
        out[name] = (dtype, tuple(shape))
    return out


def _check_headers(
    path: Path, headers: dict[str, tuple[np.dtype, tuple[int, ...]]], meta: dict[str, np.ndarray]
) -> Scenario | None:
    """Refuse, before any array's data is read, metadata that is not short text or one
    number, and arrays larger than the scenario's team and steps allow. Returns the
    scenario (None when the scenario or the targets are missing: `read` names them)."""
    for name in META:
        if name in headers:
            dtype, shape = headers[name]
            text = dtype.kind == "U" and dtype.itemsize // 4 <= META_CHARS
            if shape != () or not (text or dtype.kind in "iuf"):
                raise UsageError(f"{path}: not a uavtrack trace file ({name} is not metadata)")
    if "scenario" not in meta or "targets" not in headers:
        return None  # `read` names what is missing
    try:
        scenario = Scenario.from_dict(json.loads(str(meta["scenario"])), origin=str(path))
    except RecursionError:
        raise UsageError(f"{path}: its scenario cannot be read (nested too deeply)") from None
    except (json.JSONDecodeError, ScenarioError) as exc:
        raise UsageError(f"{path}: its scenario cannot be read ({exc})") from None
    steps = headers["targets"][1][0] if headers["targets"][1] else 0
    if steps > scenario.steps:
        raise UsageError(
            f"{path}: its arrays disagree: targets has {steps} steps, its scenario {scenario.steps}"
        )
    sizes = _sizes(scenario)
    expected: dict[str, tuple[int, ...]] = {"targets": (steps, scenario.n_targets, 4)}
    expected.update({f.name: _shape(f, sizes, steps) for f in RECORDED})
    scans = scenario.n_targets + 50 + 10 * int(np.ceil(scenario.sensor.clutter_rate))
    for name, (dtype, shape) in headers.items():
        if name in META:
            continue
        if not (np.issubdtype(dtype, np.number) or dtype.kind == "b"):
            raise UsageError(f"{path}: {name} holds {dtype}, not numbers")
        if name in TRACKED:  # (T, Nu, K) or (T, Nu, Z, ...) with Z at most a scan's
            lead, width = shape[:2], shape[2] if len(shape) > 2 else 0
            most = sizes["K"] if name in ("label", "status", "existence") else scans
            if lead != (steps, scenario.n_uavs) or width > most:
                raise UsageError(
                    f"{path}: its arrays disagree: {name} is {shape}, beyond its scenario's "
                    f"{steps} steps of {scenario.n_uavs} UAVs and {most} per UAV"
                )
        elif shape != expected[name]:
            raise UsageError(
                f"{path}: its arrays disagree: {name} is {shape}, where its scenario "
                f"({scenario.n_uavs} UAVs, {scenario.n_targets} targets) and the {steps} "
                f"steps of targets give {expected[name]}"
            )
    return scenario


def _check_format(path: Path, entry: np.ndarray | None, version: str) -> int:
    """The file's format, or refuse one this version cannot read; no entry is format 1."""
    if entry is None:
        return 1
    try:
        number = int(entry)
    except (TypeError, ValueError):
        number = None
    if number is not None and 1 <= number <= FORMAT:
        return number
    if number is not None and number > FORMAT:
        raise UsageError(
            f"{path}: trace format {number}, written by uavtrack {version}, is newer than "
            f"uavtrack {__version__} reads (format {FORMAT}); read it with uavtrack {version} "
            "or later"
        )
    raise UsageError(
        f"{path}: unknown trace format {entry!s} (written by uavtrack {version}); uavtrack "
        f"{__version__} reads format {FORMAT}"
    )


def _check_shapes(path: Path, arrays: dict[str, np.ndarray], scenario: Scenario) -> None:
    """Every array has the shape `Cycle` declares for the scenario's team over the steps
    `targets` holds, and numbers in it: a file whose arrays disagree is refused."""
    sizes = _sizes(scenario)
    targets = arrays["targets"]
    steps = targets.shape[0] if targets.ndim else 0
    expected: dict[str, tuple[int, ...]] = {"targets": (steps, scenario.n_targets, 4)}
    for f in RECORDED:
        expected[f.name] = _shape(f, sizes, steps)
    for name, shape in expected.items():
        array = arrays[name]
        if array.shape != shape:
            raise UsageError(
                f"{path}: its arrays disagree: {name} is {array.shape}, where its scenario "
                f"({scenario.n_uavs} UAVs, {scenario.n_targets} targets) and the {steps} "
                f"steps of targets give {shape}"
            )
        if not (np.issubdtype(array.dtype, np.number) or array.dtype == bool):
            raise UsageError(f"{path}: {name} holds {array.dtype}, not numbers")


def _sizes(scenario: Scenario) -> dict[str, int]:
    """The sizes a trace's shapes name: Nu UAVs, Nt targets, K track slots (the targets
    with known association, `Scenario.track_slots` with gnn or jpda)."""
    known = not scenario.tracker.unlabelled
    return {
        "Nu": scenario.n_uavs,
        "Nt": scenario.n_targets,
        "K": scenario.n_targets if known else scenario.track_slots,
    }


def _shape(f, sizes: dict[str, int], steps: int) -> tuple[int, ...]:
    """The shape `Cycle` declares for field `f` over `steps` steps, its team's sizes
    (``Nu``, ``Nt``, ``K``) from `sizes`."""
    dims = [d.strip() for d in f.metadata["shape"].strip("()").split(",") if d.strip()]
    return (steps, *(sizes[d] if d in sizes else int(d) for d in dims))


def load(
    source: str | os.PathLike[str] | Result | TraceFile | Trace,
    scenario: Scenario | None = None,
    method: str | None = None,
    seed: int | None = None,
) -> TraceFile:
    """A trace with what made it, from a trace file's path, a `Result` with a trace
    (``simulate(..., trace=True)``), a `TraceFile` (returned as it is), or a bare `Trace`
    with the `scenario` it ran (and its method and seed, if known)."""
    if isinstance(source, Trace):
        if scenario is None:
            raise UsageError("a bare Trace needs its scenario: give the Result, or the scenario")
        return TraceFile(
            trace=source, scenario=scenario, method=method or "", seed=seed, version=__version__
        )
    if (scenario, method, seed) != (None, None, None):
        raise UsageError("scenario, method and seed go with a bare Trace; this source has its own")
    if isinstance(source, TraceFile):
        return source
    if isinstance(source, Result):
        if source.trace is None:
            raise UsageError("this result holds no trace: simulate(..., trace=True)")
        return TraceFile(
            trace=source.trace,
            scenario=source.scenario,
            method=source.method,
            seed=source.seed,
            version=__version__,
        )
    if isinstance(source, str | os.PathLike):
        return read(source)
    raise UsageError(
        f"expected a trace file's path, a Result, a TraceFile or a Trace, got "
        f"{type(source).__name__}"
    )
