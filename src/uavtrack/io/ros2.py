"""ROS 2 topics over Zenoh in rmw_zenoh's conventions, so that a ROS 2 node using
rmw_zenoh_cpp (Jazzy and later) can discover and read what a swarm publishes
(``uavtrack swarm --ros2 DOMAIN``, ``uavtrack agent --ros2 DOMAIN``): each UAV program its
pose, its transform on ``/tf`` and its estimates (`UavNode`), the world program the
simulated clock on ``/clock`` (`ClockNode`), so a node with ``use_sim_time`` reads the
header stamps on the clock they were taken by.

What rmw_zenoh expects, and what `Node` does (rmw_zenoh's design document and its
liveliness and attachment helpers):

* **Data key** ``<domain>/<topic without its leading slash>/<type>/<type hash>``, the type
  in DDS form (``geometry_msgs::msg::dds_::PoseStamped_``) and its hash ROS 2's RIHS01
  (``RIHS01_<sha256 hex>``, computed by rosbags from the message definitions).
* **Payload** the message in CDR (little-endian, with its 4-byte encapsulation header),
  serialised by rosbags.
* **Attachment** zenoh-ext serialised: the text ``sequence_number`` and an int64 (from
  1), ``source_timestamp`` and an int64 [ns] (the wall clock when the sample is put, as
  rmw_zenoh takes it from the system clock; the simulated time is in the header),
  ``source_gid`` and 16 bytes (strings as a LEB128 length and UTF-8 bytes, integers as
  8 bytes little-endian, the gid as a fixed array).
* **Liveliness tokens** under ``@ros2_lv/<domain>/<session id>/<node id>/<entity id>/``:
  ``NN/<enclave>/<namespace>/<node>`` for the node, and ``MP/<enclave>/<namespace>/<node>/
  <topic>/<type>/<type hash>/<qos>`` for each publisher, names with ``/`` written ``%``
  (empty: ``%``), the QoS the default (reliable, volatile, keep last 10), written
  ``::,:,:,:,,`` (every field at its default left empty). The entity ids of a session
  are distinct: the node's is its node id, its publishers' the ones after it.

The gid is the first 16 bytes of the SHA-256 of the publisher's token (rmw_zenoh takes
an XXH3-128 of it; subscribers only compare gids).

Orientation follows REP-103: frame ``map`` east-north-up, a UAV's body frame x forward,
y left, z up, so yaw is the heading (counter-clockwise from east) and a positive roll
lowers the right wing, a turn to the right. Eq. (1)'s bank angle turns the heading by
g dT tan(phi) / V, to the left when positive: the roll published is -phi (`uav_pose`, the
one builder of a UAV's orientation for the bag and the live topics). Needs rosbags (the
io extra).
"""

from __future__ import annotations

import functools
import hashlib
import math
import struct
import time
import uuid
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import install_hint
from ..tracks.manage import CONFIRMED, STATUS_NAMES, TENTATIVE
from .mavlink import LocalFrame

try:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
except ImportError as exc:  # an optional extra
    raise ImportError(f"uavtrack.io.ros2 needs rosbags: {install_hint('io')} ({exc})") from None

ADMIN_SPACE = "@ros2_lv"
DEFAULT_QOS = "::,:,:,:,,"
"""rmw_zenoh's QoS field of a token when every policy is the default: reliable, volatile,
keep last 10, no deadline, lifespan or liveliness lease."""
POSE = "geometry_msgs/msg/PoseStamped"
ESTIMATE = "geometry_msgs/msg/PoseWithCovarianceStamped"
CLOCK = "rosgraph_msgs/msg/Clock"
TF = "tf2_msgs/msg/TFMessage"
MARKERS = "visualization_msgs/msg/MarkerArray"
RADAR_TRACKS = "radar_msgs/msg/RadarTracks"
RADAR_SCAN = "radar_msgs/msg/RadarScan"
EXISTENCE = "std_msgs/msg/Float32MultiArray"
"""The companion of a RadarTracks message, which has no field for it: on the topic
``<tracks topic>/existence`` at the same stamp, each track's probability of existence in
the order of its ``tracks`` (`existence_of`)."""
ODOMETRY = "nav_msgs/msg/Odometry"
FIX = "sensor_msgs/msg/NavSatFix"
FRAME = "map"
UNKNOWN = 1e9  # [rad^2] the variance of a rotation nobody estimates

RADAR_MSGS = {
    "radar_msgs/msg/RadarTrack": """
uint16 NO_CLASSIFICATION=0
uint16 STATIC=1
uint16 DYNAMIC=2
unique_identifier_msgs/UUID uuid
geometry_msgs/Point position
geometry_msgs/Vector3 velocity
geometry_msgs/Vector3 acceleration
geometry_msgs/Vector3 size
uint16 classification
float32[6] position_covariance
float32[6] velocity_covariance
float32[6] acceleration_covariance
float32[6] size_covariance
""",
    RADAR_TRACKS: "std_msgs/Header header\nradar_msgs/RadarTrack[] tracks\n",
    "radar_msgs/msg/RadarReturn": """
float32 range
float32 azimuth
float32 elevation
float32 doppler_velocity
float32 amplitude
""",
    RADAR_SCAN: "std_msgs/Header header\nradar_msgs/RadarReturn[] returns\n",
}
"""The message types of ROS 2's radar_msgs package (0.2.2; Jazzy's rosbags store lacks
them), as its .msg files declare their fields: rosbags registers them from this text and
computes their RIHS01 hashes as ROS 2 does, from the fields."""

DYNAMIC = 2
"""radar_msgs/RadarTrack's classification of a moving object."""

TRACKS_NAMESPACE = uuid.UUID("6f0d5a3e-3c1b-5b8e-9a57-0d2c7e4b1a90")
"""The namespace of the tracks' UUIDs (`track_uuid`)."""

_STORE = None


def store():
    """rosbags' ROS 2 Jazzy type store (its message definitions and hashes), with
    radar_msgs registered (`RADAR_MSGS`)."""
    global _STORE
    if _STORE is None:
        typestore = get_typestore(Stores.ROS2_JAZZY)
        types: dict[str, Any] = {}
        for name, text in RADAR_MSGS.items():
            types.update(get_types_from_msg(text, name))
        typestore.register(types)
        _STORE = typestore
    return _STORE


def dds_type(msgtype: str) -> str:
    """``geometry_msgs/msg/PoseStamped`` -> ``geometry_msgs::msg::dds_::PoseStamped_``."""
    package, kind, name = msgtype.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def type_hash(msgtype: str) -> str:
    """ROS 2's RIHS01 type hash of a message type."""
    return store().hash_rihs01(msgtype)


def mangle(name: str) -> str:
    """A ROS 2 name as one key chunk: ``/`` written ``%`` (the empty name: ``%``)."""
    return name.replace("/", "%") or "%"


def topic_key(domain: int, topic: str, msgtype: str) -> str:
    """The Zenoh key a ROS 2 topic's samples are put on."""
    return f"{domain}/{topic.strip('/')}/{dds_type(msgtype)}/{type_hash(msgtype)}"


def node_token(domain: int, zid: str, node_id: int, namespace: str, node: str) -> str:
    return (
        f"{ADMIN_SPACE}/{domain}/{zid}/{node_id}/{node_id}/NN/%/{mangle(namespace)}/{mangle(node)}"
    )


def publisher_token(
    domain: int, zid: str, node_id: int, entity_id: int, namespace: str, node: str,
    topic: str, msgtype: str,
) -> str:  # fmt: skip
    return (
        f"{ADMIN_SPACE}/{domain}/{zid}/{node_id}/{entity_id}/MP/%/{mangle(namespace)}/"
        f"{mangle(node)}/{mangle(topic)}/{dds_type(msgtype)}/{type_hash(msgtype)}/{DEFAULT_QOS}"
    )


def gid(token: str) -> bytes:
    return hashlib.sha256(token.encode()).digest()[:16]


def attachment(sequence: int, timestamp_ns: int, source_gid: bytes) -> bytes:
    """rmw_zenoh's attachment of one sample, zenoh-ext serialised (see the module)."""
    if len(source_gid) != 16:
        raise ValueError("a gid has 16 bytes")
    out = bytearray()
    for key, value in (("sequence_number", sequence), ("source_timestamp", timestamp_ns)):
        out += _text(key) + struct.pack("<q", value)
    return bytes(out + _text("source_gid") + source_gid)


def read_attachment(data: bytes) -> tuple[int, int, bytes]:
    """(sequence, timestamp [ns], gid) of an attachment `attachment` wrote."""
    view, values = memoryview(data), []
    for key in ("sequence_number", "source_timestamp"):
        name, view = _read_text(view)
        if name != key:
            raise ValueError(f"expected {key}, found {name!r}")
        values.append(struct.unpack("<q", view[:8])[0])
        view = view[8:]
    name, view = _read_text(view)
    if name != "source_gid" or len(view) != 16:
        raise ValueError("expected source_gid and 16 bytes")
    return values[0], values[1], bytes(view)


def _text(text: str) -> bytes:
    raw = text.encode()
    return _leb128(len(raw)) + raw


def _leb128(n: int) -> bytes:
    out = bytearray()
    while True:
        byte, n = n & 0x7F, n >> 7
        out.append(byte | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _read_text(view: memoryview) -> tuple[str, memoryview]:
    n = shift = i = 0
    while True:
        byte = view[i]
        n |= (byte & 0x7F) << shift
        shift, i = shift + 7, i + 1
        if not byte & 0x80:
            break
    return bytes(view[i : i + n]).decode(), view[i + n :]


@dataclass(kw_only=True)
class _Publisher:
    key: str
    token: str
    gid: bytes
    sequence: int = 0
    handle: Any = None


class Node:
    """A ROS 2 node ``<namespace>/<name>`` on a Zenoh session, in rmw_zenoh's conventions:
    its node token, and for each of `topics` (topic -> message type) a publisher with its
    token, key and gid. Closing it (or the session ending) drops the tokens: the node
    leaves the ROS 2 graph."""

    def __init__(
        self, session, domain: int, node_id: int, namespace: str, name: str,
        topics: dict[str, str],
    ) -> None:  # fmt: skip
        self.session, self.domain = session, domain
        zid = str(session.zid())
        self.tokens = [
            session.liveliness().declare_token(node_token(domain, zid, node_id, namespace, name))
        ]
        self.publishers: dict[str, _Publisher] = {}
        for entity, (topic, msgtype) in enumerate(topics.items(), start=node_id + 1):
            token = publisher_token(domain, zid, node_id, entity, namespace, name, topic, msgtype)
            key = topic_key(domain, topic, msgtype)
            self.tokens.append(session.liveliness().declare_token(token))
            handle = session.declare_publisher(key)
            self.publishers[topic] = _Publisher(key=key, token=token, gid=gid(token), handle=handle)

    def put(self, topic: str, message) -> None:
        """Put `message` on `topic`, its attachment stamped with the wall clock [ns]."""
        p = self.publishers[topic]
        p.sequence += 1
        payload = bytes(store().serialize_cdr(message, message.__msgtype__))
        p.handle.put(payload, attachment=attachment(p.sequence, time.time_ns(), p.gid))

    def close(self) -> None:
        """Undeclare the publishers and the tokens (once; later calls do nothing)."""
        publishers, tokens = list(self.publishers.values()), self.tokens
        self.publishers, self.tokens = {}, []
        for item in [p.handle for p in publishers] + tokens:
            try:
                item.undeclare()
            except Exception:  # already gone with its session
                pass


class UavNode(Node):
    """One UAV program as the ROS 2 node ``/uavtrack/uav_<i>``: ``/uav_<i>/pose``
    (PoseStamped, `uav_pose`), its transform ``map`` -> ``uav_<i>`` on ``/tf``
    (TFMessage, the same pose) and ``/uav_<i>/target_<j>/estimate``
    (PoseWithCovarianceStamped, `estimate_of`), stamped with the simulated clock (step k
    at k dt), in frame ``map``. With tracks (``tracks=True``: tracker.association gnn or
    jpda) the estimates are ``/uav_<i>/tracks`` instead (MarkerArray, `track_markers`:
    each track's ellipse with its team label as id, as in the bag). As data, as in the
    bag: ``/uav_<i>/odom`` (Odometry, `odometry_of`, with the GPS error's `variance`),
    ``/uav_<i>/fix`` (NavSatFix around latitude and longitude 0), ``/uav_<i>/radar_tracks``
    (RadarTracks, `radar_tracks_of`) and with tracks ``/uav_<i>/radar_scan`` (RadarScan,
    `radar_scan_of`) and ``/uav_<i>/radar_tracks/existence`` (`EXISTENCE`). Everything
    from what the UAV believes: its navigation's state."""

    def __init__(
        self, session, domain: int, uav: int, n_targets: int, dt: float, tracks: bool = False,
        variance: float = 0.0, g: float = 9.81,
    ) -> None:  # fmt: skip
        me = f"/uav_{uav}"
        topics = {f"{me}/pose": POSE, "/tf": TF, f"{me}/odom": ODOMETRY, f"{me}/fix": FIX}
        topics[f"{me}/radar_tracks"] = RADAR_TRACKS
        if tracks:
            topics.update({f"{me}/tracks": MARKERS, f"{me}/radar_scan": RADAR_SCAN})
            topics[f"{me}/radar_tracks/existence"] = EXISTENCE
        else:
            topics.update({f"{me}/target_{j}/estimate": ESTIMATE for j in range(n_targets)})
        super().__init__(session, domain, uav, "/uavtrack", f"uav_{uav}", topics)
        self.uav, self.dt, self.variance, self.g = uav, dt, variance, g
        self.markers = Markers() if tracks else None
        self.last = -1  # the last step published

    def clear(self) -> None:
        """With tracks: take this UAV's tracks from the view (a DELETEALL at the step
        after its last), as its program ends before the run does (failed, lost)."""
        if self.markers is not None and self.last >= 0:
            markers = delete_all(self.markers, sim_ns(self.last + 1, self.dt))
            self.put(f"/uav_{self.uav}/tracks", store().types[MARKERS](markers=markers))

    def publish(
        self, k: int, uav: np.ndarray, bank: float, mean, cov, label=None, status=None,
        scan: np.ndarray | None = None, existence: np.ndarray | None = None,
    ) -> None:  # fmt: skip
        """Step k: the UAV's state (x, y, h, V, heading), the bank angle it flies
        (eq. 1, positive left) and its estimates (Nt, 4), covariances (Nt, 4, 4); with
        tracks, its slots' (K, ...) with their labels, status and existence (K,) and its
        scan's ground positions (Z, 2)."""
        T = store().types
        ns = sim_ns(k, self.dt)
        header = header_of(ns)
        me = f"/uav_{self.uav}"
        pose = uav_pose(uav, bank)
        self.put(f"{me}/pose", T[POSE](header=header, pose=pose))
        self.put("/tf", T[TF](transforms=[transform_of(header, f"uav_{self.uav}", pose)]))
        child = f"uav_{self.uav}"
        self.put(f"{me}/odom", odometry_of(header, child, uav, bank, self.variance, self.g))
        lat, lon = LocalFrame().to_latlon(float(uav[0]), float(uav[1]))  # around (0, 0)
        self.put(f"{me}/fix", fix_of(header_of(ns, child), lat, lon, float(uav[2]), self.variance))
        if self.markers is not None:
            lifetime = lifetime_of(self.dt)
            markers = track_markers(self.markers, ns, label, status, mean, cov, lifetime)
            self.put(f"{me}/tracks", T[MARKERS](markers=markers))
            own = np.flatnonzero(np.asarray(status) == CONFIRMED)
            tracks = radar_tracks_of(header, np.asarray(label)[own], mean[own], cov[own])
            self.put(f"{me}/radar_tracks", tracks)
            if existence is not None:
                self.put(f"{me}/radar_tracks/existence", existence_of(np.asarray(existence)[own]))
            ground = np.zeros((0, 2)) if scan is None else scan
            self.put(f"{me}/radar_scan", radar_scan_of(header_of(ns, child), uav, bank, ground))
            self.last = k
            return
        self.put(f"{me}/radar_tracks", radar_tracks_of(header, np.arange(len(mean)), mean, cov))
        for j in range(len(mean)):
            self.put(f"{me}/target_{j}/estimate", estimate_of(header, mean[j], cov[j]))


class ClockNode(Node):
    """The world program as the ROS 2 node ``/uavtrack/world``, publishing the simulated
    clock on ``/clock`` (rosgraph_msgs/Clock, step k at k dt), as a simulator does for the
    nodes that run with ``use_sim_time``."""

    def __init__(self, session, domain: int, dt: float) -> None:
        super().__init__(session, domain, 0, "/uavtrack", "world", {"/clock": CLOCK})
        self.dt = dt

    def publish(self, k: int) -> None:
        """The clock at the start of step k."""
        self.put("/clock", store().types[CLOCK](clock=header_of(sim_ns(k, self.dt)).stamp))


def sim_ns(k: int, dt: float) -> int:
    """The simulated clock at step k [ns]: k dt."""
    return int(round(k * dt * 1e9))


def header_of(ns: int, frame: str = FRAME) -> Any:
    """A std_msgs/Header stamped `ns` nanoseconds of the simulated clock, in `frame` (of
    a class rosbags makes from the message definitions: Any to a checker)."""
    T = store().types
    stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


def pose_of(x: float, y: float, z: float, yaw: float, roll: float = 0.0):
    """A geometry_msgs/Pose at (x, y, z), turned by roll about the body's x (forward) axis
    then yaw about z (up): the quaternion q_z(yaw) q_x(roll)."""
    T = store().types
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z),
        orientation=T["geometry_msgs/msg/Quaternion"](x=sr * cy, y=sr * sy, z=cr * sy, w=cr * cy),
    )


def uav_pose(uav: np.ndarray, bank: float):
    """The geometry_msgs/Pose of a UAV in REP-103's frames: position (x, y, h), yaw the
    heading, roll -`bank` (eq. 1's bank turns left when positive; REP-103's roll turns
    right). uav: (5,) x, y, h, V, heading."""
    x, y, h, _, heading = (float(v) for v in uav)
    return pose_of(x, y, h, heading, 0.0 - float(bank))  # level flight: roll +0, not -0


def transform_of(header, child: str, pose):
    """A geometry_msgs/TransformStamped from `header`'s frame to `child`, placed at `pose`."""
    T = store().types
    p = pose.position
    return T["geometry_msgs/msg/TransformStamped"](
        header=header,
        child_frame_id=child,
        transform=T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=p.x, y=p.y, z=p.z),
            rotation=pose.orientation,
        ),
    )


def estimate_of(header, mean: np.ndarray, P: np.ndarray):
    """A target estimate (x, y, vx, vy) with covariance P (4, 4) as a
    PoseWithCovarianceStamped on the ground: the x-y block in the 6 x 6, z known (0),
    rotations unknown (`UNKNOWN`)."""
    T = store().types
    covariance = np.zeros(36)
    covariance[[0, 1, 6, 7]] = P[0, 0], P[0, 1], P[1, 0], P[1, 1]
    covariance[[21, 28, 35]] = UNKNOWN
    return T[ESTIMATE](
        header=header,
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=pose_of(float(mean[0]), float(mean[1]), 0.0, 0.0), covariance=covariance
        ),
    )


def track_uuid(label: int) -> np.ndarray:
    """The UUID (16 bytes) of the track under team label `label` (with known association,
    of target `label`): a UUID 5 of the label's number in `TRACKS_NAMESPACE`, the same
    for every UAV, every step and every run."""
    return np.frombuffer(_uuid_bytes(int(label)), np.uint8).copy()


@functools.lru_cache(maxsize=65536)
def _uuid_bytes(label: int) -> bytes:
    return uuid.uuid5(TRACKS_NAMESPACE, str(label)).bytes


def _body(uav: np.ndarray, bank: float) -> np.ndarray:
    """The rotation (3, 3) from a UAV's body frame (REP-103: x forward, y left, z up, as
    `uav_pose` orients it: yaw the heading, roll -bank) to the map's."""
    yaw, roll = float(uav[4]), -float(bank)
    cy, sy, cr, sr = math.cos(yaw), math.sin(yaw), math.cos(roll), math.sin(roll)
    return np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
        [[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]]
    )


def _upper(P: np.ndarray) -> np.ndarray:
    """A ground block P (2, 2) as radar_msgs' upper triangle of x, y, z (z known: 0)."""
    return np.array([P[0, 0], P[0, 1], 0.0, P[1, 1], 0.0, 0.0], dtype=np.float32)


def existence_of(values: np.ndarray):
    """A std_msgs/Float32MultiArray of the tracks' existence probabilities (n,), one
    dimension labelled ``tracks`` (`EXISTENCE`)."""
    T = store().types
    n = len(values)
    dim = T["std_msgs/msg/MultiArrayDimension"](label="tracks", size=n, stride=n)
    layout = T["std_msgs/msg/MultiArrayLayout"](dim=[dim], data_offset=0)
    return T[EXISTENCE](layout=layout, data=np.asarray(values, dtype=np.float32))


def radar_tracks_of(header, labels, mean: np.ndarray, cov: np.ndarray):
    """A radar_msgs/RadarTracks of tracks under team `labels` (n,), each estimate (x, y,
    vx, vy) with covariance (4, 4): on the ground (z 0, known), the position and velocity
    blocks as float32 upper triangles (their cross-covariance is not in the message),
    classification DYNAMIC, acceleration and size 0."""
    T = store().types
    Point, Vector3 = T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Vector3"]
    zero, none = Vector3(x=0.0, y=0.0, z=0.0), np.zeros(6, dtype=np.float32)
    tracks: list[Any] = [
        T["radar_msgs/msg/RadarTrack"](
            uuid=T["unique_identifier_msgs/msg/UUID"](uuid=track_uuid(label)),
            position=Point(x=float(m[0]), y=float(m[1]), z=0.0),
            velocity=Vector3(x=float(m[2]), y=float(m[3]), z=0.0),
            acceleration=zero,
            size=zero,
            classification=DYNAMIC,
            position_covariance=_upper(P[:2, :2]),
            velocity_covariance=_upper(P[2:, 2:]),
            acceleration_covariance=none,
            size_covariance=none,
        )
        for label, m, P in zip(labels, mean, cov, strict=True)
    ]
    return T[RADAR_TRACKS](header=header, tracks=tracks)


NADIR = 1e-3
"""How far off the nadir [m] a return's ground point is placed when the conversion put
it at the nadir (a range shorter than the altitude): toward its measured bearing, which
the float32 direction then keeps to about 0.05 rad (`radar_scan_of`)."""


def radar_scan_of(
    header, uav: np.ndarray, bank: float, z: np.ndarray, bearing: np.ndarray | None = None
):
    """A radar_msgs/RadarScan of one UAV's measurements in its body frame (the header's,
    ``uav_<i>``, as ``/tf`` places it: heading and roll, `uav_pose`): each ground
    position z (n, 2), less the UAV's position (x, y, h, V, heading; what its sensor
    measured), as range, azimuth (counter-clockwise from the nose, REP-103) and elevation
    (below: negative); no Doppler or amplitude (0). With the measured `bearing` (n,)
    [rad], a point within `NADIR` of the nadir moves to `NADIR` off it toward that
    bearing, so that a reader gets the bearing back (`io.recording.from_bag`)."""
    T = store().types
    offset = np.column_stack([z[:, 0] - uav[0], z[:, 1] - uav[1], np.full(len(z), -uav[2])])
    if bearing is not None:
        near = np.hypot(offset[:, 0], offset[:, 1]) < NADIR
        offset[near, 0], offset[near, 1] = (
            NADIR * np.cos(bearing[near]),
            NADIR * np.sin(bearing[near]),
        )
    body = offset @ _body(uav, bank)  # each row turned into the body frame
    returns: list[Any] = [
        T["radar_msgs/msg/RadarReturn"](
            range=float(np.linalg.norm(b)),
            azimuth=float(math.atan2(b[1], b[0])),
            elevation=float(math.atan2(b[2], math.hypot(b[0], b[1]))),
            doppler_velocity=0.0,
            amplitude=0.0,
        )
        for b in body
    ]
    return T[RADAR_SCAN](header=header, returns=returns)


FIX_KNOWN = 2
"""sensor_msgs/NavSatFix's COVARIANCE_TYPE_DIAGONAL_KNOWN."""


def fix_of(header, lat: float, lon: float, altitude: float, variance: float):
    """A sensor_msgs/NavSatFix at (lat, lon) [deg] and `altitude` [m], with the variance
    [m^2] of its east and north errors (the GPS error's; 0: no error, type unknown)."""
    T = store().types
    return T["sensor_msgs/msg/NavSatFix"](
        header=header,
        status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
        latitude=lat,
        longitude=lon,
        altitude=altitude,
        position_covariance=np.diag([variance, variance, 0.0]).ravel(),
        position_covariance_type=FIX_KNOWN if variance > 0 else 0,
    )


def odometry_of(header, child: str, uav: np.ndarray, bank: float, variance: float, g: float):
    """A nav_msgs/Odometry of a UAV (x, y, h, V, heading) flying `bank` (eq. 1): its pose
    (`uav_pose`) in the header's frame with position variance `variance` [m^2] on x and y
    (its GPS error's; the altitude and the rotations known: 0); its twist in its body
    frame `child`: V forward, and the turn rate g tan(bank) / V about the map's z turned
    into that frame (the body is rolled), known (0)."""
    T = store().types
    covariance = np.zeros(36)
    covariance[[0, 7]] = variance  # the GPS error is east and north; the altitude exact
    V = float(uav[3])
    Vector3 = T["geometry_msgs/msg/Vector3"]
    spin = _body(uav, bank).T @ np.array([0.0, 0.0, g * math.tan(float(bank)) / V])
    twist = T["geometry_msgs/msg/Twist"](
        linear=Vector3(x=V, y=0.0, z=0.0),
        angular=Vector3(x=float(spin[0]), y=float(spin[1]), z=float(spin[2])),
    )
    return T[ODOMETRY](
        header=header,
        child_frame_id=child,
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=uav_pose(uav, bank), covariance=covariance
        ),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
    )


class Markers:
    """Builders of the visualisation messages (the bag's and the live tracks'), from one
    typestore."""

    def __init__(self) -> None:
        self.store = store()
        t = self.store.types
        self.T = t
        self.Duration = t["builtin_interfaces/msg/Duration"]
        self.Point = t["geometry_msgs/msg/Point"]
        self.Vector3 = t["geometry_msgs/msg/Vector3"]
        self.Color = t["std_msgs/msg/ColorRGBA"]

    def header(self, ns: int, frame: str = FRAME) -> Any:
        return header_of(ns, frame)

    def pose(self, x: float, y: float, z: float, yaw: float):
        return pose_of(x, y, z, yaw)

    def marker(
        self, ns_time: int, ns: str, ident: int, kind: int, pose, scale, rgba, points=(),
        text: str = "", action: int = 0, lifetime: int = 0,
    ):  # fmt: skip
        """A visualization_msgs/Marker stamped `ns_time`; lifetime [ns] (0: until replaced)."""
        T = self.T
        return T["visualization_msgs/msg/Marker"](
            header=self.header(ns_time),
            ns=ns,
            id=ident,
            type=kind,
            action=action,
            pose=pose,
            scale=self.Vector3(x=scale[0], y=scale[1], z=scale[2]),
            color=self.Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]),
            lifetime=self.Duration(sec=lifetime // 10**9, nanosec=lifetime % 10**9),
            frame_locked=False,
            points=[self.Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in points],
            colors=[],
            texture_resource="",
            texture=T["sensor_msgs/msg/CompressedImage"](
                header=self.header(ns_time), format="", data=np.zeros(0, np.uint8)
            ),
            uv_coordinates=[],
            text=text,
            mesh_resource="",
            mesh_file=T["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, np.uint8)),
            mesh_use_embedded_materials=False,
        )

    def serialize(self, message) -> memoryview:
        return self.store.serialize_cdr(message, message.__msgtype__)


TRACK_COLOURS = {TENTATIVE: (0.6, 0.6, 0.6, 0.4), CONFIRMED: (0.2, 0.6, 1.0, 0.6)}
"""A track's ellipse colour by status: tentative grey, confirmed blue."""


def lifetime_of(dt: float) -> int:
    """How long a UAV's track and scan markers stay [ns]: two steps, so that those of a
    UAV that failed, or whose program ended, go from the view by themselves."""
    return sim_ns(2, dt)


def delete_all(m: Markers, ns: int) -> list[Any]:
    """The markers of a MarkerArray that clears its topic: one DELETEALL."""
    return [m.marker(ns, "", 0, 0, m.pose(0, 0, 0, 0), (0, 0, 0), (0, 0, 0, 0), action=3)]


def track_markers(m: Markers, ns: int, label, status, mean, cov, lifetime: int = 0) -> list[Any]:
    """A UAV's track slots (label, status (K,), mean (K, 4), cov (K, 4, 4)) as the
    markers of one MarkerArray: a DELETEALL (the last step's go), then per track its
    2-sigma ellipse (namespace its status, id its team label, `TRACK_COLOURS`) and a text
    ``L<label>`` above it (namespace "label"), each for `lifetime` ns (`lifetime_of`)."""
    markers = delete_all(m, ns)
    for s in np.flatnonzero(status > 0):
        ident, state = int(label[s]), int(status[s])
        markers.append(ellipse_marker(m, ns, STATUS_NAMES[state], ident, mean[s], cov[s],
                                      TRACK_COLOURS[state], lifetime))  # fmt: skip
        above = m.pose(float(mean[s, 0]), float(mean[s, 1]), 3.0, 0.0)
        markers.append(m.marker(ns, "label", ident, 9, above, (0, 0, 3.0),
                                (1.0, 1.0, 1.0, 1.0), text=f"L{ident}",
                                lifetime=lifetime))  # fmt: skip
    return markers


def ellipse_marker(m: Markers, ns: int, space: str, ident: int, mean, P, rgba, lifetime=0):
    """A flat cylinder of the 2-sigma ellipse of an estimate's position."""
    major, minor, angle = _ellipse(P[:2, :2])
    place = m.pose(float(mean[0]), float(mean[1]), 0.0, angle)
    return m.marker(
        ns, space, ident, 3, place, (4 * major, 4 * minor, 0.1), rgba, lifetime=lifetime
    )


def _ellipse(P: np.ndarray) -> tuple[float, float, float]:
    """1-sigma semi-axes and the major axis's angle of a 2 x 2 covariance."""
    values, vectors = np.linalg.eigh(P)
    values = np.maximum(values, 0.0)
    return (
        float(math.sqrt(values[1])),
        float(math.sqrt(values[0])),
        float(math.atan2(vectors[1, 1], vectors[0, 1])),
    )
