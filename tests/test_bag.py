"""The ROS 2 bag, read back by rosbags and by the MCAP library's own ROS 2 decoder."""

import math

import numpy as np
import pytest

import uavtrack
from uavtrack import cli

pytest.importorskip("rosbags")
from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from uavtrack.io.bag import write_bag  # noqa: E402

SCENARIO = uavtrack.Scenario(steps=24).with_overrides({"faults.failures": [[1, 10]]})


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    result = uavtrack.simulate(SCENARIO, seed=5, trace=True)
    path = tmp_path_factory.mktemp("bags") / "run"
    counts = write_bag(path, result.trace, SCENARIO, origin=(47.0, 8.0))
    return result.trace, path, counts


def messages(path, topic):
    with AnyReader([path]) as reader:
        chosen = [c for c in reader.connections if c.topic == topic]
        return [(t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages(chosen)]


def test_poses_and_fixes_are_the_trace(run):
    trace, path, counts = run
    poses = messages(path, "/uav_3/pose")
    assert len(poses) == 24 and counts["/uav_1/pose"] == 10  # a failed UAV stops
    for t, msg in poses:
        k = t // 500_000_000
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == t == k * 500_000_000
        p = msg.pose.position
        assert (p.x, p.y, p.z) == tuple(trace.uavs[k, 3, :3])
        roll, yaw = roll_yaw(msg.pose.orientation)
        assert yaw == pytest.approx(math.remainder(trace.uavs[k, 3, 4], math.tau), abs=1e-9)
        assert roll == pytest.approx(-trace.action[k, 3], abs=1e-9)  # REP-103: right positive
    fixes = messages(path, "/uav_3/fix")
    t, fix = fixes[7]
    x, y, h = trace.uavs[7, 3, :3]
    north = (
        6378137.0
        * (1 - 6.69437999014e-3)
        / (1 - 6.69437999014e-3 * math.sin(math.radians(47)) ** 2) ** 1.5
    )  # noqa: E501
    assert fix.latitude == pytest.approx(47.0 + math.degrees(y / north), abs=1e-12)
    assert fix.longitude > 8.0 if x > 0 else fix.longitude <= 8.0
    assert fix.altitude == h


def roll_yaw(q) -> tuple[float, float]:
    """Roll and yaw of a quaternion without pitch (the ZYX Euler angles)."""
    roll = math.atan2(2 * (q.w * q.x + q.y * q.z), 1 - 2 * (q.x**2 + q.y**2))
    yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y**2 + q.z**2))
    return roll, yaw


def test_the_roll_banks_the_way_the_uav_turns_in_rep103(run):
    """REP-103: body x forward, y left, z up in an east-north-up map; a positive roll
    lowers the right wing and turns the aircraft right, so the yaw (counter-clockwise
    from east) decreases. Every turning step's roll has the sign opposite to the yaw's
    change over the step, and /tf holds the same orientation as the pose."""
    trace, path, _ = run
    tf = {t: msg for t, msg in messages(path, "/tf")}
    turning = 0
    for i in range(trace.uavs.shape[1]):
        for t, msg in messages(path, f"/uav_{i}/pose"):
            k = t // 500_000_000
            q = msg.pose.orientation
            frame = next(f for f in tf[t].transforms if f.child_frame_id == f"uav_{i}")
            r = frame.transform.rotation
            assert (r.x, r.y, r.z, r.w) == (q.x, q.y, q.z, q.w)
            roll, yaw = roll_yaw(q)
            assert yaw == pytest.approx(math.remainder(trace.uavs[k, i, 4], math.tau), abs=1e-9)
            if k + 1 == len(trace.uavs) or not trace.alive[k + 1, i]:
                continue
            turn = math.remainder(trace.uavs[k + 1, i, 4] - trace.uavs[k, i, 4], math.tau)
            if abs(turn) > 1e-9:
                turning += 1
                assert math.copysign(1, roll) == -math.copysign(1, turn)
            else:
                assert roll == pytest.approx(0.0, abs=1e-12)
    assert turning > 20  # the test sees turns both ways
    assert {np.sign(a) for a in trace.action[trace.alive].ravel()} >= {-1.0, 1.0}


def test_estimates_carry_the_teams_best_and_its_covariance(run):
    trace, path, _ = run
    from uavtrack.metrics import team_best

    best, mean, _ = team_best(trace.mean, trace.cov, trace.alive)
    estimates = messages(path, "/team/target_2/estimate")
    assert len(estimates) == 24
    t, msg = estimates[15]
    assert (msg.pose.pose.position.x, msg.pose.pose.position.y) == tuple(mean[15, 2, :2])
    C = msg.pose.covariance.reshape(6, 6)
    assert np.array_equal(C[:2, :2], trace.cov[15, best[15, 2], 2, :2, :2])


def test_tf_links_and_assignments(run):
    trace, path, _ = run
    tf = messages(path, "/tf")
    _, msg = tf[12]
    frames = {t.child_frame_id: t.transform.translation for t in msg.transforms}
    assert "uav_1" not in frames and set(frames) >= {"uav_0", "target_3"}  # failed at 10
    assert frames["target_3"].x == trace.targets[12, 3, 0]
    links = messages(path, "/team/links")
    _, msg = links[0]
    adjacency = uavtrack.simulation.graph(trace.uavs[:1], trace.alive[:1], SCENARIO)[0]
    assert len(msg.markers[0].points) == 2 * np.triu(adjacency, 1).sum()
    lines = messages(path, "/team/assignments")[5][1].markers[0].points
    assert len(lines) == 2 * (trace.assignment[5] >= 0).sum()


def test_the_mcap_library_decodes_it_on_its_own(run):
    pytest.importorskip("mcap_ros2")
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    trace, path, counts = run
    with open(path / "run.mcap", "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        seen = {}
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
            if channel.topic == "/uav_0/pose" and message.log_time == 3 * 500_000_000:
                assert schema.name == "geometry_msgs/msg/PoseStamped"
                assert decoded.pose.position.x == trace.uavs[3, 0, 0]
    assert seen == counts


def test_type_hashes_are_ros2s(run):
    _, path, _ = run
    store = get_typestore(Stores.ROS2_JAZZY)
    text = (path / "metadata.yaml").read_text()
    for msgtype in ("geometry_msgs/msg/PoseStamped", "sensor_msgs/msg/NavSatFix"):
        assert store.hash_rihs01(msgtype) in text


def test_run_and_swarm_write_bags_and_refuse_a_taken_folder(tmp_path, capsys):
    bag = tmp_path / "bag"
    assert cli.main(["run", "--steps", "8", "--bag", str(bag)]) == 0
    assert (bag / "metadata.yaml").is_file()
    assert cli.main(["run", "--steps", "8", "--bag", str(bag)]) == 2
    assert "exists; give a new folder" in capsys.readouterr().err
    swarm = tmp_path / "swarm"
    code = cli.main(["swarm", "--steps", "6", "--transport", "memory", "--bag", str(swarm)])
    assert code == 0 and len(messages(swarm, "/uav_0/pose")) == 6
