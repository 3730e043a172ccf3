"""Whether a neighbour's avoidance beacon is one an honest UAV could send: a receiver's
check of each beacon against what it already knows (``planner.avoidance``).

The avoidance filter (`avoidance`) trusts the states its neighbours broadcast. A member
with valid keys may broadcast a state that passes every check of a single message (a
position in the field, a speed and a heading in range) and yet place itself next to
each receiver, so that the receivers give way to an aircraft that is not there. Three
checks bound that, each against a fact the receiver holds:

* **its earlier beacon**: between two beacons of one sender, the position moves at most
  the UAVs' largest ground speed times the time between them, the heading turns at most
  the largest turn rate, the altitude at most `CLIMB` per second (plus the position
  error of two GPS fixes, and a margin for real aircraft, `TURN_MARGIN`);
* **the radio's range**: where a beacon cannot be lost (no loss, no delay, no capacity
  limit), a sender not heard at the last step was out of range then, so its first
  beacon places it at most two steps of flight inside the range;
* **the start**: with ``uav.start = "grid"`` every UAV's state at step 0 is known.

An honest UAV's beacons pass all three (a test flies honest teams and checks every
beacon, unicycle and JSBSim); a refused beacon is not heard, and is counted. What the
checks do not stop: a member whose false states follow the aircraft's limits from its
first beacon on, where that first beacon is believable (docs: Security).
"""

# Strict typing, less the unknown-type rules (numpy resolves an overloaded call with an
# argument of type Any, as any array's shape, to Unknown).
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import G, Scenario
from ..robust.plausibility import SIGMAS
from ..world import HEADING, H, X, Y, start_grid, wrap_angle

__all__ = ["CLIMB", "TURN_MARGIN", "Limits", "believable"]

CLIMB = 10.0
"""The largest altitude change of an honest UAV's beacons [m/s]: the unicycle keeps its
altitude, JSBSim's altitude hold keeps it within a few metres; assumed."""

TURN_MARGIN = 2.0
"""How many times the turn rate of the largest bank angle a real aircraft's heading may
turn between two beacons (JSBSim's roll overshoots the bank held, turbulence yaws it);
assumed, measured against JSBSim in the tests."""

HEADING_SLACK = math.radians(10.0)
"""Heading change always allowed between two beacons [rad]: sensor noise of a real
aircraft's heading; assumed."""


@dataclass(frozen=True, kw_only=True)
class Limits:
    """What an honest UAV's beacons can do, for one run: speed the largest ground speed
    [m/s], turn the largest turn rate [rad/s], slack the error of a GPS fix times two
    [m], dt the step [s], reach the radio range [m] when a beacon not heard means out of
    range (else None), and start (N, 5) each UAV's state at step 0 when known (else
    None)."""

    speed: float
    turn: float
    slack: float
    dt: float
    reach: float | None
    start: np.ndarray | None

    @classmethod
    def of(cls, scenario: Scenario) -> Limits:
        u, f = scenario.uav, scenario.faults
        speed = 2.0 * (u.speed + scenario.wind.speed)  # as `plausibility.Bounds.uav_speed`
        bank = math.radians(u.bank_angle_deg)
        slowest = max(u.speed - scenario.wind.speed, 0.5 * u.speed)
        if u.min_speed is not None:  # the filter may slow a UAV, which then turns faster
            slowest = min(slowest, u.min_speed)
        turn = TURN_MARGIN * G * math.tan(bank) / slowest
        certain = f.loss == 0 and f.delay == 0 and scenario.radio.bandwidth_bps is None
        start = None
        if u.start == "grid":
            start = np.zeros((scenario.n_uavs, 5))
            start[:, [X, Y]] = start_grid(scenario.n_uavs, u.start_spread, scenario.field_size)
            start[:, H], start[:, HEADING] = scenario.altitudes(), np.pi / 2
        return cls(
            speed=speed,
            turn=turn,
            slack=2.0 * SIGMAS * f.position_std + 1.0,
            dt=scenario.dt,
            reach=scenario.comm_range if certain else None,
            start=start,
        )


def believable(
    limits: Limits,
    sender: int,
    state: np.ndarray,
    k: int,
    before: tuple[np.ndarray, int] | None,
    me: np.ndarray,
) -> str | None:
    """Why the beacon of `sender` at step k, carrying `state` (5,), is one no honest UAV
    sends (None: it could be): against its last beacon the receiver kept, before =
    (state (5,), its step) or None; the receiver's own state `me` (5,) at step k."""
    if k == 0 and limits.start is not None:
        away = np.hypot(*(state[[X, Y]] - limits.start[sender, [X, Y]]))
        turned = abs(wrap_angle(state[HEADING] - limits.start[sender, HEADING]))
        if away > limits.slack or turned > HEADING_SLACK:
            return "beacon not at its start"
        return None
    if before is not None:
        last, when = before
        seconds = (k - when) * limits.dt
        moved = np.hypot(*(state[[X, Y]] - last[[X, Y]]))
        turned = abs(wrap_angle(state[HEADING] - last[HEADING]))
        climbed = abs(state[H] - last[H])
        if (
            moved > limits.speed * seconds + limits.slack
            or turned > min(limits.turn * seconds + HEADING_SLACK, np.pi)
            or climbed > CLIMB * seconds + limits.slack
        ):
            return "beacon beyond the aircraft's limits"
        if when == k - 1 or limits.reach is None:
            return None
    if limits.reach is not None and k > 0:  # not heard at k - 1: out of range then
        apart = np.linalg.norm(state[[X, Y, H]] - me[[X, Y, H]])
        if apart < limits.reach - 2.0 * limits.speed * limits.dt - limits.slack:
            return "beacon appears inside the radio range"
    return None
