"""The paper's aircraft: the unicycle of eq. (1), at constant speed and altitude."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import G
from ..world import fly


@dataclass(frozen=True)
class Unicycle:
    """Eq. (1) over a cycle of dt: the bank angle turns the heading at g tan(phi) / V the
    moment it is chosen (`world.fly`, which the planner uses too)."""

    dt: float
    g: float = G

    def fly(self, uavs: np.ndarray, bank: np.ndarray, alive: np.ndarray) -> np.ndarray:
        new = fly(uavs, bank, self.dt, self.g)
        return new if alive.all() else np.where(alive[..., None], new, uavs)
