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


# ------------------------------------------------------------ tracks and UAVs as data

GPS = SCENARIO.with_overrides({"faults.position_std": 3.0})
TRACKED = uavtrack.Scenario(steps=24).with_overrides(
    {"tracker.association": "gnn", "sensor.clutter_rate": 1.0,
     "sensor.detection_probability": 0.9, "faults.position_std": 2.0}
)  # fmt: skip


@pytest.fixture(scope="module")
def data_runs(tmp_path_factory):
    out = {}
    for name, scenario in (("gps", GPS), ("tracked", TRACKED)):
        result = uavtrack.simulate(scenario, seed=5, trace=True)
        path = tmp_path_factory.mktemp("bags") / name
        write_bag(path, result.trace, scenario, seed=result.seed)
        out[name] = (scenario, result, path)
    return out


def uuid_of(label: int) -> bytes:
    import uuid

    from uavtrack.io.ros2 import TRACKS_NAMESPACE

    return uuid.uuid5(TRACKS_NAMESPACE, str(label)).bytes


def upper(P):
    return np.array([P[0, 0], P[0, 1], 0, P[1, 1], 0, 0], dtype=np.float32)


def test_the_teams_radar_tracks_are_its_best_estimates_under_stable_uuids(data_runs):
    """With known association the bag holds the team's best estimate of each target as a
    RadarTrack (not each UAV's: those are the live topics'), under its target's UUID."""
    scenario, result, path = data_runs["gps"]
    trace = result.trace
    _, best_mean, best_cov = uavtrack.metrics.team_best(trace.mean, trace.cov, trace.alive)
    team = messages(path, "/team/radar_tracks")
    assert len(team) == 24
    with AnyReader([path]) as reader:
        assert "/uav_2/radar_tracks" not in {c.topic for c in reader.connections}
    for t, msg in team:
        k = t // 500_000_000
        assert [bytes(tr.uuid.uuid) for tr in msg.tracks] == [uuid_of(j) for j in range(4)]
        for j, track in enumerate(msg.tracks):
            m, P = best_mean[k, j], best_cov[k, j]
            assert (track.position.x, track.position.y, track.position.z) == (m[0], m[1], 0.0)
            assert (track.velocity.x, track.velocity.y) == (m[2], m[3])
            np.testing.assert_array_equal(track.position_covariance, upper(P[:2, :2]))
            np.testing.assert_array_equal(track.velocity_covariance, upper(P[2:, 2:]))
            assert track.classification == 2  # DYNAMIC


def test_the_tracked_teams_picture_is_the_most_confident_confirmed_track_per_label(data_runs):
    from uavtrack.estimation import confidence

    scenario, result, path = data_runs["tracked"]
    trace = result.trace
    team = dict(messages(path, "/team/radar_tracks"))
    own = dict(messages(path, "/uav_0/radar_tracks"))
    seen = 0
    for k in range(trace.alive.shape[0]):
        confirmed = (trace.status[k] == 2) & trace.alive[k][:, None]
        labels = trace.label[k][confirmed]
        gamma = confidence(trace.cov[k])[confirmed]
        means = trace.mean[k][confirmed]
        expected = {}
        for label in sorted(set(labels.tolist())):
            pick = np.flatnonzero(labels == label)
            expected[uuid_of(label)] = means[pick[np.argmax(gamma[pick])], :2]
        got = {
            bytes(tr.uuid.uuid): (tr.position.x, tr.position.y)
            for tr in team[k * 500_000_000].tracks
        }
        assert got.keys() == expected.keys()
        for key, xy in got.items():
            assert xy == tuple(expected[key])
        mine = trace.label[k, 0][confirmed[0]]
        assert [bytes(tr.uuid.uuid) for tr in own[k * 500_000_000].tracks] == [
            uuid_of(int(x)) for x in mine
        ]
        seen += len(got)
    assert seen > 0


def test_each_tracks_existence_travels_in_its_companion_message(data_runs):
    """radar_msgs has no field for a track's existence: /uav_i/radar_tracks/existence
    carries it, a float32 per track in the order of the tracks, at the same stamp."""
    scenario, result, path = data_runs["tracked"]
    trace = result.trace
    assert scenario.tracker.confirmation == "existence"
    tracks = dict(messages(path, "/uav_0/radar_tracks"))
    companion = messages(path, "/uav_0/radar_tracks/existence")
    assert len(companion) == len(tracks) == trace.alive[:, 0].sum()
    for t, msg in companion:
        k = t // 500_000_000
        confirmed = trace.status[k, 0] == 2
        assert msg.layout.dim[0].label == "tracks" and msg.layout.dim[0].size == confirmed.sum()
        assert len(msg.data) == len(tracks[t].tracks)
        np.testing.assert_array_equal(msg.data, trace.existence[k, 0][confirmed].astype(np.float32))
        assert (msg.data > scenario.tracker.existence[1]).all()  # confirmed: not yet deleted
    assert len(messages(path, "/team/radar_tracks/existence")) == trace.alive.shape[0]


def rotation(q) -> np.ndarray:
    """The rotation matrix of a unit quaternion (body to map)."""
    w, x, y, z = q.w, q.x, q.y, q.z
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip


def test_the_scan_in_each_uavs_frame_gives_back_its_measurements(data_runs):
    """Each return, turned from the UAV's body frame (as its pose orients it, roll
    included) to the map and placed where its navigation says it is, lands on the
    measurement's ground position."""
    from uavtrack.faults import navigation

    scenario, result, path = data_runs["tracked"]
    trace = result.trace
    nav = navigation(scenario.faults, result.seed, trace.uavs)
    scans = messages(path, "/uav_1/radar_scan")
    poses = dict(messages(path, "/uav_1/pose"))
    assert len(scans) == trace.alive[:, 1].sum()
    rolled = 0
    for t, msg in scans:
        k = t // 500_000_000
        assert msg.header.frame_id == "uav_1"
        R = rotation(poses[t].pose.orientation)
        rolled += abs(trace.action[k, 1]) > 0
        back = [
            nav[k, 1, :3]
            + R
            @ (
                r.range
                * np.array(
                    [
                        math.cos(r.elevation) * math.cos(r.azimuth),
                        math.cos(r.elevation) * math.sin(r.azimuth),
                        math.sin(r.elevation),
                    ]
                )
            )  # fmt: skip
            for r in msg.returns
        ]
        expected = trace.scan_z[k, 1][trace.scan_valid[k, 1]]
        got = np.reshape(back, (-1, 3))
        np.testing.assert_allclose(got[:, :2], expected, atol=2e-3)  # float32 of 430 m
        np.testing.assert_allclose(got[:, 2], 0.0, atol=2e-3)
    assert rolled > 0  # some steps bank the sensor


def test_odometry_and_fix_are_what_the_uavs_navigation_said(data_runs):
    from uavtrack.faults import navigation

    scenario, result, path = data_runs["gps"]
    trace = result.trace
    nav = navigation(scenario.faults, result.seed, trace.uavs)
    assert np.abs(nav[..., :2] - trace.uavs[..., :2]).max() > 1.0  # the GPS error is there
    for t, msg in messages(path, "/uav_3/odom"):
        k = t // 500_000_000
        p = msg.pose.pose.position
        assert (p.x, p.y, p.z) == tuple(nav[k, 3, :3])
        assert msg.child_frame_id == "uav_3" and msg.header.frame_id == "map"
        assert msg.pose.covariance[0] == msg.pose.covariance[7] == 9.0
        assert msg.pose.covariance[14] == 0.0  # the altitude carries no GPS error
        V, bank = trace.uavs[k, 3, 3], trace.action[k, 3]
        assert msg.twist.twist.linear.x == V
        spin = msg.twist.twist.angular
        in_map = rotation(msg.pose.pose.orientation) @ np.array([spin.x, spin.y, spin.z])
        np.testing.assert_allclose(in_map, [0, 0, 9.81 * math.tan(bank) / V], atol=1e-12)
    _, fix = messages(path, "/uav_3/fix")[4]
    assert fix.position_covariance_type == 2 and fix.position_covariance[0] == 9.0
    assert fix.altitude == nav[4, 3, 2]


def test_a_bag_with_gps_error_needs_the_runs_seed_in_one_line(tmp_path):
    result = uavtrack.simulate(GPS, seed=1)
    with pytest.raises(ValueError, match="needs the run's seed") as info:
        write_bag(tmp_path / "bag", result.trace, GPS)
    assert "\n" not in str(info.value) and not (tmp_path / "bag").exists()


FIELD_TYPES = {
    "int8": 2, "uint8": 3, "int16": 4, "uint16": 5, "int32": 6, "uint32": 7, "int64": 8,
    "uint64": 9, "float32": 10, "float64": 11, "char": 13, "bool": 15, "byte": 16,
    "string": 17,
}  # fmt: skip
"""REP 2011's field type ids (type_description_interfaces/msg/FieldType)."""


def rihs01(store, name: str) -> str:
    """ROS 2's type hash written here from REP 2011, apart from rosbags' own: the SHA-256
    of the JSON of the type's fields and of every type it refers to, sorted by name."""
    import hashlib
    import json

    def field_type(desc):
        kind, detail = desc
        capacity, offset = 0, 0
        if kind.name in ("ARRAY", "SEQUENCE"):
            (kind, detail), size = detail
            offset = 48 if desc[0].name == "ARRAY" else (96 if size else 144)
            capacity = size
        if kind.name == "NAME":
            return {"type_id": 1 + offset, "capacity": capacity, "string_capacity": 0,
                    "nested_type_name": detail}, detail  # fmt: skip
        base, bound = detail
        type_id = FIELD_TYPES[base] if not bound else 21  # bounded string
        return {"type_id": type_id + offset, "capacity": capacity,
                "string_capacity": bound, "nested_type_name": ""}, None  # fmt: skip

    def described(name):
        fields, nested = [], []
        for fname, desc in store.fielddefs[name][1]:
            kind, inner = field_type(desc)
            fields.append({"name": fname, "type": kind})
            if inner:
                nested.append(inner)
        if not fields:
            fields = [
                {
                    "name": "structure_needs_at_least_one_member",
                    "type": {
                        "type_id": 3,
                        "capacity": 0,
                        "string_capacity": 0,
                        "nested_type_name": "",
                    },
                }
            ]
        return {"type_name": name, "fields": fields}, nested

    top, todo = described(name)
    referenced, seen = {}, set()
    while todo:
        inner = todo.pop()
        if inner in seen:
            continue
        seen.add(inner)
        referenced[inner], more = described(inner)
        todo += more
    text = json.dumps(
        {"type_description": top,
         "referenced_type_descriptions": [referenced[k] for k in sorted(referenced)]},
        separators=(", ", ": "),
    )  # fmt: skip
    return "RIHS01_" + hashlib.sha256(text.encode()).hexdigest()


def test_the_radar_types_hash_as_ros2_hashes_them():
    """An implementation of REP 2011 written here gives the hashes ROS 2 publishes for
    std_msgs/String and geometry_msgs/Twist (rmw_zenoh's examples), and rosbags' for
    every type the bags and topics use, radar_msgs' included."""
    from uavtrack.io.ros2 import ODOMETRY, RADAR_SCAN, RADAR_TRACKS, store

    typestore = store()
    assert rihs01(typestore, "std_msgs/msg/String") == (
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    )
    assert rihs01(typestore, "geometry_msgs/msg/Twist") == (
        "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
    )
    for msgtype in (RADAR_TRACKS, RADAR_SCAN, ODOMETRY, "sensor_msgs/msg/NavSatFix"):
        assert rihs01(typestore, msgtype) == typestore.hash_rihs01(msgtype), msgtype
