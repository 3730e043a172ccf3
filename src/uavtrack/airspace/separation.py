"""Separation between UAVs that share an altitude band, measured in every run.

The paper flies each UAV at its own altitude "to avoid collisions" and leaves avoidance
in the horizontal plane out (Sec. 8). Two UAVs are in the same band when their
altitudes differ by less than ``uav.vertical_separation``; such a pair must then keep a
horizontal distance of at least ``uav.separation`` (0: no minimum). A *loss of
separation* is one such pair closer than the minimum at one step.

Pairs are looked for up to the reach max(r_C, separation) apart horizontally: a UAV
learns of another from its radio, so nothing beyond r_C bears on avoidance, and
``separation_min`` reads NaN when no two UAVs of one band came within it. Small teams
compare every pair; from `network.SPARSE_FROM` UAVs the candidates come from the radio's
grid of cells (`network.grid_pairs`), so the cost grows with the pairs in reach; both
give the same pairs and distances.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..network import SPARSE_FROM, grid_pairs
from ..world import H, X, Y

NAMES = ("separation_losses", "separation_min", "conflict_time")
"""The metrics `Separation` gives (units and meaning: `metrics.METRICS`)."""


def close_pairs(
    uavs: np.ndarray, alive: np.ndarray, vertical: float, reach: float, form: str = "auto"
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pairs of living UAVs in one altitude band and within `reach` horizontally.

    uavs: (B, N, 5) [x, y, altitude, V, heading]; alive: (B, N). A pair is in one band
    when its altitudes differ by less than `vertical`. form: "dense" (every pair),
    "edges" (candidates from `network.grid_pairs`) or "auto" (edges from SPARSE_FROM
    UAVs). Returns (trial, i, q, distance), each (P,), i < q, distance horizontal [m].
    """
    B, n = alive.shape
    if form not in ("auto", "dense", "edges"):
        raise ValueError(f"form must be 'auto', 'dense' or 'edges', not {form!r}")
    if form == "dense" or (form == "auto" and n < SPARSE_FROM):
        i, q = np.triu_indices(n, 1)
        trial = np.repeat(np.arange(B), i.size)
        i, q = np.tile(i, B), np.tile(q, B)
    else:
        parts = []
        for b in range(B):
            living = np.flatnonzero(alive[b])
            first, second = grid_pairs(uavs[b, living, :3], reach)
            first, second = living[first], living[second]
            low, high = np.minimum(first, second), np.maximum(first, second)
            parts.append((np.full(low.size, b), low, high))
        trial, i, q = (np.concatenate(x) for x in zip(*parts, strict=True))
    one, other = uavs[trial, i], uavs[trial, q]
    distance = np.hypot(one[:, X] - other[:, X], one[:, Y] - other[:, Y])
    keep = (np.abs(one[:, H] - other[:, H]) < vertical) & (distance <= reach)
    keep &= alive[trial, i] & alive[trial, q]
    return trial[keep], i[keep], q[keep], distance[keep]


@dataclass(kw_only=True)
class Separation:
    """Running counts of a batch of B trials' separation (`NAMES`), fed the UAVs of one
    step at a time.

    minimum: uav.separation [m] (0: none); vertical: uav.vertical_separation [m];
    reach: how far apart pairs are looked for, max(r_C, minimum) [m]; dt [s].
    """

    batch: int
    minimum: float
    vertical: float
    reach: float
    dt: float
    losses: np.ndarray = field(init=False)
    closest: np.ndarray = field(init=False)
    conflicted: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.losses = np.zeros(self.batch, dtype=np.int64)
        self.closest = np.full(self.batch, np.inf)
        self.conflicted = np.zeros(self.batch, dtype=np.int64)

    def add(self, uavs: np.ndarray, alive: np.ndarray) -> None:
        """One step: the UAVs (B, N, 5) and which are alive (B, N)."""
        if uavs.shape[1] < 2:
            return
        trial, _, _, distance = close_pairs(uavs, alive, self.vertical, self.reach)
        if not trial.size:
            return
        np.minimum.at(self.closest, trial, distance)
        lost = trial[distance < self.minimum]
        if lost.size:
            self.losses += np.bincount(lost, minlength=self.batch)
            self.conflicted[np.unique(lost)] += 1

    def summary(self) -> dict[str, np.ndarray]:
        """The per-trial metrics of `NAMES`, each (B,)."""
        return {
            "separation_losses": self.losses.astype(float),
            "separation_min": np.where(np.isfinite(self.closest), self.closest, np.nan),
            "conflict_time": self.conflicted * self.dt,
        }
