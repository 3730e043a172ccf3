"""The decision as MAVLink: a bank-angle setpoint a real autopilot flies.

Each cycle, every UAV's bank angle goes to its flight controller as a
``SET_ATTITUDE_TARGET`` (roll from the decision, pitch at `pitch`, the current heading
as yaw, body rates ignored, `thrust` as the throttle/thrust field): ArduPlane accepts it
in GUIDED mode and PX4 as an offboard attitude setpoint. Altitude and airspeed are the
vehicle's own business: ArduPlane's GUIDED mode holds them (its TECS), and a PX4 offboard
attitude setpoint carries the thrust. The UAV's state comes back from the vehicle's
``GLOBAL_POSITION_INT`` (position, height, ground velocity), mapped to the scenario's
frame by `LocalFrame`.

The exchange waits on the vehicle's clock, not the world's: after a setpoint sent at the
vehicle's time t, `fly` returns with the first position report stamped t + dt or later
(a simulator in lockstep answers at once, a real vehicle after dt), or fails after
`deadline` seconds without one. Nothing here has been flown against PX4 or ArduPilot or
their simulators: the messages are checked by decoding them back and by an exchange with
a minimal vehicle on loopback (tests/test_mavlink.py).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import RunError, install_hint
from .jsbsim import WGS84_A, WGS84_E2

IGNORE_RATES = 0b0000_0111
"""SET_ATTITUDE_TARGET type_mask: ignore the body roll, pitch and yaw rates."""

ARDUPLANE_GUIDED = 15
"""ArduPlane's custom mode number of GUIDED."""
PX4_OFFBOARD = 6
"""PX4's main mode number of OFFBOARD."""


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


class Vehicle:
    """One flight controller over a MAVLink connection (`url` as pymavlink takes it,
    e.g. ``udpout:127.0.0.1:14551``); `target` its system id."""

    def __init__(self, url: str, target: int = 1, source: int = 245) -> None:
        self.link = _mavutil().mavlink_connection(url, source_system=source)
        self.target = target
        self.clock_ms = 0  # the vehicle's time_boot_ms, from its reports

    def connect(self, flavour: str, deadline: float) -> None:
        """Wait for the vehicle's heartbeat (sending ours, so a UDP vehicle learns where
        to answer) and put it in the mode that takes attitude setpoints."""
        mavlink = self.link.mav
        end = time.monotonic() + deadline
        while True:
            mavlink.heartbeat_send(6, 8, 0, 0, 0)  # GCS, autopilot invalid
            if self.link.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2):
                break
            if time.monotonic() > end:
                raise RunError(f"no heartbeat from the vehicle within {deadline:g} s")
        if flavour == "ardupilot":
            mavlink.set_mode_send(self.target, 1, ARDUPLANE_GUIDED)  # custom mode enabled
        elif flavour == "px4":
            mavlink.command_long_send(self.target, 1, 176, 0, 1, PX4_OFFBOARD, 0, 0, 0, 0, 0)
        else:
            raise ValueError(f"flavour must be 'ardupilot' or 'px4', not {flavour!r}")

    def command(self, roll: float, pitch: float, yaw: float, thrust: float) -> None:
        """Send one attitude setpoint (roll positive right wing down, MAVLink's)."""
        self.link.mav.set_attitude_target_send(
            self.clock_ms,
            self.target,
            1,
            IGNORE_RATES,
            quaternion(roll, pitch, yaw),
            0.0,
            0.0,
            0.0,
            thrust,
        )

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
        """Send each living UAV's bank setpoint (positive left, eq. 1), then wait for
        its state one cycle later. uavs (1, Nu, 5); bank, alive (1, Nu)."""
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
