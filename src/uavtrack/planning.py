"""Receding-horizon planning by Fisher information, Algorithm 1 lines 1-4.

For every target j, UAV i searches all |A|^h bank-angle sequences and scores each by

    V_ij = sum_{t=1..h} lambda^(t-1) det G_ij(k+t),

G evaluated at the UAV's rolled-out position and the target's position predicted
from the fused estimate, p_j(k+t) = H A^t s_ij(k). The best value is the bid, the
first action of the best sequence is what the UAV flies if it wins target j.

Two facts make this cheap without changing its result:

* the rollouts do not depend on the target: they are computed once per UAV;
* under eq. (1) the position at k+t depends only on the first t-1 actions, so the
  |A|^h sequences visit only 1 + |A| + ... + |A|^(h-1) distinct positions (13 for
  h = 3, against 81 sequence-steps). det G is evaluated once per position, and each
  sequence's score is the sum along its path, added in the same order as an
  exhaustive search adds it, so the choice is bit-identical to `plan_exhaustive`.

Sequences are numbered lexicographically with the first action most significant,
actions ordered (-phi, 0, +phi); ties go to the lowest number. The last action of a
sequence never changes the score (eq. 1), so it is always the lowest.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import cache

import numpy as np

from .config import G, SensorModel
from .estimation import transition
from .sensing import edge_range, fisher_det
from .world import HEADING, V, X, Y, fly, wrap_angle


def action_set(bank_angle: float) -> np.ndarray:
    """Bank angles (-phi, 0, +phi) [rad]."""
    return np.array([-bank_angle, 0.0, bank_angle])


@dataclass(frozen=True)
class Plan:
    """Bids and chosen first actions.

    value: (..., Nu, Nt) best score V_ij (the bid); action: (..., Nu, Nt) index into the
    action set of the first action of the best sequence; sequence: (..., Nu, Nt) its
    lexicographic number in [0, |A|^h).
    """

    value: np.ndarray
    action: np.ndarray
    sequence: np.ndarray


@cache
def _tree(n_actions: int, horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """Paths of the relevant-prefix tree.

    Returns (path (L, horizon) node index of each leaf path at depth t, prefixes
    (L, horizon-1) action indices of leaf path l), with L = |A|^(h-1) leaf paths in
    lexicographic order and nodes numbered depth by depth (depth t has |A|^(t-1)).
    """
    prefixes = np.array(
        list(itertools.product(range(n_actions), repeat=horizon - 1)), dtype=np.int64
    )
    prefixes = prefixes.reshape(-1, horizon - 1)
    path = np.empty((len(prefixes), horizon), dtype=np.int64)
    offset = 0
    for t in range(horizon):
        # node of depth t+1 reached by the first t actions
        code = np.zeros(len(prefixes), dtype=np.int64)
        for a in range(t):
            code = code * n_actions + prefixes[:, a]
        path[:, t] = offset + code
        offset += n_actions**t
    return path, prefixes


def rollout_nodes(
    uavs: np.ndarray, actions: np.ndarray, horizon: int, dt: float, g: float = G
) -> np.ndarray:
    """Ground positions of every node of the rollout tree, eq. (1).

    uavs: (..., Nu, 5). Returns (..., Nu, n_nodes, 2), nodes depth by depth: depth t
    (position at k+t) holds |A|^(t-1) nodes, one per choice of the first t-1 actions.
    """
    n = len(actions)
    turn = g * dt * np.tan(actions) / uavs[..., V][..., None]  # (..., Nu, |A|)
    step = uavs[..., V] * dt  # (..., Nu)
    heading = uavs[..., HEADING][..., None]  # (..., Nu, 1) nodes of the current depth
    pos = uavs[..., [X, Y]][..., None, :]  # (..., Nu, 1, 2)
    levels = []
    for t in range(horizon):
        pos = pos + step[..., None, None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
        levels.append(pos)
        if t < horizon - 1:
            heading = wrap_angle(heading[..., :, None] + turn[..., None, :])
            heading = heading.reshape(heading.shape[:-2] + (-1,))
            pos = np.repeat(pos, n, axis=-2)
    return np.concatenate(levels, axis=-2)


def predict_positions(mean: np.ndarray, horizon: int, dt: float) -> np.ndarray:
    """Predicted target positions H A^t s for t = 1..h.

    mean: (..., 4). Returns (..., h, 2).
    """
    A = transition(dt)
    powers = np.stack([np.linalg.matrix_power(A, t)[:2] for t in range(1, horizon + 1)])
    return np.einsum("tij,...j->...ti", powers, mean)


def plan(
    uavs: np.ndarray,
    mean: np.ndarray,
    sensor: SensorModel,
    bank_angle: float,
    horizon: int,
    dt: float,
    discount: float = 1.0,
    g: float = G,
) -> Plan:
    """Algorithm 1 lines 1-4 for every UAV and target, on the shared-prefix tree.

    uavs: (..., Nu, 5); mean: (..., Nu, Nt, 4) each UAV's fused estimates.
    """
    actions = action_set(bank_angle)
    n = len(actions)
    path, prefixes = _tree(n, horizon)
    nodes = rollout_nodes(uavs, actions, horizon, dt, g)  # (..., Nu, K, 2)
    targets = predict_positions(mean, horizon, dt)  # (..., Nu, Nt, h, 2)
    depth = np.concatenate([np.full(n**t, t) for t in range(horizon)])  # (K,)
    # ground offset of target j at the node's time from each node: (..., Nu, Nt, K, 2)
    delta = targets[..., depth, :] - nodes[..., None, :, :]
    h = uavs[..., 2][..., None, None]
    d = np.sqrt(np.einsum("...k,...k->...", delta, delta) + h * h)
    det = fisher_det(d, edge_range(h, sensor), sensor)  # (..., Nu, Nt, K)
    det = det * discount ** depth.astype(float)
    score = det[..., path[:, 0]]
    for t in range(1, horizon):
        score = score + det[..., path[:, t]]  # left to right, as the exhaustive sum
    best = np.argmax(score, axis=-1)  # (..., Nu, Nt) first maximum = lowest sequence
    value = np.take_along_axis(score, best[..., None], axis=-1)[..., 0]
    first = prefixes[best, 0] if horizon > 1 else np.zeros_like(best)
    return Plan(value=value, action=first, sequence=best * n)


def plan_exhaustive(
    uavs: np.ndarray,
    mean: np.ndarray,
    sensor: SensorModel,
    bank_angle: float,
    horizon: int,
    dt: float,
    discount: float = 1.0,
    g: float = G,
) -> Plan:
    """Reference: roll out every one of the |A|^h sequences step by step with eq. (1).

    Same arguments and result as `plan`; cost |A|^h * h per UAV and target.
    """
    actions = action_set(bank_angle)
    sequences = np.array(list(itertools.product(range(len(actions)), repeat=horizon)))
    targets = predict_positions(mean, horizon, dt)  # (..., Nu, Nt, h, 2)
    state = np.repeat(uavs[..., None, :], len(sequences), axis=-2)  # (..., Nu, S, 5)
    h = uavs[..., 2][..., None, None]
    score = 0.0
    for t in range(horizon):
        state = fly(state, actions[sequences[:, t]], dt, g)
        delta = targets[..., None, :, t, :] - state[..., :, None, :2]  # (..., Nu, S, Nt, 2)
        d = np.sqrt(np.einsum("...k,...k->...", delta, delta) + h * h)
        score = score + discount**t * fisher_det(d, edge_range(h, sensor), sensor)
    score = np.swapaxes(score, -1, -2)  # (..., Nu, Nt, S)
    best = np.argmax(score, axis=-1)
    value = np.take_along_axis(score, best[..., None], axis=-1)[..., 0]
    return Plan(value=value, action=sequences[best, 0], sequence=best)
