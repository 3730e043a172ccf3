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

All functions broadcast over leading (trial) axes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .network import closed


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

    adjacency: (..., N, N) bool, symmetric. Returns (D (..., N) int, messages (...,)):
    messages counts one per edge direction in every round the receiver still runs.
    """
    links = closed(adjacency).astype(np.float32)
    known = np.broadcast_to(np.eye(adjacency.shape[-1], dtype=bool), adjacency.shape).copy()
    D = np.full(adjacency.shape[:-1], -1, dtype=np.int64)
    degree = adjacency.sum(axis=-1)
    messages = np.zeros(adjacency.shape[:-2], dtype=np.int64)
    r = 0
    while (D < 0).any():
        r += 1
        running = D < 0
        messages += (degree * running).sum(axis=-1)
        grown = (links @ known.astype(np.float32)) > 0
        learned = (grown & ~known).any(axis=-1)
        D = np.where(running & ~learned, r - 1, D)
        known = grown
    return D, messages


def consensus_rounds(
    confidence: np.ndarray, adjacency: np.ndarray, rounds: np.ndarray
) -> np.ndarray:
    """Run the max-consensus update (27), UAV i for rounds[i] rounds.

    In round t every UAV sends its current tuple; UAV i with t <= rounds[i] adopts,
    per target, the tuple of highest confidence among itself and its neighbours (ties
    go to the lowest index); UAVs past their rounds keep their tuple and keep sending.

    confidence: (..., N, M); adjacency: (..., N, N) bool; rounds: (..., N) int.
    Returns source (..., N, M): index of the UAV whose initial tuple i holds.
    """
    n = adjacency.shape[-1]
    links = closed(adjacency)
    source = np.broadcast_to(np.arange(n)[:, None], confidence.shape).copy()
    gamma = confidence.copy()
    for t in range(1, int(rounds.max(initial=0)) + 1):
        # offer[..., i, l, j]: what neighbour l offers i for target j (-inf off the graph)
        offer = np.where(links[..., :, :, None], gamma[..., None, :, :], -np.inf)
        best = np.argmax(offer, axis=-2)  # (..., N, M), first maximum = lowest index
        active = (rounds >= t)[..., None]
        source = np.where(active, np.take_along_axis(source, best, axis=-2), source)
        gamma = np.where(active, np.take_along_axis(gamma, best, axis=-2), gamma)
    return source


def max_consensus(confidence: np.ndarray, adjacency: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Max-consensus with per-UAV stopping, Algorithm 2 lines 15-25.

    confidence: (..., N, M) floats (gamma = 1/trace P); adjacency: (..., N, N) symmetric
    bool. Returns (source (..., N, M), rounds (..., N)): source[i, j] is the UAV whose
    estimate of target j UAV i holds after the protocol, rounds[i] = D_i.
    """
    result = fuse(confidence, adjacency)
    return result.source, result.rounds


def fuse(confidence: np.ndarray, adjacency: np.ndarray) -> Consensus:
    """The fusion phase with its bookkeeping: protocol for D_i, then the rounds."""
    rounds, protocol_messages = eccentricity(adjacency)
    source = consensus_rounds(confidence, adjacency, rounds)
    messages = (adjacency.sum(axis=-1) * rounds).sum(axis=-1)
    return Consensus(source, rounds, messages, protocol_messages)


def gather(source: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Pick values[..., source[i, j], j, ...] for every (i, j).

    source: (..., N, M); values: (..., N, M, *event). Returns (..., N, M, *event).
    """
    extra = values.ndim - source.ndim
    index = source.reshape(source.shape + (1,) * extra)
    return np.take_along_axis(values, index, axis=-2 - extra)
