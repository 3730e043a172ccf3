"""A recording on disk: the tables `uavtrack replay` reads, Parquet or CSV, one file each
in a folder (``uavs.parquet`` or ``uavs.csv``, ...). Needs the io extra (pandas, pyarrow).

The tables a trace's export writes (`io.tables`, ``uavtrack export``) are a recording:
its scans replay as they were. A step is a ``step`` column (0, 1, ...) or a ``time``
column [s] on the scenario's grid of dt from the first pose's time. Ids are integers
from 0. Angles are in radians, counter-clockwise from the x axis (east).

* ``uavs`` (required): a row per step and reporting sensor: step or time, uav, x, y,
  altitude [m], heading [rad], and optionally speed [m/s] (the scenario's cruise speed
  if absent) and alive (false: not reporting; a missing row says the same). These are
  where each sensor believes it is; a sensor that stops does not come back.
* ``measurements`` (required, may be empty): a row per measurement: step or time, uav,
  and either x, y [m] on the ground with the covariance's entries R_x_x, R_x_y, R_y_y
  [m^2], or range (slant) [m] and bearing [rad], which are converted from the sensor's
  pose with the scenario's sensor model (eqs. 5-12). Optionally index (the order within
  the sensor's scan; else the file's order) and origin (for evaluation only: the target
  measured, -1 clutter).
* ``links`` (optional): the radio graph, a row per step and link: step or time, uav,
  neighbour (a link carries both ways). Without it, sensors within r_C are linked.
* ``briefing`` (optional): the targets every sensor starts with as confirmed tracks, a
  row each: target (0, 1, ...), x, y [m], vx, vy [m/s] and the covariance's upper
  triangle P_x_x, P_x_y, ..., P_vy_vy. Without it the team starts with no track.
* ``targets`` (optional): the truth, for the scores: step or time, target, x, y, vx, vy
  (a target missing at a step is away).
* ``scenario.toml`` (optional): the scenario the recording replays with by default.

A ROS 2 bag is a recording too (`from_bag`): each UAV's ``/uav_<i>/odom``
(nav_msgs/Odometry: its pose, heading as yaw and bank as roll, REP-103) and
``/uav_<i>/radar_scan`` (radar_msgs/RadarScan in its body frame ``uav_<i>``), as
``uavtrack run --bag`` writes them with tracks; a return's slant range and world
bearing are converted as a table's range and bearing.
"""

# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import UsageError, install_hint

try:
    import pandas as pd
except ImportError as exc:  # an optional extra
    raise ImportError(f"uavtrack.io.recording needs pandas: {install_hint('io')} ({exc})") from None

from ..config import Scenario
from ..simulation import convert
from ..tracks import scan as scans
from .replay import Recording

__all__ = [
    "STATE", "TABLES", "from_bag", "is_bag", "read", "read_recording", "scenario_in", "table_path",
]  # fmt: skip

TABLES = ("uavs", "measurements", "links", "briefing", "targets")
"""The tables of a recording, the first two required."""
STATE = ("x", "y", "vx", "vy")
COVARIANCE = tuple(f"P_{STATE[a]}_{STATE[b]}" for a in range(4) for b in range(a, 4))
"""The briefing's covariance columns, the upper triangle row by row."""
SUFFIXES = (".parquet", ".csv")
JITTER = 0.05
"""How far off the grid of dt a time may be, as a share of dt: a recorder's clock
jitters (a few ms at dt = 0.5 s); two rows of one sensor in one step are still refused."""
OLD_PANDAS = int(pd.__version__.split(".")[0]) < 3
"""pandas before 3 reads a CSV's numbers as written only when asked."""


def table_path(folder: Path, name: str) -> Path | None:
    """The file of table `name` in `folder` (None: absent); refused if two formats are."""
    found = [
        folder / f"{name}{suffix}" for suffix in SUFFIXES if (folder / f"{name}{suffix}").is_file()
    ]
    if len(found) > 1:
        raise UsageError(f"{folder}: both {found[0].name} and {found[1].name}; keep one")
    return found[0] if found else None


def scenario_in(folder: str | Path) -> Scenario | None:
    """The folder's ``scenario.toml``, if it has one."""
    path = Path(folder) / "scenario.toml"
    return Scenario.from_toml(path) if path.is_file() else None


def read(folder: str | Path, scenario: Scenario) -> Recording:
    """The recording in `folder`, its steps on `scenario`'s dt and its ranges and
    bearings converted with its sensor model; a one-line UsageError naming the table
    and column for anything the module's schema does not allow."""
    folder = Path(folder).expanduser()
    if not folder.is_dir():
        raise UsageError(f"{folder}: no such folder (a recording is a folder of tables)")
    frames = {name: _load(folder, name) for name in TABLES}
    for name in ("uavs", "measurements"):
        if frames[name] is None:
            raise UsageError(f"{folder}: no {name} table ({name}.parquet or {name}.csv)")
    uavs, measured = frames["uavs"], frames["measurements"]
    assert uavs is not None and measured is not None
    return _recording(uavs, measured, frames["links"], frames["briefing"], frames["targets"],
                      scenario, str(folder))  # fmt: skip


read_recording = read
"""`read`, as `uavtrack.io` names it beside the trace's `read`."""


def _recording(
    uavs: pd.DataFrame,
    measured: pd.DataFrame,
    links: pd.DataFrame | None,
    briefing: pd.DataFrame | None,
    targets: pd.DataFrame | None,
    scenario: Scenario,
    where: str,
) -> Recording:
    """A `Recording` of the module's tables (`where` names their source in errors)."""
    dt = scenario.dt
    t0 = _start(uavs, dt)
    _need(uavs, "uavs", ("uav", "x", "y", "altitude", "heading"))
    if uavs.empty:
        raise UsageError("uavs: no rows; a recording needs the sensors' poses")
    k = _steps(uavs, "uavs", t0, dt)
    i = _ids(uavs, "uavs", "uav")
    T, N = int(k.max()) + 1, int(i.max()) + 1
    missing = np.setdiff1d(np.arange(N), i)
    if missing.size:
        raise UsageError(
            f"uavs: no row of uav {missing[0]}; ids run 0 to {N - 1} with none left out"
        )
    if pd.Series(k * N + i).duplicated().any():
        raise UsageError("uavs: two rows of one uav at one step")
    poses = np.full((T, N, 5), np.nan)
    alive = np.zeros((T, N), dtype=bool)
    speed = (
        _floats(uavs, "uavs", "speed")
        if "speed" in uavs
        else np.full(len(uavs), scenario.uav.speed)
    )
    for c, name in enumerate(("x", "y", "altitude")):
        poses[k, i, c] = _floats(uavs, "uavs", name)
    poses[k, i, 3], poses[k, i, 4] = speed, _floats(uavs, "uavs", "heading")
    alive[k, i] = _flags(uavs, "uavs", "alive") if "alive" in uavs else True
    if (poses[k, i, 2] <= 0).any():
        raise UsageError("uavs: altitude must be above 0 m")
    if (poses[k, i, 3] <= 0).any():
        raise UsageError("uavs: speed must be above 0 m/s")
    heading = poses[k, i, 4]
    poses[k, i, 4] = np.where(
        np.abs(heading) > np.pi, np.remainder(heading + np.pi, 2 * np.pi) - np.pi, heading
    )
    _inside(poses[k, i, :2], "uavs", scenario)
    poses = _held(poses)
    z, R, valid, polar, origin = _measurements(measured, poses, alive, t0, scenario)
    truth, prior = _targets(targets, T, t0, dt), _briefing(briefing)
    if truth is not None:
        _inside(truth[~np.isnan(truth[..., 0])][:, :2], "targets", scenario)
    if prior is not None:
        _inside(prior[0][:, :2], "briefing", scenario)
    try:
        return Recording(
            poses=poses, alive=alive, z=z, R=R, valid=valid, polar=polar, origin=origin,
            links=_links(links, T, N, t0, dt), prior=prior, targets=truth,
        )  # fmt: skip
    except ValueError as exc:
        raise UsageError(f"{where}: {exc}") from None


def _held(poses: np.ndarray) -> np.ndarray:
    """Poses (T, N, 5) with each sensor's last one carried over the steps it has none:
    a sensor that stopped stays where it was, as a failed UAV stays where it fell."""
    out = poses.copy()
    for t in range(1, len(out)):
        gone = np.isnan(out[t, :, 0])
        out[t, gone] = out[t - 1, gone]
    return out


SPILL = {"uavs": 1.0, "targets": 0.25, "briefing": 0.25}
"""How far outside the field a table's positions may lie, as a share of its side: a
target's no further than the trackers keep a track (`tracks.manage` deletes one a
quarter of the side out), a sensor's a whole side (it flies beyond the targets)."""


def _inside(xy: np.ndarray, table: str, scenario: Scenario) -> None:
    """Refuse positions (..., 2) beyond the scenario's field plus `SPILL` of its side: a
    recording in other coordinates would track nothing, and say nothing."""
    L, spill = scenario.field_size, SPILL[table]
    out = (xy < -spill * L) | (xy > (1 + spill) * L)
    if out.any():
        bad = float(xy[out][0])
        raise UsageError(
            f"{table}: a position {bad:g} m lies outside the scenario's field (0 to {L:g} m, "
            "x and y): set field_size, or shift the coordinates"
        )


def _load(folder: Path, name: str) -> pd.DataFrame | None:
    path = table_path(folder, name)
    if path is None:
        return None
    try:
        if path.suffix == ".csv":
            if OLD_PANDAS:  # its default reads a CSV's numbers to a few ulps
                return pd.read_csv(path, float_precision="round_trip")
            return pd.read_csv(path)
        return pd.read_parquet(path)
    except Exception as exc:  # pandas and pyarrow raise many kinds for a broken file
        raise UsageError(f"{path}: cannot read it as {path.suffix[1:]} ({exc})") from None


def _need(frame: pd.DataFrame, table: str, columns: tuple[str, ...]) -> None:
    missing = [c for c in columns if c not in frame]
    if missing:
        raise UsageError(f"{table}: no column {', '.join(missing)}")


def _start(uavs: pd.DataFrame, dt: float) -> float:
    """The time of step 0: the first pose's, less its steps if it has a step column (0
    when the poses have no time column)."""
    if "time" not in uavs or uavs.empty:
        return 0.0
    t = _floats(uavs, "uavs", "time")
    if "step" not in uavs:
        return float(t.min())
    k = _ids(uavs, "uavs", "step")
    first = int(np.argmin(k))
    return float(t[first]) - float(k[first]) * dt


def _steps(frame: pd.DataFrame, table: str, t0: float, dt: float) -> np.ndarray:
    """Each row's step: its ``step``, else its ``time`` on the grid t0 + k dt; with
    both, they must agree."""
    if "time" not in frame and "step" not in frame:
        raise UsageError(f"{table}: no column step or time")
    k = _ids(frame, table, "step") if "step" in frame else None
    if "time" in frame:
        t = _floats(frame, table, "time")
        on = np.round((t - t0) / dt)
        off = np.abs(t - t0 - on * dt) > JITTER * dt
        if off.any() or (on < 0).any():
            bad = float(t[off | (on < 0)][0])
            raise UsageError(
                f"{table}: time {bad:g} s is not on the grid of dt = {dt:g} s from {t0:g} s "
                "(the first pose's time); set the scenario's dt"
            )
        if k is not None and (k != on).any():
            bad = int(np.flatnonzero(k != on)[0])
            raise UsageError(f"{table}: step {k[bad]} and time {t[bad]:g} s disagree (dt = "
                             f"{dt:g} s from {t0:g} s); give one of the two")  # fmt: skip
        k = on.astype(np.int64) if k is None else k
    assert k is not None
    return k


def _floats(frame: pd.DataFrame, table: str, column: str, away: bool = False) -> np.ndarray:
    """A column's numbers, each finite (`away`: or NaN, a target away)."""
    try:
        values = np.asarray(pd.to_numeric(frame[column], errors="raise"), dtype=np.float64)
    except (ValueError, TypeError):
        raise UsageError(f"{table}: column {column} must hold numbers") from None
    if not np.isfinite(values[~np.isnan(values)] if away else values).all():
        raise UsageError(f"{table}: column {column} holds a value that is not a finite number")
    return values


def _ids(frame: pd.DataFrame, table: str, column: str) -> np.ndarray:
    values = _floats(frame, table, column)
    if (values < 0).any() or (values != np.round(values)).any():
        raise UsageError(f"{table}: column {column} must hold whole numbers from 0")
    return values.astype(np.int64)


def _flags(frame: pd.DataFrame, table: str, column: str) -> np.ndarray:
    values = frame[column]
    if values.dtype == bool:
        return values.to_numpy()
    text = values.astype(str).str.strip().str.lower()
    known = text.isin(("true", "false", "1", "0", "1.0", "0.0"))
    if not known.all():
        raise UsageError(f"{table}: column {column} must hold true or false")
    return text.isin(("true", "1", "1.0")).to_numpy()


def _measurements(
    frame: pd.DataFrame, poses: np.ndarray, alive: np.ndarray, t0: float, scenario: Scenario
) -> tuple[np.ndarray, ...]:
    """The scans, padded: z, R, valid, polar, origin as `Recording` holds them."""
    T, N = alive.shape
    table = "measurements"
    if frame.empty:  # no sensor measured anything: every scan empty
        frame = pd.DataFrame({"step": [], "uav": [], "x": [], "y": [], "R_x_x": [],
                              "R_x_y": [], "R_y_y": []})  # fmt: skip
    _need(frame, table, ("uav",))
    k, i = _steps(frame, table, t0, scenario.dt), _ids(frame, table, "uav")
    late = (k >= T) | (i >= N)
    if late.any():
        raise UsageError(f"{table}: a measurement at step {k[late][0]} of uav {i[late][0]}, which "
                         "has no pose in uavs")  # fmt: skip
    if not alive[k, i].all():
        j = int(np.flatnonzero(~alive[k, i])[0])
        raise UsageError(f"{table}: a measurement at step {k[j]} of uav {i[j]}, which does not "
                         "report then (no pose in uavs)")  # fmt: skip
    cartesian = all(c in frame for c in ("R_x_x", "R_x_y", "R_y_y"))
    if cartesian and "range" in frame and "bearing" in frame:
        raise UsageError(f"{table}: give x, y with R, or range and bearing, not both (each "
                         "gives the measurement and its covariance)")  # fmt: skip
    polar = np.full((len(frame), 2), np.nan)
    if cartesian:
        _need(frame, table, ("x", "y"))
        z = np.stack([_floats(frame, table, "x"), _floats(frame, table, "y")], axis=-1)
        xx, xy, yy = (_floats(frame, table, c) for c in ("R_x_x", "R_x_y", "R_y_y"))
        R = np.stack([np.stack([xx, xy], -1), np.stack([xy, yy], -1)], -2)
    elif "range" in frame and "bearing" in frame:
        polar = np.stack([_floats(frame, table, "range"), _floats(frame, table, "bearing")], -1)
        if (polar[:, 0] <= 0).any():
            raise UsageError(f"{table}: range must be above 0 m")
        z, R = convert(poses[k, i], polar, scenario)
    else:
        raise UsageError(f"{table}: give x, y with R_x_x, R_x_y, R_y_y, or range and bearing")
    origin = _ids_signed(frame, table, "origin") if "origin" in frame else np.full(len(frame), -1)
    order = np.arange(len(frame))
    if "index" in frame:
        order = _ids(frame, table, "index")
        if pd.Series((k * N + i) * (len(frame) + 1) + order).duplicated().any():
            raise UsageError(f"{table}: two measurements of one uav and step share an index")
    rows = np.lexsort((order, i, k))  # step, uav, then the scan's order
    k, i = k[rows], i[rows]
    row = k * N + i
    counts = np.bincount(row, minlength=T * N)
    place = np.arange(row.size) - np.repeat(np.cumsum(counts) - counts, counts)
    Z = int(counts.max(initial=0))
    out_z = np.zeros((T, N, Z, 2))
    out_R = np.broadcast_to(np.eye(2), (T, N, Z, 2, 2)).copy()
    valid = np.zeros((T, N, Z), dtype=bool)
    out_polar = np.full((T, N, Z, 2), np.nan)
    out_origin = np.full((T, N, Z), scans.NONE, dtype=np.int64)
    out_z[k, i, place], out_R[k, i, place] = z[rows], R[rows]
    valid[k, i, place], out_polar[k, i, place] = True, polar[rows]
    out_origin[k, i, place] = origin[rows]
    return out_z, out_R, valid, out_polar, out_origin


def _ids_signed(frame: pd.DataFrame, table: str, column: str) -> np.ndarray:
    values = _floats(frame, table, column)
    if (values < -1).any() or (values != np.round(values)).any():
        raise UsageError(f"{table}: column {column} must hold whole numbers from -1")
    return values.astype(np.int64)


def _links(frame: pd.DataFrame | None, T: int, N: int, t0: float, dt: float) -> np.ndarray | None:
    if frame is None:
        return None
    _need(frame, "links", ("uav", "neighbour"))
    k, i, q = (
        _steps(frame, "links", t0, dt),
        _ids(frame, "links", "uav"),
        _ids(frame, "links", "neighbour"),
    )
    if ((k >= T) | (i >= N) | (q >= N)).any():
        raise UsageError(f"links: a link past the recording's {T} steps or {N} uavs")
    adj = np.zeros((T, N, N), dtype=bool)
    adj[k, i, q] = adj[k, q, i] = True
    return adj


def _briefing(frame: pd.DataFrame | None) -> tuple[np.ndarray, np.ndarray] | None:
    if frame is None:
        return None
    _need(frame, "briefing", STATE + COVARIANCE)
    if frame.empty:
        raise UsageError("briefing: no rows; leave the table out for a start with no track")
    order = np.arange(len(frame))
    if "target" in frame:
        j = _ids(frame, "briefing", "target")
        if not np.array_equal(np.sort(j), order):
            raise UsageError("briefing: targets must be 0, 1, ... once each")
        order = np.argsort(j)
    rows = frame.iloc[order]
    mean = np.stack([_floats(rows, "briefing", c) for c in STATE], axis=-1)
    cov = np.zeros((len(rows), 4, 4))
    upper = np.triu_indices(4)
    for c, name in enumerate(COVARIANCE):
        a, b = upper[0][c], upper[1][c]
        cov[:, a, b] = cov[:, b, a] = _floats(rows, "briefing", name)
    return mean, cov


def _targets(frame: pd.DataFrame | None, T: int, t0: float, dt: float) -> np.ndarray | None:
    if frame is None:
        return None
    _need(frame, "targets", ("target",) + STATE)
    if frame.empty:
        raise UsageError("targets: no rows; leave the table out for a recording without truth")
    k, j = _steps(frame, "targets", t0, dt), _ids(frame, "targets", "target")
    if (k >= T).any():
        raise UsageError(f"targets: a state past the recording's {T} steps")
    M = int(j.max(initial=-1)) + 1
    out = np.full((T, max(M, 1), 4), np.nan)
    values = np.stack([_floats(frame, "targets", c, away=True) for c in STATE], axis=-1)
    if (np.isnan(values).any(axis=-1) != np.isnan(values).all(axis=-1)).any():
        raise UsageError("targets: a row's state is either all numbers or all empty (away)")
    if pd.Series(k * max(M, 1) + j).duplicated().any():
        raise UsageError("targets: two rows of one target at one step")
    out[k, j] = values
    return out


def is_bag(path: str | Path) -> bool:
    """Whether `path` is a rosbag2 folder (it holds ``metadata.yaml``)."""
    return (Path(path) / "metadata.yaml").is_file()


ODOM = re.compile(r"^/uav_(\d+)/odom$")
SCAN = re.compile(r"^/uav_(\d+)/radar_scan$")


def from_bag(path: str | Path, scenario: Scenario) -> Recording:
    """The recording in a ROS 2 bag (the module's documentation): a step per odometry
    stamp on the grid of `scenario`'s dt from the first; no links, briefing or truth."""
    try:
        from rosbags.highlevel import AnyReader
    except ImportError as exc:
        raise UsageError(f"reading a bag needs rosbags: {install_hint('io')} ({exc})") from None
    path = Path(path).expanduser()
    poses: dict[tuple[int, int], np.ndarray] = {}
    returns: dict[tuple[int, int], np.ndarray] = {}
    try:
        with AnyReader([path]) as reader:
            odom = [c for c in reader.connections if ODOM.match(c.topic)]
            scans_ = [c for c in reader.connections if SCAN.match(c.topic)]
            if not odom:
                raise UsageError(f"{path}: no /uav_<i>/odom topic (nav_msgs/msg/Odometry)")
            if not scans_:
                raise UsageError(f"{path}: no /uav_<i>/radar_scan topic (radar_msgs/msg/RadarScan;"
                                 " uavtrack run --bag writes it with tracks)")  # fmt: skip
            stamps = [t for _, t, _ in reader.messages(odom)]
            t0, dt = min(stamps), round(scenario.dt * 1e9)
            for c, t, raw in reader.messages(odom + scans_):
                k = _bag_step(t, t0, dt, c.topic)
                msg: Any = reader.deserialize(raw, c.msgtype)
                match = ODOM.match(c.topic) or SCAN.match(c.topic)
                assert match is not None  # the connections chosen
                i, into = int(match.group(1)), poses if ODOM.match(c.topic) else returns
                if (k, i) in into:
                    raise UsageError(f"{c.topic}: two messages in step {k} (dt = {dt / 1e9:g} "
                                     "s); set the scenario's dt")  # fmt: skip
                if into is poses:
                    poses[k, i] = _pose(msg)
                else:
                    returns[k, i] = np.array(
                        [(r.range, r.azimuth, r.elevation) for r in msg.returns], dtype=float
                    ).reshape(-1, 3)
    except UsageError:
        raise
    except Exception as exc:  # rosbags raises its own kinds for a broken bag
        raise UsageError(f"{path}: cannot read it as a ROS 2 bag ({exc})") from None
    names = ("x", "y", "altitude", "speed", "heading", "bank")
    rows_pose = [
        {"step": k, "uav": i, **dict(zip(names, p, strict=True))} for (k, i), p in poses.items()
    ]
    rows = []
    for (k, i), found in returns.items():
        if (k, i) not in poses:
            raise UsageError(f"{path}: a scan of uav_{i} at step {k} with no odometry then")
        x, y, h, _, heading, bank = poses[k, i]
        body = _rotation(heading, bank)
        for n, (rng, az, el) in enumerate(found):
            b = rng * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
            offset = body @ b
            rows.append({"step": k, "uav": i, "index": n, "range": float(np.linalg.norm(offset)),
                         "bearing": float(np.arctan2(offset[1], offset[0]))})  # fmt: skip
    frame = pd.DataFrame(rows_pose)
    measured = pd.DataFrame(rows, columns=["step", "uav", "index", "range", "bearing"])
    return _recording(frame, measured, None, None, None, scenario, str(path))


def _bag_step(t: int, t0: int, dt: int, topic: str) -> int:
    """A bag message's step: its log time on the grid of dt from t0, within `JITTER`."""
    k = round((t - t0) / dt)
    if abs(t - t0 - k * dt) > JITTER * dt:
        raise UsageError(f"{topic}: a message at {t / 1e9:g} s is not on the grid of dt = "
                         f"{dt / 1e9:g} s from {t0 / 1e9:g} s; set the scenario's dt")  # fmt: skip
    return int(k)


def _pose(msg) -> np.ndarray:
    """x, y, altitude, speed, heading and bank of an Odometry (REP-103 roll: -bank)."""
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
    roll = math.atan2(2 * (q.w * q.x + q.y * q.z), 1 - 2 * (q.x * q.x + q.y * q.y))
    return np.array([p.x, p.y, p.z, msg.twist.twist.linear.x, yaw, -roll])


def _rotation(heading: float, bank: float) -> np.ndarray:
    """The body frame's rotation to the map's: yaw the heading, roll -bank (`ros2._body`)."""
    cy, sy, cr, sr = math.cos(heading), math.sin(heading), math.cos(-bank), math.sin(-bank)
    return np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
        [[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]]
    )
