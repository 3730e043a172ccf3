"""A run in Rerun's interactive viewer (``uavtrack run --rerun [FILE.rrd]``).

The recording holds, on the ``step`` timeline: the field, the UAVs in 3-D at their
altitudes with their headings and observation disks, the targets and their true paths,
each UAV's estimate of the target it tracks with its 2-sigma covariance ellipse, the
radio links, the assignments (a line from a UAV to its estimate of its target), and time
series (observation rate so far, consensus rounds D_i, messages per step).

Everything is logged in columns, one `send_columns` call per kind of thing over all the
steps, and one entity per kind rather than one per UAV: the viewer stays usable with
thousands of UAVs. Instance i of every UAV entity is UAV i at every step (a failed UAV
stays, grey, where it fell; what it no longer has is NaN, which the viewer does not
draw), and instance j of the targets is target j. The recording id names the method,
the seed and the scenario's digest, so recordings of different runs open side by side.
The default layout shows the field from above beside a 3-D view, and each time series
in a view on its own scale.

A run of tracks (``tracker.association`` gnn or jpda) adds `TRACK_ENTITIES`: every UAV's
tracks (instance i K + s is slot s of UAV i) with the team label as class id and a label
text ``L<label>``, confirmed in the UAV's colour, tentative grey and smaller, each with
its 2-sigma ellipse; and the scans, true detections red and clutter grey (split by the
origin the simulator knows, for evaluation). A UAV's estimate on ``world/estimates`` is
then its own estimate of the track it follows.

A recording is read back with ``rerun.chunk.RrdReader``, as pyarrow record batches.
Needs the viz extra (rerun-sdk, pyarrow).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..errors import install_hint

try:
    import rerun as rr
except ImportError as exc:  # an optional extra
    raise ImportError(
        f"uavtrack.viz.rerun needs rerun-sdk: {install_hint('viz')} ({exc})"
    ) from None

from .._files import write_bytes
from ..errors import RunError, UsageError
from ..network import in_range
from ..sensing import observation_radius
from ..tracks.manage import CONFIRMED
from ..world import present, stays

ENTITIES = (
    "world/field",
    "world/targets/paths",
    "world/targets",
    "world/uavs",
    "world/uavs/headings",
    "world/uavs/disks",
    "world/estimates",
    "world/estimates/ellipses",
    "world/links",
    "world/assignments",
    "metrics/observation_rate",
    "metrics/rounds",
    "metrics/messages",
)
"""Every entity a recording holds: one per kind, whatever the team's size."""

TRACK_ENTITIES = (
    "world/tracks",
    "world/tracks/ellipses",
    "world/scan/detections",
    "world/scan/clutter",
)
"""The entities a recording of a run of tracks holds besides `ENTITIES`."""

THIN = 0.05  # [m] the vertical half-size of flat ellipsoids (disks, ellipses)


def save(trace, scenario, path: str | Path, name: str = "uavtrack") -> None:
    """Write the recording of a run's trace to `path` (.rrd), atomically.

    The recording is encoded in memory (Rerun's binary stream), then written as one
    file: Rerun's own file sink, given a full disk, may stop in silence, hang or leave a
    truncated file; a plain write fails with an OSError naming `path` and leaves
    nothing."""
    rec = rr.RecordingStream("uavtrack", recording_id=recording_id(name, scenario))
    if not rec.is_enabled():  # Rerun would encode nothing and say so only in a log line
        with _quiet_stderr():  # as it does again when the disabled stream is dropped
            del rec
        setting = os.environ.get("RERUN")
        why = f" (the environment variable RERUN={setting})" if setting is not None else ""
        raise UsageError(
            f"cannot write {path}: Rerun is turned off here{why}; unset RERUN or set "
            "RERUN=on to record"
        )
    stream = rec.binary_stream()
    rec.send_blueprint(blueprint(scenario), make_active=False, make_default=True)
    log(rec, trace, scenario)
    data = stream.read(flush=True)
    if data is None:  # nothing was encoded: no file rather than an empty one
        raise RunError(f"cannot write {path}: Rerun encoded no recording")
    write_bytes(path, data)


def recording_id(name: str, scenario) -> str:
    """A recording's id: its name (method-seed) and the scenario's digest."""
    return f"{name}-{scenario.digest()}"


METRIC_VIEWS = {
    "metrics/observation_rate": ("observation rate so far", (0.0, 1.0)),
    "metrics/rounds": ("consensus rounds D_i (mean over living UAVs)", None),
    "metrics/messages": ("messages per step", None),
}
"""Each time series in a view of its own, on its own scale (entity: title, y range):
the observation rate, a share, on [0, 1]; rounds (a few) and messages (tens per step)
on theirs, so that none is flattened by another's."""


def metric_view(entity: str):
    """The time-series view of one metric of `METRIC_VIEWS`."""
    import rerun.blueprint as rrb

    title, span = METRIC_VIEWS[entity]
    axis = rrb.ScalarAxis(range=span) if span is not None else None
    return rrb.TimeSeriesView(name=title, origin=entity, axis_y=axis)


def blueprint(scenario):
    """The default layout: the field seen from straight above, a 3-D view and the time
    series of the metrics, one view each (`METRIC_VIEWS`)."""
    import rerun.blueprint as rrb

    L = scenario.field_size
    top = max(scenario.altitudes()) + 1.5 * L  # above every UAV, the field in view
    above = rrb.EyeControls3D(
        kind=rrb.Eye3DKind.FirstPerson,
        position=(L / 2, L / 2, top),
        look_target=(L / 2, L / 2, 0.0),
        eye_up=(0.0, 1.0, 0.0),
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="field from above", origin="world", eye_controls=above),
            rrb.Vertical(
                rrb.Spatial3DView(name="3-D", origin="world"),
                rrb.Horizontal(*(metric_view(name) for name in METRIC_VIEWS)),
            ),
        ),
        collapse_panels=True,
    )


@contextmanager
def _quiet_stderr():
    """Native writes to file descriptor 2 go nowhere for the duration."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 2)
        os.close(null)
    except (OSError, ValueError):
        yield
        return
    try:
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def show(trace, scenario, name: str = "uavtrack") -> int:
    """Open the recording in the Rerun viewer, a child process, and wait until it is
    closed; the viewer is stopped on Ctrl-C or any error. Returns its exit code."""
    with tempfile.TemporaryDirectory(prefix="uavtrack-rerun-") as folder:
        path = Path(folder) / f"{name}.rrd"
        save(trace, scenario, path, name)
        log_file = Path(folder) / "viewer.log"
        command = [sys.executable, "-m", "rerun", "--bind", "127.0.0.1", "--port", "auto"]
        with open(log_file, "w") as out:
            try:
                viewer = subprocess.Popen([*command, str(path)], stdout=out, stderr=out)
            except OSError as exc:
                raise RunError(f"cannot start the Rerun viewer: {exc}") from None
            try:
                code = viewer.wait()
            finally:  # Ctrl-C or an error here: the viewer goes too
                if viewer.poll() is None:
                    viewer.terminate()
                    try:
                        viewer.wait(timeout=5)
                    except subprocess.TimeoutExpired:
                        viewer.kill()
                        viewer.wait()
        if code != 0:
            raise RunError(
                f"the Rerun viewer stopped with exit code {code}; give --rerun FILE.rrd to "
                "save the recording and open it with `rerun FILE.rrd`"
            )
        return code


def log(rec: rr.RecordingStream, trace, scenario) -> None:
    """Log every entity of `ENTITIES` for a trace into the recording stream `rec`."""
    T, nu, nt = trace.observed.shape
    steps = rr.TimeColumn("step", sequence=np.arange(T))
    alive = trace.alive
    uavs = trace.uavs  # (T, Nu, 5)
    colors = _colors(nu)
    L = scenario.field_size
    rec.log(
        "world/field",
        rr.LineStrips3D([[[0, 0, 0], [L, 0, 0], [L, L, 0], [0, L, 0], [0, 0, 0]]], colors=128),
        static=True,
    )
    ground = np.concatenate([trace.targets[..., :2], np.zeros((T, nt, 1))], axis=-1)
    here = present(trace.targets)  # with targets that come and go: NaN while away
    if here.all():
        strips = np.swapaxes(ground, 0, 1)
        names = np.broadcast_to(np.array([f"T{j}" for j in range(nt)]), (T, nt))
    else:  # a path per stay, and the n-th target to take place j after the first: Tj.n
        stay = stays(trace.targets)
        strips = [
            ground[here[:, j] & (stay[:, j] == n), j]
            for j in range(nt)
            for n in np.unique(stay[here[:, j], j])
        ]
        names = np.array(
            [[f"T{j}.{n}" if n else f"T{j}" for j, n in enumerate(row)] for row in stay]
        )
    rec.log(
        "world/targets/paths",
        # rerun takes an (S, P, 3) array of strips, which its LineStrip3DArrayLike omits
        rr.LineStrips3D(strips, colors=[90, 90, 90], radii=0.2),  # pyright: ignore[reportArgumentType]
        static=True,
    )
    _send(
        rec,
        "world/targets",
        steps,
        here,
        rr.Points3D,
        positions=ground,
        labels=names,
        colors=np.broadcast_to(np.array([20, 20, 20]), (T, nt, 3)),
        radii=np.full((T, nt), 1.5),
    )
    where = uavs[..., :3]
    color = np.broadcast_to(colors, (T, nu, 3))
    names = np.array([f"U{i}" for i in range(nu)])
    _send(  # a failed UAV stays where it fell, grey
        rec,
        "world/uavs",
        steps,
        np.ones((T, nu), dtype=bool),
        rr.Points3D,
        positions=where,
        labels=np.where(alive, names, np.char.add(names, " (failed)")),
        colors=np.where(alive[..., None], color, np.uint8(150)),
        radii=np.where(alive, 2.0, 1.0),
    )
    heading = uavs[..., 4]
    arrows = 15 * np.stack([np.cos(heading), np.sin(heading), np.zeros_like(heading)], axis=-1)
    _send(
        rec,
        "world/uavs/headings",
        steps,
        alive,
        rr.Arrows3D,
        origins=where,
        vectors=arrows,
        colors=color,
    )
    radius = observation_radius(np.asarray(scenario.altitudes()), scenario.sensor)
    disks = np.broadcast_to(np.stack([radius, radius, np.full(nu, THIN)], axis=-1), (T, nu, 3))
    _send(
        rec,
        "world/uavs/disks",
        steps,
        alive,
        rr.Ellipsoids3D,
        centers=np.concatenate([uavs[..., :2], np.zeros((T, nu, 1))], axis=-1),
        half_sizes=disks,
        colors=color,
    )
    # each UAV's estimate of the target it tracks, with its 2-sigma ellipse
    tracking = alive & (trace.assignment >= 0)
    j = np.maximum(trace.assignment, 0)
    if trace.label is not None:  # the UAV's own slot of the track it follows
        own = tracking[..., None] & (trace.label == trace.assignment[..., None])
        tracking, j = own.any(axis=-1), own.argmax(axis=-1)
        _tracks(rec, trace, steps, colors)
    t_idx, u_idx = np.meshgrid(np.arange(T), np.arange(nu), indexing="ij")
    mean = np.nan_to_num(trace.mean[t_idx, u_idx, j, :2])  # (T, Nu, 2)
    cov = np.nan_to_num(trace.cov[t_idx, u_idx, j, :2, :2])
    at = np.concatenate([mean, np.zeros((T, nu, 1))], axis=-1)
    _send(rec, "world/estimates", steps, tracking, rr.Points3D, positions=at, colors=color)
    half, quaternion = _ellipses(cov)
    _send(
        rec,
        "world/estimates/ellipses",
        steps,
        tracking,
        rr.Ellipsoids3D,
        centers=at,
        half_sizes=half,
        quaternions=quaternion,
        colors=color,
    )
    _send(
        rec,
        "world/assignments",
        steps,
        tracking,
        rr.LineStrips3D,
        strips=np.stack([where, at], axis=-2),
        colors=color,
    )
    ends, counts = _links(uavs, alive, scenario.comm_range)
    rec.send_columns(
        "world/links",
        indexes=[steps],
        columns=rr.LineStrips3D.columns(
            strips=ends,  # pyright: ignore[reportArgumentType] (strips as an (E, 2, 3) array)
            colors=np.full((len(ends), 3), 110),
        ).partition(counts),
    )
    in_view = trace.observed.any(axis=1).mean(axis=1)
    series = {
        "metrics/observation_rate": np.cumsum(in_view) / np.arange(1, T + 1),
        "metrics/rounds": (trace.rounds * alive).sum(axis=1) / np.maximum(alive.sum(axis=1), 1),
        "metrics/messages": trace.messages.astype(float),
    }
    for entity, values in series.items():
        rec.send_columns(
            entity, indexes=[steps], columns=rr.Scalars.columns(scalars=np.nan_to_num(values))
        )


def _tracks(rec: rr.RecordingStream, trace, steps, colors: np.ndarray) -> None:
    """The entities of `TRACK_ENTITIES`: every UAV's track slots (T, Nu K), drawn where
    the slot holds a track of a living UAV, and its scans (T, Nu Z)."""
    T, nu, K = trace.label.shape
    held = (trace.status > 0) & trace.alive[..., None]  # (T, Nu, K)
    confirmed = trace.status == CONFIRMED
    at = np.concatenate([np.nan_to_num(trace.mean[..., :2]), np.zeros((T, nu, K, 1))], -1)
    own = np.broadcast_to(colors[:, None], (T, nu, K, 3))
    color = np.where(confirmed[..., None], own, np.uint8(150)).reshape(T, nu * K, 3)
    text = np.char.add("L", trace.label.astype(str))
    text = np.where(confirmed, text, np.char.add(text, " (tentative)"))
    text = np.where(held, text, "")  # an empty slot: not drawn, no text
    flat = (T, nu * K)
    shown = held.reshape(flat)
    _send(
        rec, "world/tracks", steps, shown, rr.Points3D,
        positions=at.reshape(T, nu * K, 3),
        class_ids=np.maximum(trace.label, 0).reshape(flat).astype(np.uint16),
        labels=text.reshape(flat),
        colors=color,
        radii=np.where(confirmed, 1.5, 0.7).reshape(flat),
    )  # fmt: skip
    half, quaternion = _ellipses(np.nan_to_num(trace.cov[..., :2, :2]))
    _send(
        rec, "world/tracks/ellipses", steps, shown, rr.Ellipsoids3D,
        centers=at.reshape(T, nu * K, 3),
        half_sizes=half.reshape(T, nu * K, 3),
        quaternions=quaternion.reshape(T, nu * K, 4),
        colors=color,
    )  # fmt: skip
    Z = trace.scan_valid.shape[2]
    ground = np.concatenate([trace.scan_z, np.zeros((T, nu, Z, 1))], axis=-1)
    seen = trace.scan_valid & trace.alive[..., None]
    clutter = trace.scan_origin == -1
    for entity, chosen, rgb in (
        ("world/scan/detections", seen & ~clutter, (230, 40, 40)),
        ("world/scan/clutter", seen & clutter, (150, 150, 150)),
    ):
        _send(
            rec, entity, steps, chosen.reshape(T, nu * Z), rr.Points3D,
            positions=ground.reshape(T, nu * Z, 3),
            colors=np.broadcast_to(np.array(rgb, np.uint8), (T, nu * Z, 3)),
            radii=np.full((T, nu * Z), 0.8),
        )  # fmt: skip


GEOMETRY = ("positions", "origins", "vectors", "centers", "half_sizes", "strips")
"""The fields that place an instance: NaN where it is not drawn."""


def _send(rec, entity: str, steps, shown: np.ndarray, archetype, **fields) -> None:
    """Every instance (T, n) at every step, as one column call: instance i is always the
    same UAV or target; where `shown` is False its geometry is NaN (not drawn)."""
    T, n = shown.shape
    picked = {}
    for name, value in fields.items():
        value = np.asarray(value)
        if name in GEOMETRY and not shown.all():
            hide = shown.reshape(shown.shape + (1,) * (value.ndim - 2))
            value = np.where(hide, value, np.nan)
        picked[name] = value.reshape((T * n,) + value.shape[2:])
    rec.send_columns(
        entity,
        indexes=[steps],
        columns=archetype.columns(**picked).partition(np.full(T, n)),
    )


def _colors(n: int) -> np.ndarray:
    """A colour per UAV (matplotlib's tab10, repeated), as RGB bytes."""
    from matplotlib import colormaps

    return (255 * np.asarray(colormaps["tab10"](np.arange(n) % 10))[:, :3]).astype(np.uint8)


def _ellipses(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Half sizes (2 sigma along each principal axis, flat) and rotations about z (as
    x, y, z, w quaternions) of the ellipses of 2 x 2 position covariances (..., 2, 2)."""
    values, vectors = np.linalg.eigh(cov)
    half = 2 * np.sqrt(np.maximum(values, 0.0))
    angle = np.arctan2(vectors[..., 1, 0], vectors[..., 0, 0])  # the first axis
    sizes = np.stack([half[..., 0], half[..., 1], np.full(half.shape[:-1], THIN)], axis=-1)
    zero = np.zeros_like(angle)
    quaternion = np.stack([zero, zero, np.sin(angle / 2), np.cos(angle / 2)], axis=-1)
    return sizes, quaternion


def _links(uavs: np.ndarray, alive: np.ndarray, comm_range: float):
    """Every step's radio links as two-point strips (all steps together) and their
    number per step; pairs from a k-d tree, kept by the radio model's own test."""
    # scipy's compiled k-d tree ships no type stubs; the class exists at run time
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]

    ends, counts = [], []
    for k in range(uavs.shape[0]):
        living = np.flatnonzero(alive[k])
        pos = uavs[k, living, :3]
        pairs = cKDTree(pos).query_pairs(comm_range * (1 + 1e-9) + 1e-9, output_type="ndarray")
        keep = in_range(pos[pairs[:, 0]] - pos[pairs[:, 1]], comm_range)
        pairs = pairs[keep]
        ends.append(np.stack([pos[pairs[:, 0]], pos[pairs[:, 1]]], axis=1))
        counts.append(len(pairs))
    return np.concatenate(ends) if ends else np.zeros((0, 2, 3)), np.asarray(counts)
