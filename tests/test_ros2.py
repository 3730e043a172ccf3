"""Live ROS 2 topics from the agent form, checked by a plain Zenoh subscriber against
rmw_zenoh's conventions: keys and type hashes computed here with rosbags, payloads
decoded by rosbags' CDR deserialiser, attachments by zenoh's own deserialiser."""

import math
import socket
import threading
import time

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
TF = "tf2_msgs/msg/TFMessage"
ESTIMATE = "geometry_msgs/msg/PoseWithCovarianceStamped"
MARKERS = "visualization_msgs/msg/MarkerArray"
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
    assert (
        ros2.topic_key(3, "/uav_1/pose", "geometry_msgs/msg/PoseStamped")
        == f"3/uav_1/pose/{POSE_TYPE}/{pose}"
    )
    token = ros2.publisher_token(
        0, "abc", 1, 2, "/uavtrack", "uav_1", "/uav_1/pose", "geometry_msgs/msg/PoseStamped"
    )
    assert token == (
        f"@ros2_lv/0/abc/1/2/MP/%/%uavtrack/uav_1/%uav_1%pose/{POSE_TYPE}/{pose}/::,:,:,:,,"
    )
    assert (
        ros2.node_token(0, "abc", 1, "/uavtrack", "uav_1")
        == "@ros2_lv/0/abc/1/1/NN/%/%uavtrack/uav_1"
    )


STEPS, FAILED, FAILS_AT, DT_NS = 12, 1, 3, 500_000_000


@pytest.fixture(scope="module")
def live():
    """A swarm with --ros2 7 (UAV 1 failing at step 3, cycles paced at dt) heard by a
    plain Zenoh session: every data sample and liveliness change, in arrival order, and
    the wall clock [ns] before and after the run."""
    port = free_port()
    listener = ZenohTransport([f"tcp/127.0.0.1:{port}"], [], mode="peer")
    events, lock = [], threading.Lock()

    def on_sample(sample):
        attached = sample.attachment.to_bytes() if sample.attachment else None
        with lock:
            events.append(("data", str(sample.key_expr), sample.payload.to_bytes(), attached))

    def on_token(sample):
        kind = "put" if sample.kind == zenoh.SampleKind.PUT else "delete"
        with lock:
            events.append((kind, str(sample.key_expr), None, None))

    session = listener.session
    subscriber = session.declare_subscriber("7/**", on_sample)
    watcher = session.liveliness().declare_subscriber("@ros2_lv/7/**", on_token, history=True)
    scenario = uavtrack.Scenario(steps=STEPS).with_overrides(
        {"faults.failures": [[FAILED, FAILS_AT]]}
    )
    before = time.time_ns()
    try:
        swarm = run_swarm(
            scenario, "distributed", seed=2, transport="zenoh", ros2=7, realtime=True,
            connect=(f"tcp/127.0.0.1:{port}",),
        )  # fmt: skip
    finally:
        subscriber.undeclare()
        watcher.undeclare()
        listener.close()
    after = time.time_ns()
    with lock:
        return swarm.result.trace, list(events), before, after


def on_topic(events, topic: str, msgtype: str):
    """(position in `events`, payload, attachment) of each sample of a topic, by its key."""
    package, kind, name = msgtype.split("/")
    dds = f"{package}::{kind}::dds_::{name}_"
    key = f"7/{topic.strip('/')}/{dds}/{STORE.hash_rihs01(msgtype)}"
    return [(n, e[2], e[3]) for n, e in enumerate(events) if e[0] == "data" and e[1] == key]


def stamp_of(message) -> int:
    return message.header.stamp.sec * 10**9 + message.header.stamp.nanosec


@pytest.mark.integration
def test_a_zenoh_subscriber_reads_the_swarms_ros2_topics(live):
    import zenoh.ext as ze

    trace, events, before, after = live
    poses = on_topic(events, "/uav_2/pose", "geometry_msgs/msg/PoseStamped")
    assert len(poses) == STEPS
    for _, payload, attached in poses:
        message = STORE.deserialize_cdr(payload, "geometry_msgs/msg/PoseStamped")
        stamp = stamp_of(message)
        k = stamp // DT_NS
        p = message.pose.position
        assert (p.x, p.y, p.z) == tuple(trace.uavs[k, 2, :3])  # GPS exact here
        fields = ze.z_deserialize(
            tuple[str, ze.Int64, str, ze.Int64, str, tuple[(ze.UInt8,) * 16]],
            zenoh.ZBytes(attached),
        )
        assert fields[0] == "sequence_number" and int(fields[1]) == k + 1
        # rmw_zenoh's source timestamp is the wall clock; the header's the simulated one
        assert fields[2] == "source_timestamp" and before <= int(fields[3]) <= after
        assert fields[4] == "source_gid"
    failed = on_topic(events, f"/uav_{FAILED}/pose", "geometry_msgs/msg/PoseStamped")
    assert len(failed) == FAILS_AT
    estimates = on_topic(events, "/uav_0/target_3/estimate", ESTIMATE)
    assert len(estimates) == STEPS
    last = STORE.deserialize_cdr(estimates[-1][1], ESTIMATE)
    assert last.pose.pose.position.x == trace.mean[-1, 0, 3, 0]
    assert np.array_equal(last.pose.covariance.reshape(6, 6)[:2, :2], trace.cov[-1, 0, 3, :2, :2])
    # discovery: a node token per UAV and the world's, a publisher token per topic
    tokens = {e[1] for e in events if e[0] == "put"}
    nodes = {t for t in tokens if "/NN/" in t}
    publishers = {t for t in tokens if "/MP/" in t}
    # per UAV: pose, tf, odometry, fix, radar tracks and 4 estimates; the world's clock
    assert len(nodes) == 5 + 1 and len(publishers) == 5 * (5 + 4) + 1
    pose_hash = STORE.hash_rihs01("geometry_msgs/msg/PoseStamped")
    assert any(t.endswith(f"/%uav_2%pose/{POSE_TYPE}/{pose_hash}/::,:,:,:,,") for t in publishers)
    clock_hash = STORE.hash_rihs01("rosgraph_msgs/msg/Clock")
    clock_type = "rosgraph_msgs::msg::dds_::Clock_"
    assert any(
        t.endswith(f"/world/%clock/{clock_type}/{clock_hash}/::,:,:,:,,") for t in publishers
    )
    tf = f"/%tf/tf2_msgs::msg::dds_::TFMessage_/{STORE.hash_rihs01(TF)}/::,:,:,:,,"
    assert sum(t.endswith(tf) for t in publishers) == 5
    # a session's entities have distinct ids
    ids = [tuple(t.split("/")[2:5]) for t in tokens]
    assert len(set(ids)) == len(ids)


@pytest.mark.integration
def test_the_world_publishes_the_simulated_clock(live):
    """/clock (use_sim_time's clock) reads k dt at step k, in order, each step once, each
    before the UAVs' samples stamped with it: the stamps' clock."""
    _, events, before, after = live
    clocks = on_topic(events, "/clock", "rosgraph_msgs/msg/Clock")
    read = [
        STORE.deserialize_cdr(payload, "rosgraph_msgs/msg/Clock").clock for _, payload, _ in clocks
    ]
    assert [c.sec * 10**9 + c.nanosec for c in read] == [k * DT_NS for k in range(STEPS)]
    assert all(before <= ros2.read_attachment(a)[1] <= after for _, _, a in clocks)
    poses = on_topic(events, "/uav_0/pose", "geometry_msgs/msg/PoseStamped")
    for at, payload, _ in poses:
        k = stamp_of(STORE.deserialize_cdr(payload, "geometry_msgs/msg/PoseStamped")) // DT_NS
        assert clocks[k][0] < at


@pytest.mark.integration
def test_tf_carries_each_uavs_pose(live):
    """Each UAV's /tf message is map -> uav_i at its pose, stamped like the pose."""
    _, events, _, _ = live
    poses = {}
    for i in range(5):
        for _, payload, _ in on_topic(events, f"/uav_{i}/pose", "geometry_msgs/msg/PoseStamped"):
            message = STORE.deserialize_cdr(payload, "geometry_msgs/msg/PoseStamped")
            poses[i, stamp_of(message)] = message.pose
    frames = 0
    for _, payload, _ in on_topic(events, "/tf", TF):
        (transform,) = STORE.deserialize_cdr(payload, TF).transforms
        assert transform.header.frame_id == "map"
        uav = int(transform.child_frame_id.removeprefix("uav_"))
        pose = poses.pop((uav, stamp_of(transform)))
        t, r = transform.transform.translation, transform.transform.rotation
        p, q = pose.position, pose.orientation
        assert (t.x, t.y, t.z, r.x, r.y, r.z, r.w) == (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
        frames += 1
    assert not poses and frames == 4 * STEPS + FAILS_AT


@pytest.mark.integration
def test_the_live_roll_banks_the_way_the_uav_turns_in_rep103(live):
    """A positive roll (REP-103: right wing down) on every step whose heading then
    decreases (a right turn in east-north-up), a negative one where it increases; yaw
    is the heading."""
    trace, events, _, _ = live
    turning = 0
    for i in range(5):
        for _, payload, _ in on_topic(events, f"/uav_{i}/pose", "geometry_msgs/msg/PoseStamped"):
            message = STORE.deserialize_cdr(payload, "geometry_msgs/msg/PoseStamped")
            k = stamp_of(message) // DT_NS
            q = message.pose.orientation
            roll = math.atan2(2 * (q.w * q.x + q.y * q.z), 1 - 2 * (q.x**2 + q.y**2))
            yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y**2 + q.z**2))
            assert yaw == pytest.approx(math.remainder(trace.uavs[k, i, 4], math.tau), abs=1e-9)
            assert roll == pytest.approx(-trace.action[k, i], abs=1e-9)
            if k + 1 < STEPS and trace.alive[k + 1, i]:
                turn = math.remainder(trace.uavs[k + 1, i, 4] - trace.uavs[k, i, 4], math.tau)
                if abs(turn) > 1e-9:
                    turning += 1
                    assert math.copysign(1, roll) == -math.copysign(1, turn)
    assert turning > 5


@pytest.mark.integration
def test_a_failed_uavs_node_leaves_the_ros2_graph_when_it_fails(live):
    """UAV 1 fails at step 3: its node and publisher tokens are dropped while the others
    still fly (before UAV 0's pose of the last step, eight paced cycles later), not when
    the run ends; the living UAVs' stay until they have published their last step."""
    _, events, _, _ = live
    poses = [n for n, _, _ in on_topic(events, "/uav_0/pose", "geometry_msgs/msg/PoseStamped")]
    assert len(poses) == STEPS

    def tokens(uav):
        node = f"/%uavtrack/uav_{uav}"
        mine = [(n, e[0], e[1]) for n, e in enumerate(events) if e[0] != "data" and node in e[1]]
        put = {key for _, kind, key in mine if kind == "put"}
        dropped = {key: n for n, kind, key in mine if kind == "delete"}
        return put, dropped

    put, dropped = tokens(FAILED)
    assert put and set(dropped) == put
    assert max(dropped.values()) < poses[-1]
    assert len(put) == 1 + 5 + 4  # node, pose, tf, odometry, fix, radar tracks, estimates
    for uav in (0, 2, 3, 4):
        put, dropped = tokens(uav)
        assert len(put) == 10 and all(n > poses[-2] for n in dropped.values())


def test_ros2_needs_zenoh_and_a_domain():
    with pytest.raises(UsageError, match="needs --transport zenoh"):
        run_swarm(uavtrack.Scenario(steps=2), transport="memory", ros2=0)
    with pytest.raises(UsageError, match="0 to 232"):
        run_swarm(uavtrack.Scenario(steps=2), transport="zenoh", ros2=500)


def swarm_heard_on_domain_8(scenario):
    """Run `scenario` as a Zenoh swarm publishing on ROS 2 domain 8 beside a listener:
    the swarm, and every sample the listener heard as (key, payload)."""
    port = free_port()
    listener = ZenohTransport([f"tcp/127.0.0.1:{port}"], [], mode="peer")
    events, lock = [], threading.Lock()

    def on_sample(sample):
        with lock:
            events.append((str(sample.key_expr), sample.payload.to_bytes()))

    subscriber = listener.session.declare_subscriber("8/**", on_sample)
    try:
        swarm = run_swarm(
            scenario, "distributed", seed=3, transport="zenoh", ros2=8,
            connect=(f"tcp/127.0.0.1:{port}",),
        )  # fmt: skip
    finally:
        subscriber.undeclare()
        listener.close()
    with lock:
        return swarm, list(events)


@pytest.mark.integration
def test_a_swarm_of_tracks_publishes_them_by_label():
    """With tracker.association jpda each UAV's estimates are its track slots: one
    MarkerArray a step on /uav_i/tracks, a DELETEALL then per track its ellipse (id the
    team label, namespace the status) at the trace's estimate, and its label's text."""
    steps = 6
    scenario = uavtrack.Scenario(steps=steps).with_overrides(
        {"tracker.association": "jpda", "sensor.detection_probability": 0.9,
         "sensor.clutter_rate": 2.0}
    )  # fmt: skip
    swarm, events = swarm_heard_on_domain_8(scenario)
    trace = swarm.result.trace
    seen = [(key, payload) for key, payload in events if key.startswith("8/")]
    key = f"8/uav_0/tracks/visualization_msgs::msg::dds_::MarkerArray_/{STORE.hash_rihs01(MARKERS)}"
    samples = [payload for k, payload in seen if k == key]
    # one a step; the first may go before the listener's subscription has reached the
    # program (Zenoh routes a subscription as it spreads, with no guarantee of when)
    assert steps - 1 <= len(samples) <= steps
    assert not any("/target_" in k for k, _ in seen)  # no per-target topic with tracks
    for payload in samples:
        markers = STORE.deserialize_cdr(payload, MARKERS).markers
        k = stamp_of(markers[0]) // DT_NS
        assert markers[0].action == 3  # DELETEALL
        ellipses = [mk for mk in markers[1:] if mk.ns in ("tentative", "confirmed")]
        held = np.flatnonzero(trace.status[k, 0] > 0)
        assert sorted(mk.id for mk in ellipses) == sorted(trace.label[k, 0, held].tolist())
        for mk in ellipses:
            s = held[trace.label[k, 0, held] == mk.id][0]
            assert mk.ns == ("confirmed" if trace.status[k, 0, s] == 2 else "tentative")
            assert (mk.pose.position.x, mk.pose.position.y) == tuple(trace.mean[k, 0, s, :2])
        texts = {mk.text for mk in markers if mk.ns == "label"}
        assert texts == {f"L{label}" for label in trace.label[k, 0, held]}


@pytest.mark.integration
def test_a_failed_uavs_tracks_leave_the_view_live():
    """A UAV program whose UAV fails publishes a DELETEALL on /uav_i/tracks as it ends,
    and every track marker lives two steps: the view shows each living UAV's tracks."""
    scenario = uavtrack.Scenario(steps=8).with_overrides(
        {"tracker.association": "gnn", "faults.failures": [[0, 4]]}
    )
    _, events = swarm_heard_on_domain_8(scenario)
    key = f"8/uav_0/tracks/visualization_msgs::msg::dds_::MarkerArray_/{STORE.hash_rihs01(MARKERS)}"
    samples = [STORE.deserialize_cdr(p, MARKERS).markers for k, p in events if k == key]
    assert 4 <= len(samples) <= 4 + 1  # steps (0 to) 3, then the clearing at its end
    *published, last = samples
    assert [m.action for m in last] == [3] and stamp_of(last[0]) == 4 * DT_NS
    for markers in published:
        assert {(m.lifetime.sec, m.lifetime.nanosec) for m in markers[1:]} == {(1, 0)}


@pytest.mark.integration
def test_a_swarms_tracks_odometry_and_scan_are_data_on_their_topics():
    """Each UAV program publishes, as the bag holds them: its confirmed tracks as
    radar_msgs/RadarTracks under the UUIDs of their team labels, its navigation's state
    as nav_msgs/Odometry with the GPS error's variance, its fix, and its scan as
    radar_msgs/RadarScan in its own frame; values as the trace's."""
    import uuid

    from uavtrack.faults import navigation

    steps = 6
    scenario = uavtrack.Scenario(steps=steps).with_overrides(
        {"tracker.association": "jpda", "sensor.detection_probability": 0.9,
         "sensor.clutter_rate": 2.0, "faults.position_std": 2.0}
    )  # fmt: skip
    swarm, events = swarm_heard_on_domain_8(scenario)
    trace = swarm.result.trace
    nav = navigation(scenario.faults, 3, trace.uavs)
    typestore = ros2.store()

    def samples(topic, msgtype):
        key = f"8/{topic}/{ros2.dds_type(msgtype)}/{typestore.hash_rihs01(msgtype)}"
        got = [typestore.deserialize_cdr(p, msgtype) for k, p in events if k == key]
        assert steps - 1 <= len(got) <= steps, topic  # the first may precede the subscription
        return got

    for msg in samples("uav_0/radar_tracks", ros2.RADAR_TRACKS):
        k = (msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec) // DT_NS
        held = np.flatnonzero(trace.status[k, 0] == 2)
        labels = trace.label[k, 0, held]
        names = [uuid.uuid5(ros2.TRACKS_NAMESPACE, str(int(x))).bytes for x in labels]
        assert [bytes(t.uuid.uuid) for t in msg.tracks] == names
        for t, s in zip(msg.tracks, held, strict=True):
            assert (t.position.x, t.position.y) == tuple(trace.mean[k, 0, s, :2])
    # no header: the messages heard are a run of consecutive steps, in order (the first or,
    # on a loaded machine, the last may fall outside the subscription)
    existence = [list(m.data) for m in samples("uav_0/radar_tracks/existence", ros2.EXISTENCE)]
    sent = [list(trace.existence[k, 0][trace.status[k, 0] == 2].astype(np.float32))
            for k in range(steps)]  # fmt: skip
    runs = [sent[a : a + len(existence)] for a in range(steps - len(existence) + 1)]
    assert existence in runs, (existence, sent)
    for msg in samples("uav_1/odom", ros2.ODOMETRY):
        k = (msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec) // DT_NS
        p = msg.pose.pose.position
        assert (p.x, p.y, p.z) == tuple(nav[k, 1, :3])
        assert msg.pose.covariance[0] == 4.0 and msg.child_frame_id == "uav_1"
    fixes = samples("uav_1/fix", ros2.FIX)
    assert all(f.position_covariance_type == 2 for f in fixes)
    for msg in samples("uav_2/radar_scan", ros2.RADAR_SCAN):
        k = (msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec) // DT_NS
        assert msg.header.frame_id == "uav_2"
        assert len(msg.returns) == trace.scan_valid[k, 2].sum()
