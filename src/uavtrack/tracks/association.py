"""Measurement-to-track association for one scan: gating, global nearest neighbour (GNN)
and joint probabilistic data association (JPDA), for many UAVs at once.

Shapes: P rows (one UAV of one trial each), K track slots and Z padded measurements per
row. Tracks: mean (P, K, 4) = x, y, vx, vy and cov (P, K, 4, 4), predicted to the scan,
present (P, K). Measurements: z (P, Z, 2), R (P, Z, 2, 2), valid (P, Z). The measurement
is z = H s + v with H = [I_2 0], v ~ N(0, R); R belongs to the measurement (it grows
with range), so every pair (k, j) has its own innovation covariance S_kj = H P_k H^T + R_j.

The hypothesis weights are those of Stone Soup's `PDAHypothesiser` (Bar-Shalom, Daum and
Huang, "The probabilistic data association filter", IEEE Control Systems 2009):

    track k missed:               w_k0 = 1 - P_D P_G
    measurement j is track k's:   w_kj = P_D N(z_j; H x_k, S_kj) / lambda   (gated pairs)

with P_D the detection probability, P_G the gate probability and lambda the clutter
density [1/m^2] (a detected target's measurement falls outside the gate with probability
1 - P_G, so the gate holds none of its measurements with probability 1 - P_D P_G). A
joint event gives each track one hypothesis and each measurement at
most one track; its weight is the product of its tracks' weights (a measurement no
track takes is clutter). This is the posterior of the event up to a constant factor
(lambda^Z and the normalisation of each track's weights cancel). lambda = 0 (no clutter)
is taken as its limit lambda -> 0+ (the smallest positive float, in logarithms): events
that explain more measurements by tracks win.

GNN keeps the most probable event; JPDA keeps the marginal probabilities beta of every
track's hypotheses over all events, and each track's posterior is the moment-matched
Gaussian of its hypotheses' Kalman updates weighted by beta (`pda_update`).
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown, and scipy's compiled solvers carry no types.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..estimation import filter_step, update
from ..numerics import chisquare, lsap

LBP_TOLERANCE = 1e-13
"""Loopy belief propagation stops when no message changes by more than this (relative)."""

LBP_SWEEPS = 10_000
"""Loopy belief propagation stops after this many sweeps even if not converged."""

_TINY = np.finfo(float).tiny  # lambda = 0 is taken as this (the limit lambda -> 0+)


@dataclass(frozen=True, kw_only=True)
class Innovations:
    """The innovation of every (track, measurement) pair of every row.

    d2 (P, K, Z) = nu^T S^-1 nu (the squared Mahalanobis distance that the gate tests),
    nu = z_j - H x_k, S = H P_k H^T + R_j; log_lik (P, K, Z) = log N(z_j; H x_k, S_kj)
    = -d2 / 2 - log(det S) / 2 - log(2 pi). `nu` (P, K, Z, 2) and `S` (P, K, Z, 2, 2)
    are formed when asked for: the association reads only d2 and log_lik.
    """

    d2: np.ndarray
    log_lik: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    z: np.ndarray
    R: np.ndarray

    @property
    def nu(self) -> np.ndarray:
        return self.z[:, None, :, :] - self.mean[:, :, None, :2]

    @property
    def S(self) -> np.ndarray:
        return self.cov[:, :, None, :2, :2] + self.R[:, None, :, :, :]


def innovations(mean: np.ndarray, cov: np.ndarray, z: np.ndarray, R: np.ndarray) -> Innovations:
    """Innovations of every track of a row with every measurement of the row.

    mean (P, K, 4), cov (P, K, 4, 4), z (P, Z, 2), R (P, Z, 2, 2). S^-1 is the closed-form
    2 x 2 inverse, as in `estimation.update`; S's three distinct entries and nu's two
    are formed apart, each (P, K, Z), never the (P, K, Z, 2, 2) array.
    """

    def pair(track: np.ndarray, measured: np.ndarray) -> np.ndarray:  # (P, K, Z)
        return track[:, :, None] + measured[:, None, :]

    s11 = pair(cov[..., 0, 0], R[..., 0, 0])
    s12 = pair(cov[..., 0, 1], R[..., 0, 1])
    s22 = pair(cov[..., 1, 1], R[..., 1, 1])
    n0 = z[:, None, :, 0] - mean[:, :, None, 0]
    n1 = z[:, None, :, 1] - mean[:, :, None, 1]
    det = s11 * s22 - s12 * s12
    d2 = (s22 * n0 * n0 - 2.0 * s12 * n0 * n1 + s11 * n1 * n1) / det
    log_lik = -0.5 * d2 - 0.5 * np.log(det) - np.log(2.0 * np.pi)
    return Innovations(d2=d2, log_lik=log_lik, mean=mean, cov=cov, z=z, R=R)


@lru_cache(maxsize=32)
def threshold(gate_probability: float, dim: int = 2) -> float:
    """The gate gamma = chi2.ppf(P_G, dim) (`chisquare.ppf`): a measurement of the track
    falls inside d2 <= gamma with probability P_G (d2 is chi-square with dim degrees of
    freedom)."""
    _check_gate(gate_probability)
    return chisquare.ppf(gate_probability, dim)


def gate(
    d2: np.ndarray, present: np.ndarray, valid: np.ndarray, gate_probability: float
) -> np.ndarray:
    """Gated pairs (P, K, Z) bool: a present track and a valid measurement with
    d2 <= chi2.ppf(P_G, 2) (the boundary inside, as Stone Soup's `PDAHypothesiser`)."""
    inside = d2 <= threshold(gate_probability, 2)
    return inside & present[:, :, None] & valid[:, None, :]


def gnn(
    inn: Innovations,
    gated: np.ndarray,
    pd: float | np.ndarray,
    density: float | np.ndarray,
    gate_probability: float,
) -> np.ndarray:
    """Global nearest neighbour: the joint event of largest weight (module docstring),
    as take (P, K) int, the measurement each track takes, -1 for a miss (and for a slot
    not present).

    pd: P_D, a number or (P, K) (0 for a track that cannot be detected: it takes
    nothing); density: lambda [1/m^2], a number or (P,). The event maximises
    sum_k log w_k(choice of k): a pair (k, j) whose track and measurement are gated to
    nothing else is decided alone (taken when w_kj >= w_k0, vectorised over all rows);
    the tracks and measurements of the other gated pairs of a row are solved together
    with `lsap.solve` (scipy's `linear_sum_assignment`) on the (n, m + n) cost matrix -log w, one
    column per measurement and one miss column per track (its own finite, the others'
    forbidden), which always has a feasible assignment. This is Stone Soup's
    `GlobalNearestNeighbour` (the best product over all events) with `PDAHypothesiser`;
    its `GNNWith2DAssignment` instead maximises the sum of the per-track normalised
    probabilities, which can pick another event.

    Ties (two events of exactly equal weight, of probability zero for continuous
    measurements) go to the measurement for a lone pair and to the solver's choice
    otherwise.
    """
    link, lmiss, ldet = _log_weights(inn, gated, pd, density, gate_probability)
    take = np.full(link.shape[:2], -1, dtype=np.int64)
    lone = link & (link.sum(2) == 1)[:, :, None] & (link.sum(1) == 1)[:, None, :]
    p, k, j = np.nonzero(lone & (ldet >= lmiss[:, :, None]))
    take[p, k] = j
    shared = link & ~lone
    tp, tk = np.nonzero(shared.any(axis=2))  # tracks and measurements to solve, by row
    mp, mj = np.nonzero(shared.any(axis=1))
    rows = np.unique(tp)
    t0s, t1s = np.searchsorted(tp, rows), np.searchsorted(tp, rows, side="right")
    m0s, m1s = np.searchsorted(mp, rows), np.searchsorted(mp, rows, side="right")
    bounds = zip(*(a.tolist() for a in (rows, t0s, t1s, m0s, m1s)), strict=True)
    for row, t0, t1, m0, m1 in bounds:
        tracks, meas = tk[t0:t1], mj[m0:m1]
        n, m = t1 - t0, m1 - m0
        cost = np.full((n, m + n), np.inf)
        cost[:, :m] = -ldet[row, tracks[:, None], meas]  # not gated: -(-inf), forbidden
        cost[np.arange(n), m + np.arange(n)] = -lmiss[row, tracks]
        r, c = lsap.solve(cost)
        hit = c < m
        take[row, tracks[r[hit]]] = meas[c[hit]]
    return take


def jpda(
    inn: Innovations,
    gated: np.ndarray,
    pd: float | np.ndarray,
    density: float | np.ndarray,
    gate_probability: float,
    max_events: int = 100_000,
) -> np.ndarray:
    """Joint probabilistic data association: beta (P, K, Z + 1), column 0 the
    probability that the track was missed, column 1 + j that measurement j is its
    (0 where not gated); each row of a track sums to 1 (a slot not present: beta = 1 on
    the miss). pd, density as in `gnn`.

    beta_kj = sum of the probabilities of the feasible joint events in which track k
    takes j, an event's probability its weight over the sum of all. Events factor over
    clusters (the connected components of the gating graph of tracks and measurements of
    a row), so each cluster is solved alone:

    * a cluster of one track (every measurement gated to it is gated to no other track)
      has the closed form of PDA, beta_kj = w_kj / (w_k0 + sum_i w_ki), vectorised over
      all such tracks;
    * a cluster of several tracks enumerates its feasible events exactly (the same
      marginals as Stone Soup's `JPDA` with `PDAHypothesiser`). Clusters of the same
      size (n tracks, m measurements) whose events on the complete n x m graph number at
      most `GRID_EVENTS` (and `max_events`) are solved together on those events, the
      pairs not gated weighing zero; larger ones one by one on their gated pairs;
    * a cluster with more than `max_events` feasible events is approximated by loopy
      belief propagation on the association graph (Williams and Lau, "Approximate
      evaluation of marginal association probabilities with belief propagation", IEEE
      TAES 2014; Stone Soup's `JPDAwithLBP`), iterated to its fixed point (messages
      within `LBP_TOLERANCE`, at most `LBP_SWEEPS` sweeps). It keeps the exclusion (one
      track per measurement) that independent PDA per track would drop, costs
      O(sweeps n m^2) instead of the number of events, and is exact when the cluster's
      gating graph has no cycle (a tree), as belief propagation is on a tree.
    """
    if int(max_events) < 1:
        raise ValueError(f"max_events must be a positive integer, got {max_events}")
    link, lmiss, ldet = _log_weights(inn, gated, pd, density, gate_probability)
    P, K, Z = link.shape
    beta = _normalised(np.concatenate([lmiss[:, :, None], ldet], axis=2))
    # a track sharing a gated measurement with another track is in a larger cluster
    joint = (link & (link.sum(1) > 1)[:, None, :]).any(axis=2)
    flat, lmiss, ldet = beta.reshape(P * K, Z + 1), lmiss.reshape(-1), ldet.reshape(P * K, Z)
    for tracks, meas in _clusters(link, joint):  # (C, n) rows of `flat`, (C, m) columns
        lw = np.concatenate(
            [lmiss[tracks][:, :, None], ldet[tracks[:, :, None], meas[:, None, :]]], axis=2
        )
        sub = _marginals(lw, int(max_events))
        flat[tracks] = 0.0
        flat[tracks, 0], flat[tracks[:, :, None], 1 + meas[:, None, :]] = sub[..., 0], sub[..., 1:]
    return beta


def pda_update(
    mean: np.ndarray, cov: np.ndarray, z: np.ndarray, R: np.ndarray, beta: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """JPDA's posterior of each track: the moment-matched Gaussian of the mixture of its
    hypotheses, weights beta (P, K, Z + 1) from `jpda`.

    With x_0, P_0 the prediction and x_j, P_j the Kalman update on measurement j
    (`estimation.update`): x = sum_i beta_i x_i, P = sum_i beta_i (P_i + d_i d_i^T),
    d_i = x_i - x (the PDA covariance, spread of the innovations included). R differs
    per measurement, so each hypothesis has its own gain (the mixture form rather than
    the combined-innovation form of a single gain). Only hypotheses with beta > 0 are
    updated and enter the sums, so a track whose beta is all on one hypothesis gets
    exactly that hypothesis's estimate (the prediction, or the plain update). Returns
    (mean (P, K, 4), cov (P, K, 4, 4)).
    """
    P, K, Z = beta.shape[0], beta.shape[1], beta.shape[2] - 1
    if z.shape[:2] != (P, Z) or mean.shape[:2] != (P, K):
        raise ValueError(
            f"beta {beta.shape} must be (P, K, Z + 1) for z {z.shape}, mean {mean.shape}"
        )
    out_mean, out_cov = mean.copy(), cov.copy()
    p, k, j = np.nonzero(beta[:, :, 1:] > 0)  # the pairs, grouped by track
    if not len(p):
        return out_mean, out_cov
    first = np.r_[True, (p[1:] != p[:-1]) | (k[1:] != k[:-1])]
    starts, track = np.flatnonzero(first), np.cumsum(first) - 1  # track of each pair
    tp, tk = p[starts], k[starts]
    x_j, P_j = update(mean[p, k], cov[p, k], z[p, j], R[p, j])
    b, b0 = beta[p, k, 1 + j], beta[tp, tk, 0]
    miss = (b0 > 0)[:, None]
    x0, P0 = mean[tp, tk], cov[tp, tk]
    x = np.add.reduceat(b[:, None] * x_j, starts) + np.where(miss, b0[:, None] * x0, 0.0)
    d, d0 = x_j - x[track], x0 - x
    spread = b[:, None, None] * (P_j + d[:, :, None] * d[:, None, :])
    spread0 = b0[:, None, None] * (P0 + d0[:, :, None] * d0[:, None, :])
    out_mean[tp, tk] = x
    out_cov[tp, tk] = np.add.reduceat(spread, starts) + np.where(miss[..., None], spread0, 0.0)
    return out_mean, out_cov


def assigned_update(
    mean: np.ndarray, cov: np.ndarray, z: np.ndarray, R: np.ndarray, take: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """GNN's posterior: the Kalman update (`estimation.update`) of each track on the
    measurement it takes (take (P, K) from `gnn`), the prediction where take = -1.
    Returns (mean (P, K, 4), cov (P, K, 4, 4)); the inputs are not modified."""
    observed = take >= 0
    p, k = np.nonzero(observed)
    j = take[p, k]
    mean, cov = filter_step(mean, cov, observed, z[p, j], R[p, j], None, None)
    return (mean.copy(), cov.copy()) if not len(p) else (mean, cov)


def unused_gnn(take: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Measurements (P, Z) bool that no track took under GNN (take (P, K)): valid ones
    left to start new tracks."""
    taken = np.zeros(valid.shape, dtype=bool)
    p, k = np.nonzero(take >= 0)
    taken[p, take[p, k]] = True
    return valid & ~taken


def unused_jpda(gated: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Measurements (P, Z) bool that no track may have produced under JPDA: valid ones
    gated (P, K, Z) to no track (`gate` counts only present slots; pass
    ``gated & (pd > 0)[..., None]`` to leave out tracks that cannot be detected too). A
    measurement gated to a track may be that track's, so JPDA does not start another
    track on it."""
    return valid & ~gated.any(axis=1)


# ---------------------------------------------------------------------------- internals


def _check_gate(gate_probability: float) -> None:
    if not 0.0 < gate_probability < 1.0:
        raise ValueError(f"gate_probability must be in (0, 1), got {gate_probability}")


def _log_weights(
    inn: Innovations,
    gated: np.ndarray,
    pd: float | np.ndarray,
    density: float | np.ndarray,
    gate_probability: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(link (P, K, Z) bool, log w_k0 (P, K), log w_kj (P, K, Z), -inf where not linked):
    a link is a gated pair whose track can be detected (P_D > 0)."""
    _check_gate(gate_probability)
    P, K, _ = gated.shape
    pd = np.broadcast_to(np.asarray(pd, dtype=float), (P, K))
    density = np.broadcast_to(np.asarray(density, dtype=float), (P,))
    if not np.all((pd >= 0) & (pd <= 1)):
        raise ValueError("pd must be in [0, 1]")
    if not np.all((density >= 0) & np.isfinite(density)):
        raise ValueError("density must be finite and >= 0")
    link = gated & (pd > 0)[:, :, None]
    with np.errstate(divide="ignore"):
        log_pd = np.log(pd)
    log_density = np.log(np.maximum(density, _TINY))
    ldet = log_pd[:, :, None] + inn.log_lik - log_density[:, None, None]
    return link, np.log1p(-pd * gate_probability), np.where(link, ldet, -np.inf)


def _normalised(log_w: np.ndarray) -> np.ndarray:
    """exp(log_w) normalised along the last axis (its largest entry must be finite)."""
    w = np.exp(log_w - log_w.max(axis=-1, keepdims=True))
    return w / w.sum(axis=-1, keepdims=True)


def _clusters(link: np.ndarray, joint: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The clusters of several tracks (the connected components of the gating graph that
    hold the tracks marked `joint` (P, K)), grouped by size: for each size (n, m), the
    tracks (C, n) as flat indices p K + k and the measurements (C, m) as indices j of
    the row, each in increasing order."""
    if not joint.any():
        return []
    _, K, Z = link.shape
    p, k, j = np.nonzero(link & joint[:, :, None])
    tracks, t_index = np.unique(p * K + k, return_inverse=True)
    meas, m_index = np.unique(p * Z + j, return_inverse=True)
    nt, nm = len(tracks), len(meas)
    count, label = components(t_index, nt + m_index, nt + nm)
    sizes = [np.bincount(label[:nt], minlength=count), np.bincount(label[nt:], minlength=count)]
    # members of a cluster in a run of the sorted labels, each run in increasing order
    runs = [np.argsort(label[:nt], kind="stable"), np.argsort(label[nt:], kind="stable")]
    starts = [np.cumsum(size) - size for size in sizes]
    out: list[tuple[np.ndarray, np.ndarray]] = []
    for n, m in sorted(set(zip(sizes[0].tolist(), sizes[1].tolist(), strict=True))):
        c = np.flatnonzero((sizes[0] == n) & (sizes[1] == m))
        t = tracks[runs[0][starts[0][c][:, None] + np.arange(n)]]
        out.append((t, meas[runs[1][starts[1][c][:, None] + np.arange(m)]] % Z))
    return out


def components(a: np.ndarray, b: np.ndarray, n: int) -> tuple[int, np.ndarray]:
    """The connected components of the undirected graph of n nodes and edges (a, b):
    their count and each node's component, numbered in the order of their lowest node
    (as `scipy.sparse.csgraph.connected_components` numbers them). Each node takes the
    lowest label across its edges, then its label's label (pointer jumping), until
    nothing changes: a few passes over the edges, as clusters of gated tracks are small."""
    label = np.arange(n)
    while True:
        low = np.minimum(label[a], label[b])
        new = label.copy()
        np.minimum.at(new, a, low)
        np.minimum.at(new, b, low)
        new = new[new]
        if np.array_equal(new, label):
            break
        label = new
    roots, index = np.unique(label, return_inverse=True)
    return len(roots), index


GRID_EVENTS = 1024
"""Clusters with at most this many events on their complete graph are solved together."""


def _marginals(lw: np.ndarray, max_events: int) -> np.ndarray:
    """Marginals (C, n, m + 1) of C clusters of one size from their log weights lw
    (C, n, m + 1): column 0 the miss, 1 + j measurement j (-inf where not gated)."""
    C, n, m = lw.shape[0], lw.shape[1], lw.shape[2] - 1
    events = _complete(n, m)
    if events is not None and len(events) <= max_events:
        prob = _normalised(lw[:, np.arange(n), events].sum(axis=2))  # (C, events)
        return (prob @ _indicator(n, m)).reshape(C, n, m + 1)
    out = np.empty(lw.shape)
    for c in range(C):
        choice = _events(np.isfinite(lw[c]), max_events)
        if choice is None:
            out[c] = _propagated(lw[c, :, 0], lw[c, :, 1:])
        else:
            prob = _normalised(lw[c, np.arange(n), choice].sum(axis=1))
            cell = (np.arange(n) * (m + 1) + choice).ravel()  # flat index into (n, m + 1)
            weights = np.broadcast_to(prob[:, None], choice.shape).ravel()
            out[c] = np.bincount(cell, weights=weights, minlength=n * (m + 1)).reshape(n, -1)
    return out


def _events(allowed: np.ndarray, max_events: int) -> np.ndarray | None:
    """The feasible joint events (E, n) of n tracks, allowed (n, m + 1) the hypotheses
    each may take (column 0 the miss, always allowed): each row the column each track
    takes, no measurement taken twice; None when there are more than max_events. Events
    are built track by track; each partial event extends at least by the miss, so the
    count never falls and the building stops as soon as it passes max_events."""
    n, m = allowed.shape[0], allowed.shape[1] - 1
    choice = np.zeros((1, 0), dtype=np.int64)
    used = np.zeros((1, m + 1), dtype=bool)  # column 0, the miss, is never used up
    for t in range(n):
        choices = [np.column_stack([choice, np.zeros(len(choice), dtype=np.int64)])]
        uses = [used]
        for col in 1 + np.flatnonzero(allowed[t, 1:]):
            free = ~used[:, col]
            u = used[free]
            u[:, col] = True
            choices.append(np.column_stack([choice[free], np.full(len(u), col)]))
            uses.append(u)
        choice, used = np.concatenate(choices), np.concatenate(uses)
        if len(choice) > max_events:
            return None
    return choice


@lru_cache(maxsize=64)
def _complete(n: int, m: int) -> np.ndarray | None:
    """`_events` of n tracks each gated to all m measurements, if at most GRID_EVENTS."""
    return _events(np.ones((n, m + 1), dtype=bool), GRID_EVENTS)


@lru_cache(maxsize=64)
def _indicator(n: int, m: int) -> np.ndarray:
    """(events, n (m + 1)): 1 where the event of `_complete` gives track t column c."""
    events = _complete(n, m)
    assert events is not None
    out = np.zeros((len(events), n * (m + 1)))
    out[np.arange(len(events))[:, None], np.arange(n) * (m + 1) + events] = 1.0
    return out


def _propagated(miss: np.ndarray, det: np.ndarray) -> np.ndarray:
    """Approximate marginals (n, m + 1) of one cluster by loopy belief propagation
    (Williams and Lau 2014), in logarithms so that no likelihood ratio overflows.

    With psi_kj = w_kj / w_k0 (0 where not gated), the messages iterate
        mu_kj = psi_kj / (1 + sum_{i != j} psi_ki nu_ki)      track k to measurement j
        nu_kj = 1 / (1 + sum_{l != k} mu_lj)                  measurement j to track k
    from nu = 1, and beta_k0 = 1 / s_k, beta_kj = psi_kj nu_kj / s_k with
    s_k = 1 + sum_j psi_kj nu_kj."""
    n, m = det.shape
    log_psi = det - miss[:, None]  # -inf where not gated
    others_m = ~np.eye(m, dtype=bool)  # (j, i): i != j
    others_n = ~np.eye(n, dtype=bool)
    log_nu = np.zeros((n, m))
    for _ in range(LBP_SWEEPS):
        a = log_psi + log_nu  # (n, m)
        excl = np.where(others_m[None], a[:, None, :], -np.inf)  # (n, j, i)
        log_mu = log_psi - np.logaddexp(0.0, _logsumexp(excl))
        excl = np.where(others_n[:, :, None], log_mu[None, :, :], -np.inf)  # (k, l, j)
        new = -np.logaddexp(0.0, _logsumexp(np.swapaxes(excl, 1, 2)))
        change = np.abs(new - log_nu).max()
        log_nu = new
        if change <= LBP_TOLERANCE:
            break
    return _normalised(np.concatenate([np.zeros((n, 1)), log_psi + log_nu], axis=1))


def _logsumexp(a: np.ndarray) -> np.ndarray:
    """log sum exp over the last axis; -inf where every entry is -inf."""
    top = a.max(axis=-1)
    safe = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        return np.log(np.exp(a - safe[..., None]).sum(axis=-1)) + safe
