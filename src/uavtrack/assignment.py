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
    _check(bids)
    return _solve(bids)


def _check(bids: np.ndarray) -> None:
    if not np.isfinite(bids).all():
        raise ValueError("bids must be finite")


def _solve(bids: np.ndarray) -> np.ndarray:
    n, m = bids.shape
    if n <= m:  # one round
        return linear_sum_assignment(bids, maximize=True)[1]
    choice = np.empty(n, dtype=np.int64)
    left = np.arange(n)
    while left.size:
        rows, cols = linear_sum_assignment(bids[left], maximize=True)
        choice[left[rows]] = cols
        keep = np.ones(left.size, dtype=bool)
        keep[rows] = False
        left = left[keep]
    return choice


def neighbourhood(bids: np.ndarray, adjacency: np.ndarray) -> np.ndarray:
    """Distributed auction: each UAV solves its own neighbourhood and keeps its row.

    bids: (..., N, M); adjacency: (..., N, N) bool (no self-loops needed).
    Returns (..., N) the target each UAV takes.
    """
    return neighbourhood_timed(bids, adjacency)[0]


def neighbourhood_timed(bids: np.ndarray, adjacency: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`neighbourhood`, also returning the seconds each UAV's own solve takes, (..., N).

    A UAV without neighbours solves a one-row problem: its best bid (the lowest target
    on ties, as the Hungarian solver does). UAVs with the same closed neighbourhood
    solve the same problem; it is solved once and its time charged to each of them, as
    each would solve it on its own processor.
    """
    _check(bids)
    n = bids.shape[-2]
    flat_bids = bids.reshape((-1,) + bids.shape[-2:])
    flat_adj = adjacency.reshape(-1, n, n)
    start = time.perf_counter()
    out = np.argmax(flat_bids, axis=-1)
    alone = ~flat_adj.any(axis=-1)
    seconds = np.full(out.shape, (time.perf_counter() - start) / out.size)
    members = flat_adj | np.eye(n, dtype=bool)
    solved: dict[bytes, tuple[np.ndarray, float]] = {}
    trial = -1
    for b, i in zip(*np.nonzero(~alone), strict=True):  # in order of trial, then UAV
        if b != trial:
            solved, trial = {}, b
        key = members[b, i].tobytes()
        if key not in solved:
            start = time.perf_counter()
            solved[key] = _solve(flat_bids[b, members[b, i]]), time.perf_counter() - start
        choice, seconds[b, i] = solved[key]
        out[b, i] = choice[np.count_nonzero(members[b, i, :i])]
    return out.reshape(bids.shape[:-1]), seconds.reshape(bids.shape[:-1])


def centralized(bids: np.ndarray) -> np.ndarray:
    """One global assignment over all UAVs (the centralized baseline). Returns (..., N)."""
    return centralized_timed(bids)[0]


def centralized_timed(bids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`centralized`, also returning the seconds of each global solve, (...,)."""
    _check(bids)
    flat = bids.reshape((-1,) + bids.shape[-2:])
    out = np.empty(flat.shape[:2], dtype=np.int64)
    seconds = np.empty(flat.shape[0])
    for b in range(flat.shape[0]):
        start = time.perf_counter()
        out[b] = _solve(flat[b])
        seconds[b] = time.perf_counter() - start
    return out.reshape(bids.shape[:-1]), seconds.reshape(bids.shape[:-2])


def greedy(bids: np.ndarray) -> np.ndarray:
    """Each UAV takes its own best bid, no interaction (the greedy baseline)."""
    return np.argmax(bids, axis=-1)
