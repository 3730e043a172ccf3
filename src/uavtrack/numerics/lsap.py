"""The rectangular linear sum assignment problem, solved exactly in plain Python for the
small problems a single trial, an environment or an agent program meets.

`solve(cost, maximize)` returns what `scipy.optimize.linear_sum_assignment` returns, ties
included: it runs the same algorithm, the shortest augmenting path method of Crouse (D. F.
Crouse, "On implementing 2D rectangular assignment algorithms", IEEE Trans. Aerospace and
Electronic Systems 52(4), 2016, pp. 1685-1686), with the choices that decide between
equal paths made as scipy makes them (tests/test_lsap.py compares the two on problems
whose ties are common):

- the problem is transposed when it has more rows than columns and negated to
  maximise; the costs are used as they are (scipy 1.17 no longer shifts them to a
  least entry of zero, and a shift would round some ties apart);
- rows are added one at a time, each by a Dijkstra search over the columns from that
  row; the columns not yet reached are scanned from a list that starts in decreasing
  order and loses a reached column by moving the list's last one into its place;
- among columns of equal path cost the first one scanned is kept, unless a later one is
  free (a sink), which then wins.

A forbidden pair is +inf (-inf when maximising); a problem with no complete assignment
raises ValueError, as does a NaN entry.

Importing scipy.optimize costs about half a second of CPU, many times what a single
trial's problems cost to solve here (tens of microseconds each), so small problems
(`SMALL`) are solved here and larger ones by scipy, whose compiled loop then pays.
Once scipy.optimize is loaded (by a caller, or by `load_if_worth` for a run that will
solve many problems) every problem goes to it: the answers are the same.
"""

from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np

SMALL = 4096
"""Largest rows x columns x min(rows, columns) solved here; past it scipy's compiled
solver is faster than its import costs, in the problems a run meets (a 16 x 16 problem
takes about 2 ms here)."""

INF = math.inf


IMPORT_SECONDS = 0.5
"""About what loading scipy.optimize costs, in CPU seconds."""

SECONDS_PER_CUBE = 7e-8
"""About what a problem of n x n costs here, per n^3, in CPU seconds (12 x 12: 0.12 ms)."""


def load_if_worth(problems: int, n: int) -> None:
    """Load scipy.optimize when `problems` problems of n x n would cost more here than
    loading it does (a run's track scoring: one per UAV and step)."""
    if "scipy.optimize" not in sys.modules and problems * n**3 * SECONDS_PER_CUBE > IMPORT_SECONDS:
        import scipy.optimize  # noqa: F401  # pyright: ignore[reportMissingTypeStubs]


def small(rows: int, columns: int) -> bool:
    """Whether a problem of this size is `SMALL`: solved here rather than by scipy."""
    return rows * columns * min(rows, columns) <= SMALL


def solve(cost: Any, maximize: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(rows, columns) of a least-cost (most with `maximize`) assignment of min(n, m)
    pairs of the (n, m) matrix `cost`, rows in increasing order: scipy's
    `linear_sum_assignment`, computed here when the problem is `SMALL`."""
    matrix = np.asarray(cost, dtype=float)
    if matrix.ndim != 2:
        raise ValueError(f"expected a matrix (2-d array), got a {matrix.ndim}-d array")
    if not small(*matrix.shape) or "scipy.optimize" in sys.modules:
        from scipy.optimize import linear_sum_assignment  # pyright: ignore[reportMissingTypeStubs]

        rows, cols = linear_sum_assignment(matrix, maximize=maximize)
        return np.asarray(rows, dtype=np.intp), np.asarray(cols, dtype=np.intp)
    return solve_lists(matrix.tolist(), maximize)


def solve_lists(cost: list[list[float]], maximize: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """`solve` of a matrix given as a list of rows of floats, whatever its size."""
    n = len(cost)
    m = len(cost[0]) if n else 0
    if n == 0 or m == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty.copy()
    transpose = m < n
    rows = [list(col) for col in zip(*cost, strict=True)] if transpose else [list(r) for r in cost]
    if maximize:
        rows = [[-x for x in r] for r in rows]
    for r in rows:
        for x in r:
            if x != x or x == -INF:
                raise ValueError("matrix contains invalid numeric entries")
    col4row = _shortest_paths(rows)
    if col4row is None:
        raise ValueError("cost matrix is infeasible")
    if transpose:  # col4row[j]: the original row of original column j
        order = sorted(range(len(col4row)), key=col4row.__getitem__)
        return (
            np.array([col4row[j] for j in order], dtype=np.intp),
            np.array(order, dtype=np.intp),
        )
    return np.arange(len(col4row), dtype=np.intp), np.array(col4row, dtype=np.intp)


def _shortest_paths(cost: list[list[float]]) -> list[int] | None:
    """The column of each row (rows <= columns), or None when some row cannot be
    assigned (every way to it is +inf)."""
    nr, nc = len(cost), len(cost[0])
    u = [0.0] * nr
    v = [0.0] * nc
    col4row = [-1] * nr
    row4col = [-1] * nc
    path = [-1] * nc
    for start in range(nr):
        # Dijkstra from `start` over reduced costs, until a free column is reached
        shortest = [INF] * nc
        row_seen = [False] * nr
        col_seen = [False] * nc
        left = list(range(nc - 1, -1, -1))
        reach = 0.0
        i = start
        sink = -1
        while sink < 0:
            row_seen[i] = True
            best, at = INF, -1
            row, ui = cost[i], u[i]
            for k, j in enumerate(left):
                d = reach + row[j] - ui - v[j]
                if d < shortest[j]:
                    path[j] = i
                    shortest[j] = d
                s = shortest[j]
                if s < best or (s == best and row4col[j] < 0):
                    best, at = s, k
            reach = best
            if reach == INF:
                return None
            j = left[at]
            if row4col[j] < 0:
                sink = j
            else:
                i = row4col[j]
            col_seen[j] = True
            left[at] = left[-1]
            left.pop()
        # dual update, then flip the path's pairs
        u[start] += reach
        for r in range(nr):
            if row_seen[r] and r != start:
                u[r] += reach - shortest[col4row[r]]
        for c in range(nc):
            if col_seen[c]:
                v[c] -= reach - shortest[c]
        j = sink
        while True:
            i = path[j]
            row4col[j] = i
            col4row[i], j = j, col4row[i]
            if i == start:
                break
    return col4row
