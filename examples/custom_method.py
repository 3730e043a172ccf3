"""Plug in your own decision rule: a method is `fuse` + `assign` (see uavtrack.methods).

This one keeps the paper's max-consensus fusion but replaces the neighbourhood
Hungarian auction by a sequential greedy auction over the same neighbourhood.

    python examples/custom_method.py
"""

import numpy as np

import uavtrack
from uavtrack.methods import Method


def sequential(bids):
    """Highest remaining (UAV, target) pair first; targets are reused once all are taken."""
    n, m = bids.shape
    choice = np.full(n, -1)
    free = np.ones(m, dtype=bool)
    while (choice < 0).any():
        if not free.any():
            free[:] = True  # more UAVs than targets: another round (Remark 2)
        open_bids = np.where((choice < 0)[:, None] & free[None, :], bids, -np.inf)
        row, col = np.unravel_index(np.argmax(open_bids), open_bids.shape)
        choice[row], free[col] = col, False
    return choice


class SequentialAuction(Method):
    """Each UAV runs `sequential` over itself and its one-hop neighbours, keeps its row."""

    name = "sequential"

    def assign(self, bids, adjacency):
        B, N, _ = bids.shape
        out = np.empty((B, N), dtype=np.int64)
        for b in range(B):
            for i in range(N):
                members = np.flatnonzero(adjacency[b, i] | (np.arange(N) == i))
                out[b, i] = sequential(bids[b, members])[np.searchsorted(members, i)]
        return out, np.zeros((B, N))


scenario = uavtrack.Scenario(steps=200)
for method in ("distributed", SequentialAuction(), "greedy"):
    rates = uavtrack.run(scenario, method, [uavtrack.trial_seed(0, t) for t in range(8)])
    name = method if isinstance(method, str) else method.name
    print(f"{name:12s} {rates.metrics['observation_rate'].mean():.3f}")
