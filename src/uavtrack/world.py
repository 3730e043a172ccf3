"""Truth: UAV kinematics (eq. 1), target motion (eq. 13-15), and each trial's draws.

UAV state ``(..., 5)`` = x, y, h, V, heading; target state ``(..., 4)`` = x, y, vx, vy.
Nothing here is visible to the UAVs' estimation or decisions except through sensing.

Randomness: each trial has its own `numpy.random.SeedSequence`, split into a truth
stream (initial layout, target accelerations), a sensor stream (measurement noise) and
a fault stream (`faults`). The methods therefore see the same targets, the same noise
and the same faults in a trial (common random numbers), and a trial gives the same
result alone, in a batch, or in another process.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

import math

import numpy as np

from .config import G, ManoeuvreModel, Scenario

X, Y, H, V, HEADING = range(5)


def fly(uavs: np.ndarray, bank: np.ndarray, dt: float, g: float = G) -> np.ndarray:
    """One step of the unicycle model at constant speed and altitude, eq. (1).

    x(k+1) = x(k) + V dT cos(psi(k)),   y(k+1) = y(k) + V dT sin(psi(k)),
    psi(k+1) = psi(k) + g dT tan(phi(k)) / V.

    The position moves along the current heading; the bank angle phi(k) turns the
    heading for the next step, so it first shows in the position at k+2.

    uavs: (..., 5); bank: (...,) bank angles [rad]. Returns (..., 5).
    """
    step = uavs[..., V] * dt
    heading = uavs[..., HEADING]
    out = uavs.copy()
    out[..., X] += step * np.cos(heading)
    out[..., Y] += step * np.sin(heading)
    out[..., HEADING] = wrap_angle(heading + (g * dt) * np.tan(bank) / uavs[..., V])
    return out


def believed(uavs: np.ndarray, error: np.ndarray | None) -> np.ndarray:
    """The UAV states as the UAVs believe them: the true ground position plus their own
    position error (..., 2) [m] (GPS), altitude, speed and heading exact. None: no error."""
    if error is None:
        return uavs
    out = uavs.copy()
    out[..., :2] += error
    return out


def turn_radius(speed: float, bank: float, g: float = G) -> float:
    """Radius V^2 / (g tan phi) [m] of the continuous coordinated turn at bank phi [rad]."""
    return speed**2 / (g * np.tan(bank))


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (angle + np.pi) % (2 * np.pi) - np.pi


def move_targets(
    targets: np.ndarray, accel: np.ndarray, dt: float, field_size: float
) -> np.ndarray:
    """One step of the nearly-constant-velocity model (eq. 13), reflected at the walls.

    s(k+1) = A s(k) + w(k) with w = Gamma a, Gamma = [dT^2/2, dT]^T per axis and
    a ~ N(0, diag(sigma_1^2, sigma_2^2)) (eq. 15). A target that leaves [0, L] is
    mirrored back and its velocity component reversed (targets stay in the field).

    targets: (..., 4); accel: (..., 2) accelerations [m/s^2]. Returns (..., 4).
    """
    raw = targets[..., :2] + targets[..., 2:] * dt + 0.5 * accel * dt**2
    vel = targets[..., 2:] + accel * dt
    # the walls are mirrors: fold the position back into [0, L]; an odd number of
    # crossings reverses that velocity component
    folded = np.mod(raw, 2.0 * field_size)
    pos = np.where(folded > field_size, 2.0 * field_size - folded, folded)
    vel = np.where(np.mod(np.floor_divide(raw, field_size), 2) == 1, -vel, vel)
    return np.concatenate([pos, vel], axis=-1)


def target_trajectories(
    initial: np.ndarray, accel: np.ndarray, dt: float, field_size: float
) -> np.ndarray:
    """All target states over a run, the walls acting as mirrors.

    The free nearly-constant-velocity path driven by `accel` (eq. 13, Gamma as in
    `move_targets`) is computed in closed form with cumulative sums and folded into the
    field: the position is its mirror image in [0, L], and each velocity component is
    reversed while the free path is in an odd mirror cell. Between reflections this is
    the NCV model; after one, the drawn accelerations act mirrored, which leaves the
    process's distribution unchanged (the noise is symmetric).

    initial: (..., Nt, 4) states at step 0 inside the field; accel: (..., T-1, Nt, 2).
    Returns (..., T, Nt, 4), element k the targets at step k.
    """
    p0, v0 = initial[..., None, :, :2], initial[..., None, :, 2:]
    later, _ = free_path(p0, v0, accel, dt, field_size)
    return np.concatenate([fold(p0, v0, field_size), later], axis=-3)


Sums = tuple[np.ndarray, np.ndarray, np.ndarray]
"""What the closed form carries from one block of steps to the next (`free_path`): the
accelerations summed, the free moves summed, the free velocity at the block's start."""


def free_path(
    p0: np.ndarray,
    v0: np.ndarray,
    accel: np.ndarray,
    dt: float,
    field_size: float,
    sums: Sums | None = None,
) -> tuple[np.ndarray, Sums]:
    """The states after the accelerations accel (..., n, Nt, 2) of the path that starts
    at p0, v0 (..., 1, Nt, 2), folded into the field (`fold`), and the sums to continue
    it: given `sums` of the steps before, the cumulative sums go on from them, so that
    blocks of steps give the states of the whole run bit for bit (an accumulation adds
    in order)."""
    if sums is None:
        speed, velocity = np.cumsum(accel, axis=-3), v0
    else:
        speed, velocity = _continued(sums[0], accel), sums[2]
    vel = v0 + dt * speed  # the velocity after each acceleration
    before = np.concatenate([velocity, vel[..., :-1, :, :]], axis=-3)
    moves = before * dt + 0.5 * dt**2 * accel
    moved = np.cumsum(moves, axis=-3) if sums is None else _continued(sums[1], moves)
    carried = (speed[..., -1:, :, :], moved[..., -1:, :, :], vel[..., -1:, :, :])
    return fold(p0 + moved, vel, field_size), carried


def fold(free: np.ndarray, vel: np.ndarray, field_size: float) -> np.ndarray:
    """Free positions and velocities (..., 2) folded into [0, L]: the walls are mirrors."""
    L = field_size
    folded = np.mod(free, 2.0 * L)
    pos = np.where(folded > L, 2.0 * L - folded, folded)
    mirrored = np.mod(np.floor_divide(free, L), 2) == 1
    return np.concatenate([pos, np.where(mirrored, -vel, vel)], axis=-1)


def _continued(carried: np.ndarray, values: np.ndarray) -> np.ndarray:
    """np.cumsum(values, axis=-3) continued from `carried` (..., 1, Nt, 2)."""
    return np.cumsum(np.concatenate([carried, values], axis=-3), axis=-3)[..., 1:, :, :]


# ---------------------------------------------------------------- each trial's draws


def children(seed: int | np.random.SeedSequence) -> tuple[np.random.SeedSequence, ...]:
    """The (truth, sensor, faults) streams of one trial, independent children of its seed.

    The children are derived from the seed's spawn key, not with `SeedSequence.spawn`,
    whose counter would give a reused seed object different streams.
    """
    return tuple(_child(seed, k) for k in range(3))


def _child(seed: int | np.random.SeedSequence, index: int) -> np.random.SeedSequence:
    """Child `index` of a trial's seed, derived from its spawn key (see `children`)."""
    seq = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    return np.random.SeedSequence(
        seq.entropy, spawn_key=(*seq.spawn_key, index), pool_size=seq.pool_size
    )


def flight_stream(seed: int | np.random.SeedSequence) -> np.random.SeedSequence:
    """The flight stream of one trial (turbulence, `flight.jsbsim`): a fourth child of its
    seed, so the three of `children` are the same with or without it."""
    return _child(seed, 3)


def detection_stream(seed: int | np.random.SeedSequence) -> np.random.SeedSequence:
    """The detection stream of one trial (missed detections, clutter and the order of an
    unlabelled scan, `tracks.scan`): a fifth child of its seed, so the others are the
    same whatever the sensor's detection probability and clutter rate."""
    return _child(seed, 4)


def presence_stream(seed: int | np.random.SeedSequence) -> np.random.SeedSequence:
    """The presence stream of one trial (targets leaving and entering, ``target.stay``):
    a sixth child of its seed, so the others are the same with or without it."""
    return _child(seed, 5)


def presence(here: np.ndarray, draws: np.ndarray, stay: float, away: float) -> np.ndarray:
    """Which targets are in the field over the next steps, (B, n, Nt) bool.

    Each target alternates between present and away: a present one leaves at a step
    with probability 1/stay (a death), an away one's place is taken by a new target with
    probability 1/away (a birth), so stays and absences are geometric with means `stay`
    and `away` steps. here (B, Nt): who is present at the step before; draws (B, n, Nt)
    uniforms on [0, 1), one per target and step whatever its state."""
    out = np.empty(draws.shape, dtype=bool)
    for k in range(draws.shape[1]):
        u = draws[:, k]
        here = np.where(here, u >= 1.0 / stay, u < 1.0 / away)
        out[:, k] = here
    return out


def present(targets: np.ndarray) -> np.ndarray:
    """Which targets are in the field, (...,) bool, from their states (..., 4): a target
    away (``target.stay``) has the state NaN."""
    return ~np.isnan(targets[..., 0])


def stays(targets: np.ndarray) -> np.ndarray:
    """Which stay of its place each target is on at each step, (T, Nt) from the states
    of a run (T, Nt, 4): 0 for the target present from step 0, n for the n-th to enter
    the place after it (``target.stay``)."""
    here = present(targets)
    entered = np.zeros(here.shape, dtype=np.int64)
    entered[1:] = here[1:] & ~here[:-1]
    return np.cumsum(entered, axis=0)


def streams(seed: int | np.random.SeedSequence) -> tuple[np.random.Generator, np.random.Generator]:
    """(truth, sensor) generators of one trial (see `children`)."""
    truth, sensor, _ = children(seed)
    return np.random.default_rng(truth), np.random.default_rng(sensor)


def trial_seed(seed: int, trial: int) -> np.random.SeedSequence:
    """The seed of trial `trial` of an experiment seeded with `seed`.

    Equal to ``SeedSequence(seed).spawn(n)[trial]`` for any n > trial.
    """
    return np.random.SeedSequence(seed, spawn_key=(trial,))


def initial_conditions(
    scenario: Scenario, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One trial's start (`draw_start`) and its whole target trajectories: uavs (Nu, 5),
    trajectories (T, Nt, 4), prior mean (Nt, 4), P0 (4, 4). The paper's fixed set only:
    targets that come and go draw from the trial's seed (`simulation.initial_stream`)."""
    if scenario.target.stay > 0:
        raise ValueError(
            "initial_conditions draws the fixed set of targets; with target.stay > 0 use "
            "simulation.initial_stream(scenario, seeds), which reads each trial's seed"
        )
    targets, uavs, prior, P0 = draw_start(scenario, rng)
    trajectory = Targets(targets[None], [rng], scenario, keep=True).whole()[0]
    return uavs, trajectory, prior, P0


def draw_start(
    scenario: Scenario, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Draw one trial's start and prior (all assumed; see the parameter table).

    Targets start uniformly in the field with N(0, v0^2) velocity components; UAVs
    start in a square of side `uav.start_spread` at the field centre with uniform
    headings (``uav.start = "grid"``: on a grid, heading north, `start_grid`); every
    UAV's prior of target j is N(cue_j, P0) with cue_j the true position plus
    N(0, sigma_p0^2) noise and zero velocity, and P0 = diag(sigma_p0^2, sigma_p0^2,
    sigma_v0^2, sigma_v0^2), so the prior is consistent.

    Returns the targets at step 0 (Nt, 4), uavs (Nu, 5), prior mean (Nt, 4), P0 (4, 4);
    the targets' accelerations are the stream's next draws (`Targets`).
    """
    nu, nt, L = scenario.n_uavs, scenario.n_targets, scenario.field_size
    tgt = scenario.target
    targets = np.concatenate(
        [rng.uniform(0.0, L, (nt, 2)), rng.normal(0.0, tgt.initial_velocity_std, (nt, 2))], axis=1
    )
    uavs = np.empty((nu, 5))
    half = scenario.uav.start_spread / 2
    uavs[:, :2] = L / 2 + rng.uniform(-half, half, (nu, 2))
    uavs[:, 2] = scenario.altitudes()
    uavs[:, 3] = scenario.uav.speed
    uavs[:, 4] = rng.uniform(-np.pi, np.pi, nu)
    if scenario.uav.start == "grid":  # drawn above all the same: the later draws stay
        uavs[:, :2], uavs[:, 4] = start_grid(nu, scenario.uav.start_spread, L), np.pi / 2
    est = scenario.estimation
    prior = np.zeros((nt, 4))
    prior[:, :2] = targets[:, :2] + rng.normal(0.0, est.initial_position_std, (nt, 2))
    P0 = np.diag([est.initial_position_std**2] * 2 + [est.initial_velocity_std**2] * 2)
    return targets, uavs, prior, P0


def prior_of(scenario: Scenario, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The prior every UAV of trial `seed` starts from (`draw_start`, on its truth
    stream): the targets' means (Nt, 4) and covariances (Nt, 4, 4)."""
    _, _, mean, P0 = draw_start(scenario, streams(np.random.SeedSequence(seed))[0])
    return mean, np.broadcast_to(P0, mean.shape + (4,)).copy()


class Targets:
    """The targets of a batch of trials over a run, (B, T, Nt, 4), drawn and moved a
    block of `BLOCK` steps at a time as the run reaches them, so that a run without a
    trace holds one block, whatever its length.

    Each trial's accelerations (eq. 15) are the last draws of its truth stream, in step
    order: drawn a block at a time they are the numbers drawn at once, and the closed
    form of `target_trajectories`, continued from the sums it carries, gives the same
    states bit for bit. Manoeuvring targets draw their manoeuvres after every
    acceleration, so their run is drawn whole at the first step.

    initial (B, Nt, 4) the states at step 0; rngs each trial's truth stream, after the
    draws of its start; keep: whether the steps passed stay (for `whole`).

    With ``target.stay`` > 0 targets come and go (`presence`, drawn from each trial's
    `presence_stream` of `seeds`): every target is present at step 0, and a target away
    at a step has the state NaN there. Its motion goes on unseen, so a new target enters
    wherever that motion has taken it, and the present steps are those of the fixed set.
    """

    BLOCK = 1024
    """Steps drawn at once [steps]."""

    def __init__(
        self,
        initial: np.ndarray,
        rngs: list[np.random.Generator],
        scenario: Scenario,
        keep: bool = False,
        seeds: list[np.random.SeedSequence] | None = None,
    ) -> None:
        self.scenario, self.rngs, self.keep = scenario, rngs, keep
        self.steps = scenario.steps
        self.std = np.asarray(scenario.acceleration_std())
        self.p0, self.v0 = initial[..., :2], initial[..., 2:]
        self.sums: Sums | None = None  # what the closed form carries (`free_path`)
        self.blocks = [fold(self.p0[:, None], self.v0[:, None], scenario.field_size)]
        self.present: list[np.random.Generator] | None = None  # presence streams
        if scenario.target.stay > 0:
            if seeds is None or len(seeds) != len(rngs):
                raise ValueError("target.stay > 0 needs each trial's seed (seeds=)")
            self.present = [np.random.default_rng(presence_stream(s)) for s in seeds]
            self.here = np.ones(self.p0.shape[:-1], dtype=bool)  # (B, Nt) at the last step
        self.made = 1  # steps drawn
        self.start = 0  # the step of blocks[-1][:, 0]

    def at(self, k: int) -> np.ndarray:
        """The targets at step k (B, Nt, 4). Without `keep`, only steps of the current
        block or later can be asked for."""
        if not 0 <= k < self.steps:
            raise IndexError(f"step {k} of a run of {self.steps} steps")
        while k >= self.made:
            self._next()
        if k >= self.start:
            return self.blocks[-1][:, k - self.start]
        return self.whole(k + 1)[:, k]

    def whole(self, steps: int | None = None) -> np.ndarray:
        """The first `steps` steps (default: all the run's) of every trial,
        (B, steps, Nt, 4); only with `keep`."""
        steps = self.steps if steps is None else steps
        if not self.keep:
            raise IndexError("these targets keep no steps passed (keep=False)")
        while steps > self.made:
            self._next()
        if len(self.blocks) > 1:
            self.blocks, self.start = [np.concatenate(self.blocks, axis=1)], 0
        return self.blocks[0][:, :steps]

    def _next(self) -> None:
        """Draw and move the next block of steps."""
        if self.scenario.target.motion == "manoeuvring":
            block = self._manoeuvring()
        else:
            n, nt = min(self.BLOCK, self.steps - self.made), self.p0.shape[-2]
            accel = np.stack([rng.standard_normal((n, nt, 2)) for rng in self.rngs]) * self.std
            block = self._free(accel)
        if self.present is not None:
            draws = np.stack([rng.random(block.shape[1:3]) for rng in self.present])
            here = presence(self.here, draws, self.scenario.target.stay, self.scenario.target.away)
            self.here = here[:, -1]
            block = np.where(here[..., None], block, np.nan)
        if self.keep:
            self.blocks.append(block)
        else:
            self.blocks = [block]
        self.start, self.made = self.made, self.made + block.shape[1]

    def _free(self, accel: np.ndarray) -> np.ndarray:
        """The states after the accelerations (B, n, Nt, 2), continuing the run."""
        s = self.scenario
        block, self.sums = free_path(
            self.p0[:, None], self.v0[:, None], accel, s.dt, s.field_size, self.sums
        )
        return block

    def _manoeuvring(self) -> np.ndarray:
        """Steps 1 .. T-1 of every trial's manoeuvring run, drawn whole."""
        s, nt = self.scenario, self.p0.shape[-2]
        initial = np.concatenate([self.p0, self.v0], axis=-1)
        runs = [
            manoeuvring_trajectories(
                initial[b],
                rng.standard_normal((self.steps - 1, nt, 2)) * self.std,
                s.dt,
                s.field_size,
                s.target.manoeuvre,
                rng,
            )  # fmt: skip
            for b, rng in enumerate(self.rngs)
        ]
        return np.stack(runs)[:, 1:]


def start_grid(n: int, spacing: float, field_size: float) -> np.ndarray:
    """Positions (n, 2) of n UAVs on a square grid of `spacing` [m] centred on the
    field, filled row by row from the south-west."""
    columns = math.ceil(math.sqrt(n))
    rows = math.ceil(n / columns)
    k = np.arange(n)
    east = (k % columns - (columns - 1) / 2) * spacing
    north = (k // columns - (rows - 1) / 2) * spacing
    return field_size / 2 + np.stack([east, north], axis=1)


def manoeuvring_trajectories(
    initial: np.ndarray,
    accel: np.ndarray,
    dt: float,
    field_size: float,
    manoeuvre: ManoeuvreModel,
    rng: np.random.Generator,
) -> np.ndarray:
    """Targets that manoeuvre (`config.ManoeuvreModel`), reflected at the walls.

    Each target flies segments of exponential length (mean `interval`): a stop with
    `stop_probability`, else a turn at a rate uniform in +-`turn_rate_max_deg` with
    `turn_probability` or a straight leg, at a speed uniform in [speed_max / 4,
    speed_max]. The speed moves towards the segment's at most `acceleration_max` per
    second; the heading turns at the segment's rate; the white acceleration `accel` of
    eq. (15) acts on top, as in `move_targets`. The first segment goes straight at the
    initial velocity.

    initial (Nt, 4); accel (T-1, Nt, 2). Returns (T, Nt, 4).
    """
    T, nt = accel.shape[0] + 1, initial.shape[0]
    m = manoeuvre
    length = rng.exponential(m.interval, (T, nt))  # the draws of every possible switch
    kind = rng.random((T, nt, 2))
    rate = rng.uniform(-1.0, 1.0, (T, nt)) * np.radians(m.turn_rate_max_deg)
    speed = rng.uniform(m.speed_max / 4, m.speed_max, (T, nt))
    out = np.empty((T, nt, 4))
    out[0] = initial
    state = initial.copy()
    left = length[0].copy()  # time left in the current segment
    omega = np.zeros(nt)
    wanted = np.hypot(initial[:, 2], initial[:, 3])
    for k in range(T - 1):
        switch = left <= 0
        if switch.any():
            stop = kind[k, :, 0] < m.stop_probability
            turn = ~stop & (kind[k, :, 1] < m.turn_probability)
            omega = np.where(switch, np.where(turn, rate[k], 0.0), omega)
            wanted = np.where(switch, np.where(stop, 0.0, speed[k]), wanted)
            left = np.where(switch, length[k], left)
        v = state[:, 2:]
        now = np.hypot(v[:, 0], v[:, 1])
        heading = np.arctan2(v[:, 1], v[:, 0]) + omega * dt
        now = now + np.clip(wanted - now, -m.acceleration_max * dt, m.acceleration_max * dt)
        steered = now[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
        state = move_targets(
            np.concatenate([state[:, :2], steered], axis=-1), accel[k], dt, field_size
        )
        out[k + 1] = state
        left = left - dt
    return out
