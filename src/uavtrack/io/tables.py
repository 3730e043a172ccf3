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
stays where it fell).
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

from .._version import __version__
from ..config import Scenario, ScenarioError
from ..metrics import team_best
from ..simulation import Cycle

UAV_STATE = ("x", "y", "altitude", "speed", "heading")
TARGET_STATE = ("x", "y", "vx", "vy")
UNITS = {"x": "m", "y": "m", "altitude": "m", "speed": "m/s", "heading": "rad", "vx": "m/s",
         "vy": "m/s"}  # fmt: skip
TABLES = ("steps", "uavs", "targets", "pairs")


def _docs() -> dict[str, str]:
    return {f.name: f.metadata["doc"] for f in Cycle.__dataclass_fields__.values() if f.metadata}


def to_xarray(
    trace, scenario: Scenario, method: str | None = None, seed: int | None = None
) -> xr.Dataset:
    """The trace as a Dataset: dimensions step, uav, target (and state, state_ for the
    estimates and covariances), coordinates step, time [s], uav, target; attributes dt,
    method, seed, scenario (JSON) and the uavtrack version."""
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
    variables["observed"] = (sut, trace.observed, {"description": docs["observed"]})
    mixed = "m and m/s by state (x, y: m; vx, vy: m/s)"
    variables["estimate"] = (
        sut + ("state",),
        trace.mean,
        {"description": docs["mean"], "units": mixed},
    )
    variables["covariance"] = (
        sut + ("state", "state_"), trace.cov,
        {"description": docs["cov"], "units": "products of the states' units"},
    )  # fmt: skip
    variables["bid"] = (sut, trace.bids, {"description": docs["bids"]})
    for name, dims in (("assignment", su), ("rounds", su), ("alive", su),
                       ("decision_time_ms", su), ("decision_wall_ms", su)):  # fmt: skip
        units = {"units": "ms"} if name.startswith("decision") else {}
        variables[name] = (dims, getattr(trace, name), {"description": docs[name], **units})
    variables["bank_angle"] = (su, trace.action, {"description": docs["action"], "units": "rad"})
    for name in ("messages", "delivered", "conflicts"):
        variables[name] = (step, getattr(trace, name), {"description": docs[name]})
    attrs = {
        "title": "a uavtrack trial, step by step",
        "dt": scenario.dt,
        "method": method or "",
        "scenario": json.dumps(scenario.to_dict(), sort_keys=True),
        "uavtrack": __version__,
        "missing": "a failed UAV's estimate, covariance and bid are NaN from its failure",
    }
    if seed is not None:
        attrs["seed"] = int(seed)
    coords = {
        "step": np.arange(T),
        "time": ("step", np.arange(T) * scenario.dt, {"units": "s"}),
        "uav": np.arange(Nu),
        "target": np.arange(Nt),
        "state": list(TARGET_STATE),
        "state_": list(TARGET_STATE),
    }
    return xr.Dataset(variables, coords=coords, attrs=attrs)


def _attrs(description: str, name: str) -> dict[str, str]:
    return {"description": description, "units": UNITS[name]}


def to_frames(trace, dt: float) -> dict[str, pd.DataFrame]:
    """The trace as the four tidy tables of the module's documentation."""
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
    return {
        "steps": steps,
        "uavs": pd.DataFrame(uavs),
        "targets": pd.DataFrame(targets),
        "pairs": pd.DataFrame(pairs),
    }


def results_frame(folder: str | Path) -> pd.DataFrame:
    """A results folder (``reproduce``, ``sweep``, ``robustness``, ``trackers``,
    ``flight``) as one row per trial: kind, label (the scenario's difference from the
    experiment's base, ``default`` for none), one column per field the label sets (its
    value, the base scenario's where the label leaves it), method, trial, plan_seed (the
    experiment's seed: trial t ran with ``uavtrack.trial_seed(plan_seed, t)``), then every
    scalar metric (NaN where the metric was not computed). Job files whose checksum fails
    are left out and named in ``frame.attrs["left_out"]``."""
    from ..runner import read_jobs

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
