"""A scan as a real sensor gives it: missed detections, clutter, and no labels.

The world detects each target inside a UAV's observation disk with probability P_D
(``sensor.detection_probability``) and adds a Poisson number of false measurements
(``sensor.clutter_rate`` per scan), uniform over the disk and measured through the same
range-bearing noise (eqs. 2-4) as a target there would be. Every draw comes from the
trial's own detection stream (`world.detection_stream`), not the truth or the sensor
stream, so that the paper's draws are the same whatever P_D and the clutter rate are.

With unknown association (``tracker.association`` gnn or jpda) a UAV receives its scan as
an unlabelled, shuffled set (`Scan`); the true origin of each measurement travels beside
it for evaluation only (traces, metrics, the statistics tests) and nothing a UAV decides
reads it.
"""

# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import sensing
from ..config import SensorModel

CLUTTER = -1
"""`Scan.origin` of a false measurement."""

NONE = -2
"""`Scan.origin` of a padding entry (no measurement)."""


@dataclass(frozen=True)
class Draws:
    """Each trial's generators of the sensor's imperfections, from its detection stream
    (`world.detection_stream`): detect (missed detections), clutter (false
    measurements) and order (the shuffle of an unlabelled scan), three children of it,
    so that a run with known association misses the same detections as one with gnn or
    jpda on the same trial, whatever clutter the other sees."""

    detect: list[np.random.Generator]
    clutter: list[np.random.Generator]
    order: list[np.random.Generator]

    @classmethod
    def of(cls, streams: Sequence[np.random.SeedSequence]) -> Draws:
        parts = [
            [
                np.random.default_rng(
                    np.random.SeedSequence(
                        s.entropy, spawn_key=(*s.spawn_key, k), pool_size=s.pool_size
                    )
                )
                for s in streams
            ]
            for k in range(3)
        ]
        return cls(*parts)


@dataclass(frozen=True, kw_only=True)
class Scan:
    """Each UAV's measurements of one scan, padded to Z per row: the range-bearing
    measurements polar (B, N, Z, 2) [m, rad], their conversion z (B, N, Z, 2) [m] with
    covariance R (B, N, Z, 2, 2) (eqs. 5-12, from where the UAV believes it is), valid
    (B, N, Z) bool, and for evaluation only origin (B, N, Z) int64: the target measured,
    `CLUTTER` or `NONE` (padding). Padding holds z = 0 and R = I."""

    polar: np.ndarray
    z: np.ndarray
    R: np.ndarray
    valid: np.ndarray
    origin: np.ndarray


def detected(
    rngs: Sequence[np.random.Generator], observed: np.ndarray, probability: float
) -> np.ndarray:
    """Which in-view (UAV, target) pairs are detected this scan: observed (B, N, M) and a
    uniform draw below P_D; one draw per pair of each trial, whether in view or not, so a
    trial's stream does not depend on where the vehicles are. P_D = 1 draws nothing."""
    if probability >= 1.0:
        return observed
    draws = np.stack([rng.random(observed.shape[1:]) for rng in rngs])
    return observed & (draws < probability)


def clutter(
    rng: np.random.Generator, uavs: np.ndarray, alive: np.ndarray, sensor: SensorModel
) -> tuple[np.ndarray, np.ndarray]:
    """One trial's false measurements: a Poisson count per UAV (mean
    ``sensor.clutter_rate``), each at a point uniform over the UAV's observation disk,
    measured as a target there would be (`sensing.measure`, its own noise draws).

    uavs (N, >=3) true states; alive (N,). Returns (owner (C,) the UAV of each false
    measurement, in UAV order, and polar (C, 2) range-bearing)."""
    counts = rng.poisson(sensor.clutter_rate, uavs.shape[0]) * alive
    owner = np.repeat(np.arange(uavs.shape[0]), counts)
    radius = sensing.observation_radius(uavs[owner, 2], sensor)
    u = rng.random((owner.size, 3))
    rho, phi = radius * np.sqrt(u[:, 0]), 2.0 * np.pi * u[:, 1]
    points = uavs[owner, :2] + rho[:, None] * np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    noise = rng.standard_normal((owner.size, 2))
    return owner, sensing.measure(uavs[owner], points, sensor, noise)


def assemble(
    rngs: Sequence[np.random.Generator],
    detected: np.ndarray,
    polar: np.ndarray,
    false: Sequence[tuple[np.ndarray, np.ndarray]],
    shuffle: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each UAV's measurements of the scan as a padded set.

    detected (B, N, M): the detected pairs; polar (D, 2) their measurements in the
    order of ``np.nonzero(detected)``; false: per trial the (owner, polar) of `clutter`.
    With `shuffle`, each UAV's set is put in a random order (a draw per trial from its
    stream), so that no order carries a target's identity. Returns polar (B, N, Z, 2),
    valid (B, N, Z), origin (B, N, Z).
    """
    B, N, _ = detected.shape
    b, i, j = np.nonzero(detected)
    fb = np.concatenate([np.full(len(f[0]), t, dtype=np.int64) for t, f in enumerate(false)])
    fi = np.concatenate([f[0] for f in false]).astype(np.int64)
    fz = np.concatenate([f[1].reshape(-1, 2) for f in false])
    row = np.concatenate([b * N + i, fb * N + fi])
    values = np.concatenate([polar.reshape(-1, 2), fz])
    origin = np.concatenate([j, np.full(fb.size, CLUTTER, dtype=np.int64)])
    order = np.argsort(row, kind="stable")  # detections, then clutter, per row
    row, values, origin = row[order], values[order], origin[order]
    counts = np.bincount(row, minlength=B * N)
    Z = int(counts.max(initial=0))
    place = np.arange(row.size) - np.repeat(np.cumsum(counts) - counts, counts)
    if shuffle and row.size:
        keys = np.concatenate(
            [rng.random(int(counts[t * N : (t + 1) * N].sum())) for t, rng in enumerate(rngs)]
        )
        order = np.lexsort((keys, row))
        values, origin = values[order], origin[order]
    out = np.zeros((B * N, Z, 2))
    valid = np.zeros((B * N, Z), dtype=bool)
    where = np.full((B * N, Z), NONE, dtype=np.int64)
    out[row, place], valid[row, place], where[row, place] = values, True, origin
    return out.reshape(B, N, Z, 2), valid.reshape(B, N, Z), where.reshape(B, N, Z)
