"""How a UAV's aircraft answers the avoidance filter's actions, measured by flying the
scenario's flight model (``planner.avoidance_model = "measured"``).

The filter (`avoidance`) needs two facts of every UAV: where the circle it would fly if
it held +phi from now on lies (its *backup*), and where each action moves that circle.
Under eq. (1) both have a closed form. A JSBSim aircraft rolls into a bank over about
one step, so its backup depends on the commands of the last steps: after a right turn,
the circle it settles on when told to turn left lies some 15 m from eq. (1)'s.

The model keys a UAV on its *recent* commands kappa = 3 p2 + p1, the actions it flew
two steps and one step ago (`recent`). From a state at position p and heading psi in
the air mass (the ground velocity less the wind):

* the action a moves it to p' = p + Rot(psi) move[kappa, a] and psi' = psi +
  turn[kappa, a], with recent commands 3 p1 + a;
* its backup has centre c = p + Rot(psi) centre[kappa] (`backup`) and radius `radius`,
  on which it turns by the same angle every step once settled: two UAVs of one aircraft
  and airspeed then keep the clearance of their backups, as under eq. (1).

`measure` flies the scenario's aircraft through every history of four commands followed
by each action and then the loiter, each after eight random commands of its own (243
aircraft side by side, in the scenario's wind and turbulence, `REPEATS` times with
turbulence), fits a circle to each loiter in the air mass, and takes the tables as means
over the flights. What the means miss is measured on the same flights:
`Response.centre_error`, the largest distance of a true backup centre after an action
from the table's; `position_error`, the same of the position; `transient_error`, how far
the aircraft flies off the point its backup gives it (the offset after the action
turned at the steady rate) in the steps after the action, while it rolls into the turn
(5.2 m for JSBSim's trackwing at 15 m/s); `now_error`, of the backup centre of a state
before it acts. The clearance is 1-Lipschitz in each UAV's centre and offset (u = p -
c), and each UAV's distance from its ideal point on the circle adds to a pair's at
most, so the filter keeps `Response.margin` = 2 (2 centre_error + position_error +
transient_error) above the separation for a pair, and calls a pair in conflict below
that distance less `Response.slack` = 4 now_error (the clearance of a pair kept at it
reads that much less at most); a pair in conflict is moved apart (the filter's recovery),
where the rule alone would hold it on its backups for good. These are the largest errors
seen, not bounds (the filter refuses turbulence, where they reach tens of metres). The
sound range takes the longest offset (`Response.reach`, 24.0 m against the steady
radius 23.1 m): a UAV not yet on its circle is that far from its centre.
"""

# Strict typing, less the unknown-type rules (numpy resolves an overloaded call with an
# argument of type Any, as any array's shape, to Unknown).
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import cache

import numpy as np

from ..config import Scenario
from ..world import HEADING, V, X, Y

__all__ = [
    "HISTORY", "PREFIX", "REPEATS", "START", "STEADY", "Response", "air_heading", "measure",
    "recent",
]  # fmt: skip

HISTORY = 4
"""Commands flown before the measured action, every combination: the two the model keys
on and two more, whose spread the errors take in."""

PREFIX = 8
"""Random commands flown before those, a draw of their own for each flight: states a
long flight reaches (a roll and the altitude hold not yet settled), whose spread the
errors take in too."""

SETTLE = 8
"""Steps of the loiter left out of the circle fit [steps]: the roll into it and the
altitude hold's dip; measured: a JSBSim trackwing at 15 m/s holds its circle within
0.1 m after 5."""

FIT = 24
"""Steps of the loiter the circle is fitted to [steps]: at 15 m/s and 45 deg, 1.25
turns."""

REPEATS = 4
"""Flights of every history with turbulence, each with its own gusts (without, a flight
is deterministic and one is flown)."""

START = 3 * 1 + 1
"""The recent commands of a UAV that starts in straight level flight: straight twice."""

STEADY = 3 * 2 + 2
"""The recent commands of a UAV in its backup's steady turn: +phi twice."""


def recent(before: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """The recent commands (`Response`) after flying `actions` from `before` (any shape)."""
    return 3 * (before % 3) + actions


def _rotate(psi: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v (..., 2) turned by psi (...) counterclockwise."""
    cos, sin = np.cos(psi), np.sin(psi)
    return np.stack([cos * v[..., 0] - sin * v[..., 1], sin * v[..., 0] + cos * v[..., 1]], -1)


def air_heading(uavs: np.ndarray, wind: np.ndarray) -> np.ndarray:
    """The headings (...) of UAV states (..., 5) in the air mass: of the ground velocity
    less the wind (2,) [m/s]."""
    vx = uavs[..., V] * np.cos(uavs[..., HEADING]) - wind[0]
    vy = uavs[..., V] * np.sin(uavs[..., HEADING]) - wind[1]
    return np.arctan2(vy, vx)


@dataclass(frozen=True, kw_only=True)
class Response:
    """An aircraft's measured answer to the actions (-phi, 0, +phi), keyed on its recent
    commands (9 keys): move (9, 3, 2) [m] and turn (9, 3) [rad] of one step in the frame
    of its heading, its backup's centre (9, 2) [m] in the same frame; the radius [m] and
    the turn per step [rad] of the backup's steady circle (fitted to the settled loiter);
    the steady wind (2,) [m/s] it was measured in; the largest errors of the tables on
    the flights (centre_error, position_error, now_error, and transient_error: how far
    off its backup's circle it flies while it settles [m]) and delta (3,) [m], how far
    each action moves the backup's centre and turns its offset against the loiter, at
    most over the keys."""

    move: np.ndarray
    turn: np.ndarray
    centre: np.ndarray
    radius: float
    step_turn: float
    wind: np.ndarray
    centre_error: float
    position_error: float
    now_error: float
    delta: np.ndarray
    transient_error: float = 0.0

    @property
    def margin(self) -> float:
        """What the filter keeps above the separation for a pair [m]: each UAV's
        centre and offset may each be off by the table's errors after a step, and its
        position off its backup's circle while it settles (`transient_error`)."""
        return 2.0 * (2.0 * self.centre_error + self.position_error + self.transient_error)

    @property
    def reach(self) -> float:
        """The farthest a UAV is from its backup's centre [m]: the steady radius, or an
        offset of the tables (a UAV not yet on its circle) if longer."""
        return max(self.radius, float(np.hypot(*self.centre.T).max()))

    @property
    def slack(self) -> float:
        """How far below the separation a pair's clearance may read before it is in
        conflict [m]: each UAV's centre and offset off by `now_error`."""
        return 4.0 * self.now_error

    def air(self, uavs: np.ndarray) -> np.ndarray:
        """The headings (...) of UAV states (..., 5) in the air mass (`air_heading`)."""
        return air_heading(uavs, self.wind)

    def backup(self, uavs: np.ndarray, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The centre c and offset u = p - c (each (..., 2)) of the backups of UAVs
        (..., 5) with recent commands keys (...)."""
        p = uavs[..., [X, Y]]
        c = p + _rotate(self.air(uavs), self.centre[keys])
        return c, p - c

    def after(self, uavs: np.ndarray, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The backups' centres and offsets (..., 3, 2) after each action."""
        psi = self.air(uavs)[..., None]  # (..., 1)
        p = uavs[..., None, [X, Y]] + _rotate(psi, self.move[keys])  # (..., 3, 2)
        c = p + _rotate(psi + self.turn[keys], self.centre[recent(keys[..., None], np.arange(3))])
        return c, p - c


def measure(scenario: Scenario) -> Response:
    """The `Response` of the scenario's UAVs, flown by its flight model (`flight.start`)
    at its speed, altitude, bank angle, step, wind and turbulence; cached per aircraft
    and conditions."""
    uav, wind = scenario.uav, scenario.wind
    return _measure(
        uav.dynamics, uav.aircraft, uav.speed, uav.altitude, uav.bank_angle_deg,
        uav.jsbsim_rate_hz, scenario.dt, wind.speed, wind.direction_deg, wind.turbulence,
    )  # fmt: skip


@cache
def _measure(
    dynamics: str,
    aircraft: str,
    speed: float,
    altitude: float,
    bank_deg: float,
    rate: float | None,
    dt: float,
    wind_speed: float,
    wind_deg: float,
    turbulence: str,
) -> Response:
    from .. import flight

    update: dict[str, object] = {
        "uav": {"dynamics": dynamics, "aircraft": aircraft, "speed": speed,
                "altitude": altitude, "bank_angle_deg": bank_deg, "jsbsim_rate_hz": rate},
        "wind": {"speed": wind_speed, "direction_deg": wind_deg, "turbulence": turbulence},
        "dt": dt,
    }  # fmt: skip
    if dynamics == "unicycle":  # it flies no aircraft, in still air
        update["uav"] = {"speed": speed, "altitude": altitude, "bank_angle_deg": bank_deg}
        del update["wind"]
    scenario = Scenario.model_validate(update)
    phi = math.radians(bank_deg)
    banks = np.array([-phi, 0.0, phi])
    ends = np.array(list(itertools.product(range(3), repeat=HISTORY + 1)))  # (243, 5)
    count = len(ends)
    prefix = np.random.default_rng(PREFIX).integers(0, 3, (count, PREFIX))
    plans = np.concatenate([prefix, ends], axis=1)
    steps = PREFIX + HISTORY + 1 + SETTLE + FIT
    commands = np.concatenate([plans, np.full((count, SETTLE + FIT), 2)], axis=1)
    last = PREFIX + HISTORY  # the measured action's index
    repeats = REPEATS if turbulence != "none" else 1
    seeds = [np.random.SeedSequence([7, r]) for r in range(repeats)]
    start = np.zeros((repeats, count, 5))
    start[..., 2], start[..., V] = altitude, speed
    pilot, uavs = flight.start(scenario, seeds, start)
    track = np.empty((steps + 1, repeats, count, 5))
    track[0] = uavs
    alive = np.ones((repeats, count), dtype=bool)
    for t in range(steps):
        uavs = pilot.fly(uavs, np.broadcast_to(banks[commands[:, t]], alive.shape), alive)
        track[t + 1] = uavs
    w = np.asarray(scenario.wind.velocity() if dynamics != "unicycle" else (0.0, 0.0))
    drift = w * dt * np.arange(steps + 1)[:, None]  # (T + 1, 2): the air mass moved
    air_p = track[..., [X, Y]] - drift[:, None, None]
    psi = air_heading(track, w)  # (T + 1, R, C)
    # the true backup after the action: a circle fitted to the loiter's positions
    tail = air_p[last + 1 + SETTLE :]  # (FIT, R, C, 2)
    lhs = np.concatenate([2.0 * tail, np.ones(tail.shape[:-1] + (1,))], -1)
    rhs = (tail**2).sum(-1)
    a, b = np.moveaxis(lhs, 0, -2), np.moveaxis(rhs, 0, -1)[..., None]  # (R, C, FIT, 3), (.., 1)
    solved = np.linalg.solve(np.swapaxes(a, -1, -2) @ a, np.swapaxes(a, -1, -2) @ b)[..., 0]
    true_c = solved[..., :2]  # (R, C, 2)
    radius = np.sqrt(solved[..., 2] + (true_c**2).sum(-1))
    before, after = last, last + 1
    key = np.broadcast_to(3 * plans[:, last - 2] + plans[:, last - 1], (repeats, count))
    action = np.broadcast_to(plans[:, last], (repeats, count))
    nxt = recent(key, action)
    p0, p1 = air_p[before], air_p[after]
    psi0, psi1 = psi[before], psi[after]
    moved = _rotate(-psi0, p1 - p0)  # (R, C, 2)
    turned = (psi1 - psi0 + np.pi) % (2 * np.pi) - np.pi
    seen = _rotate(-psi1, true_c - p1)  # the backup's centre in the frame after the action
    move, turn, centre = np.zeros((9, 3, 2)), np.zeros((9, 3)), np.zeros((9, 2))
    for k, act in itertools.product(range(9), range(3)):
        pick = (key == k) & (action == act)
        move[k, act], turn[k, act] = moved[pick].mean(0), turned[pick].mean()
    for k in range(9):
        centre[k] = seen[nxt == k].mean(0)
    # the tables' errors on the same flights
    p_hat = p0 + _rotate(psi0, move[key, action])
    c_hat = p_hat + _rotate(psi0 + turn[key, action], centre[nxt])
    loitered = action == 2  # the backup then is the state's own before it acted
    c_now = p0 + _rotate(psi0, centre[key])
    around = np.arctan2(*np.moveaxis(tail - true_c, -1, 0)[::-1])  # (FIT, R, C) on the circle
    steady = float(np.mean((np.diff(around, axis=0) + np.pi) % (2 * np.pi) - np.pi))
    moves = move + _rotate(turn, centre[recent(np.arange(9)[:, None], np.arange(3))])
    c_move = moves - moves[:, 2:3]  # each action's backup centre against the loiter's
    offsets = move - moves  # the offsets after each action, in the frame before it
    u_move = offsets - offsets[:, 2:3]
    delta = np.maximum(np.hypot(*c_move.T).T, np.hypot(*u_move.T).T).max(axis=0)
    # off the circle while it settles: each position after the action against the one
    # its backup would give it, the offset after the action turned at the steady rate
    flown = air_p[after:] - true_c  # (T', R, C, 2) from the true centre
    turns = steady * np.arange(len(flown))
    ideal = _rotate(np.broadcast_to(turns[:, None, None], flown.shape[:-1]), flown[0])
    transient = float(np.hypot(*(flown - ideal).T).max())
    return Response(
        move=move,
        turn=turn,
        centre=centre,
        radius=float(radius.mean()),
        step_turn=steady,
        wind=w,
        centre_error=float(np.hypot(*(true_c - c_hat).T).max()),
        position_error=float(np.hypot(*(p1 - p_hat).T).max()),
        now_error=float(np.hypot(*(true_c - c_now)[loitered].T).max()),
        delta=delta,
        transient_error=transient,
    )
