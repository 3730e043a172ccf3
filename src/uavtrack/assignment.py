"""Target assignment from bids: neighbourhood Hungarian auction (Algorithm 1 lines 5-9).

UAV i receives the bid vectors V_q of its one-hop neighbours q, solves the
assignment over itself and them (Hungarian algorithm, maximising the sum of bids),
and keeps its own row (`local`). When the neighbourhood has more UAVs than targets,
the assignment is repeated on the UAVs left over until each has a target (Remark 2).
Ties break deterministically toward lower indices.

`auction` is the driver that runs every UAV's rule for a batch of trials (`neighbourhood`
on a plain graph): UAVs that see the same problem (the same members with the same bids)
share one solve, and the driver measures how long each solve takes on the clock its
caller hands it (`Clock`; the simulator and the agents pass `uavtrack.timing`). The
module reads no clock of its own: timing belongs to the caller, and without a clock the
seconds are zeros. A stage reads the CPU clock (a system call) twice, at its start and
its end, whatever the number of UAVs and problems; each solve inside it is timed on the
cheap wall clock, and its CPU time is its share of the stage's by those wall times.
Problems of the same size are solved together (`solve_many`): small ones by
enumerating every assignment as arrays, with the exact solver for the rest and for
every problem whose optimum is not unique by a clear margin, so the answers are those
of `hungarian`, ties included.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from functools import cache
from typing import Any, Protocol

import numpy as np

from .numerics import lsap


class Clock(Protocol):
    """The clock a caller times the solves on: the `uavtrack.timing` module is one.

    start() marks both clocks; since(mark) is the seconds since, (2,) [CPU, wall];
    tick() reads the wall clock alone (seconds from any origin), cheaply; set_up() is a
    context whose work (here: loading scipy's solver on first use) is left out of
    `since` and `tick`, being no decision's time."""

    def start(self) -> Any: ...

    def since(self, mark: Any) -> np.ndarray: ...

    def tick(self) -> float: ...

    def set_up(self) -> AbstractContextManager[None]: ...


class _NoClock:
    """No clock at all: nothing is read, every duration is zero."""

    def start(self) -> None:
        return None

    def since(self, mark: Any) -> np.ndarray:
        return np.zeros(2)

    def tick(self) -> float:
        return 0.0

    def set_up(self) -> AbstractContextManager[None]:
        return nullcontext()


NO_CLOCK = _NoClock()
"""The clock of a caller that passes none: the solves' seconds are zeros."""


class _SetUpOnly(_NoClock):
    """A caller's clock for its set-up alone: nothing is read, every duration is zero."""

    def __init__(self, clock: Clock) -> None:
        self._clock = clock

    def set_up(self) -> AbstractContextManager[None]:
        return self._clock.set_up()


def set_up_only(clock: Clock | None) -> Clock:
    """`clock` for the set-up of a solver's first load only, for a caller that times the
    whole of a stage itself (the central node): its clock is read once, not again inside."""
    return NO_CLOCK if clock is None else _SetUpOnly(clock)


def charged(wall: np.ndarray, clock: Clock, stage: Any) -> np.ndarray:
    """Seconds (..., 2) [CPU, wall] of the parts of a stage begun at `stage`, from their
    wall times `wall` (`Clock.tick`): each part's CPU time is its wall time scaled by
    the stage's CPU time over its wall time, both read once, now (`Clock.since`)."""
    cpu, total = clock.since(stage).tolist()
    out = np.empty(wall.shape + (2,))
    out[..., 0] = wall * (cpu / total if total > 0 else 0.0)
    out[..., 1] = wall
    return out


def linear_sum_assignment(
    cost: np.ndarray | list[list[float]], maximize: bool = False, clock: Clock | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The exact solver: scipy's `linear_sum_assignment`, computed in plain Python for a
    small problem (`lsap`, the same answers, ties included) and by scipy for a larger
    one, `scipy.optimize` imported on first use (about half a second: set-up on the
    caller's `clock`, not a decision's time). `cost` an array or a list of rows. Batches
    of trials solve their problems by `solve_many`, without it unless bids tie."""
    listed = isinstance(cost, list)
    shape = (len(cost), len(cost[0])) if listed else cost.shape
    if lsap.small(*shape):
        return lsap.solve_lists(cost if listed else cost.tolist(), maximize)
    return load_solver(clock)(np.asarray(cost, dtype=float), maximize=maximize)


Solver = Callable[[np.ndarray], np.ndarray]
"""A neighbourhood's assignment: bids (n, m) -> (n,) the column of each row."""

_SOLVER: list[Callable[..., tuple[np.ndarray, np.ndarray]]] = []


def load_solver(clock: Clock | None = None) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """scipy's `linear_sum_assignment`, importing `scipy.optimize` on first use; the
    import is set-up on the caller's `clock` (`Clock.set_up`), not a decision's time."""
    if not _SOLVER:
        with (NO_CLOCK if clock is None else clock).set_up():
            # scipy ships no type stubs; pyright reads its Python source
            from scipy.optimize import (  # pyright: ignore[reportMissingTypeStubs]
                linear_sum_assignment as solve,
            )
        _SOLVER.append(solve)
    return _SOLVER[0]


def hungarian(bids: np.ndarray, clock: Clock | None = None) -> np.ndarray:
    """Assignment of rows (UAVs) to columns (targets) maximising the total bid, Remark 2.

    bids: (n, m), finite, or NaN for a bid that was not scored because it is below the
    row's n best (`planning.plan` with ``top``): such a bid is never read. Rows are
    assigned in rounds: each round solves the rectangular problem over the rows still
    unassigned and all columns, so with n <= m every row gets a distinct column, and
    with n > m every column is used once per round. Returns (n,) column per row.

    With n < m only each row's n best columns matter. Exchange argument: take an
    optimal assignment in which row i holds a column c outside its n best B_i. The other
    n - 1 rows hold at most n - 1 of the n columns of B_i, so some c' in B_i is free,
    and bid_i(c') >= bid_i(c); moving i to c' keeps the total at least as high and puts
    one more row inside its own list. Repeating ends with an optimal assignment where
    every row holds a column of its own B_i. So the problem restricted to those pairs
    (others forbidden) over the union of the B_i (at most n^2 columns, whatever m is)
    has the same optimal total, and the same assignment when the optimum is unique.
    B_i is the n largest bids of row i, ties to the lower column, so the restricted
    problem, and the choice among tied optima, depends only on the bids at or above
    each row's n-th best.

    clock: the caller's (`Clock`), on whose set-up a first load of scipy's solver is
    counted; it is read for nothing else.
    """
    bids = np.asarray(bids, dtype=float)
    if bids.ndim != 2:
        raise ValueError(f"bids must be (n, m), got shape {bids.shape}")
    _check(bids)
    return _solve(bids, clock)


def local(
    bids: np.ndarray, me: int, solve: Solver | None = None, clock: Clock | None = None
) -> int:
    """One UAV's auction (Algorithm 1 lines 5-9): its target from the bids of its closed
    neighbourhood, (n, m) with its own row at `me` and the others in index order.
    solve: the neighbourhood problem's solver (default `hungarian`, with `clock` for the
    set-up of its first load)."""
    if solve is None:
        return int(hungarian(bids, clock)[me])
    return int(solve(bids)[me])


def able(bids: np.ndarray, members: np.ndarray, me: int) -> np.ndarray:
    """The members of UAV `me`'s auction that can serve it: in an auction of k members
    `hungarian` reads each member's min(k, m) best bids, so a member with fewer scored
    (NaN: not scored, `planning.plan` with ``top``) cannot take part. Such members are
    left out until every one left can (leaving one out lowers k). An honest neighbour
    always can (it scores as many bids as the largest neighbourhood it belongs to has
    members), and so can `me`, which stays.

    bids (n, m) with NaN; members (n,) bool. Returns (n,) bool."""
    m = bids.shape[-1]
    scored = (~np.isnan(bids)).sum(axis=-1)
    members = members.copy()
    while True:
        short = members & (scored < min(int(members.sum()), m))
        short[me] = False
        if not short.any():
            return members
        members &= ~short


def _check(bids: np.ndarray) -> None:
    if np.isinf(bids).any():
        raise ValueError("bids must be finite (NaN only for a bid not scored)")


def ranked(bids: np.ndarray, count: int) -> np.ndarray:
    """Each row's `count` largest bids, best first, ties to the lower column; a bid not
    scored (NaN) is never chosen.

    bids: (R, m). Returns (R, count) columns, -1 past a row's scored bids. The first k
    of a row's list are its k best by the same rule, whatever `count` >= k is.
    """
    R, m = bids.shape
    count = min(count, m)
    scored = ~np.isnan(bids)
    if m > 2 * count:  # only bids at or above the count-th largest can be chosen
        filled = np.where(scored, bids, -np.inf)
        kth = np.partition(filled, m - count, axis=1)[:, m - count]
        scored &= filled >= kth[:, None]
    row, col = np.nonzero(scored)
    order = np.lexsort((col, -bids[row, col], row))
    row, col = row[order], col[order]
    rank = np.arange(row.size) - np.searchsorted(row, row)  # place within its row
    keep = rank < count
    out = np.full((R, count), -1, dtype=np.int64)
    out[row[keep], rank[keep]] = col[keep]
    return out


def _restricted(bids: np.ndarray, best: np.ndarray, clock: Clock | None = None) -> np.ndarray:
    """The problem over rows (n, m) restricted to each row's n best columns `best`
    (n, n), solved (`hungarian`'s exchange argument). Returns (n,) columns.

    When the rows' first choices differ and each is strictly better than the row's
    second, giving every row its first is the unique optimum: no solve needed."""
    n = best.shape[0]
    if (best < 0).any():
        raise ValueError(f"every row needs its {n} best bids scored (not NaN)")
    values = np.take_along_axis(bids, best, axis=1)
    first = best[:, 0]
    if n == 1 or (np.unique(first).size == n and (values[:, 0] > values[:, 1]).all()):
        return first
    columns, position = np.unique(best, return_inverse=True)
    problem = np.full((n, columns.size), -np.inf)
    problem[np.arange(n)[:, None], position.reshape(best.shape)] = values
    return columns[linear_sum_assignment(problem, maximize=True, clock=clock)[1]]


def _solve(bids: np.ndarray, clock: Clock | None = None) -> np.ndarray:
    n, m = bids.shape
    if n < m:  # one round, over each row's n best columns (the exchange argument)
        return _restricted(bids, ranked(bids, n), clock)
    if np.isnan(bids).any():
        raise ValueError(f"{n} rows and {m} columns: every bid must be scored (not NaN)")
    choice = np.empty(n, dtype=np.int64)
    left = np.arange(n)
    while left.size:
        rows, cols = linear_sum_assignment(bids[left], maximize=True, clock=clock)
        choice[left[rows]] = cols
        keep = np.ones(left.size, dtype=bool)
        keep[rows] = False
        left = left[keep]
    return choice


TOGETHER = 8
"""Fewest problems of one size that the auction solves together (`solve_many`): below
it each is solved alone, which costs less than building the arrays (a single trial's
UAVs, where the decision time of Fig. 7 is measured, see few problems of each size)."""

ENUMERATED = 720
"""Most candidate assignments enumerated for one problem (720 = 6!); a problem with more
goes to the exact solver."""

MARGIN = 1e-9
"""An enumerated optimum is taken only when it beats the second-best assignment by more
than this, relative to the problem's scale (k times its largest |bid|): far above the
exact solver's rounding, so the solver would find the same one. Otherwise (a tie or a
near-tie) the problem goes to the exact solver, which breaks the tie its own way."""


def solve_many(
    bids: np.ndarray, best: np.ndarray | None = None, clock: Clock | None = None
) -> np.ndarray:
    """`hungarian` of each problem of a stack, the same answers, ties included.

    bids: (Q, k, m) problems of k rows each; best: (Q, k, k) each row's k best columns
    (`ranked`), when already known and k < m. Returns (Q, k) the column of each row.
    Small problems are solved for the whole stack at once by enumeration; a problem
    whose optimum is not unique by `MARGIN`, or is too large to enumerate, is solved
    alone by the exact solver (`_solve`), as is one with unscored bids where every bid
    is needed (which raises as `hungarian` does). clock: as `hungarian`'s.
    """
    Q, k, m = bids.shape
    if k < m:
        if best is None:
            best = ranked(bids.reshape(Q * k, m), k).reshape(Q, k, k)
        return _restricted_many(bids, best, clock)
    out = np.empty((Q, k), dtype=np.int64)
    scored = ~np.isnan(bids).any(axis=(1, 2))
    for q in np.flatnonzero(~scored):
        out[q] = _solve(bids[q], clock)  # raises: every bid is needed here
    if scored.any():
        out[scored] = _rounds_many(bids[scored], clock)
    return out


def _restricted_many(bids: np.ndarray, best: np.ndarray, clock: Clock | None = None) -> np.ndarray:
    """`_restricted` of each problem: (Q, k, m) bids, (Q, k, k) each row's k best."""
    Q, k, _ = best.shape
    if k == 1:
        for q in np.flatnonzero(best[:, 0, 0] < 0):
            _restricted(bids[q], best[q])  # raises: the row's best bid is needed
        return best[:, :, 0].copy()
    out = np.empty((Q, k), dtype=np.int64)
    values = np.take_along_axis(bids, np.maximum(best, 0), axis=2)
    first = best[:, :, 0]
    ordered = np.sort(first, axis=1)
    easy = (
        (ordered[:, 1:] != ordered[:, :-1]).all(axis=1)
        & (values[:, :, 0] > values[:, :, 1]).all(axis=1)
        & (best >= 0).all(axis=(1, 2))
    )
    out[easy] = first[easy]  # every row's first choice, strictly: the unique optimum
    rest = np.flatnonzero(~easy & (best >= 0).all(axis=(1, 2)))
    alone = np.flatnonzero((best < 0).any(axis=(1, 2)))  # raises in `_restricted`
    if rest.size and k**k <= ENUMERATED:
        place = _positions(k)  # (E, k): the place in its list each row takes
        rows = np.arange(k)
        cols = best[rest][:, rows, place]  # (R, E, k)
        total = values[rest][:, rows, place].sum(axis=2)
        total[~_distinct_columns(cols)] = -np.inf
        pick, unique = _unique_best(total, np.abs(values[rest]).max(axis=(1, 2)) * k)
        done = rest[unique]
        out[done] = cols[unique, pick[unique]]
        rest = rest[~unique]
    for q in np.concatenate([rest, alone]):
        out[q] = _restricted(bids[q], best[q], clock)
    return out


def _rounds_many(bids: np.ndarray, clock: Clock | None = None) -> np.ndarray:
    """`_solve`'s rounds (k >= m, every bid scored) for each problem of (Q, k, m)."""
    Q, k, _ = bids.shape
    choice = np.empty((Q, k), dtype=np.int64)
    left = np.broadcast_to(np.arange(k), (Q, k))
    while left.shape[1]:
        sub = np.take_along_axis(bids, left[:, :, None], axis=1)
        cols = _lsa_many(sub, clock)  # (Q, r), -1 for a row left for the next round
        np.put_along_axis(choice, left, cols, axis=1)
        # every problem leaves the same number of rows (min(r, m) are assigned a round)
        left = left[cols < 0].reshape(Q, -1)
    return choice


def _lsa_many(bids: np.ndarray, clock: Clock | None = None) -> np.ndarray:
    """One `linear_sum_assignment(maximize=True)` of each problem of (Q, r, c), every bid
    finite: (Q, r) the column of each row, -1 for a row left out (r > c)."""
    Q, r, c = bids.shape
    out = np.full((Q, r), -1, dtype=np.int64)
    todo = np.arange(Q)
    if math.perm(max(r, c), min(r, c)) <= ENUMERATED:
        if r <= c:  # each row a distinct column
            perm = _permutations(c, r)  # (E, r) the column of each row
            total = bids[:, np.arange(r), perm].sum(axis=2)  # (Q, E)
        else:  # each column a distinct row
            perm = _permutations(r, c)  # (E, c) the row of each column
            total = bids[:, perm, np.arange(c)].sum(axis=2)
        pick, unique = _unique_best(total, np.abs(bids).max(axis=(1, 2)) * min(r, c))
        done = np.flatnonzero(unique)
        if r <= c:
            out[done] = perm[pick[done]]
        else:
            out[done[:, None], perm[pick[done]]] = np.arange(c)
        todo = np.flatnonzero(~unique)
    for q in todo:
        rows, cols = linear_sum_assignment(bids[q], maximize=True, clock=clock)
        out[q, rows] = cols
    return out


def _unique_best(total: np.ndarray, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per problem (rows of `total`, candidates along axis 1, -inf for none): the best
    candidate, and whether it beats every other by more than MARGIN * scale."""
    pick = np.argmax(total, axis=1)
    rows = np.arange(total.shape[0])
    top = total[rows, pick]
    other = total.copy()
    other[rows, pick] = -np.inf
    second = other.max(axis=1) if total.shape[1] > 1 else np.full(top.shape, -np.inf)
    return pick, np.isfinite(top) & (top - second > MARGIN * np.maximum(scale, 1e-300))


def _distinct_columns(cols: np.ndarray) -> np.ndarray:
    """(..., k) -> (...): whether the k columns are pairwise different."""
    k = cols.shape[-1]
    ok = np.ones(cols.shape[:-1], dtype=bool)
    for a, b in itertools.combinations(range(k), 2):
        ok &= cols[..., a] != cols[..., b]
    return ok


@cache
def _positions(k: int) -> np.ndarray:
    """Every tuple of k places in 0..k-1, (k**k, k)."""
    return np.array(list(itertools.product(range(k), repeat=k)), dtype=np.int64).reshape(-1, k)


@cache
def _permutations(n: int, r: int) -> np.ndarray:
    """Every ordered choice of r distinct items of n, (n!/(n-r)!, r)."""
    return np.array(list(itertools.permutations(range(n), r)), dtype=np.int64).reshape(-1, r)


def neighbourhood(
    bids: np.ndarray, adjacency: np.ndarray, solve: Solver | None = None
) -> np.ndarray:
    """Distributed auction on a graph: each UAV solves its own neighbourhood and keeps
    its row. bids: (..., N, M); adjacency: (..., N, N) bool (no self-loops needed).
    Returns (..., N) the target each UAV takes."""
    n = bids.shape[-2]
    members = adjacency.reshape(-1, n, n) | np.eye(n, dtype=bool)
    target, _ = auction(bids.reshape((-1,) + bids.shape[-2:]), members, solve)
    return target.reshape(bids.shape[:-1])


def auction(
    bids: np.ndarray,
    members: np.ndarray,
    solve: Solver | None = None,
    clock: Clock | None = None,
    known: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Every UAV's `local` rule over the members of its closed neighbourhood, for B trials.

    bids: (B, N, M), the bids every receiver holds of every UAV, or (B, N, N, M), each
    receiver's own view [trial, receiver, sender] (when messages are lost or late, UAVs
    hold different bids of the same neighbour). members: (B, N, N) bool [trial,
    receiver, sender], the UAVs in each receiver's auction; a receiver is always a
    member of its own. solve: the neighbourhood problem's solver (default `hungarian`).
    known: (B, N, M) bool, the columns each receiver's problem has (None: all): with
    tracks, the labels it knows (`methods.distributed.known_labels`). Its problem is
    over those columns alone, in their order, as the agent's over the labels it knows;
    a receiver that knows none takes -1.

    Returns (target (B, N), seconds (B, N, 2)): the time of the solve each UAV needed on
    the caller's `clock`, CPU and wall (zeros without one), charged to every UAV that
    shares it, as each would solve it on its own processor (problems solved together
    share their time).
    A UAV alone takes its best bid (the lowest target on ties, as the solver does).
    """
    clock = NO_CLOCK if clock is None else clock
    solve = solve or _solve
    if solve is hungarian:
        solve = _solve  # the same, without checking every problem again
    _check(bids)
    B, n = members.shape[:2]
    m = bids.shape[-1]
    views = bids.ndim == 4
    if known is not None and known.all():
        known = None  # every problem over every column: the paper's case
    own = bids[:, np.arange(n), np.arange(n)] if views else bids  # (B, N, M)
    stage, tick = clock.start(), clock.tick
    begun = tick()
    out = greedy(own, known)
    wall = np.full(out.shape, (tick() - begun) / max(out.size, 1))
    if solve is _solve and not views and B * n <= FEW:
        _auction_lists(bids, members, out, wall, clock, known)
        return out, charged(wall, clock, stage)
    idx = np.arange(n)
    members = members.copy()
    members[:, idx, idx] = True
    b, i = np.nonzero(members.sum(axis=-1) > 1)  # UAVs with others in their auction
    if not b.size:
        return out, charged(wall, clock, stage)
    rows = members[b, i]  # (K, N)
    keys = rows if known is None else np.concatenate([rows, known[b, i]], axis=1)
    first, which = _distinct(b, keys, n, bids[b, i] if views else None)
    row = np.cumsum(rows, axis=1)[np.arange(b.size), i] - 1  # UAV i's row in its problem
    choice = np.empty((first.size, n), dtype=np.int64)
    cost = np.zeros(first.size)
    size = rows[first].sum(axis=1)
    if known is not None:  # problems over some columns: solved apart
        _auction_known(
            bids,
            b[first],
            i[first],
            rows[first],
            known[b[first], i[first]],
            choice,
            cost,
            solve,
            clock,
        )
        out[b, i] = choice[which, row]
        wall[b, i] = cost[which]
        return out, charged(wall, clock, stage)
    lists, share = None, 0.0
    if solve is _solve and not views and (size < m).any():
        # the built-in solver reads each member's k best bids only: rank every bidder's
        # once, as many as the largest problem needs (`ranked` keeps the order of each
        # shorter prefix), and charge the ranking to the problems by their members
        begun = tick()
        problem, member = np.nonzero(rows[first])
        bidders = np.unique(b[first][problem] * n + member)
        lists = np.full((B * n, int(size[size < m].max())), -1, dtype=np.int64)
        lists[bidders] = ranked(bids.reshape(B * n, m)[bidders], lists.shape[1])
        share = (tick() - begun) / bidders.size
    if solve is _solve:  # problems of one size together (`solve_many`) when many
        for width in np.unique(size).tolist():
            group = np.flatnonzero(size == width)
            if group.size < TOGETHER:  # a few: each alone costs less than the arrays
                for u in group.tolist():
                    k = first[u]
                    problem = bids[b[k], i[k], rows[k]] if views else bids[b[k], rows[k]]
                    begun = tick()
                    if lists is not None and width < m:
                        who = np.flatnonzero(rows[k]) + n * b[k]
                        solved = _restricted(problem, lists[who, :width], clock)
                    else:
                        solved = _solve(problem, clock)
                    cost[u] = tick() - begun + share * width
                    choice[u, :width] = solved
                continue
            k = first[group]
            who = np.nonzero(rows[k])[1].reshape(-1, width)  # members, in index order
            begun = tick()
            if views:
                problem = bids[b[k][:, None], i[k][:, None], who]
            else:
                problem = bids[b[k][:, None], who]
            best = None
            if lists is not None and width < m:
                best = lists[who + n * b[k][:, None], :width]
            choice[group, :width] = solve_many(problem, best, clock)
            cost[group] = (tick() - begun) / group.size + share * width
    else:
        for u, k in enumerate(first.tolist()):  # a method's own solver: one call per problem
            problem = bids[b[k], i[k], rows[k]] if views else bids[b[k], rows[k]]
            begun = tick()
            solved = solve(problem)
            cost[u] = tick() - begun
            choice[u, : solved.size] = solved
    out[b, i] = choice[which, row]
    wall[b, i] = cost[which]
    return out, charged(wall, clock, stage)


def _auction_known(
    bids: np.ndarray,
    trial: np.ndarray,
    receiver: np.ndarray,
    rows: np.ndarray,
    known: np.ndarray,
    choice: np.ndarray,
    cost: np.ndarray,
    solve: Solver,
    clock: Clock,
) -> None:
    """`auction`'s problems, each over the columns its receiver knows. trial, receiver
    (P,): each problem's; rows (P, N) its members; known (P, M) its columns. Writes each
    problem's column of every member (-1 with no column) into `choice` (P, N), and its
    solve's wall seconds into `cost` (P,)."""
    tick = clock.tick
    size, span = rows.sum(axis=1), known.sum(axis=1)
    for u in np.flatnonzero(span == 0).tolist():
        choice[u, : size[u]] = -1
    for width, count in np.unique(np.stack([size, span], axis=1)[span > 0], axis=0).tolist():
        group = np.flatnonzero((size == width) & (span == count))
        who = np.nonzero(rows[group])[1].reshape(-1, width)  # members, in index order
        cols = np.nonzero(known[group])[1].reshape(-1, count)  # columns, in order
        begun = tick()
        if bids.ndim == 4:
            problem = bids[trial[group][:, None], receiver[group][:, None], who]
        else:
            problem = bids[trial[group][:, None], who]
        problem = np.take_along_axis(problem, cols[:, None, :], axis=2)
        if solve is _solve and group.size >= TOGETHER:
            solved = solve_many(problem, clock=clock)
        else:
            one = (lambda p: _solve(p, clock)) if solve is _solve else solve
            solved = np.stack([one(p) for p in problem])
        choice[group, :width] = np.take_along_axis(cols, solved, axis=1)
        cost[group] = (tick() - begun) / group.size


FEW = 32
"""Most UAVs (trials x team) whose auctions run on Python lists (`_auction_lists`): in a
single trial's small team each problem is a few bids, and a numpy call per step of the
rule costs more than the arithmetic."""


def _auction_lists(
    bids: np.ndarray,
    members: np.ndarray,
    out: np.ndarray,
    wall: np.ndarray,
    clock: Clock,
    known: np.ndarray | None = None,
) -> None:
    """`auction`'s rule with the built-in solver on Python lists, for few UAVs: the same
    problems (one per distinct trial, neighbourhood and columns known) solved by the
    same rule (`_solve_lists`), the same targets. Writes the target and the solve's wall
    seconds of every UAV with others in its auction into `out` and `wall` (B, N)."""
    tick = clock.tick
    values = bids.tolist()
    m = bids.shape[-1]
    everything = tuple(range(m))
    knows = None if known is None else known.tolist()
    solved: dict[tuple[int, tuple[int, ...], tuple[int, ...]], tuple[float, list[int]]] = {}
    for b, team in enumerate(members.tolist()):
        for i, row in enumerate(team):
            who = tuple(q for q in range(len(row)) if row[q] or q == i)
            if len(who) < 2:
                continue
            cols = everything if knows is None else tuple(c for c in everything if knows[b][i][c])
            key = (b, who, cols)
            if key not in solved:
                begun = tick()
                if not cols:  # no column to take
                    choice = [-1] * len(who)
                elif knows is None:
                    choice = _solve_lists([values[b][q] for q in who], clock)
                else:
                    problem = [[values[b][q][c] for c in cols] for q in who]
                    choice = [cols[c] for c in _solve_lists(problem, clock)]
                solved[key] = (tick() - begun, choice)
            seconds, choice = solved[key]
            out[b, i] = choice[who.index(i)]
            wall[b, i] = seconds


def _solve_lists(bids: list[list[float]], clock: Clock) -> list[int]:
    """`_solve` of one problem given as lists: the column of each row."""
    k, m = len(bids), len(bids[0])
    if k < m:  # the problem restricted to each row's k best columns (`_restricted`)
        best: list[list[int]] = []
        for row in bids:
            scored = sorted((-x, c) for c, x in enumerate(row) if x == x)  # not NaN
            if len(scored) < k:
                raise ValueError(f"every row needs its {k} best bids scored (not NaN)")
            best.append([c for _, c in scored[:k]])
        first = [b[0] for b in best]
        if k == 1 or (
            len(set(first)) == k
            and all(row[b[0]] > row[b[1]] for row, b in zip(bids, best, strict=True))
        ):
            return first
        columns = sorted({c for b in best for c in b})
        place = {c: x for x, c in enumerate(columns)}
        problem = [[-math.inf] * len(columns) for _ in range(k)]
        for line, row, b in zip(problem, bids, best, strict=True):
            for c in b:
                line[place[c]] = row[c]
        cols = linear_sum_assignment(problem, True, clock)[1]
        return [columns[c] for c in cols.tolist()]
    if any(x != x for row in bids for x in row):
        raise ValueError(f"{k} rows and {m} columns: every bid must be scored (not NaN)")
    choice = [0] * k
    left = list(range(k))
    while left:
        rows, cols = linear_sum_assignment([bids[r] for r in left], True, clock)
        for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
            choice[left[r]] = c
        taken = set(rows.tolist())
        left = [r for x, r in enumerate(left) if x not in taken]
    return choice


def _distinct(
    trial: np.ndarray, members: np.ndarray, n: int, views: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Group equal (trial, neighbourhood[, columns known][, bids held]) rows: (first row
    of each group, group of each row). members (K, n [+ M]) bool: the neighbourhood,
    then the columns known when given."""
    if views is not None or trial.size <= 8:  # a dictionary: few rows, or bids in the key
        groups: dict[tuple[int | bytes, ...], int] = {}
        heads: list[int] = []
        which = np.empty(trial.size, dtype=np.int64)
        for k in range(trial.size):
            key: tuple[int | bytes, ...] = (int(trial[k]), members[k].tobytes())
            if views is not None:
                key += (views[k][members[k, :n]].tobytes(),)
            if key not in groups:
                groups[key] = len(heads)
                heads.append(k)
            which[k] = groups[key]
        return np.array(heads), which
    n = members.shape[1]  # with the columns known, their bits too
    if n + int(trial.max()).bit_length() <= 62:  # the neighbourhood as an integer bitmask
        keys = (trial << n) | (members @ (1 << np.arange(n, dtype=np.int64)))
        _, first, which = np.unique(keys, return_index=True, return_inverse=True)
    else:
        keys = np.concatenate(
            [trial[:, None], np.packbits(members, axis=1)], axis=1, dtype=np.int64
        )
        _, first, which = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return first, which.reshape(-1)


def centralized(
    bids: np.ndarray,
    members: np.ndarray | None = None,
    clock: Clock | None = None,
    known: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One global assignment per trial over the member UAVs (all by default).

    bids: (B, N, M); members: (B, N) bool; known: (B, M) bool, the columns of each
    trial's problem (None: all), in their order. Returns (target (B, N), -1 for a UAV
    left out or with no column; seconds (B, 2) of each trial's solve on the caller's
    `clock`, CPU and wall (zeros without one), the solve of trials with as many members
    and columns shared among them).
    """
    clock = NO_CLOCK if clock is None else clock
    B, n, m = bids.shape
    members = np.ones((B, n), dtype=bool) if members is None else members
    _check(bids[members])
    known = np.ones((B, m), dtype=bool) if known is None else known
    out = np.full((B, n), -1, dtype=np.int64)
    wall = np.zeros(B)
    stage, tick = clock.start(), clock.tick
    count, span = members.sum(axis=1), known.sum(axis=1)
    shapes = np.stack([count, span], axis=1)[(count > 0) & (span > 0)]
    for size, width in np.unique(shapes, axis=0).tolist():  # trials of one shape together
        trials = np.flatnonzero((count == size) & (span == width))
        cols = np.nonzero(known[trials])[1].reshape(-1, width)
        if trials.size < TOGETHER:  # a few: each alone
            for t, b in enumerate(trials.tolist()):
                rows = np.flatnonzero(members[b])
                begun = tick()
                out[b, rows] = cols[t, _solve(bids[b, rows][:, cols[t]], clock)]
                wall[b] = tick() - begun
            continue
        who = np.nonzero(members[trials])[1].reshape(-1, size)
        begun = tick()
        problem = np.take_along_axis(bids[trials[:, None], who], cols[:, None, :], axis=2)
        solved = solve_many(problem, clock=clock)
        out[trials[:, None], who] = np.take_along_axis(cols, solved, axis=1)
        wall[trials] = (tick() - begun) / trials.size
    return out, charged(wall, clock, stage)


def greedy(bids: np.ndarray, known: np.ndarray | None = None) -> np.ndarray:
    """Each UAV takes its own best bid, no interaction (the greedy baseline); a bid not
    scored (NaN) is never the best; ties to the lowest target.

    known: which columns each row may take (bids' shape, bool; None: all). A row that
    knows none takes -1."""
    if known is None:
        return np.argmax(np.where(np.isnan(bids), -np.inf, bids), axis=-1)
    best = np.argmax(np.where(known & ~np.isnan(bids), bids, -np.inf), axis=-1)
    return np.where(known.any(axis=-1), best, -1)
