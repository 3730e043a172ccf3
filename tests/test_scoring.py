"""Tracks scored against the truth (uavtrack.tracks.scoring): GOSPA and SIAP against Stone
Soup, switches, fragmentations and times to confirm against their definitions step by
step, and the NEES of the matched tracks."""

import datetime

import numpy as np
import pytest
from scipy import stats

from uavtrack import estimation
from uavtrack.metrics import NEES_BINS_PER_DECADE, gospa, ospa
from uavtrack.tracks.scoring import (
    TRACK_METRICS,
    TrackScore,
    confirm_clock,
    gospa_assignment,
    label_changes,
    label_purity,
    matched_nees,
    nearest_truth,
    ospa2,
    team_picture,
    unassigned_kinds,
    window_tracks,
)

stonesoup = pytest.importorskip("stonesoup")
from stonesoup.dataassociator.tracktotrack import TrackToTruth  # noqa: E402
from stonesoup.measures import Euclidean  # noqa: E402
from stonesoup.metricgenerator.manager import MultiManager  # noqa: E402
from stonesoup.metricgenerator.ospametric import GOSPAMetric  # noqa: E402
from stonesoup.metricgenerator.tracktotruthmetrics import SIAPMetrics  # noqa: E402
from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState  # noqa: E402
from stonesoup.types.state import State  # noqa: E402
from stonesoup.types.track import Track  # noqa: E402

NOW = datetime.datetime(2026, 1, 1)
FAR = 1e4  # a track this far from everything is matched to nothing


def states(points, t=NOW):
    return [State(np.asarray(x, dtype=float).reshape(-1, 1), timestamp=t) for x in points]


def random_rows(rng, P, Nt, K, scale=30.0):
    X = rng.uniform(0, scale, (P, Nt, 2))
    # tracks near truths, some far: matched, cut and false ones
    Y = rng.uniform(0, scale, (P, K, 2))
    near = rng.integers(0, max(Nt, 1), (P, K))
    close = rng.random((P, K)) < 0.6
    if Nt:
        Y = np.where(
            close[..., None], X[np.arange(P)[:, None], near] + rng.normal(0, 3, Y.shape), Y
        )
    present = rng.random((P, Nt)) < 0.8
    confirmed = rng.random((P, K)) < 0.7
    # what absent truths and unconfirmed slots hold must not matter
    X = np.where(present[..., None], X, np.nan)
    Y = np.where(confirmed[..., None], Y, np.inf)
    return X, present, Y, confirmed


@pytest.mark.parametrize("p", [1.0, 2.0, 3.0])
@pytest.mark.parametrize(("Nt", "K"), [(3, 5), (4, 10), (6, 3), (0, 4), (5, 0)])
def test_gospa_and_its_assignment_equal_stone_soups(p, Nt, K):
    rng = np.random.default_rng(int(p) * 100 + Nt * 10 + K)
    P = 30
    X, present, Y, confirmed = random_rows(rng, P, Nt, K)
    c = rng.uniform(2.0, 20.0)
    assigned, ours = gospa_assignment(X, present, Y, confirmed, c, p)
    assert assigned.shape == (P, Nt)
    for r in range(P):
        truths, slots = np.flatnonzero(present[r]), np.flatnonzero(confirmed[r])
        if not len(truths) and not len(slots):  # Stone Soup needs a state for a time
            assert ours.distance[r] == 0 and (assigned[r] == -1).all()
            continue
        metric, theirs = GOSPAMetric(c=c, p=p).compute_gospa_metric(
            states(Y[r, slots]), states(X[r, truths])
        )
        value = metric.value
        assert ours.distance[r] == pytest.approx(value["distance"], abs=1e-9)
        for part in ("localisation", "missed", "false"):
            assert getattr(ours, part)[r] == pytest.approx(value[part], abs=1e-9), part
        # the same pairs (random points: the optimal assignment is unique)
        expected = np.full(Nt, -1)
        for i, j in zip(truths, list(theirs) or [-1] * len(truths), strict=True):
            expected[i] = slots[j] if j >= 0 else -1
        assert np.array_equal(assigned[r], expected)
        pairs = truths[assigned[r, truths] >= 0]
        assert (np.linalg.norm(X[r, pairs] - Y[r, assigned[r, pairs]], axis=-1) < c).all()


def test_without_masks_it_is_the_metrics_gospa(rng):
    X, Y = rng.uniform(0, 40, (20, 5, 2)), rng.uniform(0, 40, (20, 8, 2))
    _, ours = gospa_assignment(X, np.ones((20, 5), bool), Y, np.ones((20, 8), bool), 10.0, 2.0)
    reference = gospa(X, Y, 10.0, 2.0)
    for part in ("distance", "localisation", "missed", "false"):
        assert getattr(ours, part) == pytest.approx(getattr(reference, part), rel=1e-12), part


def test_siap_equals_stone_soups_over_several_steps():
    """Three targets (one appears late, one leaves early) and tracks that follow them,
    duplicate one, wander off, are deleted and reborn in another slot; Stone Soup's SIAP
    with TrackToTruth at the same threshold, one step to start or end an association."""
    rng = np.random.default_rng(7)
    T, Nt, K, threshold = 12, 3, 5, 4.0
    X = np.cumsum(rng.normal(0, 1.5, (T, Nt, 2)), axis=0) + np.array([[0, 0], [15, 0], [0, 15]])
    present = np.ones((T, Nt), bool)
    present[:3, 2] = False
    present[9:, 1] = False
    # (label, slot, first step, last step, target followed or None, noise)
    lives = [
        (10, 0, 0, 11, 0, 1.0),
        (11, 1, 1, 8, 1, 1.5),
        (12, 2, 2, 6, 0, 2.0),  # a duplicate of target 0
        (13, 3, 0, 4, None, 0.0),  # a false track
        (14, 2, 8, 11, 2, 1.0),  # slot 2 reused
        (15, 4, 4, 11, 1, 6.0),  # often beyond the threshold, and on after its target left
    ]
    tracks = np.full((T, K, 2), np.nan)
    labels = np.full((T, K), -1)
    confirmed = np.zeros((T, K), bool)
    paths = []
    for label, slot, first, last, target, noise in lives:
        steps = np.arange(first, last + 1)
        if target is None:
            where = rng.uniform(-20, 40, (len(steps), 2))
        else:
            where = X[steps, target] + rng.normal(0, noise, (len(steps), 2))
        tracks[steps, slot], labels[steps, slot], confirmed[steps, slot] = where, label, True
        times = [NOW + datetime.timedelta(seconds=int(k)) for k in steps]
        paths.append(Track([s for w, t in zip(where, times, strict=True) for s in states([w], t)]))
    truths = [
        GroundTruthPath(
            [
                GroundTruthState(
                    X[k, i].reshape(2, 1), timestamp=NOW + datetime.timedelta(seconds=k)
                )
                for k in range(T)
                if present[k, i]
            ]
        )
        for i in range(Nt)
    ]
    score = TrackScore(batch=1, rows=1, n_targets=Nt, cutoff=10.0, threshold=threshold)
    for k in range(T):
        score.add(
            truth=X[k][None],
            present=present[k][None],
            tracks=tracks[k][None],
            labels=labels[k][None],
            confirmed=confirmed[k][None],
            in_view=present[k][None],
        )
    ours = score.summary()
    siap = SIAPMetrics(position_measure=Euclidean((0, 1)), velocity_measure=Euclidean((0, 1)))
    associator = TrackToTruth(
        association_threshold=threshold, consec_pairs_confirm=1, consec_misses_end=1
    )
    manager = MultiManager([siap], associator)
    manager.add_data({"groundtruth_paths": set(truths), "tracks": set(paths)})
    theirs = {m.title: m.value for m in manager.generate_metrics()["siap_generator"].values()}
    assert 0 < ours["siap_completeness"][0] < 1 and ours["siap_ambiguity"][0] > 1
    assert 0 < ours["siap_spuriousness"][0] < 1
    for name in ("Completeness", "Ambiguity", "Spuriousness"):
        key = f"siap_{name.lower()}"
        assert ours[key][0] == pytest.approx(theirs[f"SIAP {name}"], rel=1e-12), name


def test_the_siap_association_is_the_nearest_truth_within_the_threshold():
    X = np.array([[[0.0, 0.0], [4.0, 0.0], [50.0, 0.0]]])
    Y = np.array([[[1.0, 0.0], [2.9, 0.0], [3.0, 3.0], [48.0, 0.0], [20.0, 0.0]]])
    present = np.array([[True, True, False]])
    nearest = nearest_truth(X, present, Y, np.ones((1, 5), bool), threshold=3.0)
    # (3, 3) is 3.16 from truth 1: out; (48, 0) is near truth 2, which is absent
    assert nearest.tolist() == [[0, 1, -1, -1, -1]]


def reference_changes(labels, present, in_view):
    """Switches and fragmentations by their definitions, one target at a time."""
    T, Nt = labels.shape
    switches = fragments = 0
    for i in range(Nt):
        last = None
        for k in range(T):
            if labels[k, i] >= 0:
                switches += last is not None and labels[k, i] != last
                last = labels[k, i]
            elif k > 0 and labels[k - 1, i] >= 0 and present[k, i] and in_view[k, i]:
                fragments += 1
    return switches, fragments


def test_switches_and_fragmentations_follow_their_definitions(rng):
    T, Nt = 40, 6
    for _ in range(20):
        labels = np.where(rng.random((T, Nt)) < 0.7, rng.integers(0, 3, (T, Nt)), -1)
        present = rng.random((T, Nt)) < 0.9
        labels = np.where(present, labels, -1)
        in_view = rng.random((T, Nt)) < 0.6
        last, was = np.full(Nt, -1), np.zeros(Nt, bool)
        switches = fragments = 0
        for k in range(T):
            s, f = label_changes(labels[k], last, was, present[k], in_view[k])
            switches, fragments = switches + s.sum(), fragments + f.sum()
            last, was = np.where(labels[k] >= 0, labels[k], last), labels[k] >= 0
        assert (switches, fragments) == reference_changes(labels, present, in_view)


def test_the_clock_of_a_target_found_anew():
    # target 0: in view from step 2, matched from 5: 3 steps; lost at 7, matched again at
    # 8: 1 step; target 1: matched before it is ever in view without a track (the team
    # knew it): no time; target 2: found at 6, never matched
    T = 9
    matched = np.zeros((T, 3), bool)
    matched[5:, 0] = matched[0:, 1] = True
    matched[7, 0] = False
    in_view = np.zeros((T, 3), bool)
    in_view[2:, 0] = in_view[3:, 1] = in_view[6:, 2] = True
    start, times = np.full(3, -1), []
    for k in range(T):
        start, time = confirm_clock(k, start, matched[k], np.ones(3, bool), in_view[k])
        times += [(k, i, t) for i, t in enumerate(time) if t >= 0]
    assert times == [(5, 0, 3), (8, 0, 1)]
    assert start.tolist() == [-1, -1, 6]


def place(X, follow, K):
    """Track positions: slot j on truth follow[j] (-1: far from everything)."""
    Y = np.full(X.shape[:-2] + (K, 2), FAR)
    for j, i in enumerate(follow):
        if i >= 0:
            Y[..., j, :] = X[..., i, :] + 0.5
    return Y


def test_the_accumulator_per_row_and_per_trial():
    """Two trials of two UAVs: the scores of each row by hand, a trial the mean of its rows,
    a failed UAV's steps counted in nothing."""
    Nt, K, c = 2, 4, 10.0
    X = np.array([[0.0, 0.0], [100.0, 0.0]])
    score = TrackScore(batch=2, rows=2, n_targets=Nt, cutoff=c)
    # per step and row: the truth each slot follows (-1 far), its labels, the confirmed slots
    plans = {
        # row 0: target 0 by label 1, then 2 (a switch), lost at step 3 in view (a
        # fragmentation); target 1 never followed; a false track at step 1
        0: [([0, -1, -1, -1], [1, -1, -1, -1]), ([0, -1, -1, -1], [1, -1, 9, -1]),
            ([0, -1, -1, -1], [2, -1, -1, -1]), ([-1, -1, -1, -1], [-1, -1, -1, -1])],
        # row 1: both targets by one track each, plus a duplicate of target 1 throughout
        1: [([0, 1, 1, -1], [3, 4, 5, -1])] * 4,
        # row 2: nothing confirmed; row 3: target 0 followed, then the UAV fails at step 2
        2: [([-1, -1, -1, -1], [-1, -1, -1, -1])] * 4,
        3: [([0, -1, -1, -1], [6, -1, -1, -1])] * 2 + [([-1, -1, -1, -1], [7, -1, -1, -1])] * 2,
    }  # fmt: skip
    in_view = np.ones((4, Nt), bool)
    in_view[:, 1] = False  # target 1 never in view: never new
    for k in range(4):
        follow = np.array([plans[r][k][0] for r in range(4)])
        labels = np.array([plans[r][k][1] for r in range(4)])
        tracks = np.stack([place(X, f, K) for f in follow])
        alive = np.array([True, True, True, k < 2])
        score.add(
            truth=np.broadcast_to(X, (4, Nt, 2)),
            tracks=tracks,
            labels=labels,
            confirmed=labels >= 0,
            in_view=in_view,
            alive=alive,
        )
    s = score.summary()
    half = c / 2  # c^p / 2 at p = 1
    loc = np.hypot(0.5, 0.5)
    rows = {
        "gospa": [
            np.mean([loc + half, loc + 2 * half, loc + half, 2 * half]),
            2 * loc + half,
            2 * half,
            loc + half,
        ],
        "gospa_false": [half / 4, half, 0.0, 0.0],
        "gospa_missed": [np.mean([half, half, half, 2 * half]), 0.0, 2 * half, half],
        "switches": [100 * 1 / 8, 0.0, 0.0, 0.0],
        "fragmentations": [100 * 1 / 8, 0.0, 0.0, 0.0],
        "unassigned_tracks": [1 / 4, 1.0, 0.0, 0.0],
        "unassigned_tracks_per_target": [1 / 8, 1 / 2, 0.0, 0.0],
        # row 0's label 9 never followed a target; row 1's second track of target 1
        "duplicate_tracks": [0.0, 1 / 2, 0.0, 0.0],
        "stale_tracks": [0.0, 0.0, 0.0, 0.0],
        "never_tracks": [1 / 8, 0.0, 0.0, 0.0],
        "never_tracks_new": [100 / 4, 0.0, 0.0, 0.0],
        "siap_completeness": [3 / 8, 1.0, 0.0, 1 / 2],
        "siap_ambiguity": [1.0, 3 / 2, np.nan, 1.0],
        "siap_spuriousness": [1 / 4, 0.0, np.nan, 0.0],
    }
    for name, values in rows.items():
        expected = [np.nanmean(values[:2]), np.nanmean(values[2:])]
        assert s[name] == pytest.approx(expected, rel=1e-12, abs=1e-12), name
    # row 0 loses target 0 in view at step 3 and row 2 never confirms it: each a clock
    # still running at the end; rows 1 and 3 hold their targets in view throughout
    assert np.isnan(s["time_to_confirm"]).all()
    assert s["never_confirmed"].tolist() == [1.0, 1.0]
    assert set(s) == set(TRACK_METRICS)


def test_the_nees_of_the_matched_tracks(rng):
    B, rows, Nt, K, T = 2, 3, 4, 7, 300
    score = TrackScore(batch=B, rows=rows, n_targets=Nt, cutoff=30.0)
    samples = [[] for _ in range(B)]
    for _ in range(T):
        # targets 100 m apart, tracks a few metres off: each track on its own target
        where = rng.uniform(0, 20, (B * rows, Nt, 2)) + 100.0 * np.arange(Nt)[:, None]
        states = np.concatenate([where, rng.normal(0, 2, (B * rows, Nt, 2))], -1)
        A = rng.normal(size=(B * rows, K, 4, 4))
        cov = A @ np.swapaxes(A, -1, -2) + 0.5 * np.eye(4)
        follow = rng.permutation(K)[:Nt]  # slot follow[i] on target i, the rest empty
        error = (np.linalg.cholesky(cov) @ rng.normal(size=(B * rows, K, 4, 1)))[..., 0]
        mean = np.full((B * rows, K, 4), np.nan)
        mean[:, follow] = states - error[:, follow]
        confirmed = ~np.isnan(mean[..., 0])
        confirmed[0, follow[0]] = False  # a tentative track is not scored
        score.add(
            truth=states[..., :2],
            tracks=mean[..., :2],
            labels=np.tile(np.arange(K), (B * rows, 1)),
            confirmed=confirmed,
            in_view=np.ones((B * rows, Nt), bool),
            mean=mean,
            cov=np.where(confirmed[..., None, None], cov, np.nan),
            states=states,
        )
        assigned, _ = gospa_assignment(
            states[..., :2], np.ones((B * rows, Nt), bool), mean[..., :2], confirmed, 30.0
        )
        q = estimation.nees(mean[:, follow], cov[:, follow], states)
        ok = assigned == follow  # every confirmed track is on its target (errors of a few m)
        assert ok.sum() == B * rows * Nt - 1
        both = matched_nees(assigned, mean, cov, states)
        assert both[ok] == pytest.approx(q[ok], rel=1e-12) and np.isnan(both[~ok]).all()
        for b in range(B):
            samples[b].extend(q[b * rows : (b + 1) * rows][ok[b * rows : (b + 1) * rows]])
    s = score.summary()
    resolution = 10 ** (1 / (2 * NEES_BINS_PER_DECADE))
    low, high = stats.chi2.ppf([0.025, 0.975], 4)
    for b in range(B):
        q = np.array(samples[b])
        assert s["nees"][b] == pytest.approx(q.mean(), rel=1e-12)
        assert 1 / resolution <= s["nees_median"][b] / np.median(q) <= resolution
        assert s["nees_inside"][b] * len(q) == pytest.approx(np.sum((q >= low) & (q <= high)))
        lo, hi = stats.binom.interval(0.99, len(q), 0.95)
        assert lo / len(q) <= s["nees_inside"][b] <= hi / len(q)


def test_inputs_of_the_wrong_shape_are_refused():
    score = TrackScore(batch=1, rows=2, n_targets=3)
    good = dict(
        truth=np.zeros((2, 3, 2)),
        tracks=np.zeros((2, 4, 2)),
        labels=np.zeros((2, 4), int),
        confirmed=np.ones((2, 4), bool),
        in_view=np.ones((2, 3), bool),
    )
    with pytest.raises(ValueError, match="truth must be"):
        score.add(**(good | {"truth": np.zeros((1, 3, 2))}))
    with pytest.raises(ValueError, match="labels and confirmed"):
        score.add(**(good | {"labels": np.zeros((2, 5), int)}))
    score.add(**good)
    assert score.steps == 1


def test_unassigned_tracks_split_into_duplicates_stale_and_never_followed():
    """Three unassigned tracks of one row: a second track on a followed target, a track
    that followed a target before and is now off it, and one that never followed any."""
    assigned = np.array([[0, -1]])  # target 0 held by slot 0; target 1 by none
    nearest = np.array([[0, 0, -1, -1, 1]])  # slot 1 sits on target 0 too; slot 4 near 1
    confirmed = np.array([[True, True, True, True, True]])
    before = np.array([[True, False, True, False, False]])
    duplicate, stale, never = unassigned_kinds(assigned, nearest, confirmed, before)
    assert duplicate.tolist() == [[False, True, False, False, False]]
    assert stale.tolist() == [[False, False, True, False, False]]
    # slot 4 is near target 1, which nothing holds: not a duplicate, never followed
    assert never.tolist() == [[False, False, False, True, True]]


def test_the_team_picture_takes_each_labels_most_confident_confirmed_track():
    labels = np.array([[[4, 7, -1], [7, 4, 9]]])  # one trial, two UAVs, three slots
    confirmed = np.array([[[True, True, False], [True, True, False]]])
    tracks = np.arange(12.0).reshape(1, 2, 3, 2)
    gamma = np.array([[[1.0, 5.0, 9.0], [2.0, 1.0, 9.0]]])  # 4: a tie, UAV 0 first
    label, where, held = team_picture(labels, confirmed, tracks, gamma)
    assert label[0, held[0]].tolist() == [4, 7] and held.sum() == 2  # 9 is not confirmed
    np.testing.assert_array_equal(where[0, :2], [tracks[0, 0, 0], tracks[0, 0, 1]])


def test_label_purity_counts_the_uavs_that_carry_the_majority_label():
    # one trial, four UAVs, two targets: target 0 held as 5, 5, 8 and unmatched (3 of 3
    # pairs matched, 2 agree); target 1 as 6 by two UAVs, 2 unmatched (2 of 2 agree)
    label = np.array([[[5, 6], [5, -1], [8, 6], [-1, -1]]])
    agreeing, matched = label_purity(label)
    assert agreeing.tolist() == [4] and matched.tolist() == [5]


def brute_ospa2(X, xe, Y, ye, c, p):
    """OSPA(2) of one row by its definition (Beard, Vo and Vo 2020), every matching tried."""
    import itertools

    xs = [a for a in range(X.shape[1]) if xe[:, a].any()]
    ys = [b for b in range(Y.shape[1]) if ye[:, b].any()]

    def base(a, b):
        steps = [t for t in range(X.shape[0]) if xe[t, a] or ye[t, b]]
        total = sum(
            min(c, float(np.linalg.norm(X[t, a] - Y[t, b]))) if xe[t, a] and ye[t, b] else c
            for t in steps
        )
        return total / len(steps)

    if not xs and not ys:
        return 0.0
    small, large, d = (xs, ys, base) if len(xs) <= len(ys) else (ys, xs, lambda a, b: base(b, a))
    best = min(
        sum(d(a, b) ** p for a, b in zip(small, chosen, strict=True))
        for chosen in itertools.permutations(large, len(small))
    )
    return ((best + c**p * (len(large) - len(small))) / len(large)) ** (1 / p)


@pytest.mark.parametrize("p", [1.0, 2.0])
def test_ospa2_equals_its_definition(rng, p):
    """Random windows of tracks that come and go: the vectorised OSPA(2) equals the
    definition with every matching tried."""
    c, w = 10.0, 5
    for _ in range(30):
        m, n = rng.integers(0, 4, 2)
        X = rng.uniform(0, 25, (w, 1, m, 2))
        Y = rng.uniform(0, 25, (w, 1, n, 2))
        xe, ye = rng.random((w, 1, m)) < 0.7, rng.random((w, 1, n)) < 0.7
        got = ospa2(X, xe, Y, ye, c, p)[0]
        assert got == pytest.approx(brute_ospa2(X[:, 0], xe[:, 0], Y[:, 0], ye[:, 0], c, p))


def test_ospa2_of_one_step_is_ospa(rng):
    """A window of one step: each track is a point, and OSPA(2) is OSPA."""
    for _ in range(20):
        m, n = rng.integers(0, 5, 2)
        X, Y = rng.uniform(0, 30, (m, 2)), rng.uniform(0, 30, (n, 2))
        got = ospa2(
            X[None, None], np.ones((1, 1, m), bool), Y[None, None], np.ones((1, 1, n), bool),
            10.0, 2.0,
        )[0]  # fmt: skip
        assert got == pytest.approx(ospa(X, Y, 10.0, 2.0), abs=1e-12)


def test_window_tracks_gives_each_key_of_a_row_a_column():
    keys = np.array([[[5, 7], [1, 0]], [[7, 9], [1, 0]]])  # (w 2, P 2, M 2)
    exists = np.array([[[True, True], [True, False]], [[True, True], [True, False]]])
    positions = np.arange(16.0).reshape(2, 2, 2, 2)
    where, held = window_tracks(keys, exists, positions)
    # row 0: keys 5, 7, 9 -> columns 0, 1, 2; row 1: key 1 -> column 0
    assert held[:, 0].tolist() == [[True, True, False], [False, True, True]]
    assert held[:, 1].tolist() == [[True, False, False], [True, False, False]]
    assert where[1, 0, 1].tolist() == positions[1, 0, 0].tolist()  # key 7 moved slot


def test_a_label_switch_costs_in_ospa2_and_not_in_gospa():
    """One target followed exactly, by label 1 for 5 steps and label 2 for 5: over a
    window of 10 steps the truth matches one label half the time (c/2) and the other is
    left over (c), so OSPA(2) = (c/2 + c) / 2; windows of 5 see one label each: 0."""
    c = 10.0
    for window, expected in ((10, 0.75 * c), (5, 0.0)):
        score = TrackScore(batch=1, rows=1, n_targets=1, cutoff=c, window=window)
        for k in range(10):
            score.add(
                truth=np.zeros((1, 1, 2)), tracks=np.zeros((1, 1, 2)),
                labels=np.array([[1 if k < 5 else 2]]), confirmed=np.ones((1, 1), bool),
                in_view=np.ones((1, 1), bool),
            )  # fmt: skip
        s = score.summary()
        assert s["gospa"][0] == 0.0
        assert s["ospa2"][0] == pytest.approx(expected, abs=1e-12)


def test_the_team_clock_stops_at_any_uavs_confirmed_track():
    """One target and two UAVs: found by UAV 0 at step 0, confirmed by UAV 1 at step 2
    (2 steps); found again at 3, confirmed by UAV 0 at 4 (1 step); found at 6 and gone
    at 7 before anyone confirms it (no time). The team's median: 1.5."""
    held = {2: 1, 4: 0, 5: 0}  # step -> the UAV whose confirmed track is on the target
    score = TrackScore(batch=1, rows=2, n_targets=1, cutoff=10.0)
    for k in range(9):
        labels = np.full((2, 1), -1)
        if k in held:
            labels[held[k], 0] = 3
        in_view = np.array([[k in (0, 1, 3, 6)], [False]])
        score.add(
            truth=np.zeros((2, 1, 2)), present=np.full((2, 1), k != 7),
            tracks=np.zeros((2, 1, 2)), labels=labels, confirmed=labels >= 0,
            in_view=in_view,
        )  # fmt: skip
    assert score.summary()["time_to_confirm_team"][0] == pytest.approx(1.5)


def test_reading_the_scores_mid_run_changes_nothing(rng):
    """summary() part way (as an environment's render does) leaves the windows of OSPA(2)
    whole, and arrays the caller reuses after a step do not reach the windows held."""
    P, Nt, K, steps = 4, 3, 5, 23
    frames = [random_rows(rng, P, Nt, K) for _ in range(steps)]
    labels = rng.integers(0, 6, (steps, P, K))

    def scored(peek, reuse):
        score = TrackScore(batch=2, rows=2, n_targets=Nt, cutoff=10.0)
        buffers = [np.empty_like(a) for a in (frames[0][0], frames[0][2], labels[0])]
        for k, (X, present, Y, confirmed) in enumerate(frames):
            X, Y, lab = np.nan_to_num(X), np.where(confirmed[..., None], Y, 0.0), labels[k]
            if reuse:  # the same arrays, overwritten each step
                for buffer, value in zip(buffers, (X, Y, lab), strict=True):
                    buffer[...] = value
                X, Y, lab = buffers
            score.add(
                truth=X, present=present, tracks=Y, labels=lab, confirmed=confirmed,
                in_view=np.ones((P, Nt), bool),
            )  # fmt: skip
            if peek and k in (4, 13):
                score.summary()
        return score.summary()["ospa2"]

    plain = scored(False, False)
    assert np.array_equal(scored(True, False), plain)
    assert np.array_equal(scored(False, True), plain)
