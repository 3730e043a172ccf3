"""A run as tidy data: an xarray Dataset with named dimensions, tables for pandas, and a
results folder as one row per trial. Needs the io extra (xarray, pandas, pyarrow).

Tables (one row per ...):

* ``steps``: step: time [s], messages, delivered, conflicts, in_view (share of targets in
  some UAV's disk), alive_uavs (how many);
* ``uavs``: step and UAV: its true state (x, y, altitude [m], speed [m/s], heading
  [rad]), alive, assignment (-1: failed), bank_angle [rad], rounds, decision times [ms];
* ``targets``: step and target: its true state (x, y [m], vx, vy [m/s]), in_view (of
  some UAV), the team's best estimate (best_x ... best_vy, from best_uav, the most
  confident living UAV, 1/trace P; -1 and NaN when every UAV has failed);
* ``pairs``: step, UAV and target: in_view (of this UAV), bid, the UAV's fused estimate (est_x ...
  est_vy) and the 10 entries of its covariance's upper triangle (P_x_x, P_x_y, ...).

A failed UAV's estimate, covariance and bid are NaN from the step it fails (its state
stays where it fell). Units travel with the data: a frame's ``attrs["units"]``, a
Parquet field's metadata (``unit``), a netCDF variable's ``units`` (see `unit`).
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import install_hint

try:
    import pandas as pd
    import xarray as xr
except ImportError as exc:  # an optional extra
    raise ImportError(
        f"uavtrack.io.tables needs xarray and pandas: {install_hint('io')} ({exc})"
    ) from None

from ..config import Scenario, ScenarioError
from ..errors import UsageError
from ..metrics import METRICS, team_best
from ..simulation import Cycle, Trace
from . import trace as trace_file

UAV_STATE = ("x", "y", "altitude", "speed", "heading")
TARGET_STATE = ("x", "y", "vx", "vy")
UNITS = {"x": "m", "y": "m", "altitude": "m", "speed": "m/s", "heading": "rad", "vx": "m/s",
         "vy": "m/s", "time": "s", "bank_angle": "rad", "decision_time_ms": "ms",
         "decision_wall_ms": "ms"}  # fmt: skip
"""The unit of every table column that has one (estimates and covariance entries: see
`unit`); netCDF variables and Parquet fields carry the same strings (UDUNITS syntax)."""
TABLES = ("steps", "uavs", "targets", "pairs")


def unit(column: str) -> str | None:
    """A table column's unit, or None for counts, flags and indices: ``est_vx`` -> m/s,
    ``P_x_vy`` -> m^2/s (a covariance entry's unit is the product of its states')."""
    if column.startswith("P_"):
        velocities = sum(UNITS[name] == "m/s" for name in column[2:].split("_") if name)
        return ("m^2", "m^2/s", "m^2/s^2")[velocities]
    for prefix in ("est_", "best_"):
        if column.startswith(prefix) and column[len(prefix) :] in TARGET_STATE:
            return UNITS[column[len(prefix) :]]
    return UNITS.get(column)


def _docs() -> dict[str, str]:
    return {f.name: f.metadata["doc"] for f in Cycle.__dataclass_fields__.values() if f.metadata}


def to_xarray(
    source, scenario: Scenario | None = None, method: str | None = None, seed: int | None = None
) -> xr.Dataset:
    """A trial as a Dataset, in one call, as ``xarray.open_dataset`` reads a file:
    `source` is a trace file's path (``uavtrack run --trace``), a `Result` with a trace,
    a `TraceFile`, or a bare `Trace` with its `scenario` (method and seed optional).

    Dimensions step, uav, target (and state, state_ for the estimates and covariances);
    coordinates step, time, uav, target. ``time`` is the CF time axis (standard_name
    time): on disk seconds since `trace.EPOCH` (2000-01-01), so xarray decodes it to
    datetimes, step k at EPOCH + k dt. Every variable has a long_name and, where it has
    one, its units (UDUNITS; the estimates' and covariances' units, which differ by
    state, are in their comment). Attributes: dt [s], method, seed, scenario (JSON) and
    uavtrack, the version that ran the trial."""
    saved = trace_file.load(source, scenario, method, seed)
    trace, scenario = saved.trace, saved.scenario
    scenario.refuse_tracks("the tables")
    T, Nu = trace.uavs.shape[:2]
    Nt = trace.targets.shape[1]
    docs = _docs()
    step = ("step",)
    su, st, sut = ("step", "uav"), ("step", "target"), ("step", "uav", "target")
    variables: dict[str, Any] = {}
    for i, name in enumerate(TARGET_STATE):
        variables[f"target_{name}"] = (
            st,
            trace.targets[..., i],
            _attrs(f"true target {name}", name),
        )
    for i, name in enumerate(UAV_STATE):
        variables[f"uav_{name}"] = (su, trace.uavs[..., i], _attrs(f"true UAV {name}", name))
    variables["uav_altitude"][2]["standard_name"] = "height"  # above the flat ground
    variables["observed"] = (sut, trace.observed, {"long_name": docs["observed"]})
    variables["estimate"] = (
        sut + ("state",), trace.mean,
        {"long_name": docs["mean"], "comment": "units by state: x, y in m; vx, vy in m/s"},
    )  # fmt: skip
    variables["covariance"] = (
        sut + ("state", "state_"), trace.cov,
        {"long_name": docs["cov"], "comment": "units: the product of its two states' units "
         "(m^2, m^2/s, m^2/s^2)"},
    )  # fmt: skip
    variables["bid"] = (sut, trace.bids, {"long_name": docs["bids"]})
    for name, dims in (("assignment", su), ("rounds", su), ("alive", su),
                       ("decision_time_ms", su), ("decision_wall_ms", su)):  # fmt: skip
        units = {"units": UNITS[name]} if name in UNITS else {}
        variables[name] = (dims, getattr(trace, name), {"long_name": docs[name], **units})
    variables["bank_angle"] = (
        su, trace.action, {"long_name": docs["action"], "units": UNITS["bank_angle"]}
    )  # fmt: skip
    for name in ("messages", "delivered", "conflicts"):
        variables[name] = (step, getattr(trace, name), {"long_name": docs[name]})
    attrs = {
        "title": "a uavtrack trial, step by step",
        "source": f"uavtrack {saved.version}",
        "dt": scenario.dt,
        "method": saved.method,
        "scenario": json.dumps(scenario.to_dict(), sort_keys=True),
        "uavtrack": saved.version,
        "missing": "a failed UAV's estimate, covariance and bid are NaN from its failure",
    }
    if saved.seed is not None:
        attrs["seed"] = int(saved.seed)
    elapsed = np.round(np.arange(T) * scenario.dt * 1e9).astype("timedelta64[ns]")
    time = {"standard_name": "time", "long_name": "simulated time of the step"}
    coords = {
        "step": ("step", np.arange(T), {"long_name": "decision cycle"}),
        "time": ("step", np.datetime64(trace_file.EPOCH, "ns") + elapsed, time),
        "uav": ("uav", np.arange(Nu), {"long_name": "UAV index"}),
        "target": ("target", np.arange(Nt), {"long_name": "target index"}),
        "state": ("state", list(TARGET_STATE), {"long_name": "component of a target's state"}),
        "state_": ("state_", list(TARGET_STATE), {"long_name": "the same, second axis"}),
    }
    dataset = xr.Dataset(variables, coords=coords, attrs=attrs)
    dataset["time"].encoding.update(
        units=f"seconds since {trace_file.EPOCH:%Y-%m-%d}",  # midnight
        calendar="proleptic_gregorian",
        dtype="float64",
    )
    return dataset


def _attrs(long_name: str, name: str) -> dict[str, str]:
    return {"long_name": long_name, "units": UNITS[name]}


def to_frames(source, dt: float | None = None) -> dict[str, pd.DataFrame]:
    """A trial as the four tidy tables of the module's documentation, from a trace
    file's path, a `Result` with a trace, a `TraceFile`, or a bare `Trace` with its step
    `dt` [s]. Each frame's ``attrs["units"]`` maps its columns to their units (Parquet
    keeps them, see `write_table`)."""
    if isinstance(source, Trace):
        if dt is None:
            raise UsageError("a bare Trace needs its step dt: to_frames(trace, dt)")
        trace = source
    else:
        saved = trace_file.load(source)
        trace, dt = saved.trace, saved.dt
        saved.scenario.refuse_tracks("the tables")
    if trace.label is not None:  # a bare Trace of tracks
        raise UsageError("the tables do not take a trace of tracks (gnn or jpda) yet")
    T, Nu = trace.uavs.shape[:2]
    Nt = trace.targets.shape[1]
    time = np.arange(T) * dt
    steps = pd.DataFrame(
        {
            "step": np.arange(T),
            "time": time,
            "messages": trace.messages,
            "delivered": trace.delivered,
            "conflicts": trace.conflicts,
            "in_view": trace.observed.any(axis=1).mean(axis=1),
            "alive_uavs": trace.alive.sum(axis=1),
        }
    )
    k, i = (a.ravel() for a in np.meshgrid(np.arange(T), np.arange(Nu), indexing="ij"))
    uavs = {"step": k, "time": time[k], "uav": i}
    for c, name in enumerate(UAV_STATE):
        uavs[name] = trace.uavs[..., c].ravel()
    uavs.update(
        alive=trace.alive.ravel(),
        assignment=trace.assignment.ravel(),
        bank_angle=trace.action.ravel(),
        rounds=trace.rounds.ravel(),
        decision_time_ms=trace.decision_time_ms.ravel(),
        decision_wall_ms=trace.decision_wall_ms.ravel(),
    )
    best, best_mean, _ = team_best(trace.mean, trace.cov, trace.alive)
    k, j = (a.ravel() for a in np.meshgrid(np.arange(T), np.arange(Nt), indexing="ij"))
    targets = {"step": k, "time": time[k], "target": j}
    for c, name in enumerate(TARGET_STATE):
        targets[name] = trace.targets[..., c].ravel()
    targets["in_view"] = trace.observed.any(axis=1).ravel()
    targets["best_uav"] = best.ravel()
    for c, name in enumerate(TARGET_STATE):
        targets[f"best_{name}"] = best_mean[..., c].ravel()
    k, i, j = (
        a.ravel() for a in np.meshgrid(np.arange(T), np.arange(Nu), np.arange(Nt), indexing="ij")
    )
    pairs = {"step": k, "time": time[k], "uav": i, "target": j}
    pairs["in_view"] = trace.observed.ravel()
    pairs["bid"] = trace.bids.ravel()
    for c, name in enumerate(TARGET_STATE):
        pairs[f"est_{name}"] = trace.mean[..., c].ravel()
    for a in range(4):
        for b in range(a, 4):
            pairs[f"P_{TARGET_STATE[a]}_{TARGET_STATE[b]}"] = trace.cov[..., a, b].ravel()
    frames = {
        "steps": steps,
        "uavs": pd.DataFrame(uavs),
        "targets": pd.DataFrame(targets),
        "pairs": pd.DataFrame(pairs),
    }
    for frame in frames.values():
        frame.attrs["units"] = {c: unit(c) for c in frame.columns if unit(c)}
    return frames


def write_table(frame: pd.DataFrame, path: str | Path, format: str = "parquet") -> None:
    """`frame` as a Parquet or CSV file at `path` (no index). Parquet carries each
    column's unit (``frame.attrs["units"]``) in its field's metadata under ``unit``
    (``pyarrow.parquet.read_schema(path).field("x").metadata[b"unit"] == b"m"``), and
    the frame's attrs, which ``pandas.read_parquet`` restores; CSV holds the values only."""
    if format == "csv":
        frame.to_csv(path, index=False)
        return
    import pyarrow as pa

    units = frame.attrs.get("units", {})
    schema = pa.Schema.from_pandas(frame, preserve_index=False)
    for name, text in units.items():
        i = schema.get_field_index(name)
        if i >= 0:
            schema = schema.set(i, schema.field(i).with_metadata({"unit": text}))
    frame.to_parquet(path, index=False, schema=schema)


def results_frame(folder: str | Path) -> pd.DataFrame:
    """A results folder (``reproduce``, ``sweep``, ``robustness``, ``trackers``,
    ``flight``) as one row per trial: kind, label (the scenario's difference from the
    experiment's base, ``default`` for none), one column per field the label sets (its
    value, the base scenario's where the label leaves it), method, trial, plan_seed (the
    experiment's seed: trial t ran with ``uavtrack.trial_seed(plan_seed, t)``), then every
    scalar metric (NaN where the metric was not computed). Job files whose checksum fails
    are left out and named in ``frame.attrs["left_out"]``."""
    from .results import read_jobs

    base = _base_scenario(Path(folder))
    rows, left_out = [], []
    for job, metrics in read_jobs(Path(folder), left_out):
        count = int(job["count"])
        scalars = {
            name: np.array([np.nan if v is None else v for v in values], dtype=float)
            for name, values in metrics.items()
            if len(np.shape(values)) == 1
        }
        settings = parse_label(job["label"])
        for t in range(count):
            row = {"kind": job["kind"], "label": job["label"], **settings}
            row.update(method=job["method"], trial=int(job["first"]) + t, plan_seed=job["seed"])
            row.update({name: values[t] for name, values in scalars.items()})
            rows.append(row)
    if not rows:
        frame = pd.DataFrame()
        frame.attrs["left_out"] = left_out
        return frame
    frame = pd.DataFrame(rows)
    set_fields = [c for c in frame.columns if "." in c or c in Scenario.model_fields]
    for name in set_fields:  # the value the base scenario gives where a label leaves it
        default = _plain(base.value(name)) if base is not None else None
        frame[name] = [default if v is None or v != v else v for v in frame[name]]
    frame = frame.sort_values(["kind", "label", "method", "trial"], ignore_index=True)
    frame.attrs["left_out"] = left_out
    frame.attrs["units"] = {c: METRICS[c][0] for c in frame.columns if METRICS.get(c, ("",))[0]}
    return frame


def _base_scenario(folder: Path) -> Scenario | None:
    try:
        manifest = json.loads((folder / "manifest.json").read_text(encoding="utf-8"))
        return Scenario.from_dict(manifest["scenario"])
    except (OSError, ValueError, KeyError, TypeError, ScenarioError):
        return None


def _plain(value: Any) -> Any:
    """A scenario value as `parse_label` reads a label's: numbers as floats, else text."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return value if isinstance(value, str) else json.dumps(value)
    return float(value)


def parse_label(label: str) -> dict[str, Any]:
    """The fields a job's label sets, ``"comm_range=10,sensor.half_fov_deg=8"`` ->
    {"comm_range": 10.0, "sensor.half_fov_deg": 8.0} (values that are not numbers stay
    text; ``default`` sets nothing)."""
    if label == "default":
        return {}
    out: dict[str, Any] = {}
    for part in re.split(r",(?=[a-z_][a-z0-9_.]*=)", label):
        key, _, value = part.partition("=")
        try:
            out[key] = float(value)
        except ValueError:
            out[key] = value
    return out
