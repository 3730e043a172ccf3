"""``greedy``: the same fusion as distributed; each UAV takes the target of its own
highest bid, with no interaction.
"""

from __future__ import annotations

import numpy as np

from .. import assignment, timing
from .base import Assigned, Fused, Inputs, Method, Setting


class Greedy(Method):
    """Same fusion as distributed; each UAV takes its own best bid."""

    name = "greedy"

    def top(self, setting: Setting, largest: np.ndarray | None) -> np.ndarray | None:
        """Its own best bid only."""
        if not setting.prune or largest is None:
            return None
        return np.ones(largest.shape, dtype=np.int64)

    def assign(self, inputs: Inputs, fused: Fused, bids: np.ndarray) -> Assigned:
        start = timing.start()
        out = assignment.greedy(bids, inputs.holds)  # with tracks: over the labels it holds
        seconds = np.empty(out.shape + (2,))
        seconds[...] = timing.since(start) / out.size
        none = np.zeros(bids.shape[0], dtype=np.int64)
        return Assigned(
            target=np.where(inputs.alive, out, -1), seconds=seconds, sent=none, delivered=none
        )
