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
    on ties, as the Hungarian solver does). UAVs of a trial with the same closed
    neighbourhood solve the same problem; it is solved once and its time charged to
    each of them, as each would solve it on its own processor.
    """
    _check(bids)
    n = bids.shape[-2]
    flat_bids = bids.reshape((-1,) + bids.shape[-2:])
    flat_adj = adjacency.reshape(-1, n, n)
    start = time.perf_counter()
    out = np.argmax(flat_bids, axis=-1)
    seconds = np.full(out.shape, (time.perf_counter() - start) / out.size)
    b, i = np.nonzero(flat_adj.any(axis=-1))  # UAVs with neighbours
    if b.size:
        members = flat_adj[b, i]
        members[np.arange(b.size), i] = True  # closed neighbourhoods, (K, N)
        first, which = _distinct(b, members)
        row = np.cumsum(members, axis=1)[np.arange(b.size), i] - 1  # UAV i's row in its problem
        choice = np.empty((first.size, n), dtype=np.int64)
        cost = np.empty(first.size)
        for u, k in enumerate(first):  # one solve per distinct problem
            start = time.perf_counter()
            solved = _solve(flat_bids[b[k], members[k]])
            cost[u] = time.perf_counter() - start
            choice[u, : solved.size] = solved
        out[b, i] = choice[which, row]
        seconds[b, i] = cost[which]
    return out.reshape(bids.shape[:-1]), seconds.reshape(bids.shape[:-1])


def _distinct(trial: np.ndarray, members: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group equal (trial, neighbourhood) rows: (first row of each group, group of each row)."""
    if trial.size <= 8:  # a few rows: a dictionary beats numpy's set routines
        groups: dict[tuple[int, bytes], int] = {}
        first, which = [], np.empty(trial.size, dtype=np.int64)
        for k in range(trial.size):
            key = (int(trial[k]), members[k].tobytes())
            if key not in groups:
                groups[key] = len(first)
                first.append(k)
            which[k] = groups[key]
        return np.array(first), which
    n = members.shape[1]
    if n + int(trial.max()).bit_length() <= 62:  # the neighbourhood as an integer bitmask
        keys = (trial << n) | (members @ (1 << np.arange(n, dtype=np.int64)))
        _, first, which = np.unique(keys, return_index=True, return_inverse=True)
    else:
        keys = np.concatenate(
            [trial[:, None], np.packbits(members, axis=1)], axis=1, dtype=np.int64
        )
        _, first, which = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return first, which.reshape(-1)


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
