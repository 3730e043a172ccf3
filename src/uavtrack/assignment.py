"""Target assignment from bids: neighbourhood Hungarian auction (Algorithm 1 lines 5-9).

UAV i receives the bid vectors V_q of its one-hop neighbours q, solves the
assignment over itself and them (Hungarian algorithm, maximising the sum of bids),
and keeps its own row. When the neighbourhood has more UAVs than targets, the
assignment is repeated on the UAVs left over until each has a target (Remark 2).
Ties break deterministically toward lower indices.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.optimize import linear_sum_assignment


def hungarian(bids: np.ndarray) -> np.ndarray:
    """Assignment of rows (UAVs) to columns (targets) maximising the total bid, Remark 2.

    bids: (n, m) finite. Rows are assigned in rounds: each round solves the rectangular
    problem over the rows still unassigned and all columns, so with n <= m every row
    gets a distinct column, and with n > m every column is used once per round.
    Returns (n,) column per row.
    """
    if not np.isfinite(bids).all():
        raise ValueError("bids must be finite")
    n = bids.shape[0]
    choice = np.full(n, -1, dtype=np.int64)
    left = np.arange(n)
    while left.size:
        rows, cols = linear_sum_assignment(bids[left], maximize=True)
        choice[left[rows]] = cols
        left = np.delete(left, rows)
    return choice


def neighbourhood(bids: np.ndarray, adjacency: np.ndarray) -> np.ndarray:
    """Distributed auction: each UAV solves its own neighbourhood and keeps its row.

    bids: (..., N, M); adjacency: (..., N, N) bool (no self-loops needed).
    Returns (..., N) the target each UAV takes.
    """
    return neighbourhood_timed(bids, adjacency)[0]


def neighbourhood_timed(bids: np.ndarray, adjacency: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`neighbourhood`, also returning the seconds each UAV's own solve takes, (..., N).

    UAVs with the same closed neighbourhood solve the same problem; it is solved once
    and its time charged to each of them, as each would solve it on its own processor.
    """
    flat_bids = bids.reshape((-1,) + bids.shape[-2:])
    flat_adj = adjacency.reshape((-1,) + adjacency.shape[-2:])
    n = bids.shape[-2]
    out = np.empty(flat_bids.shape[:2], dtype=np.int64)
    seconds = np.empty(flat_bids.shape[:2])
    for b in range(flat_bids.shape[0]):
        solved: dict[bytes, tuple[np.ndarray, float]] = {}
        for i in range(n):
            members = flat_adj[b, i].copy()
            members[i] = True
            key = members.tobytes()
            if key not in solved:
                start = time.perf_counter()
                choice = hungarian(flat_bids[b, members])
                solved[key] = choice, time.perf_counter() - start
            choice, seconds[b, i] = solved[key]
            out[b, i] = choice[np.count_nonzero(members[:i])]
    return out.reshape(bids.shape[:-1]), seconds.reshape(bids.shape[:-1])


def centralized(bids: np.ndarray) -> np.ndarray:
    """One global assignment over all UAVs (the centralized baseline). Returns (..., N)."""
    flat = bids.reshape((-1,) + bids.shape[-2:])
    return np.stack([hungarian(b) for b in flat]).reshape(bids.shape[:-1])


def greedy(bids: np.ndarray) -> np.ndarray:
    """Each UAV takes its own best bid, no interaction (the greedy baseline)."""
    return np.argmax(bids, axis=-1)
