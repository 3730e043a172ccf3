"""Distributed fusion by max-consensus with per-UAV stopping (eqs. 26-27, Theorem 1).

Per target j, UAV i repeatedly adopts, among itself and its one-hop neighbours, the
(estimate, covariance, confidence) tuple with the highest confidence (eq. 27,
Algorithm 2 lines 17-24). UAV i runs D_i rounds, D_i the depth of the shortest-path
tree rooted at i in its connected component (its eccentricity); Theorem 1 shows that
this is the fewest rounds after which i holds its component's maximum.

The UAVs do not read the global graph: D_i is learned by a flooding protocol in
which each UAV sends its neighbours the set of UAV identifiers it knows to be within
reach (`eccentricity`). A UAV that has finished its rounds keeps relaying its final
tuple to neighbours still iterating: on the path m - j - i, j needs one round but i
needs two, and receives m's value only through j. Messages travel along edges only,
so nothing crosses from one component to another.

All functions broadcast over leading (trial) axes. A round is simulated on the dense
N x N neighbour relation for small teams and on the list of edges for large ones
(`SPARSE_FROM` UAVs); both compute the same thing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .network import closed, without_self_loops

SPARSE_FROM = 24
"""Team size from which consensus rounds run on edge lists rather than N x N arrays."""


@dataclass(frozen=True)
class Consensus:
    """Outcome of one fusion phase.

    source: (..., N, M) index of the UAV whose local estimate of target j UAV i holds.
    rounds: (..., N) D_i, the rounds UAV i ran.
    messages: (...,) tuples sent over the radio (one per edge direction and round in
        which the receiver still iterates; each carries M estimates).
    protocol_messages: (...,) messages of the eccentricity protocol.
    """

    source: np.ndarray
    rounds: np.ndarray
    messages: np.ndarray
    protocol_messages: np.ndarray


def eccentricity(adjacency: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """D_i learned by flooding known identifiers to neighbours (Remark 1, APSP).

    After round r UAV i knows K_i(r), the UAVs within r hops: K_i(r) = K_i(r-1) united
    with the K_l(r-1) its neighbours l sent. The first round that teaches i nothing new
    shows its ball has covered its component, so i stops with D_i = r - 1: it needs no
    knowledge of the team size.

    adjacency: (..., N, N) bool, symmetric; the diagonal is ignored. Returns (D (..., N)
    int, messages (...,)): messages counts one per edge direction in every round the
    receiver still runs.
    """
    adjacency = without_self_loops(adjacency)
    degree = adjacency.sum(axis=-1)
    D = np.zeros(adjacency.shape[:-1], dtype=np.int64)
    if not degree.any():  # nobody hears anybody: round 1 teaches nothing
        return D, np.zeros(adjacency.shape[:-2], dtype=np.int64)
    links = closed(adjacency)
    weights = links.astype(np.float64)
    known = links  # K(1): each UAV and its neighbours
    running = degree > 0  # isolated UAVs learned nothing in round 1: D = 0
    messages = degree.sum(axis=-1)  # round 1: every receiver runs
    r = 1
    while running.any():
        r += 1
        messages = messages + (degree * running).sum(axis=-1)
        grown = (weights @ known.astype(np.float64)) > 0
        stopped = running & ~(grown != known).any(axis=-1)
        D[stopped] = r - 1
        running &= ~stopped
        known = grown
    return D, messages


def consensus_rounds(
    confidence: np.ndarray, adjacency: np.ndarray, rounds: np.ndarray
) -> np.ndarray:
    """Run the max-consensus update (27), UAV i for rounds[i] rounds.

    In round t every UAV sends its current tuple; UAV i with t <= rounds[i] adopts,
    per target, the tuple of highest confidence among itself and its neighbours (ties
    go to the lowest index); UAVs past their rounds keep their tuple and keep sending.

    confidence: (..., N, M); adjacency: (..., N, N) bool (diagonal ignored); rounds:
    (..., N) int. Returns source (..., N, M): index of the UAV whose initial tuple i holds.
    """
    lead = confidence.shape[:-2]
    n, m = confidence.shape[-2:]
    gamma = confidence.reshape(-1, n, m)
    adj = adjacency.reshape(-1, n, n)
    todo = rounds.reshape(-1, n)
    source = _identity(gamma.shape)
    total = int(todo.max(initial=0))
    if total:
        step = _sparse_round(adj) if n >= SPARSE_FROM else _dense_round(adj)
        b = np.arange(gamma.shape[0])[:, None, None]
        j = np.arange(m)
        for t in range(1, total + 1):
            best = step(gamma)  # (B, N, M) neighbour chosen by each UAV, per target
            active = (todo >= t)[..., None]
            source = np.where(active, source[b, best, j], source)
            gamma = np.where(active, gamma[b, best, j], gamma)
    return source.reshape(lead + (n, m))


def _dense_round(adj: np.ndarray):
    """best[b, i, j] = argmax over i's closed neighbourhood of gamma[b, :, j]."""
    mask = np.where(closed(adj), 0.0, -np.inf)[..., None]  # (B, N, N, 1)

    def best(gamma: np.ndarray) -> np.ndarray:
        return np.argmax(gamma[:, None, :, :] + mask, axis=-2)  # first maximum = lowest index

    return best


def _sparse_round(adj: np.ndarray):
    """The same on edge lists: segment maxima over each UAV's incoming edges."""
    B, n, _ = adj.shape
    b, receiver, sender = np.nonzero(closed(adj))  # sorted by (b, receiver), self-edges included
    starts = np.flatnonzero(np.r_[True, (b[1:] != b[:-1]) | (receiver[1:] != receiver[:-1])])
    row = b * n + receiver

    def best(gamma: np.ndarray) -> np.ndarray:
        offered = gamma[b, sender]  # (E, M)
        top = np.maximum.reduceat(offered, starts, axis=0)  # (B*N, M)
        lowest = np.where(offered == top[row], sender[:, None], n)
        return np.minimum.reduceat(lowest, starts, axis=0).reshape(B, n, -1)

    return best


def max_consensus(confidence: np.ndarray, adjacency: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Max-consensus with per-UAV stopping, Algorithm 2 lines 15-25.

    confidence: (..., N, M) floats (gamma = 1/trace P); adjacency: (..., N, N) symmetric
    bool, diagonal ignored. Returns (source (..., N, M), rounds (..., N)): source[i, j]
    is the UAV whose estimate of target j UAV i holds after the protocol, rounds[i] = D_i.
    """
    result = fuse(confidence, adjacency)
    return result.source, result.rounds


def _identity(shape: tuple[int, ...]) -> np.ndarray:
    """source[..., i, j] = i: every UAV holds its own estimates."""
    source = np.empty(shape, dtype=np.int64)
    source[...] = np.arange(shape[-2])[:, None]
    return source


def fuse(confidence: np.ndarray, adjacency: np.ndarray) -> Consensus:
    """The fusion phase with its bookkeeping: protocol for D_i, then the rounds.

    A user-given adjacency may mark a UAV as its own neighbour; the diagonal is ignored.
    """
    adjacency = without_self_loops(adjacency)
    if not adjacency.any():  # nobody hears anybody: no rounds, no messages
        zeros = np.zeros(adjacency.shape[:-1], dtype=np.int64)
        return Consensus(_identity(confidence.shape), zeros, zeros[..., 0], zeros[..., 0])
    rounds, protocol_messages = eccentricity(adjacency)
    source = consensus_rounds(confidence, adjacency, rounds)
    messages = (adjacency.sum(axis=-1) * rounds).sum(axis=-1)
    return Consensus(source, rounds, messages, protocol_messages)


def gather(source: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Pick values[..., source[i, j], j, ...] for every (i, j).

    source: (B, N, M); values: (B, N, M, *event). Returns (B, N, M, *event).
    """
    b = np.arange(source.shape[0])[:, None, None]
    return values[b, source, np.arange(source.shape[-1])]
