"""Tracks scored against the truth: GOSPA and its parts, track switches and
fragmentations, false tracks, the time to confirm a new target, SIAP completeness,
ambiguity and spuriousness, and the NEES of the tracks that follow a target.

A row (P rows) is one UAV of one trial: its confirmed tracks are scored against the
trial's targets, and a trial's value is the mean over its rows. Per step a row gives the
true positions X (P, Nt, 2) with `present` (P, Nt), and its track positions Y (P, K, 2),
`labels` (P, K) and `confirmed` (P, K); only present truths and confirmed tracks take
part. Two associations of tracks with truths serve, each the one its metrics are
defined with:

* **the GOSPA assignment** (Rahmathullah, Garcia-Fernandez and Svensson 2017, alpha = 2):
  the one-to-one assignment of least GOSPA cost; a track assigned to a truth closer than
  the cut-off c is *matched* to it. GOSPA, false tracks, switches, fragmentations, the
  time to confirm and the NEES read it.
* **the SIAP association** (Votruba et al. 2001): at each step, each track to its
  nearest truth closer than a threshold, so that several tracks may follow one truth,
  which the ambiguity counts; nothing is carried from step to step.

Against Stone Soup: GOSPA, its parts and its assignment are those of ``GOSPAMetric``
(same c and p, alpha = 2) without its switching term (``switching_penalty`` = 0; switches
are counted apart here). Completeness, ambiguity and spuriousness are ``SIAPMetrics``'s,
per UAV and then averaged over the UAVs, given the association above: a
``TimeRangeAssociation`` per run of steps a track keeps one truth, from its first step to
its last plus a microsecond (a test holds them equal to 1e-12 on a tracked run).
Stone Soup's own ``TrackToTruth`` cannot stand in: at ``consec_pairs_confirm =
consec_misses_end = 1`` it makes the same associations but raises ValueError on one
that lasts a single step (its ``TimeRange`` asks start < end), and at its defaults (3
steps in a row to start an association, 2 to end one, an association kept across the
steps a track is absent) it associates otherwise, which moves the three numbers in the
second decimal.
"""

# Strict typing less the rules metrics.py turns off, for the same reasons: numpy resolves
# calls with arguments of shape tuple[Any, ...] to Unknown; point sets keep their capital
# names (X, Y) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportConstantRedefinition=false

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..airspace.separation import NAMES as SEPARATION
from ..airspace.separation import Separation
from ..config import Scenario
from ..estimation import confidence, nees
from ..metrics import GOSPA, METRICS, PER_UAV_SETS, NeesSpread, Tally, cut_costs, matching, mean_std
from ..records import RECORDED, Cycle, Result, Trace
from ..world import present as targets_present

TRACK_METRICS: dict[str, tuple[str, str]] = {
    "gospa": ("m", "GOSPA distance (alpha = 2) of the row's confirmed tracks, mean per step"),
    **{
        name: METRICS[name]
        for name in (
            "gospa_localisation",
            "gospa_missed",
            "gospa_false",
            "switches",
            "fragmentations",
            "unassigned_tracks",
            "unassigned_tracks_per_target",
            "duplicate_tracks",
            "stale_tracks",
            "never_tracks",
            "never_tracks_new",
            "gospa_team",
            "label_purity",
            "ospa2",
            "ospa2_team",
            "time_to_confirm",
            "time_to_confirm_team",
            "never_confirmed",
            "siap_completeness",
            "siap_ambiguity",
            "siap_spuriousness",
        )
    },  # fmt: skip
    "nees": ("", "mean NEES of the confirmed tracks matched to a truth (4 when consistent)"),
    "nees_median": ("", "its median, as metrics.NeesSpread reads it (3.36 when consistent)"),
    "nees_inside": ("", "its fraction inside the 95 % chi-square(4) interval (0.95)"),
}
"""`TrackScore.summary`'s metrics: name -> (unit, meaning); see the functions for the
definitions."""


def gospa_assignment(
    X: np.ndarray,
    present: np.ndarray,
    Y: np.ndarray,
    confirmed: np.ndarray,
    c: float,
    p: float = 1.0,
) -> tuple[np.ndarray, GOSPA]:
    """The GOSPA assignment of confirmed tracks Y (..., K, 2) to present truths X (..., Nt, 2)
    and the GOSPA distance with its parts (each (...)), alpha = 2.

    GOSPA^p = min over assignments gamma of sum over (i, j) in gamma of d_ij^p
    + c^p / 2 (m + n - 2 |gamma|) (m present truths, n confirmed tracks, pairs closer than
    c): localisation + missed + false, the parts of `uavtrack.metrics.gospa`. It is solved
    as one square assignment of size max(Nt, K) (`metrics.matching`) whose costs are
    min(d, c)^p between a truth and a track, c^p / 2 between either and a place holder
    (an absent truth, an unconfirmed slot, the padding) and 0 between place holders: a
    truth and a track c or more apart cost c^p, the same as both left alone, so the least
    cost is GOSPA^p. Returns `assigned` (..., Nt), the slot matched to each truth (closer
    than c; -1 for none), and the GOSPA record.
    """
    present, confirmed = np.asarray(present, dtype=bool), np.asarray(confirmed, dtype=bool)
    # absent truths and unconfirmed slots may hold anything: give them a finite place
    X = np.where(present[..., None], X, 0.0)
    Y = np.where(confirmed[..., None], Y, 0.0)
    cost, Nt, K = cut_costs(X, Y, c, p)  # (..., Nt, K): min(d, c)^p
    half, N = c**p / 2, max(Nt, K)
    truth, track = present[..., :, None], confirmed[..., None, :]
    full = np.zeros(cost.shape[:-2] + (N, N))
    full[..., :Nt, :K] = np.where(truth & track, cost, np.where(truth ^ track, half, 0.0))
    full[..., Nt:, :K] = np.where(track, half, 0.0)
    full[..., :Nt, K:] = np.where(truth, half, 0.0)
    # a truth given the padding reads column K, an unconfirmed stand-in
    slot = np.minimum(matching(full)[..., :Nt], K)  # (..., Nt)
    cost = np.concatenate([cost, np.full(cost.shape[:-1] + (1,), c**p)], axis=-1)
    confirmed_ = np.concatenate([confirmed, np.zeros(confirmed.shape[:-1] + (1,), bool)], -1)
    pair = np.take_along_axis(cost, slot[..., None], axis=-1)[..., 0]
    matched = present & np.take_along_axis(confirmed_, slot, axis=-1) & (pair < c**p)
    q = matched.sum(axis=-1)
    local = np.where(matched, pair, 0.0).sum(axis=-1)
    missed = half * (present.sum(axis=-1) - q)
    false = half * (confirmed.sum(axis=-1) - q)
    distance = (local + missed + false) ** (1.0 / p)
    return np.where(matched, slot, -1), GOSPA(distance, local, missed, false)


def nearest_truth(
    X: np.ndarray, present: np.ndarray, Y: np.ndarray, confirmed: np.ndarray, threshold: float
) -> np.ndarray:
    """The SIAP association: for each confirmed track Y (..., K, 2), the index of the
    nearest present truth X (..., Nt, 2) closer than `threshold` (strictly, as Stone Soup's
    ``TrackToTruth``; the lowest index on ties), -1 for none. Returns (..., K)."""
    X = np.where(present[..., None], X, 0.0)  # what absent ones hold does not matter
    Y = np.where(confirmed[..., None], Y, 0.0)
    diff = Y[..., :, None, :] - X[..., None, :, :]
    d = np.sqrt(np.einsum("...k,...k->...", diff, diff))  # (..., K, Nt)
    d = np.where(confirmed[..., :, None] & present[..., None, :], d, np.inf)
    if d.shape[-1] == 0:  # no truth at all
        return np.full(d.shape[:-1], -1, dtype=np.intp)
    nearest = np.argmin(d, axis=-1)
    close = np.take_along_axis(d, nearest[..., None], axis=-1)[..., 0] < threshold
    return np.where(close, nearest, -1)


def siap_counts(
    nearest: np.ndarray, present: np.ndarray, confirmed: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """SIAP's counts at one step from the association `nearest` (..., K) (Votruba et al.
    2001; Stone Soup's ``SIAPMetrics``): J truths, JT truths with an associated track,
    N confirmed tracks, NA associated tracks, each (...). Over steps, completeness is
    sum JT / sum J, ambiguity sum NA / sum JT and spuriousness (sum N - sum NA) / sum N."""
    Nt = present.shape[-1]
    followed = (nearest[..., :, None] == np.arange(Nt)).any(axis=-2) & present
    return (
        present.sum(axis=-1),
        followed.sum(axis=-1),
        confirmed.sum(axis=-1),
        ((nearest >= 0) & confirmed).sum(axis=-1),
    )


def unassigned_kinds(
    assigned: np.ndarray,
    nearest: np.ndarray,
    confirmed: np.ndarray,
    followed_before: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """GOSPA's unassigned confirmed tracks split as a tracking engineer reads them, each
    (..., K) bool: *duplicates*, whose nearest target within the cut-off (`nearest`,
    `nearest_truth`) is assigned to another track (a target followed twice); *stale*,
    the others whose label followed a target at an earlier step (`followed_before`,
    (..., K)); *never*, the rest, tracks that never followed a target (clutter-born, so
    far). assigned (..., Nt): the slot assigned to each target (-1: none), as
    `gospa_assignment` gives it."""
    K = confirmed.shape[-1]
    slot = np.arange(K)
    held = (assigned[..., None, :] == slot[:, None]).any(axis=-1)  # (..., K)
    unassigned = confirmed & ~held
    taken = np.take_along_axis(assigned, np.maximum(nearest, 0), axis=-1) >= 0
    duplicate = unassigned & (nearest >= 0) & taken
    stale = unassigned & ~duplicate & followed_before
    return duplicate, stale, unassigned & ~duplicate & ~followed_before


def team_picture(
    labels: np.ndarray, confirmed: np.ndarray, tracks: np.ndarray, gamma: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The team's picture: one track per team label, the confirmed track of that label
    held with the most confidence (1/trace P) by any UAV of the trial (the lowest UAV and
    slot on ties), as ``to_stonesoup(tracks="best")`` exports it. labels, confirmed, confidence
    (B, N, K) (a failed UAV's tracks not confirmed), tracks (B, N, K, 2). Returns (label
    (B, N K), position (B, N K, 2), held (B, N K)): each trial's labels first, padded."""
    B, N, K = labels.shape
    flat = labels.reshape(B, N * K)
    ok = confirmed.reshape(B, N * K)
    gamma = np.where(ok, gamma.reshape(B, N * K), -np.inf)
    key = np.where(ok, flat, np.iinfo(np.int64).max)
    order = np.lexsort((-gamma, key), axis=-1)  # by label, the most confident first
    key = np.take_along_axis(key, order, axis=-1)
    first = np.ones(key.shape, dtype=bool)
    first[:, 1:] = key[:, 1:] != key[:, :-1]
    first &= np.take_along_axis(ok, order, axis=-1)
    rank = np.argsort(~first, axis=-1, kind="stable")  # the picked ones first
    pick = np.take_along_axis(order, rank, axis=-1)
    held = np.take_along_axis(first, rank, axis=-1)
    position = np.take_along_axis(tracks.reshape(B, N * K, 2), pick[..., None], axis=1)
    return np.where(held, np.take_along_axis(flat, pick, axis=-1), -1), position, held


def label_purity(label: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each trial, the (UAV, target) pairs whose matched track carries the team's
    majority label for that target, and the pairs matched at all: label (B, N, Nt) the
    label of the track GOSPA matched to each target (-1: none). Ties between majority
    labels count once. Returns (agreeing (B,), matched (B,))."""
    B, N, Nt = label.shape
    lab = np.moveaxis(label, 1, -1).reshape(B * Nt, N)  # each (trial, target): its UAVs
    srt = np.sort(lab, axis=-1)
    # the longest run of one label >= 0 in each sorted row
    start = np.ones(srt.shape, dtype=bool)
    start[:, 1:] = srt[:, 1:] != srt[:, :-1]
    run_id = np.cumsum(start, axis=-1) - 1
    counts = np.zeros(srt.shape, dtype=np.int64)
    np.add.at(counts, (np.arange(srt.shape[0])[:, None], run_id), srt >= 0)
    agreeing = counts.max(axis=-1).reshape(B, Nt).sum(axis=-1)
    return agreeing, (label >= 0).sum(axis=(1, 2))


def label_changes(
    label: np.ndarray,
    last: np.ndarray,
    was_matched: np.ndarray,
    present: np.ndarray,
    in_view: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Switches and fragmentations of each target at one step, (..., Nt) booleans.

    `label` is the label of the track matched to each target now (-1: none), `last` the
    label last matched to it at any earlier step (-1: never), `was_matched` whether it
    was matched at the previous step.

    * A **switch** (a mismatch of CLEAR MOT, Bernardin and Stiefelhagen 2008, as
      py-motmetrics counts it): the target is matched to a label other than the one last
      matched to it, however many steps ago.
    * A **fragmentation**: the target was matched at the previous step and is not now,
      while present and in view of the row's UAV. It is MOT's "tracked to untracked"
      transition (Li, Huang and Nevatia 2009), counted when it happens, resumed or not,
      and only where the UAV could see the target (a target lost out of view is not
      a tracking failure of the UAV).
    """
    now = label >= 0
    switch = now & (last >= 0) & (label != last)
    fragment = was_matched & ~now & present & in_view
    return switch, fragment


def confirm_clock(
    k: int,
    start: np.ndarray,
    matched: np.ndarray,
    present: np.ndarray,
    in_view: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """One step of the time to confirm a target found anew, per (row, target).

    A target is *found anew* by a row at a step k0 at which it is present, in view of
    the row's UAV and matched to none of its confirmed tracks (a target the UAV meets for
    the first time, or one whose track it lost or let drift past the cut-off, whatever
    the briefing said); its time to confirm is k1 - k0 [steps], k1 the first step after
    k0 at which a confirmed track is matched to it (whether or not it is still in view).
    Every such episode is timed. A clock still running at the end gives no time:
    `TrackScore` counts it in `never_confirmed`.

    `start` (..., Nt) is the step its clock started (-1: not running). Returns the new
    start and the times (..., Nt) of the clocks stopped at step k (-1 elsewhere).
    """
    stop = (start >= 0) & matched
    time = np.where(stop, k - start, -1)
    begin = (start < 0) & present & in_view & ~matched
    return np.where(stop, -1, np.where(begin, k, start)), time


def window_tracks(
    keys: np.ndarray, exists: np.ndarray, positions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The tracks of each row over a window of w steps, one column per distinct key.

    keys (w, P, M) int in [0, 2^40) name each slot's track at each step (a label, or a
    target and its life), exists (w, P, M) whether it is there, positions (w, P, M, 2).
    Returns positions (w, P, L, 2) and exists (w, P, L), L the most keys of a row; a
    row's columns past its own keys never exist."""
    w, P, _ = keys.shape
    row = np.broadcast_to(np.arange(P, dtype=np.int64)[None, :, None], keys.shape)
    full = (row << LABEL_BITS) | np.asarray(keys, dtype=np.int64)
    t, r, m = np.nonzero(exists)
    there = full[t, r, m]
    distinct = np.unique(there)
    owner = distinct >> LABEL_BITS
    L = max(int(np.bincount(owner, minlength=P).max(initial=0)), 1)
    column = np.arange(distinct.size) - np.searchsorted(owner, owner)  # rank in its row
    col = column[np.searchsorted(distinct, there)]
    out = np.zeros((w, P, L, 2))
    held = np.zeros((w, P, L), dtype=bool)
    out[t, r, col], held[t, r, col] = positions[t, r, m], True
    return out, held


def ospa2(
    X: np.ndarray, x_exists: np.ndarray, Y: np.ndarray, y_exists: np.ndarray, c: float, p: float
) -> np.ndarray:
    """OSPA(2) (Beard, Vo and Vo 2020) of the track sets of each row over a window.

    X (w, P, m, 2) and Y (w, P, n, 2) are the tracks' positions over the window's w
    steps, x_exists (w, P, m) and y_exists (w, P, n) the steps each track exists (a
    column that never exists is no track). The distance between two tracks is the mean
    over the steps either exists of min(d, c) where both do and c where one does; OSPA
    of order p and cut-off c over that distance gives the row's value (P,), 0 for two
    empty sets. A label switch inside the window costs, where per-step OSPA sees none."""
    diff = X[:, :, :, None, :] - Y[:, :, None, :, :]
    d = np.minimum(np.sqrt(np.einsum("...k,...k->...", diff, diff)), c)  # (w, P, m, n)
    xe, ye = x_exists[:, :, :, None], y_exists[:, :, None, :]
    step = np.where(xe & ye, d, np.where(xe | ye, c, 0.0))
    either = (xe | ye).sum(axis=0)
    base = np.where(either > 0, step.sum(axis=0) / np.maximum(either, 1), 0.0)  # (P, m, n)
    P, m, n = base.shape
    N = max(m, n)
    cost = np.zeros((P, N, N))  # a missing track against a real one costs c^p (it never exists)
    cost[:, :m, :n] = base**p
    real_x, real_y = np.any(x_exists, axis=0), np.any(y_exists, axis=0)  # (P, m), (P, n)
    cost[:, m:, :n] = np.where(real_y[:, None, :], c**p, 0.0)
    cost[:, :m, n:] = np.where(real_x[:, :, None], c**p, 0.0)
    match = matching(cost)
    total = np.take_along_axis(cost, match[..., None], axis=-1)[..., 0].sum(axis=-1)
    size = np.maximum(real_x.sum(axis=-1), real_y.sum(axis=-1))
    return np.where(size > 0, (total / np.maximum(size, 1)) ** (1.0 / p), 0.0)


def matched_nees(
    assigned: np.ndarray, mean: np.ndarray, cov: np.ndarray, states: np.ndarray
) -> np.ndarray:
    """NEES (`estimation.nees`, over the 4-D state) of the track matched to each truth:
    means (..., K, 4), covariances (..., K, 4, 4), true states (..., Nt, 4); (..., Nt),
    NaN where no track is matched."""
    matched = assigned >= 0
    slot = np.where(matched, assigned, 0)
    m = np.take_along_axis(mean, slot[..., None], axis=-2)
    P = np.take_along_axis(cov, slot[..., None, None], axis=-3)
    # an unmatched slot may hold anything: score a harmless stand-in and drop it
    m = np.where(matched[..., None], m, states)
    P = np.where(matched[..., None, None], P, np.eye(4))
    return np.where(matched, nees(m, P, states), np.nan)


_SUMS = (
    "steps", "targets", "gospa", "localisation", "missed", "false", "switches",
    "fragmentations", "unassigned_tracks", "J", "JT", "N", "NA", "confirm_time", "confirmed",
    "duplicate_tracks", "stale_tracks", "never_tracks", "never_new", "ospa2", "windows",
)  # fmt: skip
_TEAM_SUMS = ("steps", "gospa", "agreeing", "matched", "ospa2", "windows")
"""What `TrackScore` sums per trial: the team picture's GOSPA and the label purity."""

LABEL_BITS = 40
"""A (row, label) pair is kept as row << LABEL_BITS | label: labels stay below 2^40."""


@dataclass(kw_only=True)
class TrackScore:
    """Running scores of the confirmed tracks of B trials of `rows` UAVs each (P = B x rows
    rows, a trial's rows consecutive), fed one step at a time, like `metrics.Tally`.

    Each row sums over the steps it is alive (a failed UAV's row stops where it failed;
    a confirm clock it left running counts as never confirmed); `summary` turns the sums
    into the row's values, then averages each over the trial's rows where it is defined
    (NaN when none is):

    * gospa and its parts: means per step; unassigned_tracks: confirmed tracks matched
      to no truth per step (gospa_false / (c^p / 2)), unassigned_tracks_per_target: per
      present target and step; duplicate_tracks, stale_tracks and never_tracks their
      kinds per target and step (`unassigned_kinds`), never_tracks_new the never-followed
      (row, label) pairs new to a row per 100 steps;
    * gospa_team, the team picture's GOSPA (`team_picture`) per step, and label_purity
      (`label_purity`), per trial over its rows at once;
    * switches and fragmentations (`label_changes`): 100 x count / target-steps (present
      targets summed over the steps), per target and 100 steps;
    * time_to_confirm (`confirm_clock`): the mean of the row's times [steps];
      never_confirmed: the fraction of its clocks still running at the end;
    * siap_*: from the counts of `siap_counts` summed over the steps (Stone Soup's
      values over a time range); where Stone Soup reports 0 or 1 for an empty
      denominator (no truth, no track), they are NaN here.

    The NEES (`matched_nees`) is pooled over the trial's matched pairs instead: it is a
    distribution, its median and inside fraction (`metrics.NeesSpread`) those of all its
    samples. `threshold` (SIAP) defaults to the GOSPA cut-off `cutoff`; `order` is p.

    Cost per step: one square assignment of max(Nt, K) per row (milliseconds for 250
    rows of 12 slots); a team of thousands of targets would want a sparse assignment.
    """

    batch: int
    rows: int
    n_targets: int
    cutoff: float = 20.0
    order: float = 1.0
    threshold: float | None = None
    window: int = 10
    steps: int = 0
    log: list[dict[str, np.ndarray]] | None = None
    """With a list: each step's own values (B,) of the metrics that are means over the
    steps, appended as the steps are added (`tracks.scoring.series`)."""
    sums: dict[str, np.ndarray] = field(init=False)
    spread: NeesSpread = field(init=False)
    _nees: np.ndarray = field(init=False, repr=False)  # (2, B): sum, count
    _state: dict[str, np.ndarray] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        P, Nt = self.batch * self.rows, self.n_targets
        self.sums = {name: np.zeros(P) for name in _SUMS}
        self.team = {name: np.zeros(self.batch) for name in _TEAM_SUMS}
        self.spread = NeesSpread(self.batch)
        self._nees = np.zeros((2, self.batch))
        self._state = {
            "last": np.full((P, Nt), -1, np.int64),  # label last matched
            "was": np.zeros((P, Nt), bool),  # matched at the previous step
            "start": np.full((P, Nt), -1, np.int64),  # confirm clock
            "followed": np.zeros(0, np.int64),  # (row, label) keys once matched, sorted
            "never": np.zeros(0, np.int64),  # keys counted as never-followed, sorted
            "life": np.zeros((P, Nt), np.int64),  # the targets that held each place so far
            "here": np.ones((P, Nt), bool),  # present at the previous step
            "team_start": np.full((self.batch, Nt), -1, np.int64),  # the team's clock
        }
        self._window: dict[str, list[tuple[np.ndarray, ...]]] = {"rows": [], "team": []}
        self._logged: dict[str, np.ndarray] = {}  # the step's values beyond the rows' own
        self._team_times: list[np.ndarray] = [np.zeros(0, np.int64)] * self.batch

    def add(
        self,
        *,
        truth: np.ndarray,
        tracks: np.ndarray,
        labels: np.ndarray,
        confirmed: np.ndarray,
        in_view: np.ndarray,
        present: np.ndarray | None = None,
        alive: np.ndarray | None = None,
        mean: np.ndarray | None = None,
        cov: np.ndarray | None = None,
        states: np.ndarray | None = None,
    ) -> None:
        """Add one step: truth (P, Nt, 2), tracks (P, K, 2), labels (P, K) int, confirmed
        (P, K), in_view (P, Nt) (the target inside the row's UAV's observation disk),
        present (P, Nt) (default: every target), alive (P,) (default: every row); for the
        NEES the tracks' mean (P, K, 4) and cov (P, K, 4, 4) and the true states (P, Nt, 4).
        """
        P, Nt = self.batch * self.rows, self.n_targets
        if np.shape(truth) != (P, Nt, 2) or np.shape(in_view) != (P, Nt):
            raise ValueError(
                f"truth must be (P, Nt, 2) and in_view (P, Nt) with P = {P}, Nt = {Nt}; got "
                f"{np.shape(truth)} and {np.shape(in_view)}"
            )
        K = np.shape(tracks)[1] if np.ndim(tracks) == 3 else -1
        if np.shape(tracks) != (P, K, 2) or not np.shape(labels) == np.shape(confirmed) == (P, K):
            raise ValueError(
                f"tracks must be (P, K, 2), labels and confirmed (P, K) with P = {P}; got "
                f"{np.shape(tracks)}, {np.shape(labels)} and {np.shape(confirmed)}"
            )
        # copies: the windows of OSPA(2) hold them past this call
        present = np.ones((P, Nt), bool) if present is None else np.array(present, bool)
        alive = np.ones(P, bool) if alive is None else np.array(alive, bool)
        # a failed UAV holds no track (its slots may hold NaN)
        confirmed = np.asarray(confirmed, bool) & alive[:, None]
        in_view = np.asarray(in_view, bool)
        s, st = self.sums, self._state
        assigned, g = gospa_assignment(truth, present, tracks, confirmed, self.cutoff, self.order)
        matched = assigned >= 0
        label = np.where(matched, np.take_along_axis(labels, np.maximum(assigned, 0), 1), -1)
        switch, fragment = label_changes(label, st["last"], st["was"], present, in_view)
        start, time = confirm_clock(self.steps, st["start"], matched, present, in_view)
        threshold = self.cutoff if self.threshold is None else self.threshold
        nearest = nearest_truth(truth, present, tracks, confirmed, threshold)
        within_c = (
            nearest
            if threshold == self.cutoff  # SIAP's threshold is the cut-off unless given
            else nearest_truth(truth, present, tracks, confirmed, self.cutoff)
        )
        J, JT, N, NA = siap_counts(nearest, present, confirmed)
        labels = np.array(labels, dtype=np.int64)
        key = (np.arange(P, dtype=np.int64)[:, None] << LABEL_BITS) | np.maximum(labels, 0)
        duplicate, stale, never = unassigned_kinds(
            assigned, within_c, confirmed,
            _member(key, st["followed"]),
        )  # fmt: skip
        first = never & ~_member(key, st["never"]) & alive[:, None]
        step = {
            "steps": 1, "targets": present.sum(axis=1), "gospa": g.distance,
            "localisation": g.localisation, "missed": g.missed, "false": g.false,
            "switches": switch.sum(axis=1), "fragmentations": fragment.sum(axis=1),
            "unassigned_tracks": confirmed.sum(axis=1) - matched.sum(axis=1),
            "duplicate_tracks": duplicate.sum(axis=1), "stale_tracks": stale.sum(axis=1),
            "never_tracks": never.sum(axis=1), "never_new": first.sum(axis=1),
            "J": J, "JT": JT, "N": N, "NA": NA,
            "confirm_time": np.where(time >= 0, time, 0).sum(axis=1),
            "confirmed": (time >= 0).sum(axis=1),
        }  # fmt: skip
        step = {name: np.where(alive, value, 0) for name, value in step.items()}
        for name, value in step.items():
            s[name] += value
        # a failed UAV's row keeps what it had
        keep = alive[:, None]
        st["last"] = np.where(keep & matched, label, st["last"])
        st["was"] = np.where(keep, matched, st["was"])
        st["start"] = np.where(keep, start, st["start"])
        if not present.all():  # a target that left: the next one there is another
            st["last"] = np.where(present, st["last"], -1)
            st["start"] = np.where(present, st["start"], -1)
        matched_key = np.take_along_axis(key, np.maximum(assigned, 0), axis=1)[matched & keep]
        st["followed"] = np.union1d(st["followed"], matched_key)
        st["never"] = np.union1d(st["never"], key[first])
        B, rows = self.batch, self.rows
        agreeing, pairs = label_purity(np.where(alive[:, None], label, -1).reshape(B, rows, Nt))
        self.team["agreeing"] += agreeing
        self.team["matched"] += pairs
        if self.log is not None:
            self._logged = {
                name: mean_std(value.reshape(B, rows), axis=1)[0]
                for name, value in _row_values(step).items()
            }
            purity = np.where(pairs > 0, agreeing / np.maximum(pairs, 1), np.nan)
            self._logged["label_purity"] = purity
        self._team_clock(matched & keep, present, in_view & keep)
        born = present & ~st["here"]
        st["life"] += born
        st["here"] = present
        target = (st["life"] << 20) | np.arange(Nt)  # a place and the target that holds it
        held_truth = np.array(truth)  # a copy: the windows hold it past this call
        self._window["rows"].append(
            (target, present, held_truth, labels, confirmed, np.array(tracks), alive)
        )
        if cov is not None:  # the team picture needs each track's confidence
            gamma = confidence(np.asarray(cov))
            label_, where, held = team_picture(
                np.asarray(labels).reshape(B, rows, K), confirmed.reshape(B, rows, K),
                np.asarray(tracks).reshape(B, rows, K, 2), gamma.reshape(B, rows, K),
            )  # fmt: skip
            L = max(int(held.sum(axis=1).max()), 1)  # the labels held, not every slot
            label_, where, held = label_[:, :L], where[:, :L], held[:, :L]
            whole = np.any(alive.reshape(B, rows), axis=1)
            _, team = gospa_assignment(
                truth.reshape(B, rows, Nt, 2)[:, 0], present.reshape(B, rows, Nt)[:, 0],
                where, held, self.cutoff, self.order,
            )  # fmt: skip
            self.team["gospa"] += np.where(whole, team.distance, 0.0)
            self.team["steps"] += whole
            if self.log is not None:
                self._logged["gospa_team"] = np.where(whole, team.distance, np.nan)
            B_ = slice(None, None, rows)  # each trial's first row: its truth
            self._window["team"].append(
                (target[B_], present[B_], held_truth[B_], np.maximum(label_, 0), held,
                 where, whole)
            )  # fmt: skip
        if mean is not None and cov is not None and states is not None:
            q = matched_nees(assigned, mean, cov, states)
            counted = matched & keep
            self.spread.add(q.reshape(self.batch, -1), counted.reshape(self.batch, -1))
            self._nees[0] += np.where(counted, q, 0.0).reshape(self.batch, -1).sum(axis=1)
            self._nees[1] += counted.reshape(self.batch, -1).sum(axis=1)
        self.steps += 1
        if self.steps % self.window == 0:
            self.close_windows()
        if self.log is not None:
            self.log.append(self._logged)

    def _team_clock(self, matched: np.ndarray, present: np.ndarray, in_view: np.ndarray) -> None:
        """The team's time to confirm (`confirm_clock` over the whole team): a target is
        found anew when present, in some living UAV's view and matched by none of their
        confirmed tracks; its clock stops when any UAV's confirmed track is matched."""
        B, rows, Nt = self.batch, self.rows, self.n_targets
        anyone = np.any(matched.reshape(B, rows, Nt), axis=1)
        seen = np.any(in_view.reshape(B, rows, Nt), axis=1)
        here = present.reshape(B, rows, Nt)[:, 0]
        st = self._state
        start, time = confirm_clock(self.steps, st["team_start"], anyone, here, seen)
        st["team_start"] = np.where(here, start, -1)  # a target that left is no one's
        for b in np.flatnonzero((time >= 0).any(axis=1)):
            self._team_times[b] = np.concatenate([self._team_times[b], time[b][time[b] >= 0]])

    def _window_ospa2(self, kind: str) -> tuple[np.ndarray, np.ndarray] | None:
        """The OSPA(2) of the steps held (a window) of `kind` ("rows" or "team") and the
        rows it counts for (alive at its last step), or None without any step held."""
        held = self._window[kind]
        if not held:
            return None
        target, present, truth, labels, exists, tracks, alive = (
            _stacked(part) for part in zip(*held, strict=True)
        )
        X, x_exists = window_tracks(target, present, truth)
        Y, y_exists = window_tracks(labels, exists, tracks)
        return ospa2(X, x_exists, Y, y_exists, self.cutoff, self.order), alive[-1]

    def close_windows(self) -> None:
        """Add the OSPA(2) of the steps held (a window) per row and for the team: at
        each window's last step, and once more at the end of a run for its last steps
        (`Scores.series`; `summary` reads them without adding them)."""
        for kind, sums in (("rows", self.sums), ("team", self.team)):
            scored = self._window_ospa2(kind)
            if scored is None:
                continue
            _count_window(sums, scored)
            value, counted = scored
            if self.log is not None:  # at the window's last step
                name = "ospa2" if kind == "rows" else "ospa2_team"
                per = np.where(counted, value, np.nan)
                self._logged[name] = (
                    per
                    if kind == "team"
                    else mean_std(per.reshape(self.batch, self.rows), axis=1)[0]
                )
            self._window[kind] = []

    def summary(self) -> dict[str, np.ndarray]:
        """The metrics of `TRACK_METRICS`, each an array over the B trials."""
        s, team = dict(self.sums), dict(self.team)  # read, not changed: the run may go on
        for kind, sums in (("rows", s), ("team", team)):
            scored = self._window_ospa2(kind)  # the last steps, a shorter window
            if scored is not None:
                _count_window(sums, scored)

        running = (self._state["start"] >= 0).sum(axis=1)
        per_row = _row_values(s) | {
            "time_to_confirm": ratio(s["confirm_time"], s["confirmed"]),
            "never_confirmed": ratio(running, s["confirmed"] + running),
            "ospa2": ratio(s["ospa2"], s["windows"]),
        }
        out = {
            name: mean_std(value.reshape(self.batch, self.rows), axis=1)[0]
            for name, value in per_row.items()
        }
        out["gospa_team"] = ratio(team["gospa"], team["steps"])
        out["label_purity"] = ratio(team["agreeing"], team["matched"])
        out["ospa2_team"] = ratio(team["ospa2"], team["windows"])
        out["time_to_confirm_team"] = np.array(
            [np.median(t) if t.size else np.nan for t in self._team_times]
        )
        out["nees"] = ratio(self._nees[0], self._nees[1])
        out["nees_median"] = self.spread.median()
        out["nees_inside"] = self.spread.inside_fraction()
        return out


TRACKS_ONLY = tuple(
    name for name in TRACK_METRICS if name not in ("gospa", "nees", "nees_median", "nees_inside")
)
"""The metrics a run of known association does not have (NaN there)."""

REPLACED = ("rmse", "rmse_best", "nees_best", "nees_best_median", "nees_best_inside", "ospa",
            "ospa_best", "gospa_best", "gospa_missed_best")  # fmt: skip
"""The per-target estimate metrics a run of tracks does not have (NaN there): a track
set has no estimate per target index."""


@dataclass(kw_only=True)
class Scores:
    """The metrics of a run (`metrics.METRICS`): its `metrics.Tally`, and with tracks of
    unknown association their `TrackScore` (created at the first cycle that carries
    labels), whose GOSPA and NEES stand for the tally's per-target ones."""

    tally: Tally
    separation: Separation | None = None
    tracks: TrackScore | None = None

    @classmethod
    def of(cls, scenario: Scenario, batch: int, timed: bool) -> Scores:
        """The metrics of a run of `batch` trials of `scenario`, fed one `Cycle` at a
        time; decision times only if `timed`."""
        e, u = scenario.evaluation, scenario.uav
        return cls(
            tally=Tally(
                batch=batch,
                n_uavs=scenario.n_uavs,
                n_targets=scenario.n_targets,
                timed=timed,
                cutoff=e.ospa_cutoff,
                order=e.ospa_order,
            ),
            separation=Separation(
                batch=batch,
                minimum=u.separation,
                vertical=u.vertical_separation,
                reach=max(scenario.comm_range, u.separation),
                dt=scenario.dt,
            ),
        )

    def add(self, cycle: Cycle, truth: np.ndarray) -> None:
        """Add one step: a `records.Cycle` and the true targets (B, Nt, 4)."""
        self.tally.add(cycle, truth)
        if self.separation is not None:
            self.separation.add(cycle.uavs, cycle.alive)
        if cycle.label is None or cycle.status is None:
            return
        t = self.tally
        B, Nu, K = cycle.label.shape
        if t.n_targets > PER_UAV_SETS:  # as the per-UAV sets of the tally: too costly
            return
        if self.tracks is None:
            self.tracks = TrackScore(
                batch=B, rows=Nu, n_targets=t.n_targets, cutoff=t.cutoff, order=t.order,
                log=None if t.log is None else [],
            )  # fmt: skip
        P = B * Nu
        states = np.repeat(truth, Nu, axis=0)  # (P, Nt, 4): each row its trial's targets
        alive = cycle.alive.reshape(P)
        mean = np.where(alive[:, None, None], cycle.mean.reshape(P, K, 4), 0.0)
        cov = np.where(alive[:, None, None, None], cycle.cov.reshape(P, K, 4, 4), np.eye(4))
        self.tracks.add(
            truth=states[..., :2],
            present=None if t.fixed else targets_present(states),
            tracks=mean[..., :2],
            labels=cycle.label.reshape(P, K),
            confirmed=cycle.status.reshape(P, K) == 2,
            in_view=cycle.observed.reshape(P, t.n_targets),
            alive=alive,
            mean=mean,
            cov=cov,
            states=states,
        )

    def summary(self) -> dict[str, np.ndarray]:
        """Per-trial metrics of `METRICS`, each an array over the batch."""
        out = self.tally.summary()
        nothing = np.full(self.tally.batch, np.nan)
        out |= (
            {name: nothing for name in SEPARATION}
            if self.separation is None
            else self.separation.summary()
        )
        if self.tracks is None:
            return out | {name: nothing for name in TRACKS_ONLY}
        return out | {name: nothing for name in REPLACED} | self.tracks.summary()

    def series(self) -> dict[str, np.ndarray]:
        """Each step's own value of the metrics that are means over the steps, (T, B)
        per name (NaN where a step has none); the tally must keep a log (``log=[]``)."""
        if self.tally.log is None:
            raise ValueError("these scores keep no log: make their Tally with log=[]")
        self.tally.summary()  # scores the steps still pending
        T = len(self.tally.log)
        rows = self.tally.log
        if self.tracks is not None and self.tracks.log is not None:
            self.tracks.close_windows()  # the last, shorter window: at the run's end
            rows = [a | b for a, b in zip(rows, self.tracks.log, strict=True)]
        if not T:
            return {}
        names = list(dict.fromkeys(name for row in rows for name in row))
        nothing = np.full(self.tally.batch, np.nan)
        return {name: np.stack([row.get(name, nothing) for row in rows]) for name in names}


def series(source: Result | Trace, scenario: Scenario | None = None) -> dict[str, np.ndarray]:
    """Each step's own value (T,) of every metric of a trial that is a mean over its steps
    (the observation rate, GOSPA and its parts, the kinds of unassigned tracks, the team
    picture's GOSPA, label purity, messages, bytes ...; OSPA(2) at the last step of each
    window), for plots: the run's metrics replayed step by step from a `Result` with its
    trace, or a `Trace` and its scenario (``uavtrack.series(result)``).

    With the paper's fixed set of targets and every UAV alive, a series' mean over the
    steps is the run's value for the metrics that are means over the steps; it is not for
    those that are ratios of sums (rmse and rmse_best, the square root of a mean;
    label_purity and SIAP, sums over the run divided), nor with targets that come and go,
    where the run weighs each step by the targets present (a step's value by its count
    of present targets, summed and divided by their total, gives the run's)."""
    if isinstance(source, Result):
        if source.trace is None:
            raise ValueError("this result holds no trace: simulate(..., trace=True)")
        trace, scenario = source.trace, source.scenario
    else:
        trace = source
    if scenario is None:
        raise ValueError("a bare Trace needs its scenario: series(trace, scenario)")
    score = Scores.of(scenario, 1, timed=True)
    score.tally.log = []
    arrays: dict[str, np.ndarray] = trace.arrays()  # the recorded fields, not None
    names = [f.name for f in RECORDED] + [n for n in ("label", "status") if n in arrays]
    for k in range(trace.targets.shape[0]):
        values: dict[str, Any] = {name: arrays[name][k][None] for name in names}
        score.add(Cycle(**values), trace.targets[k][None])
    return {name: values[:, 0] for name, values in score.series().items()}


def _count_window(sums: dict[str, np.ndarray], scored: tuple[np.ndarray, np.ndarray]) -> None:
    """Add a window's OSPA(2) (value, counted rows) to `sums`, binding new arrays: a copy
    of the dict (`TrackScore.summary`) leaves the running sums as they were. A row that
    failed inside the window is left out."""
    value, counted = scored
    sums["ospa2"] = sums["ospa2"] + np.where(counted, value, 0.0)
    sums["windows"] = sums["windows"] + counted


def ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a / b, NaN where b is 0 (nothing to average)."""
    return np.where(b > 0, a / np.where(b > 0, b, 1.0), np.nan)


def _row_values(s: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The per-row metrics that are ratios of `TrackScore`'s sums: over a run from its
    sums, over one step from that step's counts (`series`)."""
    return {
        "gospa": ratio(s["gospa"], s["steps"]),
        "gospa_localisation": ratio(s["localisation"], s["steps"]),
        "gospa_missed": ratio(s["missed"], s["steps"]),
        "gospa_false": ratio(s["false"], s["steps"]),
        "switches": 100 * ratio(s["switches"], s["targets"]),
        "fragmentations": 100 * ratio(s["fragmentations"], s["targets"]),
        "unassigned_tracks": ratio(s["unassigned_tracks"], s["steps"]),
        "unassigned_tracks_per_target": ratio(s["unassigned_tracks"], s["targets"]),
        "duplicate_tracks": ratio(s["duplicate_tracks"], s["targets"]),
        "stale_tracks": ratio(s["stale_tracks"], s["targets"]),
        "never_tracks": ratio(s["never_tracks"], s["targets"]),
        "never_tracks_new": 100 * ratio(s["never_new"], s["steps"]),
        "siap_completeness": ratio(s["JT"], s["J"]),
        "siap_ambiguity": ratio(s["NA"], s["JT"]),
        "siap_spuriousness": ratio(s["N"] - s["NA"], s["N"]),
    }


def _stacked(arrays: tuple[np.ndarray, ...]) -> np.ndarray:
    """The arrays stacked on a new first axis, each padded with zeros (False) to the
    largest (the team picture holds a number of labels that varies by step)."""
    shape = np.max([a.shape for a in arrays], axis=0)
    out = np.zeros((len(arrays), *shape), dtype=arrays[0].dtype)
    for k, a in enumerate(arrays):
        out[(k, *(slice(0, n) for n in a.shape))] = a
    return out


def _member(key: np.ndarray, sorted_keys: np.ndarray) -> np.ndarray:
    """Whether each key is in `sorted_keys` (a sorted 1-D array)."""
    if sorted_keys.size == 0:
        return np.zeros(key.shape, dtype=bool)
    at = np.minimum(np.searchsorted(sorted_keys, key), sorted_keys.size - 1)
    return sorted_keys[at] == key
