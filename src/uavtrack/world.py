"""Truth: UAV kinematics (eq. 1) and target motion (eq. 13-15) in a square field.

UAV state ``(..., 5)`` = x, y, h, V, heading; target state ``(..., 4)`` = x, y, vx, vy.
Nothing here is visible to the UAVs' estimation or decisions except through sensing.
"""

from __future__ import annotations

import numpy as np

from .config import G

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
    vel = np.concatenate([v0, v0 + dt * np.cumsum(accel, axis=-3)], axis=-3)
    moves = vel[..., :-1, :, :] * dt + 0.5 * dt**2 * accel
    free = np.concatenate([p0, p0 + np.cumsum(moves, axis=-3)], axis=-3)
    folded = np.mod(free, 2.0 * field_size)
    pos = np.where(folded > field_size, 2.0 * field_size - folded, folded)
    mirrored = np.mod(np.floor_divide(free, field_size), 2) == 1
    return np.concatenate([pos, np.where(mirrored, -vel, vel)], axis=-1)
