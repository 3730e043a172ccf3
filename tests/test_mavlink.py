"""The MAVLink autopilot: its messages decoded back, and its exchange with a minimal
vehicle on loopback (no PX4 or ArduPilot simulator is run)."""

import contextlib
import math
import socket
import threading
import time

import numpy as np
import pytest

from uavtrack.config import G
from uavtrack.errors import RunError
from uavtrack.world import fly

mavutil = pytest.importorskip("pymavlink.mavutil")

from uavtrack.io.mavlink import (  # noqa: E402
    ARDUPLANE_GUIDED,
    IGNORE_RATES,
    PX4_OFFBOARD,
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


BOOT_MS = 60_000
"""The fake vehicle's clock when it starts (it booted a minute ago): no setpoint sent before
its first report can carry this stamp."""
LOSS_S = 0.5
"""PX4's offboard rule: setpoints more often than 2 Hz, so no gap longer than this [s]."""
OFFBOARD = PX4_OFFBOARD << 16
"""PX4's HEARTBEAT custom_mode in OFFBOARD (the main mode in bits 16-23)."""
HOLD = (4 << 16) | (3 << 24)
"""PX4's custom_mode of AUTO.LOITER, its failsafe when offboard setpoints stop."""


class FakeVehicle(threading.Thread):
    """A plane simulated in lockstep with the decisions and paced at real time, on loopback.

    Its clock starts at BOOT_MS. It reports its state (GLOBAL_POSITION_INT) on entering the
    mode that takes setpoints and after each tick; a tick flies dt along the unicycle of
    eq. (1) with the bank (MAVLink's sign) of the decision for its clock, the first attitude
    setpoint stamped with that clock, no sooner than dt seconds of its own monotonic time
    after the previous tick. Out of that mode it ignores setpoints and flies wings level.

    flavour "px4" keeps PX4's offboard rules on its own receive times: it accepts the switch
    to OFFBOARD only after setpoints have arrived for `proof` seconds with no gap over LOSS_S
    (more often than 2 Hz), answering COMMAND_ACK TEMPORARILY_REJECTED otherwise, and leaves
    OFFBOARD for HOLD when no setpoint has come for LOSS_S. flavour "ardupilot" takes GUIDED
    from SET_MODE at once.
    """

    def __init__(self, port, start, dt, frame, flavour="ardupilot", proof=1.0):
        super().__init__(daemon=True)
        self.link = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=1)
        self.state, self.dt, self.frame = start.copy(), dt, frame
        self.flavour, self.proof = flavour, proof
        self.commanded = OFFBOARD if flavour == "px4" else ARDUPLANE_GUIDED
        self.clock_ms, self.mode, self.decision, self.last_tick = BOOT_MS, 0, None, None
        self.arrivals, self.stream_start = [], None  # setpoints' receive times
        self.flown, self.acks, self.exits = [], [], []  # (in the mode, roll) per tick
        self.left, self.stop = threading.Event(), threading.Event()
        self.heartbeats = []  # (receive time, system, component, type) of each HEARTBEAT

    def run(self):
        while not self.stop.is_set():
            msg = self.link.recv_match(blocking=True, timeout=0.02)
            now = time.monotonic()
            if msg is not None:
                self.handle(msg, now)
            if self.mode == OFFBOARD and now - self.arrivals[-1] > LOSS_S:
                self.mode = HOLD
                self.exits.append(now)
                self.left.set()
            if self.decision is not None and now - self.last_tick >= self.dt:
                self.tick(now)

    def handle(self, msg, now):
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            self.heartbeats.append((now, msg.get_srcSystem(), msg.get_srcComponent(), msg.type))
            autopilot = 12 if self.flavour == "px4" else 3  # MAV_AUTOPILOT_PX4, ARDUPILOTMEGA
            self.link.mav.heartbeat_send(1, autopilot, 1, self.mode, 4)  # fixed wing, active
        elif kind == "SET_MODE" and self.flavour == "ardupilot":
            self.mode = msg.custom_mode
            if self.mode == ARDUPLANE_GUIDED:
                self.enter(now)
        elif kind == "COMMAND_LONG" and msg.command == 176 and self.flavour == "px4":
            streaming = self.stream_start is not None and now - self.arrivals[-1] <= LOSS_S
            accepted = int(msg.param2) == PX4_OFFBOARD and streaming
            accepted = accepted and now - self.stream_start >= self.proof
            result = 0 if accepted else 1  # MAV_RESULT_ACCEPTED, TEMPORARILY_REJECTED
            self.acks.append(result)
            self.link.mav.command_ack_send(176, result)
            if accepted:
                self.mode = OFFBOARD
                self.enter(now)
        elif kind == "SET_ATTITUDE_TARGET":
            if not self.arrivals or now - self.arrivals[-1] > LOSS_S:
                self.stream_start = now  # a stream (re)starts
            self.arrivals.append(now)
            if self.last_tick is not None and msg.time_boot_ms == self.clock_ms:
                if self.decision is None:
                    self.decision = euler(msg.q)[0]

    def enter(self, now):
        self.last_tick = now
        self.report()

    def tick(self, now):
        in_mode = self.mode == self.commanded
        roll = self.decision if in_mode else 0.0
        self.flown.append((in_mode, roll))
        self.state = fly(self.state, np.array(-roll), self.dt, G)
        self.clock_ms += round(1000 * self.dt)
        self.decision, self.last_tick = None, now
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


@contextlib.contextmanager
def flying(start, dt, frame, **fake):
    """A fake vehicle on loopback and a `Vehicle` talking to it, both closed on the way out."""
    port = free_udp_port()
    vehicle_side = FakeVehicle(port, start, dt, frame, **fake)
    vehicle_side.start()
    try:
        vehicle = Vehicle(f"udpout:127.0.0.1:{port}")
        try:
            yield vehicle_side, vehicle
        finally:
            vehicle.close()
            assert not vehicle.stream.is_alive()
    finally:
        vehicle_side.stop.set()
        vehicle_side.join(timeout=10)
        vehicle_side.link.close()
        assert not vehicle_side.is_alive()


def fly_banks(vehicle, frame, dt, start, banks):
    """Fly `banks` through the pilot, checking each cycle's state against eq. (1)."""
    pilot = MavlinkPilot([vehicle], frame, dt, deadline=30.0)
    uavs, expected = start[None, None].copy(), start.copy()
    alive = np.ones((1, 1), dtype=bool)
    for bank in banks:
        uavs = pilot.fly(uavs, np.array([[bank]]), alive)
        expected = fly(expected, np.array(bank), dt, G)
        # positions through 1e-7 deg integers (about 1 cm), speeds through cm/s
        assert uavs[0, 0, :3] == pytest.approx(expected[:3], abs=0.02)
        assert uavs[0, 0, 3] == pytest.approx(15.0, abs=0.01)
        assert uavs[0, 0, 4] == pytest.approx(expected[4], abs=1e-3)


@pytest.mark.integration
def test_the_pilot_flies_a_vehicle_over_mavlink_as_the_unicycle_would():
    frame, dt = LocalFrame(47.4, 8.5), 0.5
    start = np.array([100.0, 50.0, 425.0, 15.0, 0.3])
    banks = [0.785, 0.785, 0.0, -0.785, 0.3, 0.0]
    with flying(start, dt, frame) as (vehicle_side, vehicle):
        vehicle.connect("ardupilot", deadline=30.0)
        fly_banks(vehicle, frame, dt, start, banks)
        assert vehicle_side.mode == ARDUPLANE_GUIDED
        # eq. (1)'s positive bank turns left; MAVLink's positive roll turns right
        assert [roll for _, roll in vehicle_side.flown] == pytest.approx([-b for b in banks])
        assert all(in_mode for in_mode, _ in vehicle_side.flown)


@pytest.mark.integration
@pytest.mark.parametrize("dt", [0.5, 1.0])
def test_px4_takes_offboard_and_keeps_it_through_the_run(dt):
    frame = LocalFrame(47.4, 8.5)
    start = np.array([-40.0, 80.0, 425.0, 15.0, 2.0])
    banks = [0.785, 0.0, -0.785, 0.3]
    with flying(start, dt, frame, flavour="px4") as (vehicle_side, vehicle):
        vehicle.connect("px4", deadline=30.0)
        assert vehicle_side.acks == [0] and vehicle_side.mode == OFFBOARD
        fly_banks(vehicle, frame, dt, start, banks)
        # every decision flown in OFFBOARD, which the vehicle never left
        assert [in_mode for in_mode, _ in vehicle_side.flown] == [True] * len(banks)
        assert [roll for _, roll in vehicle_side.flown] == pytest.approx([-b for b in banks])
        assert vehicle_side.exits == [] and vehicle_side.mode == OFFBOARD
        arrivals = np.array(vehicle_side.arrivals)
        # 20 Hz sent; a loaded machine may stretch it, so only half of that is asserted
        assert (len(arrivals) - 1) / (arrivals[-1] - arrivals[0]) > 10.0
        # a companion computer of vehicle 1 (component 191, MAV_TYPE_ONBOARD_CONTROLLER),
        # never the broadcast id 0, with a heartbeat at 1 Hz beside the setpoints
        beats = vehicle_side.heartbeats
        assert {(system, component, kind) for _, system, component, kind in beats} == {(1, 191, 18)}
        streamed = [t for t, *_ in beats if t >= arrivals[0]]
        assert len(streamed) >= 2
        rate = (len(streamed) - 1) / (streamed[-1] - streamed[0])
        assert 0.5 < rate < 1.5  # 1 Hz sent: a loaded machine may stretch it
        vehicle.close()  # the stream stops, and the vehicle falls back in half a second
        assert vehicle_side.left.wait(timeout=30.0)
        assert vehicle_side.mode == HOLD and not vehicle.stream.is_alive()


@pytest.mark.integration
def test_px4_refusing_offboard_fails_the_connection_in_one_line():
    frame, start = LocalFrame(), np.array([0.0, 0.0, 425.0, 15.0, 0.0])
    # a vehicle wanting a longer stream than the vehicle's lead-in gives it
    with flying(start, 0.5, frame, flavour="px4", proof=60.0) as (vehicle_side, vehicle):
        with pytest.raises(RunError, match="vehicle 1 refused OFFBOARD") as info:
            vehicle.connect("px4", deadline=30.0)
        assert "MAV_RESULT_TEMPORARILY_REJECTED" in str(info.value)
        assert "\n" not in str(info.value)
        assert vehicle_side.acks == [1] and vehicle_side.mode != OFFBOARD
        assert not vehicle.stream.is_alive()  # the failed connection stopped its stream


@pytest.mark.integration
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
