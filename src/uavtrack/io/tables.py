"""A run as tidy data: an xarray Dataset with named dimensions, tables for pandas, and a
results folder as one row per trial. Needs the io extra (xarray, pandas, pyarrow).

Tables (one row per ...):

* ``steps``: step: time [s], messages, delivered, conflicts, in_view (share of the
  targets present in some UAV's disk), alive_uavs (how many), and from a trace file or
  a `Result` (which carry the scenario) each metric's own value at the step, for plots
  (`tracks.scoring.series`; in_view is the step's observation rate): rounds, bytes, with
  known association
  rmse, ospa, gospa, nees and their _best twins, with tracks gospa and its parts, the
  kinds of unassigned tracks, switches, SIAP, gospa_team, label_purity, and ospa2 and
  ospa2_team at the last step of each window (NaN elsewhere);
* ``uavs``: step and UAV: its true state (x, y, altitude [m], speed [m/s], heading
  [rad]), alive, assignment (-1: failed), bank_angle [rad], rounds, decision times [ms];
* ``targets``: step and target: its true state (x, y [m], vx, vy [m/s]), in_view (of
  some UAV), the team's best estimate (best_x ... best_vy, from best_uav, the most
  confident living UAV, 1/trace P; -1 and NaN when every UAV has failed);
* ``pairs``: step, UAV and target: in_view (of this UAV), bid, the UAV's fused estimate (est_x ...
  est_vy) and the 10 entries of its covariance's upper triangle (P_x_x, P_x_y, ...).

With unknown association (``tracker.association`` gnn or jpda) a UAV's estimates are track
slots, not targets: ``pairs`` and the ``best_*`` columns of ``targets`` are left out (a slot
is no target), ``uavs``' assignment is the team label of the UAV's track, and two tables
come instead (`TRACK_TABLES`):

* ``tracks``: step, UAV and slot holding a track (tentative or confirmed) of a living UAV:
  its team label, status (``tentative``, ``confirmed``), existence (its probability;
  from trace format 4), bid (NaN unless confirmed), the
  estimate (est_x ... est_vy) and its covariance's 10 entries, as in ``pairs``;
* ``measurements``: one row per measurement of a scan: step, UAV, index (its place in the
  UAV's scan), range [m], bearing [rad], x, y (its conversion to the ground [m]), origin
  (for evaluation only: the target measured, -1 for clutter) and clutter (origin -1);
* ``briefing`` (with ``tracker.briefing`` and the trial's seed): a row per target, the
  prior every UAV started with as a confirmed track: x ... vy and P_x_x ... P_vy_vy.

These tables are a recording that ``uavtrack replay`` reads (`io.recording`): the scans
replay to the run's tracks.

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

from ..config import Scenario
from ..errors import UsageError
from ..metrics import METRICS, team_best
from ..records import TRACKED, Cycle, Trace
from ..tracks.manage import STATUS_NAMES
from ..tracks.scoring import series
from ..world import present, prior_of
from . import trace as trace_file

UAV_STATE = ("x", "y", "altitude", "speed", "heading")
TARGET_STATE = ("x", "y", "vx", "vy")
UNITS = {"x": "m", "y": "m", "altitude": "m", "speed": "m/s", "heading": "rad", "vx": "m/s",
         "vy": "m/s", "time": "s", "bank_angle": "rad", "decision_time_ms": "ms",
         "decision_wall_ms": "ms", "range": "m", "bearing": "rad", "bytes": "byte",
         "node_bytes": "byte"}  # fmt: skip
"""The unit of every table column that has one (estimates and covariance entries: see
`unit`); netCDF variables and Parquet fields carry the same strings (UDUNITS syntax)."""
TABLES = ("steps", "uavs", "targets", "pairs")
TRACK_TABLES = ("steps", "uavs", "targets", "tracks", "measurements")
"""The tables of a run of tracks (unknown association)."""


def unit(column: str) -> str | None:
    """A table column's unit, or None for counts, flags and indices: ``est_vx`` -> m/s,
    ``P_x_vy`` -> m^2/s (a covariance entry's unit is the product of its states')."""
    if column.startswith("P_"):
        velocities = sum(UNITS[name] == "m/s" for name in column[2:].split("_") if name)
        return ("m^2", "m^2/s", "m^2/s^2")[velocities]
    for prefix in ("est_", "best_"):
        if column.startswith(prefix) and column[len(prefix) :] in TARGET_STATE:
            return UNITS[column[len(prefix) :]]
    if column in UNITS:
        return UNITS[column]
    metric = METRICS.get(column, ("",))[0]  # a metric's series (``steps``)
    return metric if metric not in ("", "1") else None


def _estimates(mean: np.ndarray, cov: np.ndarray) -> dict[str, np.ndarray]:
    """Columns est_x ... est_vy and the covariance's upper triangle P_x_x ... P_vy_vy of
    estimates (..., 4) and covariances (..., 4, 4), flattened over the leading axes."""
    out = {f"est_{name}": mean[..., c].ravel() for c, name in enumerate(TARGET_STATE)}
    for a in range(4):
        for b in range(a, 4):
            out[f"P_{TARGET_STATE[a]}_{TARGET_STATE[b]}"] = cov[..., a, b].ravel()
    return out


def _docs() -> dict[str, str]:
    return {f.name: f.metadata["doc"] for f in Cycle.__dataclass_fields__.values() if f.metadata}


def to_xarray(
    source, scenario: Scenario | None = None, method: str | None = None, seed: int | None = None
) -> xr.Dataset:
    """A trial as a Dataset, in one call, as ``xarray.open_dataset`` reads a file:
    `source` is a trace file's path (``uavtrack run --trace``), a `Result` with a trace,
    a `TraceFile`, or a bare `Trace` with its `scenario` (method and seed optional).

    Dimensions step, uav, target (and state, state_ for the estimates and covariances);
    coordinates step, time, uav, target (indices: units "1"), and the state's names (as
    characters on disk). ``time`` is the CF time axis (standard_name
    time): on disk seconds since `trace.EPOCH` (2000-01-01), so xarray decodes it to
    datetimes, step k at EPOCH + k dt. Every variable has a long_name and, where it has
    one, its units (UDUNITS; the estimates' and covariances' units, which differ by
    state, are in their comment). Attributes: Conventions (CF-1.8: the CF checker,
    cfchecks, finds no error in an exported file), dt [s], method, seed, scenario (JSON)
    and uavtrack, the version that ran the trial.

    With unknown association (``tracker.association`` gnn or jpda) the estimates,
    covariances and bids are per track slot (dimension ``slot``, not ``target``), with
    each slot's ``label`` and ``status``, and the scans' measurements (dimension
    ``measurement``, padded: ``scan_valid``) as ``scan_range``, ``scan_bearing``,
    ``scan_x``, ``scan_y`` and ``scan_origin`` (`records.TRACKED`)."""
    saved = trace_file.load(source, scenario, method, seed)
    trace, scenario = saved.trace, saved.scenario
    T, Nu = trace.uavs.shape[:2]
    Nt = trace.targets.shape[1]
    docs = _docs()
    step = ("step",)
    su, st = ("step", "uav"), ("step", "target")
    tracked = trace.label is not None
    sut = ("step", "uav", "slot" if tracked else "target")
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
    variables["observed"] = (
        ("step", "uav", "target"),
        trace.observed,
        {"long_name": docs["observed"]},
    )
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
    variables["bytes"] = (su, trace.bytes, {"long_name": docs["bytes"], "units": "byte"})
    node = {"long_name": docs["node_bytes"], "units": "byte"}
    variables["node_bytes"] = (step, trace.node_bytes, node)
    if tracked:
        _track_variables(variables, trace, sut)
    attrs = {
        "Conventions": "CF-1.8",
        "title": "a uavtrack trial, step by step",
        "source": f"uavtrack {saved.version}",
        "dt": scenario.dt,
        "method": saved.method,
        "scenario": json.dumps(scenario.to_dict(), sort_keys=True),
        "uavtrack": saved.version,
        "missing": "a failed UAV's estimate, covariance and bid are NaN from its failure; "
        "a target away (target.stay) has a NaN state",
    }
    if saved.seed is not None:
        attrs["seed"] = int(saved.seed)
    elapsed = np.round(np.arange(T) * scenario.dt * 1e9).astype("timedelta64[ns]")
    time = {"standard_name": "time", "long_name": "simulated time of the step"}
    index = {"units": "1"}  # an index is a count: dimensionless (CF 3.1)
    coords = {
        "step": ("step", np.arange(T), {"long_name": "decision cycle", **index}),
        "time": ("step", np.datetime64(trace_file.EPOCH, "ns") + elapsed, time),
        "uav": ("uav", np.arange(Nu), {"long_name": "UAV index", **index}),
        "target": ("target", np.arange(Nt), {"long_name": "target index", **index}),
        "state": ("state", list(TARGET_STATE), {"long_name": "component of a target's state"}),
        "state_": ("state_", list(TARGET_STATE), {"long_name": "the same, second axis"}),
    }
    if tracked:
        K, Z = trace.label.shape[2], trace.scan_valid.shape[2]
        coords["slot"] = ("slot", np.arange(K), {"long_name": "track slot of a UAV", **index})
        coords["measurement"] = (
            "measurement", np.arange(Z),
            {"long_name": "place of a measurement in a UAV's scan", **index},
        )  # fmt: skip
    dataset = xr.Dataset(variables, coords=coords, attrs=attrs)
    for name in ("state", "state_"):  # text on disk as characters: netCDF-3 types, as CF asks
        dataset[name].encoding["dtype"] = "S1"
    dataset["time"].encoding.update(
        units=f"seconds since {trace_file.EPOCH:%Y-%m-%d}",  # midnight
        calendar="proleptic_gregorian",
        dtype="float64",
    )
    return dataset


def _track_variables(variables: dict[str, Any], trace: Trace, sus: tuple[str, ...]) -> None:
    """The variables of `records.TRACKED`: labels and statuses per slot, the scans."""
    variables["label"] = (sus, trace.label, {"long_name": TRACKED["label"][1]})
    variables["status"] = (sus, trace.status, {"long_name": TRACKED["status"][1]})
    if trace.existence is not None:  # from trace format 4
        variables["existence"] = (sus, trace.existence, {"long_name": TRACKED["existence"][1]})
    sum_ = ("step", "uav", "measurement")
    for c, (name, units) in enumerate((("range", "m"), ("bearing", "rad"))):
        variables[f"scan_{name}"] = (
            sum_, trace.scan_polar[..., c],
            {"long_name": f"measured {name}, in the order the UAV received them", "units": units},
        )  # fmt: skip
    for c, name in enumerate(("x", "y")):
        variables[f"scan_{name}"] = (
            sum_, trace.scan_z[..., c],
            {"long_name": f"the measurement's conversion to the ground, {name}", "units": "m"},
        )  # fmt: skip
    variables["scan_valid"] = (sum_, trace.scan_valid, {"long_name": TRACKED["scan_valid"][1]})
    variables["scan_origin"] = (sum_, trace.scan_origin, {"long_name": TRACKED["scan_origin"][1]})


def _attrs(long_name: str, name: str) -> dict[str, str]:
    return {"long_name": long_name, "units": UNITS[name]}


def to_frames(source, dt: float | None = None) -> dict[str, pd.DataFrame]:
    """A trial as the tidy tables of the module's documentation, from a trace file's
    path, a `Result` with a trace, a `TraceFile`, or a bare `Trace` with its step `dt`
    [s]: `TABLES`, or with tracks of unknown association `TRACK_TABLES`. Each frame's
    ``attrs["units"]`` maps its columns to their units (Parquet keeps them, see
    `write_table`)."""
    scenario = seed = None
    if isinstance(source, Trace):
        if dt is None:
            raise UsageError("a bare Trace needs its step dt: to_frames(trace, dt)")
        trace = source
    else:
        saved = trace_file.load(source)
        trace, dt, scenario, seed = saved.trace, saved.dt, saved.scenario, saved.seed
    tracked = trace.label is not None
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
            "node_bytes": trace.node_bytes,
            "in_view": _in_view_share(trace),
            "alive_uavs": trace.alive.sum(axis=1),
        }
    )
    if scenario is not None:  # each metric's own value per step (in_view: the rate's)
        for name, values in series(trace, scenario).items():
            if name not in steps and name != "observation_rate":
                steps[name] = values
    k, i = (a.ravel() for a in np.meshgrid(np.arange(T), np.arange(Nu), indexing="ij"))
    uavs = {"step": k, "time": time[k], "uav": i}
    for c, name in enumerate(UAV_STATE):
        uavs[name] = trace.uavs[..., c].ravel()
    uavs.update(
        alive=trace.alive.ravel(),
        assignment=trace.assignment.ravel(),
        bank_angle=trace.action.ravel(),
        rounds=trace.rounds.ravel(),
        bytes=trace.bytes.ravel(),
        decision_time_ms=trace.decision_time_ms.ravel(),
        decision_wall_ms=trace.decision_wall_ms.ravel(),
    )
    k, j = (a.ravel() for a in np.meshgrid(np.arange(T), np.arange(Nt), indexing="ij"))
    targets = {"step": k, "time": time[k], "target": j}
    for c, name in enumerate(TARGET_STATE):
        targets[name] = trace.targets[..., c].ravel()
    targets["in_view"] = trace.observed.any(axis=1).ravel()
    here = present(trace.targets)
    if not here.all():  # targets that come and go: NaN while away
        targets["present"] = here.ravel()
    frames = {"steps": steps, "uavs": pd.DataFrame(uavs)}
    if tracked:
        frames["targets"] = pd.DataFrame(targets)
        frames["tracks"] = _tracks(trace, time)
        frames["measurements"] = _measurements(trace, time)
        if scenario is not None and scenario.tracker.briefing and seed is not None:
            frames["briefing"] = _briefing(scenario, seed)
    else:
        best, best_mean, _ = team_best(trace.mean, trace.cov, trace.alive)
        targets["best_uav"] = best.ravel()
        for c, name in enumerate(TARGET_STATE):
            targets[f"best_{name}"] = best_mean[..., c].ravel()
        k, i, j = (
            a.ravel()
            for a in np.meshgrid(np.arange(T), np.arange(Nu), np.arange(Nt), indexing="ij")
        )
        pairs = {"step": k, "time": time[k], "uav": i, "target": j}
        pairs["in_view"] = trace.observed.ravel()
        pairs["bid"] = trace.bids.ravel()
        pairs.update(_estimates(trace.mean, trace.cov))
        frames["targets"] = pd.DataFrame(targets)
        frames["pairs"] = pd.DataFrame(pairs)
    for frame in frames.values():
        frame.attrs["units"] = {c: unit(c) for c in frame.columns if unit(c)}
    return frames


def _in_view_share(trace: Trace) -> np.ndarray:
    """The share of the targets present in some UAV's disk at each step (T,) (NaN at a
    step with none present; every target is present with the paper's fixed set)."""
    in_view = trace.observed.any(axis=1)
    here = present(trace.targets)
    if here.all():
        return in_view.mean(axis=1)
    there = here.sum(axis=1)
    return np.where(there > 0, (in_view & here).sum(axis=1) / np.maximum(there, 1), np.nan)


def _tracks(trace: Trace, time: np.ndarray) -> pd.DataFrame:
    """The ``tracks`` table: a row per step, living UAV and slot that holds a track."""
    held = (trace.status > 0) & trace.alive[..., None]
    k, i, s = np.nonzero(held)  # step, UAV, slot in order
    rows = {"step": k, "time": time[k], "uav": i, "slot": s, "label": trace.label[held]}
    names = np.array([STATUS_NAMES[code] for code in range(len(STATUS_NAMES))])
    rows["status"] = names[trace.status[held]]
    if trace.existence is not None:  # from trace format 4
        rows["existence"] = trace.existence[held]
    rows["bid"] = trace.bids[held]
    rows.update(_estimates(trace.mean[held], trace.cov[held]))
    return pd.DataFrame(rows)


def _briefing(scenario: Scenario, seed: int) -> pd.DataFrame:
    """The ``briefing`` table of a trial: the prior every UAV started with as a confirmed
    track (drawn from the trial's seed, `world.prior_of`)."""
    return briefing_frame(*prior_of(scenario, seed))


def briefing_frame(mean: np.ndarray, cov: np.ndarray) -> pd.DataFrame:
    """The ``briefing`` table of targets' means (M, 4) and covariances (M, 4, 4): a row
    per target, x ... vy and P_x_x ... P_vy_vy."""
    rows = {"target": np.arange(mean.shape[0])}
    estimates = _estimates(mean, cov)
    rows.update({name.removeprefix("est_"): value for name, value in estimates.items()})
    frame = pd.DataFrame(rows)
    frame.attrs["units"] = {c: unit(c) for c in frame.columns if unit(c)}
    return frame


def _measurements(trace: Trace, time: np.ndarray) -> pd.DataFrame:
    """The ``measurements`` table: a row per measurement of every UAV's scan."""
    k, i, z = np.nonzero(trace.scan_valid)
    origin = trace.scan_origin[k, i, z]
    return pd.DataFrame(
        {
            "step": k,
            "time": time[k],
            "uav": i,
            "index": z,
            "range": trace.scan_polar[k, i, z, 0],
            "bearing": trace.scan_polar[k, i, z, 1],
            "x": trace.scan_z[k, i, z, 0],
            "y": trace.scan_z[k, i, z, 1],
            "origin": origin,
            "clutter": origin == -1,
        }
    )


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
        default = _plain(base.value(name))
        frame[name] = [default if v is None or v != v else v for v in frame[name]]
    frame = frame.sort_values(["kind", "label", "method", "trial"], ignore_index=True)
    frame.attrs["left_out"] = left_out
    frame.attrs["units"] = {
        c: unit for c in frame.columns if (unit := METRICS.get(c, ("",))[0]) not in ("", "m^p")
    }  # m^p (p the scenario's evaluation.ospa_order) is no UDUNITS unit: its description says
    return frame


def _base_scenario(folder: Path) -> Scenario:
    from .results import manifest

    return Scenario.from_dict(manifest(folder)["scenario"])


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
