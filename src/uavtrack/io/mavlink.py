"""The decision as MAVLink: a bank-angle setpoint a real autopilot flies.

Each cycle, every UAV's bank angle goes to its flight controller as a
``SET_ATTITUDE_TARGET`` (roll from the decision, pitch at `pitch`, the current heading
as yaw, body rates ignored, `thrust` as the throttle/thrust field): ArduPlane accepts it
in GUIDED mode and PX4 as an offboard attitude setpoint. Altitude and airspeed are the
vehicle's own business: ArduPlane's GUIDED mode holds them (its TECS), and a PX4 offboard
attitude setpoint carries the thrust. The UAV's state comes back from the vehicle's
``GLOBAL_POSITION_INT`` (position, height, ground velocity), mapped to the scenario's
frame by `LocalFrame`.

Setpoints are streamed, not sent once per cycle: PX4 takes OFFBOARD only from a vehicle
that has received setpoints more often than 2 Hz for about a second, and leaves it (its
offboard-loss failsafe) when they stop for COM_OF_LOSS_T, while a cycle is 0.5 s or 1 s.
So each `Vehicle` has a sender of its own, `SetpointStream`, a thread that resends the
current setpoint at `STREAM_HZ` (as MAVSDK's offboard plugin does) from before the switch
of mode until the vehicle is closed, and a HEARTBEAT at 1 Hz beside them; a decision only
replaces the setpoint it resends. The bridge is a companion computer of its vehicle: the
vehicle's system id, component 191 (MAV_COMP_ID_ONBOARD_COMPUTER).

The exchange waits on the vehicle's clock, not the world's: after a setpoint decided on
the vehicle's report of time t, `fly` returns with the first position report stamped
t + dt or later (a simulator in lockstep answers at once, a real vehicle after dt), or
fails after `deadline` seconds without one. Nothing here has been flown against PX4 or
ArduPilot or their simulators: the messages are checked by decoding them back and by an
exchange with a minimal vehicle on loopback that keeps PX4's offboard rules
(tests/test_mavlink.py).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import RunError, install_hint
from ..flight.jsbsim import WGS84_A, WGS84_E2

IGNORE_RATES = 0b0000_0111
"""SET_ATTITUDE_TARGET type_mask: ignore the body roll, pitch and yaw rates."""

ARDUPLANE_GUIDED = 15
"""ArduPlane's custom mode number of GUIDED."""
PX4_OFFBOARD = 6
"""PX4's main mode number of OFFBOARD."""
DO_SET_MODE = 176
"""MAV_CMD_DO_SET_MODE, the command PX4 switches modes by (acknowledged)."""
STREAM_HZ = 20.0
"""How often a vehicle's current setpoint is resent [Hz]: PX4 needs more than 2 Hz to
enter and stay in OFFBOARD; 20 Hz is MAVSDK's rate, ten times that."""
HEARTBEAT_HZ = 1.0
"""How often the bridge says it is there [Hz]: MAVLink's heartbeat rate, by which a
flight controller and a ground station see a component alive."""
COMPANION = 191
"""The bridge's component id: MAV_COMP_ID_ONBOARD_COMPUTER, a companion computer on the
vehicle (never 0, MAVLink's broadcast id); its system id is the vehicle's."""
ONBOARD_CONTROLLER, AUTOPILOT_INVALID = 18, 8
"""Its HEARTBEAT's type (MAV_TYPE_ONBOARD_CONTROLLER) and autopilot (MAV_AUTOPILOT_INVALID:
it flies nothing itself)."""
LEAD_S = 1.5
"""How long setpoints stream before PX4 is asked for OFFBOARD [s]: PX4 enables offboard
control after about a second of them; half a second more so that the vehicle has seen a
second even if the link delays the first ones."""


def _mavutil():
    try:
        from pymavlink import mavutil
    except ImportError:
        raise ImportError(
            "the MAVLink autopilot needs pymavlink, which the flight extra installs: "
            + install_hint("flight")
        ) from None
    return mavutil


def quaternion(roll: float, pitch: float, yaw: float) -> list[float]:
    """[w, x, y, z] of the aerospace (z-y-x) Euler angles [rad], MAVLink's order."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]


def euler(q: Sequence[float]) -> tuple[float, float, float]:
    """(roll, pitch, yaw) [rad] of a quaternion [w, x, y, z]."""
    w, x, y, z = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


@dataclass(frozen=True)
class LocalFrame:
    """The scenario's frame (x east, y north [m]) around a geodetic origin (lat0, lon0)
    [deg] on WGS84, flat: distances are the angles times the ellipsoid's radii of
    curvature at the origin."""

    lat0: float = 0.0
    lon0: float = 0.0

    @property
    def radii(self) -> tuple[float, float]:
        """Metres per radian of longitude (east) and of latitude (north) at the origin."""
        s = math.sin(math.radians(self.lat0))
        n = WGS84_A / math.sqrt(1 - WGS84_E2 * s * s)
        m = WGS84_A * (1 - WGS84_E2) / (1 - WGS84_E2 * s * s) ** 1.5
        return n * math.cos(math.radians(self.lat0)), m

    def to_xy(self, lat: float, lon: float) -> tuple[float, float]:
        east, north = self.radii
        return east * math.radians(lon - self.lon0), north * math.radians(lat - self.lat0)

    def to_latlon(self, x: float, y: float) -> tuple[float, float]:
        east, north = self.radii
        return self.lat0 + math.degrees(y / north), self.lon0 + math.degrees(x / east)


class SetpointStream(threading.Thread):
    """Resends one vehicle's current setpoint every 1/`rate` seconds until stopped.

    `send(setpoint)` puts one on the wire; `set` replaces the setpoint and sends it at once
    (the period restarts from there). Sends keep to a schedule, so late wake-ups do not
    lower the rate; after a stall of the machine the schedule restarts, with no burst to
    catch up. `ready` is set once the stream has run for `lead` seconds; a failed send
    ends the thread and is kept in `error`.
    """

    def __init__(
        self,
        send: Callable[[tuple], None],
        rate: float,
        lead: float,
        beat: Callable[[], None] | None = None,
    ) -> None:
        super().__init__(daemon=True, name="uavtrack-setpoints")
        self.send, self.period, self.lead = send, 1.0 / rate, lead
        self.beat = beat  # a HEARTBEAT, sent at HEARTBEAT_HZ beside the setpoints
        self.beats = 0
        self.setpoint: tuple | None = None
        self.sent = 0
        self.error: BaseException | None = None
        self.ready = threading.Event()
        self._wake, self._stopped = threading.Event(), False

    def set(self, setpoint: tuple) -> None:
        self.setpoint = setpoint  # one reference assigned: the sender reads old or new
        self._wake.set()

    def stop(self, timeout: float = 5.0) -> None:
        self._stopped = True
        self._wake.set()
        if self.is_alive():
            self.join(timeout)

    def run(self) -> None:
        first = due = beat_due = time.monotonic()
        while True:
            woken = self._wake.wait(max(0.0, due - time.monotonic()))
            self._wake.clear()
            if self._stopped:
                return
            try:
                if self.setpoint is None:
                    raise RuntimeError("the setpoint stream started without a setpoint")
                self.send(self.setpoint)
                if self.beat is not None and time.monotonic() >= beat_due:
                    self.beat()
                    self.beats += 1
                    beat_due = max(beat_due + 1.0 / HEARTBEAT_HZ, time.monotonic())
            except Exception as exc:  # noqa: BLE001 (a closed link, a dead interface)
                self.error = exc
                return
            self.sent += 1
            now = time.monotonic()
            if now - first >= self.lead:
                self.ready.set()
            # on schedule, so a late wake-up shortens the next wait; after a new setpoint
            # or a stall longer than a period, the schedule restarts from now
            due += self.period
            if woken or due <= now:
                due = now + self.period


class Vehicle:
    """One flight controller over a MAVLink connection (`url` as pymavlink takes it,
    e.g. ``udpout:127.0.0.1:14551``); `target` its system id. The bridge speaks as a
    companion computer of that vehicle: system id `source` (default: the vehicle's),
    component `COMPANION`, a HEARTBEAT at `HEARTBEAT_HZ` from the connection on."""

    def __init__(self, url: str, target: int = 1, source: int | None = None) -> None:
        self.link = _mavutil().mavlink_connection(
            url, source_system=target if source is None else source, source_component=COMPANION
        )
        self.target = target
        self.clock_ms = 0  # the vehicle's time_boot_ms, from its reports
        self._sending = threading.Lock()  # the stream and this thread share one link
        self.stream = self._stream()

    def _stream(self) -> SetpointStream:
        return SetpointStream(self._send_setpoint, STREAM_HZ, LEAD_S, self._heartbeat)

    def _heartbeat(self) -> None:
        self._send("heartbeat_send", ONBOARD_CONTROLLER, AUTOPILOT_INVALID, 0, 0, 0)

    def connect(
        self, flavour: str, deadline: float, pitch: float = 0.0, thrust: float = 0.5
    ) -> None:
        """Wait for the vehicle's heartbeat (sending ours, so a UDP vehicle learns where
        to answer), start streaming setpoints (wings level at `pitch` and `thrust` until the
        first decision), put the vehicle in the mode that takes them and wait for its first
        position report, whose stamp the first decision carries.

        ArduPlane's GUIDED is asked for at once by SET_MODE (streaming before it is harmless:
        ArduPlane ignores attitude setpoints outside GUIDED). PX4's OFFBOARD is asked for by
        MAV_CMD_DO_SET_MODE after `LEAD_S` seconds of setpoints, and its COMMAND_ACK must
        accept it."""
        if flavour not in ("ardupilot", "px4"):
            raise ValueError(f"flavour must be 'ardupilot' or 'px4', not {flavour!r}")
        end = time.monotonic() + deadline
        while True:
            self._heartbeat()
            if self.link.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2):
                break
            if time.monotonic() > end:
                raise RunError(f"no heartbeat from the vehicle within {deadline:g} s")
        self.stream = self._stream()
        self.command(0.0, pitch, 0.0, thrust)
        self.stream.start()
        try:
            if flavour == "ardupilot":
                self._send("set_mode_send", self.target, 1, ARDUPLANE_GUIDED)  # custom mode
            else:
                if not self.stream.ready.wait(max(0.0, end - time.monotonic())):
                    raise RunError(
                        self._stream_failure()
                        if self.stream.error is not None
                        else f"no time for {LEAD_S:g} s of setpoints before OFFBOARD within "
                        f"the deadline of {deadline:g} s"
                    )
                self._switch(PX4_OFFBOARD, "OFFBOARD", end, deadline)
            self.report(0, max(0.0, end - time.monotonic()))
        except BaseException:
            self.stream.stop()  # no thread left behind; connecting again starts a new one
            raise

    def _switch(self, mode: int, name: str, end: float, deadline: float) -> None:
        """Ask PX4 for main mode `mode` until its COMMAND_ACK accepts (or refuses, or the
        deadline passes); unanswered, the command is repeated each second with its
        confirmation counting the repeats (MAVLink's command protocol)."""
        mavlink = _mavutil().mavlink
        assert mavlink is not None  # the dialect loaded with the connection
        for confirmation in range(max(1, math.ceil(deadline))):
            params = (1, mode, 0, 0, 0, 0, 0)  # custom mode enabled, PX4's main mode
            self._send("command_long_send", self.target, 1, DO_SET_MODE, confirmation, *params)
            repeat = min(end, time.monotonic() + 1.0)
            while (left := repeat - time.monotonic()) > 0:
                ack = self.link.recv_match(type="COMMAND_ACK", blocking=True, timeout=left)
                if ack is None or ack.command != DO_SET_MODE:
                    continue
                if ack.result == mavlink.MAV_RESULT_ACCEPTED:
                    return
                if ack.result != mavlink.MAV_RESULT_IN_PROGRESS:
                    verdict = mavlink.enums["MAV_RESULT"][ack.result].name
                    raise RunError(f"vehicle {self.target} refused {name}: {verdict}")
            if time.monotonic() >= end:
                break
        raise RunError(f"vehicle {self.target} did not enter {name} within {deadline:g} s")

    def command(self, roll: float, pitch: float, yaw: float, thrust: float) -> None:
        """Make (roll, pitch, yaw) [rad] and `thrust` the setpoint the stream sends (roll
        positive right wing down, MAVLink's), stamped with the vehicle's time of the state
        it was decided on. Before `connect` it is only kept."""
        if self.stream.error is not None:
            raise RunError(self._stream_failure())
        self.stream.set((self.clock_ms, quaternion(roll, pitch, yaw), thrust))

    def _send_setpoint(self, setpoint: tuple) -> None:
        stamp, q, thrust = setpoint
        self._send(
            "set_attitude_target_send", stamp, self.target, 1, IGNORE_RATES, q, 0, 0, 0, thrust
        )

    def _send(self, method: str, *args) -> None:
        with self._sending:  # pymavlink's packing (sequence numbers) is not thread-safe
            getattr(self.link.mav, method)(*args)

    def _stream_failure(self) -> str:
        return f"the setpoint stream to vehicle {self.target} failed: {self.stream.error}"

    def report(self, after_ms: int, deadline: float):
        """The first GLOBAL_POSITION_INT stamped `after_ms` or later."""
        end = time.monotonic() + deadline
        while time.monotonic() < end:
            msg = self.link.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=0.2)
            if msg is not None:
                self.clock_ms = max(self.clock_ms, msg.time_boot_ms)
                if msg.time_boot_ms >= after_ms:
                    return msg
        raise RunError(f"no position report from vehicle {self.target} within {deadline:g} s")

    def close(self) -> None:
        """Stop the stream (PX4 then leaves OFFBOARD for its failsafe) and the link."""
        self.stream.stop()
        self.link.close()


class MavlinkPilot:
    """The autopilot of one trial whose UAVs are real (or simulated) vehicles.

    vehicles: one `Vehicle` per UAV, connected; frame: where the scenario's origin is;
    dt: the cycle [s]; pitch [rad] and thrust [0, 1]: the rest of the setpoint.
    """

    def __init__(
        self,
        vehicles: Sequence[Vehicle],
        frame: LocalFrame,
        dt: float,
        pitch: float = 0.0,
        thrust: float = 0.5,
        deadline: float = 10.0,
    ) -> None:
        self.vehicles, self.frame, self.dt = list(vehicles), frame, dt
        self.pitch, self.thrust, self.deadline = pitch, thrust, deadline

    def fly(self, uavs: np.ndarray, bank: np.ndarray, alive: np.ndarray) -> np.ndarray:
        """Make each living UAV's bank (positive left, eq. 1) the setpoint its stream
        sends, then wait for its state one cycle later. uavs (1, Nu, 5); bank, alive
        (1, Nu). A failed UAV's vehicle keeps its last setpoint."""
        out = uavs.copy()
        due = {}
        for i, vehicle in enumerate(self.vehicles):
            if alive[0, i]:
                due[i] = vehicle.clock_ms + round(1000 * self.dt)
                yaw = math.pi / 2 - float(uavs[0, i, 4])  # heading east-CCW -> north-CW
                vehicle.command(-float(bank[0, i]), self.pitch, yaw, self.thrust)
        for i, after in due.items():
            out[0, i] = self.state(self.vehicles[i].report(after, self.deadline))
        return out

    def state(self, msg) -> np.ndarray:
        """x, y, h, V, heading of a GLOBAL_POSITION_INT (ground speed and course)."""
        x, y = self.frame.to_xy(msg.lat / 1e7, msg.lon / 1e7)
        north, east = msg.vx / 100, msg.vy / 100
        return np.array(
            [x, y, msg.relative_alt / 1000, math.hypot(east, north), math.atan2(north, east)]
        )
