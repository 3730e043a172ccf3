"""The MAVLink autopilot: its messages decoded back, and its exchange with a minimal
vehicle on loopback (no PX4 or ArduPilot simulator is run)."""

import math
import socket
import threading

import numpy as np
import pytest

from uavtrack.config import G
from uavtrack.errors import RunError
from uavtrack.world import fly

mavutil = pytest.importorskip("pymavlink.mavutil")

from uavtrack.flight.mavlink import (  # noqa: E402
    ARDUPLANE_GUIDED,
    IGNORE_RATES,
    LocalFrame,
    MavlinkPilot,
    Vehicle,
    euler,
    quaternion,
)


@pytest.mark.parametrize("roll, pitch, yaw", [(0.3, 0.0, 1.0), (-0.785, 0.05, -2.5), (0, 0, 0)])
def test_the_quaternion_is_the_euler_angles(roll, pitch, yaw):
    q = quaternion(roll, pitch, yaw)
    assert sum(c * c for c in q) == pytest.approx(1.0)
    assert euler(q) == pytest.approx((roll, pitch, yaw))


def test_a_setpoint_decodes_back_to_the_bank_angle():
    sender = mavutil.mavlink.MAVLink(None, srcSystem=245)
    message = sender.set_attitude_target_encode(
        1234, 1, 1, IGNORE_RATES, quaternion(-0.5, 0.02, 0.7), 0, 0, 0, 0.4
    )
    wire = message.pack(sender)
    decoded = mavutil.mavlink.MAVLink(None).parse_char(wire)
    assert decoded.get_type() == "SET_ATTITUDE_TARGET"
    assert (decoded.time_boot_ms, decoded.target_system, decoded.type_mask) == (1234, 1, 7)
    assert euler(decoded.q) == pytest.approx((-0.5, 0.02, 0.7), abs=1e-6)
    assert decoded.thrust == pytest.approx(0.4)


def test_the_local_frame_round_trips_and_measures_metres():
    frame = LocalFrame(47.4, 8.5)
    lat, lon = frame.to_latlon(1200.0, -300.0)
    assert frame.to_xy(lat, lon) == pytest.approx((1200.0, -300.0), abs=1e-9)
    # one arc minute of latitude is about a nautical mile (1852 m) at mid latitudes
    assert frame.to_xy(47.4 + 1 / 60, 8.5)[1] == pytest.approx(1852, rel=0.01)


class FakeVehicle(threading.Thread):
    """A plane in lockstep: each attitude setpoint flies it dt along the unicycle of
    eq. (1) with the setpoint's bank (MAVLink's sign) and answers with its position."""

    def __init__(self, port, start, dt, frame):
        super().__init__(daemon=True)
        self.link = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=1)
        self.state, self.dt, self.frame = start.copy(), dt, frame
        self.clock_ms, self.mode, self.setpoints = 0, None, []
        self.stop = threading.Event()

    def run(self):
        while not self.stop.is_set():
            msg = self.link.recv_match(blocking=True, timeout=0.1)
            if msg is None:
                continue
            kind = msg.get_type()
            if kind == "HEARTBEAT":
                self.link.mav.heartbeat_send(1, 3, 0, 0, 0)  # fixed wing, ArduPilot
            elif kind == "SET_MODE":
                self.mode = msg.custom_mode
            elif kind == "SET_ATTITUDE_TARGET":
                roll = euler(msg.q)[0]
                self.setpoints.append(roll)
                self.state = fly(self.state, np.array(-roll), self.dt, G)
                self.clock_ms += round(1000 * self.dt)
                self.report()

    def report(self):
        x, y, h, v, heading = self.state
        lat, lon = self.frame.to_latlon(x, y)
        self.link.mav.global_position_int_send(
            self.clock_ms,
            round(lat * 1e7),
            round(lon * 1e7),
            round(h * 1000),
            round(h * 1000),
            round(100 * v * math.sin(heading)),
            round(100 * v * math.cos(heading)),
            0,
            65535,
        )


def free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_the_pilot_flies_a_vehicle_over_mavlink_as_the_unicycle_would():
    frame, dt = LocalFrame(47.4, 8.5), 0.5
    start = np.array([100.0, 50.0, 425.0, 15.0, 0.3])
    port = free_udp_port()
    vehicle_side = FakeVehicle(port, start, dt, frame)
    vehicle_side.start()
    vehicle = Vehicle(f"udpout:127.0.0.1:{port}")
    try:
        vehicle.connect("ardupilot", deadline=30.0)
        pilot = MavlinkPilot([vehicle], frame, dt, deadline=30.0)
        banks = [0.785, 0.785, 0.0, -0.785, 0.3, 0.0]
        uavs, expected = start[None, None].copy(), start.copy()
        alive = np.ones((1, 1), dtype=bool)
        for bank in banks:
            uavs = pilot.fly(uavs, np.array([[bank]]), alive)
            expected = fly(expected, np.array(bank), dt, G)
            # positions through 1e-7 deg integers (about 1 cm), speeds through cm/s
            assert uavs[0, 0, :3] == pytest.approx(expected[:3], abs=0.02)
            assert uavs[0, 0, 3] == pytest.approx(15.0, abs=0.01)
            assert uavs[0, 0, 4] == pytest.approx(expected[4], abs=1e-3)
        assert vehicle_side.mode == ARDUPLANE_GUIDED
        # eq. (1)'s positive bank turns left; MAVLink's positive roll turns right
        assert vehicle_side.setpoints == pytest.approx([-b for b in banks], abs=1e-6)
    finally:
        vehicle_side.stop.set()
        vehicle_side.join(timeout=5)
        vehicle.close()
        vehicle_side.link.close()


def test_a_silent_vehicle_fails_the_cycle_after_its_deadline():
    vehicle = Vehicle(f"udpout:127.0.0.1:{free_udp_port()}")
    try:
        with pytest.raises(RunError, match="no heartbeat from the vehicle within 0.5 s"):
            vehicle.connect("px4", deadline=0.5)
        pilot = MavlinkPilot([vehicle], LocalFrame(), 0.5, deadline=0.5)
        with pytest.raises(RunError, match="no position report from vehicle 1"):
            pilot.fly(np.zeros((1, 1, 5)), np.zeros((1, 1)), np.ones((1, 1), dtype=bool))
    finally:
        vehicle.close()
