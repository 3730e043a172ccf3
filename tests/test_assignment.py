import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uavtrack import assignment


def brute_force_value(bids):
    """Best total of an injective assignment of the smaller side."""
    n, m = bids.shape
    if n <= m:
        return max(
            sum(bids[i, c] for i, c in enumerate(cols))
            for cols in itertools.permutations(range(m), n)
        )
    return max(
        sum(bids[r, j] for j, r in enumerate(rows)) for rows in itertools.permutations(range(n), m)
    )


matrices = st.tuples(st.integers(1, 6), st.integers(1, 6), st.integers(0, 2**32 - 1)).map(
    lambda t: np.random.default_rng(t[2]).random((t[0], t[1]))
)


@settings(max_examples=120, deadline=None)
@given(matrices)
def test_hungarian_matches_brute_force(bids):
    n, m = bids.shape
    choice = assignment.hungarian(bids)
    assert (choice >= 0).all() and (choice < m).all()
    if n <= m:
        assert len(set(choice)) == n
        assert bids[np.arange(n), choice].sum() == pytest.approx(brute_force_value(bids))
    else:
        # Remark 2: the first round is an optimal matching of m UAVs, then it repeats
        counts = np.bincount(choice, minlength=m)
        assert counts.max() - counts.min() <= 1
        assert counts.min() == n // m


def test_remark_2_repeats_on_the_uavs_left_over():
    bids = np.array([[5.0, 1.0], [4.0, 3.0], [3.0, 0.0], [2.0, 2.5], [0.0, 0.1]])
    choice = assignment.hungarian(bids)
    # round 1 over all rows: best matching is rows 0 -> 0 and 1 -> 1 (5 + 3)
    # round 2 over rows 2, 3, 4: row 2 -> 0 and row 3 -> 1 (3 + 2.5)
    # round 3: row 4 alone takes column 1 (0.1)
    assert choice.tolist() == [0, 1, 0, 1, 1]


def test_ties_go_to_lower_indices():
    assert assignment.hungarian(np.ones((1, 4))).tolist() == [0]
    assert assignment.hungarian(np.zeros((3, 3))).tolist() == [0, 1, 2]
    assert assignment.greedy(np.ones((2, 3))).tolist() == [0, 0]


def test_infinite_bids_and_missing_needed_bids_rejected():
    with pytest.raises(ValueError, match="finite"):
        assignment.hungarian(np.array([[1.0, np.inf]]))
    with pytest.raises(ValueError, match="2 best bids scored"):  # row 1 lacks its 2nd best
        assignment.hungarian(np.array([[1.0, 0.5, 0.2], [np.nan, 0.3, np.nan]]))
    with pytest.raises(ValueError, match="every bid must be scored"):  # n >= m reads all
        assignment.hungarian(np.array([[1.0, np.nan], [0.5, 0.2]]))
    # a bid below the row's n best is never read: NaN there changes nothing
    assert assignment.hungarian(np.array([[1.0, np.nan, 0.5]])).tolist() == [0]


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 7), st.integers(1, 5), st.integers(0, 2**32 - 1))
def test_neighbourhood_extremes(n, m, seed):
    rng = np.random.default_rng(seed)
    bids = rng.random((2, n, m))
    full = np.ones((2, n, n), dtype=bool)
    none = np.zeros((2, n, n), dtype=bool)
    # complete graph: every UAV solves the global problem
    assert np.array_equal(assignment.neighbourhood(bids, full), assignment.centralized(bids)[0])
    # no links: every UAV alone is greedy
    assert np.array_equal(assignment.neighbourhood(bids, none), assignment.greedy(bids))


def test_neighbourhood_keeps_own_row_of_local_problem():
    # path 0 - 1 - 2: UAV 0 solves {0, 1}, UAV 1 solves {0, 1, 2}, UAV 2 solves {1, 2}
    bids = np.array([[1.0, 0.0], [0.9, 0.1], [0.0, 1.0]])
    adj = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], dtype=bool)
    out = assignment.neighbourhood(bids, adj)
    assert out[0] == assignment.hungarian(bids[[0, 1]])[0]
    assert out[1] == assignment.hungarian(bids)[1]
    assert out[2] == assignment.hungarian(bids[[1, 2]])[1]
    assert out.tolist() == [0, 0, 1]


def full_problem(bids):
    """Remark 2 over every column (the solver before restriction): the oracle."""
    from scipy.optimize import linear_sum_assignment

    n = bids.shape[0]
    choice, left = np.empty(n, dtype=np.int64), np.arange(n)
    while left.size:
        rows, cols = linear_sum_assignment(bids[left], maximize=True)
        choice[left[rows]] = cols
        left = np.delete(left, rows)
    return choice


@settings(max_examples=150, deadline=None)
@given(st.integers(1, 8), st.integers(1, 30), st.integers(0, 2**32 - 1))
def test_restriction_to_each_rows_best_bids_loses_nothing(n, m, seed):
    rng = np.random.default_rng(seed)
    bids = rng.random((n, m))  # continuous: the optimum is unique almost surely
    assert np.array_equal(assignment.hungarian(bids), full_problem(bids))
    # integer bids: many tied optima; the same total, and the same choice every time
    ties = rng.integers(0, 3, (n, m)).astype(float)
    choice = assignment.hungarian(ties)
    oracle = full_problem(ties)
    total = ties[np.arange(n), choice].sum()
    assert total == ties[np.arange(n), oracle].sum()
    assert np.array_equal(choice, assignment.hungarian(ties.copy()))
    if n <= m:
        assert np.unique(choice).size == n
    # a bid below its row's n best may be unscored (NaN) without changing the choice
    if n < m:
        lists = assignment.ranked(ties, n)
        hidden = np.full_like(ties, np.nan)
        np.put_along_axis(hidden, lists, np.take_along_axis(ties, lists, axis=1), axis=1)
        assert np.array_equal(assignment.hungarian(hidden), choice)


def test_ranked_lists_best_first_ties_to_lower_column():
    bids = np.array([[0.5, 2.0, 2.0, np.nan, 1.0], [np.nan, np.nan, 3.0, np.nan, np.nan]])
    assert assignment.ranked(bids, 3).tolist() == [[1, 2, 4], [2, -1, -1]]
    # a shorter list is the prefix of a longer one
    assert assignment.ranked(bids, 2).tolist() == [[1, 2], [2, -1]]


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 30), st.integers(1, 40), st.integers(0, 2**32 - 1))
def test_auction_with_ranked_bidders_equals_one_full_solve_per_uav(n, m, seed):
    rng = np.random.default_rng(seed)
    bids = rng.random((2, n, m))
    points = rng.uniform(0, 100, (2, n, 2))
    links = np.linalg.norm(points[:, :, None] - points[:, None], axis=-1) < 40
    fast, _ = assignment.auction(bids, links)
    slow, _ = assignment.auction(bids, links, solve=full_problem)
    assert np.array_equal(fast, slow)
    for b, i in [(0, 0), (1, n - 1)]:  # and each is its own neighbourhood's problem
        rows = np.flatnonzero(links[b, i] | (np.arange(n) == i))
        me = int(np.flatnonzero(rows == i)[0])
        assert fast[b, i] == full_problem(bids[b, rows])[me]


def stacks(levels: int, scale: float, k: int, m: int, count: int, seed: int) -> np.ndarray:
    """(count, k, m) problems; few levels make ties common, a scale tests relative margins."""
    rng = np.random.default_rng(seed)
    bids = rng.integers(0, levels, (count, k, m)).astype(float) * scale
    near = rng.random((count, k, m)) < 0.2  # some bids a rounding error apart
    return np.where(near, bids * (1 + 1e-15), bids)


@settings(max_examples=200, deadline=None)
@given(
    st.integers(2, 1000),
    st.sampled_from([1e-12, 1.0, 1e9]),
    st.integers(1, 7),
    st.integers(1, 8),
    st.integers(1, 12),
    st.integers(0, 2**32 - 1),
)
def test_solve_many_equals_the_exact_solver_ties_included(levels, scale, k, m, count, seed):
    bids = stacks(levels, scale, k, m, count, seed)
    expected = np.stack([assignment._solve(p) for p in bids])
    assert np.array_equal(assignment.solve_many(bids), expected)
    if k < m:  # with each row's k best given, as the auction passes them
        best = assignment.ranked(bids.reshape(-1, m), k).reshape(count, k, k)
        assert np.array_equal(assignment.solve_many(bids, best), expected)


def test_solve_many_enumerates_without_the_exact_solver_when_optima_are_unique(monkeypatch):
    calls = []
    exact = assignment.linear_sum_assignment
    monkeypatch.setattr(
        assignment, "linear_sum_assignment", lambda *a, **kw: calls.append(1) or exact(*a, **kw)
    )
    rng = np.random.default_rng(0)
    for k, m in [(2, 4), (3, 4), (4, 4), (5, 4), (6, 3), (3, 9)]:
        bids = rng.random((50, k, m))
        expected = np.stack([assignment._solve(p) for p in bids])
        calls.clear()
        assert np.array_equal(assignment.solve_many(bids), expected)
        assert not calls, (k, m)
    ties = np.zeros((3, 4, 4))  # every assignment ties: the exact solver decides
    calls.clear()
    assert np.array_equal(assignment.solve_many(ties), np.tile(np.arange(4), (3, 1)))
    assert len(calls) == 3


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 9), st.integers(1, 7), st.integers(2, 6), st.integers(0, 2**32 - 1))
def test_batched_auction_equals_one_solve_per_problem(n, m, levels, seed):
    rng = np.random.default_rng(seed)
    bids = rng.integers(0, levels, (3, n, m)).astype(float)
    members = rng.random((3, n, n)) < 0.5
    members |= members.transpose(0, 2, 1)
    views = np.where(rng.random((3, n, n, m)) < 0.3, bids[:, None] + 1, bids[:, None])
    for together in (assignment.TOGETHER, 1):  # few problems each alone; all together
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(assignment, "TOGETHER", together)
            for held in (bids, views):
                one_by_one = assignment.auction(held, members, lambda p: assignment._solve(p))
                assert np.array_equal(assignment.auction(held, members)[0], one_by_one[0])


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 8), st.integers(1, 7), st.integers(2, 6), st.integers(0, 2**32 - 1))
def test_centralized_equals_one_solve_per_trial(n, m, levels, seed):
    rng = np.random.default_rng(seed)
    bids = rng.integers(0, levels, (6, n, m)).astype(float)
    members = rng.random((6, n)) < 0.7
    members[0] = True
    for together in (assignment.TOGETHER, 1):
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(assignment, "TOGETHER", together)
            target, _ = assignment.centralized(bids, members)
        for b in range(6):
            rows = np.flatnonzero(members[b])
            expected = np.full(n, -1)
            if rows.size:
                expected[rows] = assignment._solve(bids[b, rows])
            assert np.array_equal(target[b], expected)


def _over_known(bids, known):
    """The problem over the known columns alone, solved, as columns of the whole."""
    cols = np.flatnonzero(known)
    if not cols.size:
        return np.full(bids.shape[0], -1)
    return cols[assignment._solve(bids[:, cols])]


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 7), st.integers(1, 6), st.integers(2, 5), st.integers(0, 2**32 - 1))
def test_an_auction_over_the_columns_each_receiver_knows(n, m, levels, seed):
    """With `known`, each receiver solves its neighbourhood over its known columns only,
    on every path (lists, one by one, together; shared bids and views): a column it
    does not know is never taken, and a receiver that knows none takes -1."""
    rng = np.random.default_rng(seed)
    B = 6
    bids = rng.integers(0, levels, (B, n, m)).astype(float)
    members = rng.random((B, n, n)) < 0.5
    members |= members.transpose(0, 2, 1)
    members[:, np.arange(n), np.arange(n)] = True
    known = rng.random((B, n, m)) < 0.6
    views = np.where(rng.random((B, n, n, m)) < 0.3, bids[:, None] + 1, bids[:, None])
    for held in (bids, views):
        expected = np.empty((B, n), dtype=np.int64)
        for b, i in itertools.product(range(B), range(n)):
            rows = np.flatnonzero(members[b, i])
            problem = held[b, i, rows] if held.ndim == 4 else held[b, rows]
            if rows.size == 1:
                cols = np.flatnonzero(known[b, i])
                best = cols[np.argmax(problem[0, cols])] if cols.size else -1
                expected[b, i] = best
            else:
                expected[b, i] = _over_known(problem, known[b, i])[np.searchsorted(rows, i)]
        for few, together in ((assignment.FEW, 8), (0, 8), (0, 1)):
            with pytest.MonkeyPatch.context() as patch:
                patch.setattr(assignment, "FEW", few)
                patch.setattr(assignment, "TOGETHER", together)
                target, _ = assignment.auction(held, members, known=known)
                alone = lambda p: assignment._solve(p)  # noqa: E731
                custom, _ = assignment.auction(held, members, alone, known=known)
            assert np.array_equal(target, expected), (few, together)
            assert np.array_equal(custom, expected)
    everything, _ = assignment.auction(bids, members, known=np.ones((B, n, m), dtype=bool))
    assert np.array_equal(everything, assignment.auction(bids, members)[0])


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 7), st.integers(1, 6), st.integers(2, 5), st.integers(0, 2**32 - 1))
def test_centralized_over_each_trials_known_columns(n, m, levels, seed):
    """With `known` (B, M), each trial's one assignment is over its known columns only:
    a trial padded with columns it does not have decides as it would alone."""
    rng = np.random.default_rng(seed)
    bids = rng.integers(0, levels, (9, n, m)).astype(float)
    members = rng.random((9, n)) < 0.7
    known = rng.random((9, m)) < 0.6
    for together in (assignment.TOGETHER, 1):
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(assignment, "TOGETHER", together)
            target, _ = assignment.centralized(bids, members, known=known)
        for b in range(9):
            rows = np.flatnonzero(members[b])
            expected = np.full(n, -1)
            if rows.size:
                expected[rows] = _over_known(bids[b, rows], known[b])
            assert np.array_equal(target[b], expected)


def test_greedy_takes_only_a_known_column():
    bids = np.array([[3.0, 1.0, 2.0], [0.0, 0.0, 0.0]])
    known = np.array([[False, True, True], [False, False, False]])
    assert assignment.greedy(bids, known).tolist() == [2, -1]
    assert assignment.greedy(bids).tolist() == [0, 0]


def test_assignment_and_planning_read_no_clock():
    """Timing belongs to the caller: the maths imports neither `time` nor `timing`."""
    import ast
    from pathlib import Path

    import uavtrack

    root = Path(uavtrack.__file__).parent
    for module in ("assignment.py", "planning.py"):
        imported = set()
        for node in ast.walk(ast.parse((root / module).read_text())):
            if isinstance(node, ast.Import):
                imported |= {alias.name.split(".")[-1] for alias in node.names}
            elif isinstance(node, ast.ImportFrom):
                imported.add((node.module or "").split(".")[-1])
                imported |= {alias.name for alias in node.names}
        assert not imported & {"time", "timing"}, (module, imported & {"time", "timing"})


class Recording:
    """`timing` with a count of the set-ups entered."""

    def __init__(self):
        from uavtrack import timing

        self.timing, self.set_ups = timing, 0

    def start(self):
        return self.timing.start()

    def since(self, mark):
        return self.timing.since(mark)

    def tick(self):
        return self.timing.tick()

    def set_up(self):
        self.set_ups += 1
        return self.timing.set_up()


def test_the_drivers_time_on_the_callers_clock_and_without_one_give_zeros(monkeypatch):
    from uavtrack import timing

    rng = np.random.default_rng(3)
    bids = rng.integers(0, 3, (10, 5, 4)).astype(float)  # ties: the exact solver decides
    members = rng.random((10, 5, 5)) < 0.6
    members |= members.transpose(0, 2, 1)
    for together in (assignment.TOGETHER, 1):
        monkeypatch.setattr(assignment, "TOGETHER", together)
        timed, seconds = assignment.auction(bids, members, clock=timing)
        untimed, zeros = assignment.auction(bids, members, clock=None)
        assert np.array_equal(timed, untimed)
        assert seconds.shape == zeros.shape == (10, 5, 2)
        assert (seconds >= 0).all() and seconds.sum() > 0 and not zeros.any()
        timed, seconds = assignment.centralized(bids, clock=timing)
        untimed, zeros = assignment.centralized(bids)
        assert np.array_equal(timed, untimed) and seconds.sum() > 0 and not zeros.any()
    for me in range(5):
        mine = assignment.local(bids[0], me, clock=None)
        assert mine == assignment.local(bids[0], me, clock=timing)
    # small problems never load scipy's solver; a large one's first load is set-up on
    # the caller's clock, no decision's time
    monkeypatch.setattr(assignment, "_SOLVER", [])
    clock = Recording()
    assignment.auction(bids, members, clock=clock)
    assert clock.set_ups == 0 and not assignment._SOLVER
    large = rng.integers(0, 3, (1, 20, 20)).astype(float)
    assignment.auction(large, np.ones((1, 20, 20), dtype=bool), clock=clock)
    assignment.auction(large, np.ones((1, 20, 20), dtype=bool), clock=clock)
    assert clock.set_ups == 1 and len(assignment._SOLVER) == 1


def test_the_auction_on_lists_decides_as_the_arrays_do(monkeypatch):
    """A few UAVs' auction runs on Python lists (`assignment.FEW`); the same problems on
    the array path give the same targets, ties and unscored (NaN) bids included, and
    the same refusal when a problem lacks the bids it needs."""
    rng = np.random.default_rng(11)
    compared = refused = 0
    for t in range(1500):
        B, n, m = int(rng.integers(1, 3)), int(rng.integers(1, 9)), int(rng.integers(1, 9))
        if t % 3 == 0:
            bids = rng.integers(0, 3, (B, n, m)).astype(float)  # ties everywhere
        else:
            bids = rng.random((B, n, m))
        if t % 5 == 0:
            bids[rng.random((B, n, m)) < 0.2] = np.nan
        members = rng.random((B, n, n)) < 0.5
        members |= members.transpose(0, 2, 1)
        out = []
        for few in (0, assignment.FEW):
            monkeypatch.setattr(assignment, "FEW", few)
            try:
                out.append(assignment.auction(bids, members)[0])
            except ValueError:
                out.append(None)
        monkeypatch.undo()
        if out[0] is None or out[1] is None:
            assert out[0] is None and out[1] is None
            refused += 1
        else:
            assert np.array_equal(out[0], out[1])
            compared += 1
    assert compared > 1000 and refused > 20
