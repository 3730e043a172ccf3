"""A run as a ROS 2 bag (rosbag2 format 9, MCAP storage, ROS 2 Jazzy message types),
written with rosbags (the io extra): what ``ros2 bag play``, Foxglove, RViz and
PlotJuggler open.

Time: the simulated clock, step k at k dt seconds (also on ``/clock``, for
``use_sim_time``). Frame ``map``: x east, y north, z up [m] from the scenario's origin;
GPS fixes convert it to WGS84 around (`origin` lat, lon) [deg], flat (as
`io.mavlink.LocalFrame`). Topics:

* ``/clock`` rosgraph_msgs/msg/Clock, each step;
* ``/tf`` tf2_msgs/msg/TFMessage: ``map`` -> ``uav_i`` (its pose) and ``map`` ->
  ``target_j`` (true position, course as yaw);
* ``/uav_i/pose`` geometry_msgs/msg/PoseStamped, each UAV's true state, while it is
  alive: heading as yaw, the flown bank angle as REP-103's roll (positive: right wing
  down; `ros2.uav_pose`); ``/uav_i/fix`` sensor_msgs/msg/NavSatFix, its navigation's
  position (the truth without GPS error);
* ``/targets/truth`` visualization_msgs/msg/MarkerArray: a sphere per target (with
  targets that come and go, ``target.stay``, a DELETEALL first, then the targets
  present: one that left leaves the view);
* ``/team/target_j/estimate`` geometry_msgs/msg/PoseWithCovarianceStamped: the team's
  best estimate of target j (the most confident living UAV's, as the metrics take it),
  its x-y covariance in the 6 x 6 (z known: 0; rotations unknown: 1e9);
* ``/team/estimates`` MarkerArray: those estimates as 2-sigma ellipses (flat cylinders);
* ``/team/assignments`` MarkerArray: a line from each UAV to its target's estimate;
* ``/team/links`` MarkerArray: the radio links (3-D distance within r_C);
* ``/uav_i/odom`` nav_msgs/msg/Odometry: what the UAV's navigation says (with GPS error,
  ``faults.position_std``, the run's seed gives it), with that error's variance;
* ``/team/radar_tracks`` radar_msgs/msg/RadarTracks: the team's best estimates as data
  (`ros2.radar_tracks_of`), each under the UUID of its target (`ros2.track_uuid`).

A run of tracks (``tracker.association`` gnn or jpda) has no estimate per target: the
``/team/target_j/estimate`` and ``/team/estimates`` topics give way to

* ``/uav_i/tracks`` MarkerArray, each living UAV's tracks: a DELETEALL marker (RViz
  forgets the last step's), then per track a 2-sigma ellipse (flat cylinder, id = its team
  label, ns ``confirmed`` or ``tentative``, blue or grey) and a text marker (ns
  ``label``, id = the label, text ``L<label>``) above it;
* ``/uav_i/radar_scan`` radar_msgs/msg/RadarScan, the same as data in the UAV's frame
  (`ros2.radar_scan_of`), and ``/uav_i/radar_tracks`` its confirmed tracks, with
  ``/uav_i/radar_tracks/existence`` (std_msgs/msg/Float32MultiArray, `ros2.EXISTENCE`)
  each one's probability of existence, as ``/team/radar_tracks/existence`` the team's;
* ``/uav_i/scan`` MarkerArray, each living UAV's measurements of the step at their
  ground positions: two sphere lists, ns ``detections`` (red) and ``clutter`` (grey),
  split by the origin the simulator knows (for evaluation: a UAV does not);

each of their markers with a lifetime of two steps, and at the step a UAV fails a
DELETEALL alone on both topics: a failed UAV's tracks leave the view;

and ``/team/assignments`` draws a line from each UAV to its own estimate of the track it
follows.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RunError, install_hint

try:
    from rosbags.rosbag2 import StoragePlugin, Writer
except ImportError as exc:  # an optional extra
    raise ImportError(f"uavtrack.io.bag needs rosbags: {install_hint('io')} ({exc})") from None

from .._files import check_new_folder, new_folder
from ..config import G
from ..estimation import confidence
from ..faults import navigation
from ..metrics import team_best
from ..network import radio_links
from ..tracks.manage import CONFIRMED
from ..tracks.scoring import team_picture
from ..world import present
from .mavlink import LocalFrame
from .ros2 import (
    Markers,
    delete_all,
    ellipse_marker,
    estimate_of,
    existence_of,
    fix_of,
    header_of,
    lifetime_of,
    odometry_of,
    radar_scan_of,
    radar_tracks_of,
    track_markers,
    transform_of,
    uav_pose,
)


def write_bag(
    path: str | Path,
    trace,
    scenario,
    origin: tuple[float, float] = (0.0, 0.0),
    seed: int | None = None,
) -> dict[str, int]:
    """Write `trace` (of `scenario`) as a ROS 2 bag folder at `path`, which must not
    exist; it appears only once complete. Returns the messages written per topic. With
    GPS error (``faults.position_std``) the run's `seed` gives what each UAV's
    navigation told it (`faults.navigation`), for its fix and odometry."""
    if scenario.faults.position_std > 0 and seed is None:
        raise ValueError(
            "with faults.position_std the bag needs the run's seed (its GPS errors): "
            "give write_bag(..., seed=result.seed)"
        )
    path = check_new_folder(path, "--bag", "the bag")
    try:
        with new_folder(path) as folder:  # rosbags makes it: path.name.mcap inside
            return _write(folder, trace, scenario, origin, seed)
    except OSError as exc:
        raise RunError(f"cannot write the bag {path}: {exc.strerror or exc}") from None


def _write(folder: Path, trace, scenario, origin, seed) -> dict[str, int]:
    m = Markers()
    T, Nu = trace.uavs.shape[:2]
    dt_ns = int(round(scenario.dt * 1e9))
    frame = LocalFrame(*origin)
    variance = scenario.faults.position_std**2
    nav = trace.uavs if seed is None else navigation(scenario.faults, seed, trace.uavs)
    best = best_mean = best_cov = None
    if trace.label is None:
        best, best_mean, best_cov = team_best(trace.mean, trace.cov, trace.alive)
    counts: dict[str, int] = {}
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {}

        def topic(name: str, msgtype: str):
            if name not in connections:
                connections[name] = writer.add_connection(name, msgtype, typestore=m.store)
            return connections[name]

        def write(name: str, message, ns: int) -> None:
            writer.write(topic(name, message.__msgtype__), ns, m.serialize(message))
            counts[name] = counts.get(name, 0) + 1

        T_ = m.T
        everyone = bool(present(trace.targets).all())  # else targets come and go
        for k in range(T):
            ns = k * dt_ns
            stamp = m.header(ns).stamp
            write("/clock", T_["rosgraph_msgs/msg/Clock"](clock=stamp), ns)
            uavs, targets, alive = trace.uavs[k], trace.targets[k], trace.alive[k]
            transforms = []
            for i in np.flatnonzero(alive):
                pose = uav_pose(uavs[i], trace.action[k, i])
                write(f"/uav_{i}/pose", T_["geometry_msgs/msg/PoseStamped"](
                    header=m.header(ns), pose=pose), ns)  # fmt: skip
                x, y, h = (float(v) for v in nav[k, i, :3])  # what its navigation says
                lat, lon = frame.to_latlon(x, y)
                write(f"/uav_{i}/fix", fix_of(m.header(ns, f"uav_{i}"), lat, lon, h, variance), ns)
                odometry = odometry_of(
                    m.header(ns), f"uav_{i}", nav[k, i], trace.action[k, i], variance, G
                )
                write(f"/uav_{i}/odom", odometry, ns)
                transforms.append(transform_of(m.header(ns), f"uav_{i}", pose))
            # with targets that come and go (NaN while away) RViz forgets the last step's
            truth = [] if everyone else delete_all(m, ns)
            for j in map(int, np.flatnonzero(present(targets))):  # away: no pose
                x, y, vx, vy = (float(v) for v in targets[j])
                course = math.atan2(vy, vx)
                place = m.pose(x, y, 0.0, course)
                transforms.append(transform_of(m.header(ns), f"target_{j}", place))
                truth.append(m.marker(ns, "truth", j, 2, place,
                                      (4.0, 4.0, 4.0), (1.0, 0.2, 0.2, 1.0)))  # fmt: skip
            write("/tf", T_["tf2_msgs/msg/TFMessage"](transforms=transforms), ns)
            write("/targets/truth", T_["visualization_msgs/msg/MarkerArray"](markers=truth), ns)
            if trace.label is None:
                ellipses, lines = _estimates(m, ns, write, trace, k, best, best_mean, best_cov)
                write("/team/estimates", T_["visualization_msgs/msg/MarkerArray"](
                    markers=ellipses), ns)  # fmt: skip
            else:
                lines = _tracks(m, ns, write, trace, k, scenario.dt)
            _radar(ns, write, trace, k, nav, best, best_mean, best_cov)
            write("/team/assignments", T_["visualization_msgs/msg/MarkerArray"](markers=[
                m.marker(ns, "assignment", 0, 5, m.pose(0, 0, 0, 0), (0.5, 0, 0),
                         (0.2, 0.9, 0.2, 0.8), lines)]), ns)  # fmt: skip
            step = slice(k, k + 1)  # one step at a time: memory of one graph
            links = radio_links(trace.uavs[step], trace.alive[step], scenario.comm_range, "dense")
            a, b = np.nonzero(np.triu(links.adjacency()[0], 1))
            ends = [p for pair in zip(uavs[a, :3], uavs[b, :3], strict=True) for p in pair]
            write("/team/links", T_["visualization_msgs/msg/MarkerArray"](markers=[
                m.marker(ns, "link", 0, 5, m.pose(0, 0, 0, 0), (0.3, 0, 0),
                         (0.9, 0.9, 0.9, 0.6), ends)]), ns)  # fmt: skip
    return counts


def _radar(ns: int, write, trace, k: int, nav, best, best_mean, best_cov) -> None:
    """The tracks of step k as data: with tracks each living UAV's confirmed ones
    (`/uav_<i>/radar_tracks`, under their team labels), and the team's picture
    (`/team/radar_tracks`: per label the most confident living UAV's, `team_picture`;
    per target the team's best, `team_best`) and with tracks each UAV's scan
    (`/uav_<i>/radar_scan`, in its frame from where its navigation places it)."""
    alive = trace.alive[k]
    mean, cov = trace.mean[k], trace.cov[k]
    header = header_of(ns)
    if trace.label is None:  # as the estimates: the team's (each UAV's: 1.2 GB at 1000 UAVs)
        held = np.flatnonzero(best[k] >= 0)
        team = radar_tracks_of(header, held, best_mean[k, held], best_cov[k, held])
        write("/team/radar_tracks", team, ns)
        return
    label, status = trace.label[k], trace.status[k]
    confirmed = (status == CONFIRMED) & alive[:, None]
    for i in np.flatnonzero(alive):
        own = np.flatnonzero(confirmed[i])
        tracks = radar_tracks_of(header, label[i, own], mean[i, own], cov[i, own])
        write(f"/uav_{i}/radar_tracks", tracks, ns)
        if trace.existence is not None:  # its companion: a trace of format 4 has it
            write(f"/uav_{i}/radar_tracks/existence", existence_of(trace.existence[k, i, own]), ns)
        valid = trace.scan_valid[k, i]
        scan = radar_scan_of(
            header_of(ns, f"uav_{i}"), nav[k, i], trace.action[k, i], trace.scan_z[k, i][valid],
            trace.scan_polar[k, i][valid, 1],
        )  # fmt: skip
        write(f"/uav_{i}/radar_scan", scan, ns)
    N, K = label.shape
    where = np.stack(np.meshgrid(np.arange(N), np.arange(K), indexing="ij"), -1)  # (N, K, 2)
    picked, at, held = team_picture(
        label[None], confirmed[None], where[None].astype(float), confidence(cov)[None]
    )
    uav, slot = at[0, held[0]].astype(int).T
    team = radar_tracks_of(header, picked[0, held[0]], mean[uav, slot], cov[uav, slot])
    write("/team/radar_tracks", team, ns)
    if trace.existence is not None:
        write("/team/radar_tracks/existence", existence_of(trace.existence[k, uav, slot]), ns)


def _estimates(m: Markers, ns: int, write, trace, k: int, best, best_mean, best_cov):
    """The team's best estimate of each target at step k (its topic), and the ellipses and
    the assignment lines of the step."""
    uavs, alive = trace.uavs[k], trace.alive[k]
    ellipses = []
    for j in np.flatnonzero(best[k] >= 0):
        P = best_cov[k, j]
        write(f"/team/target_{j}/estimate", estimate_of(m.header(ns), best_mean[k, j], P), ns)
        ellipses.append(ellipse_marker(m, ns, "estimate", int(j), best_mean[k, j], P,
                                        (0.2, 0.6, 1.0, 0.5)))  # fmt: skip
    lines = []
    for i in np.flatnonzero(alive & (trace.assignment[k] >= 0)):
        j = int(trace.assignment[k, i])
        if best[k, j] >= 0:
            lines += [uavs[i, :3], (*best_mean[k, j, :2], 0.0)]
    return ellipses, lines


def _tracks(m: Markers, ns: int, write, trace, k: int, dt: float) -> list:
    """Each living UAV's tracks and scan at step k (their topics); the assignment lines,
    from each UAV to its own estimate of the track it follows."""
    MarkerArray = m.T["visualization_msgs/msg/MarkerArray"]
    lifetime = lifetime_of(dt)
    lines = []
    if k > 0:  # a UAV failed at this step: its tracks and scan go from the view
        for i in np.flatnonzero(trace.alive[k - 1] & ~trace.alive[k]):
            write(f"/uav_{i}/tracks", MarkerArray(markers=delete_all(m, ns)), ns)
            write(f"/uav_{i}/scan", MarkerArray(markers=delete_all(m, ns)), ns)
    for i in np.flatnonzero(trace.alive[k]):
        label, status = trace.label[k, i], trace.status[k, i]
        markers = track_markers(m, ns, label, status, trace.mean[k, i], trace.cov[k, i], lifetime)
        followed = np.flatnonzero((status == CONFIRMED) & (label == trace.assignment[k, i]))
        for s in followed:
            lines += [trace.uavs[k, i, :3], (*trace.mean[k, i, s, :2], 0.0)]
        write(f"/uav_{i}/tracks", MarkerArray(markers=markers), ns)
        valid = trace.scan_valid[k, i]
        clutter = trace.scan_origin[k, i] == -1
        where = np.concatenate([trace.scan_z[k, i], np.zeros((len(valid), 1))], axis=1)
        scan: list[Any] = [
            m.marker(ns, name, n, 7, m.pose(0, 0, 0, 0), (2.0, 2.0, 2.0), rgba, where[chosen],
                     lifetime=lifetime)  # fmt: skip
            for n, (name, chosen, rgba) in enumerate(
                (("detections", valid & ~clutter, (1.0, 0.2, 0.2, 1.0)),
                 ("clutter", valid & clutter, (0.6, 0.6, 0.6, 1.0)))
            )
        ]  # fmt: skip
        write(f"/uav_{i}/scan", MarkerArray(markers=scan), ns)
    return lines
