"""Collision avoidance at one altitude: a decentralized filter on each UAV's action that
keeps ``uav.separation`` from the neighbours it has heard (``planner.avoidance = "loiter"``).

The idea is a backup manoeuvre every UAV can always fall back on: the *loiter*, the
action +phi held for ever. Under eq. (1) it flies a regular polygon: the position moves
L = V dT along the heading, then the heading turns by Delta = g dT tan(phi) / V, so the
positions are vertices of a polygon of circumradius R = L / (2 sin(Delta/2)) around a
fixed centre c (`loiter`). Write u = p - c (|u| = R; it turns with the heading).

Two UAVs i and q that both loiter from now on keep the same centres while their u turn
at the same rate (equal speeds), so their distance |(c_i - c_q) + (u_i - u_q)| never
falls below

    Lambda(i, q) = | |c_i - c_q| - |u_i - u_q| |                          (`clearance`)

at any step. **Invariant**: Lambda >= s for every pair of one altitude band (s the
separation). It bounds the distance: |p_i - p_q| >= Lambda >= s.

**Rule** (each UAV, every cycle, from the states its neighbours broadcast): the loiter
is always allowed. Another action a is allowed if, for every neighbour q heard,

* q of higher priority (a lower index): Lambda(i after a, q after b) >= s + A for
  every action b q might take;
* q of lower priority: Lambda(i after a, q after the loiter) >= s + A;

where q's state is its last broadcast, flown forward on the loiter for its age
(`predicted`), and A = `allowance(age)` bounds how far q can be from that prediction
after age unknown steps (`deviation`: an action other than the loiter moves the centre
and turns u by at most delta = 2 R sin(|Delta_b - Delta| / 2) each; Lambda is
1-Lipschitz in the centres and offsets). The planned action flies if allowed; if not,
the UAV flies the allowed action the planner scores best for its target
(`planning.first_values`); where no such scores are at hand (tracks of unknown
association), -phi falls back to straight when that is allowed, otherwise the loiter.

**Why the invariant holds** (by induction over steps, pair by pair, i of lower priority
than q): both loiter: Lambda is unchanged. i loiters, q moves: q checked its move
against i's loiter. i moves, q loiters or moves: i checked every action of q. The
allowance covers what a stale broadcast does not say.

**Assumptions** (what the guarantee needs): the invariant holds at step 0 (a start such
as ``uav.start = "grid"``: one heading, neighbours at least s apart); equal speeds
(unequal speeds make the relative phase drift: Lambda is then not kept by two loiters);
the unicycle of eq. (1) (JSBSim's aircraft bank over time: the margin it needs is
measured, not proven); the states as each UAV believes them (a position error moves
the true distance by up to the two errors); every UAV within reach is heard, with a
known age: a beacon lost while a pair is close voids the guarantee for that pair, and
a UAV never heard is taken to be far. The radio range bounds this: a UAV out of range
has Lambda > r_C - 4R, so the rule is sound whenever r_C >= 4R + s + 2 A(d + 1)
(`sound_range`, d the delay). The paper's r_C = 50 m is below it (161 m at
V = 15 m/s, phi = 45 deg, s = 10 m): a pair can enter radio range already in
conflict. Such a pair is left out of the rule: each of the two keeps the rule with
everyone else and, among what that allows, takes the action that most increases its
clearance to the other (*recovery*, best effort); every other pair keeps its
guarantee, also beside a member whose beacons lie.

Between steps the aircraft fly the chords of the polygon; the separation is measured
at the steps, as every metric of a run is.

**Airspeed as a second control** (``uav.min_speed`` = v): every UAV's backup is the loiter
at v, the same speed for all, so two backups keep their clearance as above; its radius
shrinks with v^2 (10.3 m at 10 m/s against 23.0 m at 15 m/s), and so does the room a
pair needs. The actions are the three banks at the cruise speed and at v (`speeds`);
the rule is the same over six, each action of a neighbour bounded by its move of the
backup's centre and offset (`Turn.slowed`), and the proof is unchanged: it needs equal
speeds only of the backups. A desired action that is not allowed is first flown at v,
at the same bank, if that is allowed: the filter slows a UAV before it bends its path.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import G, Scenario
from ..world import HEADING, H, V, X, Y
from .response import START, STEADY, Response, measure

MODES = ("none", "loiter")
"""The values of ``planner.avoidance``."""

LOITER = 2
"""The index of +phi in the action set (-phi, 0, +phi): the backup manoeuvre."""

STRAIGHT = 1
"""The index of the zero bank angle."""

ROUND_OFF = 1e-9
"""Relative slack of the recovery's test: a clearance kept at exactly s reads a few
ulps below it after the loiter's rotations, which is no conflict."""

MEMORY = 20
"""Steps a neighbour's broadcast is kept without a newer one when beacons can be lost
[steps]; assumed: 10 s at dT = 0.5 s, longer than the loss bursts of the
Gilbert-Elliott channel at the defaults of ``faults``."""


def minimum(scenario: Scenario) -> float:
    """The separation the filter keeps [m]: ``uav.separation`` plus
    ``planner.avoidance_margin`` (for flight that differs from eq. (1))."""
    return scenario.uav.separation + scenario.planner.avoidance_margin


def choose_in(
    scenario: Scenario,
    desired: np.ndarray,
    believed: np.ndarray,
    alive: np.ndarray,
    heard: Heard,
    k: int,
    values: np.ndarray | None = None,
    recent: np.ndarray | None = None,
) -> np.ndarray:
    """`choose` with the scenario's settings (the separation kept, `minimum`; the vertical
    separation; the bank angle; the step; the model of flight and, with the measured
    one, each UAV's `recent` commands (B, N)): the actions (B, N) the batch and each
    agent fly, one place that reads them from the scenario."""
    uav = scenario.uav
    model = measure(scenario) if scenario.planner.avoidance_model == "measured" else None
    chosen, _ = choose(
        desired, believed, alive, heard, k, minimum(scenario), uav.vertical_separation,
        np.radians(uav.bank_angle_deg), scenario.dt, values=values, slow=uav.min_speed,
        cruise=uav.speed, response=model, recent=recent,
    )  # fmt: skip
    return chosen


def memory_of(delay: int, loss: float) -> int:
    """Steps a broadcast is kept: with no loss a UAV whose beacon of d steps ago did not
    arrive was out of radio range (or down) then, which the range assumption covers, so
    a record older than the delay d says nothing more; with loss, `MEMORY` (at least d)."""
    return max(delay, MEMORY) if loss > 0 else delay


@dataclass(frozen=True)
class Heard:
    """The last broadcast state each UAV heard of each other: state (B, N, N, 5)
    [trial, receiver, sender] as the sender believed it, and the step it was sent,
    stamp (B, N, N) (-1: never heard, or forgotten after `MEMORY` steps); with the
    measured model, the sender's recent commands then, recent (B, N, N)
    (`response.recent`)."""

    state: np.ndarray
    stamp: np.ndarray
    recent: np.ndarray | None = None

    @classmethod
    def nothing(cls, batch: int, n: int) -> Heard:
        return cls(np.zeros((batch, n, n, 5)), np.full((batch, n, n), -1, dtype=np.int64))

    def update(
        self,
        got: np.ndarray,
        state: np.ndarray,
        stamp: np.ndarray,
        k: int,
        memory: int,
        recent: np.ndarray | None = None,
    ) -> Heard:
        """After this cycle's beacons: got (B, N, N) [receiver, sender] those that
        arrived, carrying the senders' states (B, N, 5) sent at stamp (B, N), and their
        recent commands (B, N) if the beacons carry them. Records older than `memory`
        steps at k are forgotten (`memory_of`)."""
        newer = got & (stamp[:, None, :] > self.stamp)
        held = np.where(newer[..., None], state[:, None], self.state)
        stamps = np.where(newer, stamp[:, None, :], self.stamp)
        stamps = np.where(k - stamps > memory, -1, stamps)
        kept = None
        if recent is not None:
            before = self.recent if self.recent is not None else np.full(stamps.shape, START)
            kept = np.where(newer, np.asarray(recent, dtype=np.int64)[:, None, :], before)
        return Heard(held, stamps, kept)


@dataclass(frozen=True)
class Turn:
    """The loiter's geometry for UAVs of speed V (any shape): step L = V dT [m], turn
    per step Delta [rad], circumradius R [m], and delta (3,) [m] how far each action
    moves the centre (and turns u) against the loiter's next state."""

    step: np.ndarray
    turn: np.ndarray
    radius: np.ndarray
    delta: np.ndarray

    @classmethod
    def of(cls, speed: np.ndarray, bank: float, dt: float, g: float = G) -> Turn:
        speed = np.asarray(speed, dtype=float)
        turn = g * dt * np.tan(bank) / speed
        radius = speed * dt / (2.0 * np.sin(turn / 2.0))
        banks = np.tan(np.array([-bank, 0.0, bank]))
        turns = g * dt * banks / speed[..., None]  # (..., 3)
        delta = 2.0 * radius[..., None] * np.abs(np.sin((turns - turn[..., None]) / 2.0))
        return cls(speed * dt, turn, radius, delta)

    @classmethod
    def slowed(cls, slow: float, cruise: float, bank: float, dt: float, g: float = G) -> Turn:
        """The loiter at the backup speed `slow` of UAVs that may fly each bank at
        `cruise` or `slow` (``uav.min_speed``): delta (6,) bounds how far each action
        (`speeds`) moves the backup loiter's centre, and turns its offset, against the
        loiter's next state. A state's centre after action a is its centre plus a fixed
        vector D_a turned by its heading, and its offset turns by the action's turn, so
        both bounds hold at every state; they are measured at heading 0."""
        loitering = cls.of(np.asarray(slow), bank, dt, g)
        start = np.array([0.0, 0.0, 1.0, slow, 0.0])
        moves = successors(start, bank, dt, g, speeds(slow, cruise))  # (6, 5)
        c, u = loiter(moves, bank, dt, g, slow)
        backup = LOITER + 3
        delta = np.maximum(
            np.hypot(*(c - c[backup]).T), np.hypot(*(u - u[backup]).T)
        )  # the loiter's own is 0
        return cls(loitering.step, loitering.turn, loitering.radius, delta)


def loiter(
    uavs: np.ndarray, bank: float, dt: float, g: float = G, speed: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The centre c and offset u = p - c (each (..., 2)) of the polygon that UAVs
    (..., 5) fly when they hold +phi from now on (eq. 1), at their own speed or at
    `speed` (the backup loiter of ``uav.min_speed``)."""
    t = Turn.of(uavs[..., V] if speed is None else np.full(uavs.shape[:-1], speed), bank, dt, g)
    psi = uavs[..., HEADING]
    along, across = t.step / 2.0, t.step / (2.0 * np.tan(t.turn / 2.0))
    u = np.empty(uavs.shape[:-1] + (2,))
    u[..., 0] = -(along * np.cos(psi) - across * np.sin(psi))
    u[..., 1] = -(along * np.sin(psi) + across * np.cos(psi))
    c = uavs[..., [X, Y]] - u
    return c, u


def clearance(ci: np.ndarray, ui: np.ndarray, cq: np.ndarray, uq: np.ndarray) -> np.ndarray:
    """Lambda = | |c_i - c_q| - |u_i - u_q| |: the closest two UAVs of equal speed come
    when both loiter from now on (centres c, offsets u, each (..., 2))."""
    centres = np.hypot(*np.moveaxis(ci - cq, -1, 0))
    offsets = np.hypot(*np.moveaxis(ui - uq, -1, 0))
    return np.abs(centres - offsets)


def allowance(age: np.ndarray, turn: Turn) -> tuple[np.ndarray, np.ndarray]:
    """How far a neighbour last heard `age` steps ago can be from its state flown on the
    loiter (`predicted`), in clearance: A_move after its next action, whichever it is
    (for the checks against every action), and A_now at this step. Each unknown step
    adds delta to the centre's and the offset's error and turns the offset's error into
    the centre's by at most m = max delta / R (c' - c = (Rot(Delta) - Rot(Delta_b)) u).
    age (...,) and turn of the neighbours' speeds, broadcast together."""
    delta = turn.delta.max(axis=-1)
    m = delta / turn.radius
    centre = np.zeros(np.broadcast(age, delta).shape)
    offset = np.zeros_like(centre)
    age = np.broadcast_to(age, centre.shape)
    for _ in range(int(age.max(initial=0))):
        more = age > 0
        centre = np.where(more, centre + m * offset + delta, centre)
        offset = np.where(more, offset + delta, offset)
        age = age - 1
    return centre + m * offset + offset, centre + offset


def sound_range(
    separation: float,
    speed: float,
    bank: float,
    dt: float,
    delay: int = 0,
    slow: float | None = None,
) -> float:
    """The radio range [m] above which a UAV never heard cannot break the invariant, for
    a separation [m], a speed [m/s], a bank angle [rad], a step dT [s] and a delay
    [steps]
    within the next step: out of range at the step its beacon would have been sent, it
    has Lambda > r_C - 4R, and each side may take d + 1 steps unknown to the other
    (`allowance`). With `slow` (``uav.min_speed``), R is the backup loiter's at it."""
    if slow is None:
        turn = Turn.of(np.asarray(speed), bank, dt)
    else:
        turn = Turn.slowed(slow, speed, bank, dt)
    unknown = allowance(np.asarray(delay + 1), turn)[1]
    return float(4.0 * turn.radius + separation + 2.0 * unknown)


def sound_range_in(scenario: Scenario) -> float:
    """`sound_range` of the scenario's filter [m]: its separation kept (`minimum`), speed,
    bank angle, step, delay and slowest speed; with the measured model of flight, the
    backup's radius and moves and the margin of its tables (`response.Response`)."""
    uav = scenario.uav
    bank = np.radians(uav.bank_angle_deg)
    if scenario.planner.avoidance_model != "measured":
        return sound_range(
            minimum(scenario), uav.speed, bank, scenario.dt, scenario.faults.delay, uav.min_speed
        )
    model = measure(scenario)
    steady = model.move[STEADY, LOITER]
    turn = Turn(
        np.asarray(float(np.hypot(*steady))), np.asarray(model.step_turn),
        np.asarray(model.radius), model.delta,
    )  # fmt: skip
    unknown = allowance(np.asarray(scenario.faults.delay + 1), turn)[1]
    return float(4.0 * model.reach + minimum(scenario) + model.margin + 2.0 * unknown)


def predicted(
    state: np.ndarray,
    age: np.ndarray,
    bank: float,
    dt: float,
    g: float = G,
    speed: float | None = None,
) -> np.ndarray:
    """States (..., 5) flown on the loiter (at their own speed, or `speed`) for age
    (...,) steps, in closed form: the centre stays, u and the heading turn by age
    Delta."""
    c, u = loiter(state, bank, dt, g, speed)
    own = state[..., V] if speed is None else np.full(state.shape[:-1], speed)
    turn = Turn.of(own, bank, dt, g).turn * age
    cos, sin = np.cos(turn), np.sin(turn)
    out = state.copy()
    out[..., X] = c[..., 0] + cos * u[..., 0] - sin * u[..., 1]
    out[..., Y] = c[..., 1] + sin * u[..., 0] + cos * u[..., 1]
    out[..., HEADING] = state[..., HEADING] + turn
    if speed is not None:
        out[..., V] = speed
    return out


def speeds(slow: float, cruise: float) -> np.ndarray:
    """The speed of each action (6,) with ``uav.min_speed``: the three banks at the
    cruise speed, then at the slowest; the last, +phi at the slowest, is the backup."""
    return np.repeat([cruise, slow], 3)


def successors(
    uavs: np.ndarray, bank: float, dt: float, g: float = G, speed: np.ndarray | None = None
) -> np.ndarray:
    """The states (..., 3, 5) after each action (-phi, 0, +phi) of eq. (1); with
    `speed` (A,) (`speeds`), (..., A, 5) after each bank of the action set at its
    speed, which the state then holds."""
    if speed is None:
        step = uavs[..., V] * dt
        out = np.repeat(uavs[..., None, :], 3, axis=-2)
        out[..., X] += (step * np.cos(uavs[..., HEADING]))[..., None]
        out[..., Y] += (step * np.sin(uavs[..., HEADING]))[..., None]
        banks = np.tan(np.array([-bank, 0.0, bank]))
        out[..., HEADING] += g * dt * banks / uavs[..., V, None]
        return out
    count = speed.shape[0]
    out = np.repeat(uavs[..., None, :], count, axis=-2)
    step = speed * dt  # (A,)
    out[..., X] += np.cos(uavs[..., HEADING])[..., None] * step
    out[..., Y] += np.sin(uavs[..., HEADING])[..., None] * step
    banks = np.tile(np.tan(np.array([-bank, 0.0, bank])), count // 3)
    out[..., HEADING] += g * dt * banks / speed
    out[..., V] = speed
    return out


def choose(
    desired: np.ndarray,
    believed: np.ndarray,
    alive: np.ndarray,
    heard: Heard,
    k: int,
    separation: float,
    vertical: float,
    bank: float,
    dt: float,
    g: float = G,
    values: np.ndarray | None = None,
    slow: float | None = None,
    cruise: float | None = None,
    response: Response | None = None,
    recent: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The actions (B, N) each living UAV flies under the rule of this module, from the
    actions it would fly (desired, indices into (-phi, 0, +phi)), its own believed state
    (B, N, 5) and the broadcasts it heard (`Heard`) at step k. Returns (actions,
    overridden (B, N) bool: where the action differs from the desired one).

    A desired action that is not allowed is replaced by the allowed one of the highest
    value (B, N, 3) when given (the planner's best score of the sequences that start
    with each action, `planning.first_values`; the lowest index on ties), otherwise by
    straight after -phi and by the loiter after straight.

    Only neighbours heard within `memory_of` steps and within ``vertical`` in altitude
    count. A pair that certainly breaks the invariant already (its clearance plus the
    allowance of the record's age below s: met in conflict beyond the sound range, or
    a neighbour that lies) is out of the rule's reach: the UAV keeps the rule with
    every other neighbour, and among the actions that allows takes the one of the
    largest worst clearance to those in conflict (recovery; ties: the desired action,
    then the loiter). So the invariant of every other pair holds whatever the pairs in
    conflict do.

    slow, cruise: with ``uav.min_speed`` (`slow`) the actions are the three banks at
    `cruise`, then at `slow` (indices 3 to 5, `speeds`), and the backup is the loiter at
    `slow`, every UAV's the same (`Turn.slowed`): the rule is the same, over six
    actions. A desired action that is not allowed is first flown slowly, at the same
    bank, if that is allowed; the values, if given, rank the slow actions as their bank.

    response: the measured model of flight (`response.Response`) in place of eq. (1):
    the backups and their moves are its tables', keyed on each UAV's recent commands
    (recent (B, N) its own, ``heard.recent`` its neighbours'; straight flight when not
    given); an action is allowed `Response.margin` above `separation`, and a pair is in
    conflict `Response.slack` below that distance: a pair inside the margin (a start
    closer than it, or flight the tables did not foresee) is moved apart by the recovery,
    not held on its backup, which keeps its clearance. Every beacon must be of this step
    (age 0)."""
    B, n = alive.shape
    out = np.array(desired, dtype=np.int64, copy=True)
    moves = None if slow is None else speeds(slow, cruise if cruise is not None else slow)
    count = 3 if moves is None else 6
    backup = LOITER if moves is None else LOITER + 3
    trial, me, other = np.nonzero(heard.stamp >= 0)
    mine = believed[trial, me]
    theirs = heard.state[trial, me, other]
    keep = alive[trial, me] & (me != other) & (np.abs(mine[:, H] - theirs[:, H]) < vertical)
    trial, me, other, mine, theirs = trial[keep], me[keep], other[keep], mine[keep], theirs[keep]
    if not trial.size:
        return out, np.zeros((B, n), dtype=bool)
    age = k - heard.stamp[trial, me, other]
    floor = separation
    if response is not None:  # the measured model: fresh beacons only
        if age.max() > 0:
            raise ValueError("the measured model of flight needs every beacon of this step")
        own = np.full((B, n), START) if recent is None else recent
        kq = np.full(age.shape, START) if heard.recent is None else heard.recent[trial, me, other]
        ki = own[trial, me]
        move = held = np.zeros(age.shape)
        ci, ui = response.after(mine, ki)  # (P, 3, 2)
        cq, uq = response.after(theirs, kq)
        c_now, u_now = response.backup(mine, ki)
        cq_now, uq_now = response.backup(theirs, kq)
        separation = separation + response.margin
        floor = separation - response.slack  # below it, recovery: no lock inside the margin
    else:
        now = predicted(theirs, age, bank, dt, g, slow)  # (P, 5) the neighbour if it loitered
        if moves is None:
            turn = Turn.of(theirs[:, V], bank, dt, g)
        else:
            assert slow is not None
            turn = Turn.slowed(slow, float(moves[0]), bank, dt, g)
        move, held = allowance(age, turn)
        ci, ui = loiter(successors(mine, bank, dt, g, moves), bank, dt, g, slow)  # (P, A, 2)
        cq, uq = loiter(successors(now, bank, dt, g, moves), bank, dt, g, slow)  # (P, A, 2)
        c_now, u_now = loiter(mine, bank, dt, g, slow)
        cq_now, uq_now = loiter(now, bank, dt, g, slow)
    lam = clearance(ci[:, :, None], ui[:, :, None], cq[:, None], uq[:, None])  # (P, a, b)
    higher = other < me  # a lower index has priority
    every = lam.min(axis=2) - move[:, None]  # against each action of the neighbour
    loitering = lam[:, :, backup] - held[:, None]  # against its loiter
    worst = np.where(higher[:, None], every, loitering)  # (P, A)
    # a pair certainly in conflict already (its clearance less the record's allowance
    # below s) is out of the rule's reach: the UAV keeps the rule with every other
    # neighbour and, among what that allows, takes the action that most increases its
    # worst clearance to those (recovery)
    now_clear = clearance(c_now, u_now, cq_now, uq_now) + held
    conflict = now_clear < floor - ROUND_OFF * (1.0 + floor)
    flat = trial * n + me
    kept = np.full((B * n, count), np.inf)  # the worst over the pairs the rule holds for
    np.minimum.at(kept, flat[~conflict], worst[~conflict])
    broken = np.full((B * n, count), np.inf)  # and over the pairs in conflict
    np.minimum.at(broken, flat[conflict], worst[conflict])
    kept, broken = kept.reshape(B, n, count), broken.reshape(B, n, count)
    allowed = kept >= separation
    allowed[..., backup] = True
    pick = np.take_along_axis(allowed, out[..., None], axis=-1)[..., 0]
    if values is None:  # -phi falls back to straight, straight to the loiter
        fallback = np.where((out == 0) & allowed[..., STRAIGHT], STRAIGHT, backup)
    else:
        ranked = values if moves is None else np.concatenate([values, values], axis=-1)
        fallback = np.argmax(np.where(allowed, np.nan_to_num(ranked, nan=-np.inf), -np.inf), -1)
    if moves is not None:  # slower at the same bank first
        slower = np.minimum(out + 3, count - 1)
        fine = np.take_along_axis(allowed, slower[..., None], axis=-1)[..., 0] & (out < 3)
        fallback = np.where(fine, slower, fallback)
    out = np.where(pick, out, fallback)
    # recovery: the largest worst clearance; the desired action, then the loiter, on ties
    score = np.where(allowed, broken, -np.inf)
    top = score >= score.max(axis=-1, keepdims=True)
    rescue = np.where(
        np.take_along_axis(top, desired[..., None], axis=-1)[..., 0],
        desired,
        np.where(top[..., backup], backup, np.argmax(top, axis=-1)),
    )
    out = np.where(np.isfinite(broken).any(axis=-1), rescue, out)
    out = np.where(alive, out, desired)
    return out, out != desired
