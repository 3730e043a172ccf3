"""Live ROS 2 topics from the agent form, checked by a plain Zenoh subscriber against
rmw_zenoh's conventions: keys and type hashes computed here with rosbags, payloads
decoded by rosbags' CDR deserialiser, attachments by zenoh's own deserialiser."""

import socket
import threading

import numpy as np
import pytest

import uavtrack

pytest.importorskip("rosbags")
zenoh = pytest.importorskip("zenoh")
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from uavtrack.agents.swarm import run_swarm  # noqa: E402
from uavtrack.agents.transport import ZenohTransport  # noqa: E402
from uavtrack.errors import UsageError  # noqa: E402
from uavtrack.io import ros2  # noqa: E402

STORE = get_typestore(Stores.ROS2_JAZZY)
POSE_TYPE = "geometry_msgs::msg::dds_::PoseStamped_"
ESTIMATE_TYPE = "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_the_attachment_is_what_zenohs_own_serialiser_makes():
    import zenoh.ext as ze

    gid = bytes(range(3, 19))
    ours = ros2.attachment(42, 1_500_000_000, gid)
    theirs = ze.z_serialize(
        ("sequence_number", ze.Int64(42), "source_timestamp", ze.Int64(1_500_000_000),
         "source_gid", tuple(ze.UInt8(b) for b in gid))
    )  # fmt: skip
    assert ours == theirs.to_bytes()
    assert ros2.read_attachment(ours) == (42, 1_500_000_000, gid)


def test_keys_and_tokens_follow_rmw_zenoh():
    pose = STORE.hash_rihs01("geometry_msgs/msg/PoseStamped")
    assert pose.startswith("RIHS01_") and len(pose) == 7 + 64
    assert ros2.topic_key(3, "/uav_1/pose", ros2.POSE) == f"3/uav_1/pose/{POSE_TYPE}/{pose}"
    token = ros2.publisher_token(0, "abc", 1, 2, "/uavtrack", "uav_1", "/uav_1/pose", ros2.POSE)
    assert token == (
        f"@ros2_lv/0/abc/1/2/MP/%/%uavtrack/uav_1/%uav_1%pose/{POSE_TYPE}/{pose}/::,:,:,:,,"
    )
    assert (
        ros2.node_token(0, "abc", 1, "/uavtrack", "uav_1")
        == "@ros2_lv/0/abc/1/1/NN/%/%uavtrack/uav_1"
    )


def test_a_zenoh_subscriber_reads_the_swarms_ros2_topics():
    port = free_port()
    listener = ZenohTransport([f"tcp/127.0.0.1:{port}"], [], mode="peer")
    samples, tokens, lock = [], set(), threading.Lock()

    def on_sample(sample):
        attached = sample.attachment.to_bytes() if sample.attachment else None
        with lock:
            samples.append((str(sample.key_expr), sample.payload.to_bytes(), attached))

    def on_token(sample):
        if sample.kind == zenoh.SampleKind.PUT:
            with lock:
                tokens.add(str(sample.key_expr))

    session = listener.session
    subscriber = session.declare_subscriber("7/**", on_sample)
    watcher = session.liveliness().declare_subscriber("@ros2_lv/7/**", on_token, history=True)
    scenario = uavtrack.Scenario(steps=6)
    try:
        swarm = run_swarm(
            scenario, "distributed", seed=2, transport="zenoh", ros2=7,
            connect=(f"tcp/127.0.0.1:{port}",),
        )  # fmt: skip
    finally:
        subscriber.undeclare()
        watcher.undeclare()
        listener.close()
    trace = swarm.result.trace
    pose_hash = STORE.hash_rihs01("geometry_msgs/msg/PoseStamped")
    estimate_hash = STORE.hash_rihs01("geometry_msgs/msg/PoseWithCovarianceStamped")
    poses = [s for s in samples if s[0] == f"7/uav_2/pose/{POSE_TYPE}/{pose_hash}"]
    assert len(poses) == 6
    import zenoh.ext as ze

    for _, payload, attached in poses:
        message = STORE.deserialize_cdr(payload, "geometry_msgs/msg/PoseStamped")
        stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
        k = stamp // 500_000_000
        p = message.pose.position
        assert (p.x, p.y, p.z) == tuple(trace.uavs[k, 2, :3])  # GPS exact here
        fields = ze.z_deserialize(
            tuple[str, ze.Int64, str, ze.Int64, str, tuple[(ze.UInt8,) * 16]],
            zenoh.ZBytes(attached),
        )
        assert fields[0] == "sequence_number" and int(fields[1]) == k + 1
        assert fields[2] == "source_timestamp" and int(fields[3]) == stamp
        assert fields[4] == "source_gid"
    estimates = [
        s for s in samples if s[0] == f"7/uav_0/target_3/estimate/{ESTIMATE_TYPE}/{estimate_hash}"
    ]
    assert len(estimates) == 6
    last = STORE.deserialize_cdr(estimates[-1][1], "geometry_msgs/msg/PoseWithCovarianceStamped")
    assert last.pose.pose.position.x == trace.mean[-1, 0, 3, 0]
    assert np.array_equal(last.pose.covariance.reshape(6, 6)[:2, :2], trace.cov[-1, 0, 3, :2, :2])
    # discovery: a node token per UAV and a publisher token per topic
    nodes = {t for t in tokens if "/NN/" in t}
    publishers = {t for t in tokens if "/MP/" in t}
    assert len(nodes) == 5 and len(publishers) == 5 * (1 + 4)
    assert any(t.endswith(f"/%uav_2%pose/{POSE_TYPE}/{pose_hash}/::,:,:,:,,") for t in publishers)


def test_ros2_needs_zenoh_and_a_domain():
    with pytest.raises(UsageError, match="needs --transport zenoh"):
        run_swarm(uavtrack.Scenario(steps=2), transport="memory", ros2=0)
    with pytest.raises(UsageError, match="0 to 232"):
        run_swarm(uavtrack.Scenario(steps=2), transport="zenoh", ros2=500)
