"""ROS 2 topics over Zenoh in rmw_zenoh's conventions, so that a ROS 2 node using
rmw_zenoh_cpp (Jazzy and later) can discover and read what a UAV program publishes
(``uavtrack swarm --ros2 DOMAIN``, ``uavtrack agent --ros2 DOMAIN``).

What rmw_zenoh expects, and what `Node` does (rmw_zenoh's design document and its
liveliness and attachment helpers):

* **Data key** ``<domain>/<topic without its leading slash>/<type>/<type hash>``, the type
  in DDS form (``geometry_msgs::msg::dds_::PoseStamped_``) and its hash ROS 2's RIHS01
  (``RIHS01_<sha256 hex>``, computed by rosbags from the message definitions).
* **Payload** the message in CDR (little-endian, with its 4-byte encapsulation header),
  serialised by rosbags.
* **Attachment** zenoh-ext serialised: the text ``sequence_number`` and an int64 (from
  1), ``source_timestamp`` and an int64 [ns], ``source_gid`` and 16 bytes (strings as a
  LEB128 length and UTF-8 bytes, integers as 8 bytes little-endian, the gid as a
  fixed array).
* **Liveliness tokens** under ``@ros2_lv/<domain>/<session id>/<node id>/<entity id>/``:
  ``NN/<enclave>/<namespace>/<node>`` for the node, and ``MP/<enclave>/<namespace>/<node>/
  <topic>/<type>/<type hash>/<qos>`` for each publisher, names with ``/`` written ``%``
  (empty: ``%``), the QoS the default (reliable, volatile, keep last 10), written
  ``::,:,:,:,,`` (every field at its default left empty).

The gid is the first 16 bytes of the SHA-256 of the publisher's token (rmw_zenoh takes
an XXH3-128 of it; subscribers only compare gids). Needs rosbags (the io extra).
"""

from __future__ import annotations

import hashlib
import math
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import install_hint

try:
    from rosbags.typesys import Stores, get_typestore
except ImportError as exc:  # an optional extra
    raise ImportError(f"uavtrack.io.ros2 needs rosbags: {install_hint('io')} ({exc})") from None

ADMIN_SPACE = "@ros2_lv"
DEFAULT_QOS = "::,:,:,:,,"
"""rmw_zenoh's QoS field of a token when every policy is the default: reliable, volatile,
keep last 10, no deadline, lifespan or liveliness lease."""
POSE = "geometry_msgs/msg/PoseStamped"
ESTIMATE = "geometry_msgs/msg/PoseWithCovarianceStamped"
UNKNOWN = 1e9  # [rad^2] the variance of a rotation nobody estimates

_STORE = None


def store():
    """rosbags' ROS 2 Jazzy type store (its message definitions and hashes)."""
    global _STORE
    if _STORE is None:
        _STORE = get_typestore(Stores.ROS2_JAZZY)
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


@dataclass
class _Publisher:
    key: str
    token: str
    gid: bytes
    sequence: int = 0
    handle: Any = None


class Node:
    """One UAV program as a ROS 2 node ``/uavtrack/uav_<i>`` on a Zenoh session:
    ``/uav_<i>/pose`` (PoseStamped: its position, heading as yaw, the bank angle flown as
    roll) and ``/uav_<i>/target_<j>/estimate`` (PoseWithCovarianceStamped: its fused
    estimate of target j, the x-y covariance in the 6 x 6), stamped with the simulated
    clock (step k at k dt), in frame ``map``."""

    def __init__(self, session, domain: int, uav: int, n_targets: int, dt: float) -> None:
        self.session, self.domain, self.dt = session, domain, dt
        self.node, self.namespace = f"uav_{uav}", "/uavtrack"
        zid = str(session.zid())
        self.tokens = [session.liveliness().declare_token(
            node_token(domain, zid, uav, self.namespace, self.node))]  # fmt: skip
        topics = {f"/uav_{uav}/pose": POSE}
        topics.update({f"/uav_{uav}/target_{j}/estimate": ESTIMATE for j in range(n_targets)})
        self.publishers: dict[str, _Publisher] = {}
        for entity, (topic, msgtype) in enumerate(topics.items(), start=1):
            token = publisher_token(
                domain, zid, uav, entity, self.namespace, self.node, topic, msgtype
            )
            key = topic_key(domain, topic, msgtype)
            self.tokens.append(session.liveliness().declare_token(token))
            handle = session.declare_publisher(key)
            self.publishers[topic] = _Publisher(key, token, gid(token), handle=handle)
        self.uav = uav

    def publish(self, k: int, pose: np.ndarray, bank: float, mean, cov) -> None:
        """Step k: the UAV's pose (x, y, h, V, heading) and its estimates (Nt, 4),
        covariances (Nt, 4, 4)."""
        T = store().types
        ns = int(round(k * self.dt * 1e9))
        header = header_of(ns)
        x, y, h, _, heading = (float(v) for v in pose)
        message = T[POSE](header=header, pose=pose_of(x, y, h, heading, bank))
        self._put(f"/uav_{self.uav}/pose", message, ns)
        for j in range(len(mean)):
            estimate = estimate_of(header, mean[j], cov[j])
            self._put(f"/uav_{self.uav}/target_{j}/estimate", estimate, ns)

    def _put(self, topic: str, message, ns: int) -> None:
        p = self.publishers[topic]
        p.sequence += 1
        payload = bytes(store().serialize_cdr(message, message.__msgtype__))
        p.handle.put(payload, attachment=attachment(p.sequence, ns, p.gid))

    def close(self) -> None:
        for p in self.publishers.values():
            try:
                p.handle.undeclare()
            except Exception:  # already gone with its session
                pass
        for token in self.tokens:
            try:
                token.undeclare()
            except Exception:
                pass


def header_of(ns: int, frame: str = "map"):
    """A std_msgs/Header stamped `ns` nanoseconds of the simulated clock, in `frame`."""
    T = store().types
    stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


def pose_of(x: float, y: float, z: float, yaw: float, roll: float = 0.0):
    """A geometry_msgs/Pose at (x, y, z), turned by roll about x then yaw about z."""
    T = store().types
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z),
        orientation=T["geometry_msgs/msg/Quaternion"](x=sr * cy, y=sr * sy, z=cr * sy, w=cr * cy),
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
