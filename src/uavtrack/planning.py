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
  h = 3, against 81 sequence-steps). det G is evaluated once per position (det G has
  a closed form in the slant range, `sensing.fisher_det`) and each sequence's score
  is the sum along its path; the tree's positions come in closed form from index
  tables, with no loop over sequences. The choices equal `plan_exhaustive`'s, which
  flies every sequence step by step (the scores agree to round-off).

Sequences are numbered lexicographically with the first action most significant,
actions ordered (-phi, 0, +phi); ties go to the lowest number. The last action of a
sequence never changes the score (eq. 1), so it is always the lowest.
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
from dataclasses import dataclass
from functools import cache

import numpy as np

from .config import G, SensorModel
from .sensing import edge_range, fisher_det, fisher_det_bound
from .world import HEADING, V, X, Y, fly


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


@dataclass(frozen=True)
class Tree:
    """The relevant-prefix tree of |A|^h sequences, as index tables.

    Nodes are numbered depth by depth; depth t (the position at k+t+1) has |A|^t nodes,
    one per choice of the first t actions, numbered parent * |A| + action.

    depth (K,): depth of each node; counts (K, |A|): how often each action occurs among
    the node's actions; first (L,): the first action of each of the L = |A|^(h-1) paths
    to the deepest nodes, in lexicographic order.
    """

    depth: np.ndarray
    counts: np.ndarray
    first: np.ndarray


@cache
def tree(n_actions: int, horizon: int) -> Tree:
    """Index tables of the rollout tree (cached per |A| and h)."""
    prefixes = [p for t in range(horizon) for p in itertools.product(range(n_actions), repeat=t)]
    depth = np.array([len(p) for p in prefixes])
    counts = np.array(
        [np.bincount(np.array(p, dtype=int), minlength=n_actions) for p in prefixes], dtype=float
    )
    leaves = itertools.product(range(n_actions), repeat=horizon - 1)
    first = np.array([leaf[0] if leaf else 0 for leaf in leaves], dtype=np.int64)
    return Tree(depth, counts, first)


def rollout_nodes(
    uavs: np.ndarray, actions: np.ndarray, horizon: int, dt: float, g: float = G
) -> np.ndarray:
    """Ground positions of every node of the rollout tree, eq. (1), in closed form.

    uavs: (..., Nu, 5). Returns (..., Nu, K, 2), K = 1 + |A| + ... + |A|^(h-1).
    """
    east, north = _rollout(uavs, actions, horizon, dt, g)
    out = np.empty(east.shape + (2,))
    out[..., 0], out[..., 1] = east, north
    return out


def _rollout(
    uavs: np.ndarray, actions: np.ndarray, horizon: int, dt: float, g: float
) -> tuple[np.ndarray, np.ndarray]:
    """Node coordinates (x, y), each (..., Nu, K), level by level.

    A node at depth t is its parent moved by V dT (cos psi, sin psi), psi the heading
    after the node's t actions: psi = psi_k + (g dT / V) times the sum of tan(phi) over
    them. Nodes of depth t are numbered parent * |A| + action.
    """
    n = len(actions)
    t = tree(n, horizon)
    tangents = t.counts @ np.tan(actions)  # (K,) sum of tan(phi) over each node's actions
    heading = uavs[..., HEADING, None] + tangents * (g * dt / uavs[..., V, None])  # (..., Nu, K)
    step = (uavs[..., V] * dt)[..., None]
    out: list[np.ndarray] = []
    for base, trig in ((uavs[..., X, None], np.cos), (uavs[..., Y, None], np.sin)):
        moves = step * trig(heading)
        level = base + moves[..., :1]
        levels, offset = [level], 1
        for depth in range(1, horizon):
            children = moves[..., offset : offset + n**depth].reshape(moves.shape[:-1] + (-1, n))
            level = (level[..., :, None] + children).reshape(moves.shape[:-1] + (-1,))
            levels.append(level)
            offset += n**depth
        out.append(np.concatenate(levels, axis=-1))
    return out[0], out[1]


def air_relative(uavs: np.ndarray, drift: np.ndarray) -> np.ndarray:
    """UAV states (..., 5) over the ground (V the ground speed, heading the course) as
    states in an air mass moving at `drift` (2,) [m/s]: V the airspeed, heading the
    direction through the air."""
    out = uavs.copy()
    east = uavs[..., V] * np.cos(uavs[..., HEADING]) - drift[0]
    north = uavs[..., V] * np.sin(uavs[..., HEADING]) - drift[1]
    out[..., V], out[..., HEADING] = np.hypot(east, north), np.arctan2(north, east)
    return out


def predict_positions(mean: np.ndarray, horizon: int, dt: float) -> np.ndarray:
    """Predicted target positions H A^t s = p + t dT v for t = 1..h (eq. 14).

    mean: (..., 4). Returns (..., h, 2).
    """
    lead = dt * np.arange(1, horizon + 1)[:, None]
    return mean[..., None, :2] + lead * mean[..., None, 2:]


CHUNK_BYTES = 64 * 2**20
"""Working memory of one planning pass; larger problems are planned a block of UAVs at a time."""


def floats_per_pair(n_actions: int, horizon: int) -> int:
    """Floats the planner holds at its peak per (UAV, target) pair: the tree's K nodes
    (offsets, ranges and three temporaries of det G) and the L leaf scores, twice."""
    K = sum(n_actions**t for t in range(horizon))
    return 5 * K + 2 * n_actions ** (horizon - 1)


def memory(rows: int, n_targets: int, n_actions: int, horizon: int) -> int:
    """Peak bytes of `plan` for `rows` UAVs (trials times team) and `n_targets` targets."""
    per_row = n_targets * floats_per_pair(n_actions, horizon) * 8
    return min(rows * per_row, max(CHUNK_BYTES, per_row)) + rows * n_targets * 3 * 8


def plan(
    uavs: np.ndarray,
    mean: np.ndarray,
    sensor: SensorModel,
    bank_angle: float,
    horizon: int,
    dt: float,
    discount: float = 1.0,
    g: float = G,
    top: np.ndarray | None = None,
    drift: np.ndarray | None = None,
) -> Plan:
    """Algorithm 1 lines 1-4 for every UAV and target, on the shared-prefix tree.

    uavs: (..., Nu, 5); mean: (..., Nu, Nt, 4) each UAV's fused estimates. Every
    (UAV, target) pair is scored on its own, so planning a block of UAVs at a time (to
    bound the memory, `CHUNK_BYTES`) gives the same result bit for bit.

    top: (..., Nu) int, how many of its best bids each UAV needs (None: all). Then only
    the targets that can be among them are scored (`plan_top`); the others get value
    NaN and action and sequence -1. Every value returned equals the full search's.

    drift: (2,) a steady wind [m/s] (east, north) the UAVs drift with (None: none, the
    paper's eq. 1). Then `uavs` hold airspeed and air heading (`air_relative`), each
    node is flown in the air mass and moved by the drift over its time from now.
    """
    if top is not None:
        return plan_top(uavs, mean, sensor, bank_angle, horizon, dt, discount, g, top, drift)
    lead, nt = uavs.shape[:-1], mean.shape[-2]
    per_row = nt * floats_per_pair(3, horizon) * 8
    rows = int(np.prod(lead))
    if rows * per_row <= CHUNK_BYTES:
        return _plan(uavs, mean, sensor, bank_angle, horizon, dt, discount, g, drift)
    flat_uavs, flat_mean = uavs.reshape(rows, 5), mean.reshape(rows, nt, 4)
    block = max(1, CHUNK_BYTES // per_row)
    parts = [
        _plan(
            flat_uavs[r : r + block],
            flat_mean[r : r + block],
            sensor,
            bank_angle,
            horizon,
            dt,
            discount,
            g,
            drift,
        )
        for r in range(0, rows, block)
    ]
    return Plan(
        *(
            np.concatenate([getattr(p, name) for p in parts]).reshape(lead + (nt,))
            for name in ("value", "action", "sequence")
        )
    )


PRUNE_SLACK = 8
"""Targets scored beyond a UAV's `top` in the first pass of `plan_top`."""


def plan_top(
    uavs: np.ndarray,
    mean: np.ndarray,
    sensor: SensorModel,
    bank_angle: float,
    horizon: int,
    dt: float,
    discount: float,
    g: float,
    top: np.ndarray,
    drift: np.ndarray | None = None,
) -> Plan:
    """`plan` scoring only the targets that can be among each UAV's `top` best bids.

    Within the horizon a UAV moves at most h (V + |drift|) dT and target j's predicted position at
    most h dT |v_j| (eq. 14), so every slant range the search evaluates is at least
    d_lb = sqrt(max(0, r - h dT (V + |v_j|))^2 + h_i^2), r the ground distance now, and
    since `sensing.fisher_det_bound` is non-increasing, V_ij <= bound(d_lb) sum_t
    lambda^t. Per UAV the targets are taken in increasing order of that lower bound:
    the first w (w = top + `PRUNE_SLACK`, doubled until it suffices) are scored exactly;
    which ones depends only on the UAV's own state, estimates and top (not on the other
    UAVs or trials planned with it);
    when the bound of the next one is below the top-th best score found, no target left
    out can reach the UAV's `top` best, ties included. A UAV whose bound never falls
    low enough is scored in full.

    uavs (..., Nu, 5), mean (..., Nu, Nt, 4), top (..., Nu). Returns a `Plan` with NaN
    values (action and sequence -1) where a target was not scored.
    """
    lead, nt = uavs.shape[:-1], mean.shape[-2]
    top = np.asarray(top)
    if nt <= PRUNE_SLACK + 1 or bool((top >= nt - PRUNE_SLACK).all()):
        # every UAV's first pass covers all targets (a small team's always): the full search
        return plan(uavs, mean, sensor, bank_angle, horizon, dt, discount, g, None, drift)
    rows = int(np.prod(lead))
    flat_uavs, flat_mean = uavs.reshape(rows, 5), mean.reshape(rows, nt, 4)
    need = np.clip(top.reshape(rows), 1, nt)
    value = np.full((rows, nt), np.nan)
    action = np.full((rows, nt), -1, dtype=np.int64)
    sequence = np.full((rows, nt), -1, dtype=np.int64)
    altitude = flat_uavs[:, 2, None]
    speed = flat_uavs[:, V, None] + (0.0 if drift is None else float(np.hypot(*drift)))
    reach = horizon * dt * (speed + np.hypot(flat_mean[..., 2], flat_mean[..., 3]))
    ground = np.hypot(
        flat_mean[..., 0] - flat_uavs[:, X, None], flat_mean[..., 1] - flat_uavs[:, Y, None]
    )
    gap = ground - reach - 1e-6 * (1.0 + ground)  # the slack covers round-off
    weight = sum(discount**t for t in range(horizon))
    args = (sensor, bank_angle, horizon, dt, discount, g, None, drift)
    width = need + PRUNE_SLACK  # per UAV: what is scored depends on its own data only
    pending = np.arange(rows)
    while pending.size:
        left = []
        whole = width[pending] >= nt
        if whole.any():  # score these in full, together
            these = pending[whole]
            full = plan(flat_uavs[these], flat_mean[these], *args)
            value[these], action[these], sequence[these] = full.value, full.action, full.sequence
            pending = pending[~whole]
        for w in np.unique(width[pending]).tolist():
            these = pending[width[pending] == w]
            order = np.argpartition(gap[these], w, axis=1)
            chosen, after = order[:, :w], order[:, w]  # the w nearest, and the next one
            part = plan(flat_uavs[these], flat_mean[these[:, None], chosen], *args)
            kth = -np.sort(-part.value, axis=1)[np.arange(these.size), need[these] - 1]
            nearest = np.maximum(gap[these, after], 0.0)
            d_edge = edge_range(altitude[these, 0], sensor)
            d_lb = np.sqrt(nearest * nearest + altitude[these, 0] ** 2)
            done = fisher_det_bound(d_lb, d_edge, sensor) * weight < kth
            r, c = these[done, None], chosen[done]
            value[r, c], action[r, c], sequence[r, c] = (
                part.value[done],
                part.action[done],
                part.sequence[done],
            )
            left.append(these[~done])
        pending = np.concatenate(left) if left else np.zeros(0, dtype=np.int64)
        width[pending] *= 2
    return Plan(
        value.reshape(lead + (nt,)), action.reshape(lead + (nt,)), sequence.reshape(lead + (nt,))
    )


def _plan(
    uavs: np.ndarray,
    mean: np.ndarray,
    sensor: SensorModel,
    bank_angle: float,
    horizon: int,
    dt: float,
    discount: float,
    g: float,
    drift: np.ndarray | None = None,
) -> Plan:
    score = _scores(uavs, mean, sensor, bank_angle, horizon, dt, discount, g, drift)
    best = np.argmax(score, axis=-1)  # first maximum = lowest sequence
    return Plan(value=score.max(axis=-1), action=tree(3, horizon).first[best], sequence=best * 3)


def first_values(
    uavs: np.ndarray,
    mean: np.ndarray,
    sensor: SensorModel,
    bank_angle: float,
    horizon: int,
    dt: float,
    discount: float = 1.0,
    g: float = G,
    drift: np.ndarray | None = None,
) -> np.ndarray:
    """The best score V_ij of the sequences that start with each action: (..., Nu, Nt,
    |A|), whose maximum over the last axis is `plan`'s value (what a UAV loses by
    flying another first action, for a filter that must override it)."""
    score = _scores(uavs, mean, sensor, bank_angle, horizon, dt, discount, g, drift)
    return score.reshape(score.shape[:-1] + (3, -1)).max(axis=-1)  # first action leads


def _scores(
    uavs: np.ndarray,
    mean: np.ndarray,
    sensor: SensorModel,
    bank_angle: float,
    horizon: int,
    dt: float,
    discount: float,
    g: float,
    drift: np.ndarray | None = None,
) -> np.ndarray:
    """The score of each of the L = |A|^(h-1) leaf paths (..., Nu, Nt, L), lexicographic."""
    actions = action_set(bank_angle)
    t = tree(len(actions), horizon)
    east, north = _rollout(uavs, actions, horizon, dt, g)  # (..., Nu, K)
    lead = dt * (t.depth + 1.0)  # time from now to each node
    if drift is not None:  # flown in the air mass, which moves
        east, north = east + lead * drift[0], north + lead * drift[1]
    dx = lead * mean[..., 2, None]  # (..., Nu, Nt, K): target minus node, along x
    dx += mean[..., 0, None]
    dx -= east[..., None, :]
    dy = lead * mean[..., 3, None]
    dy += mean[..., 1, None]
    dy -= north[..., None, :]
    h = uavs[..., 2, None, None]
    np.square(dx, out=dx)
    dx += np.square(dy, out=dy)
    dx += h * h
    d = np.sqrt(dx, out=dx)
    det = fisher_det(d, edge_range(h, sensor), sensor)
    if discount != 1.0:
        det = det * discount ** t.depth.astype(float)
    n, score, offset = len(actions), det[..., :1], 1  # depth 1 has a single node
    for depth in range(1, horizon):  # every path so far continues with each action
        level = det[..., offset : offset + n**depth]  # node code = parent * n + action
        offset += n**depth
        score = (score[..., :, None] + level.reshape(level.shape[:-1] + (-1, n))).reshape(
            level.shape
        )
    return score  # (..., Nu, Nt, L): the sum along each of the L = n^(h-1) leaf paths


def plan_exhaustive(
    uavs: np.ndarray,
    mean: np.ndarray,
    sensor: SensorModel,
    bank_angle: float,
    horizon: int,
    dt: float,
    discount: float = 1.0,
    g: float = G,
    drift: np.ndarray | None = None,
) -> Plan:
    """Reference: roll out every one of the |A|^h sequences step by step with eq. (1).

    Same arguments and result as `plan`; cost |A|^h * h per UAV and target.
    """
    moved = np.zeros(2) if drift is None else np.asarray(drift, dtype=float)
    actions = action_set(bank_angle)
    sequences = np.array(list(itertools.product(range(len(actions)), repeat=horizon)))
    targets = predict_positions(mean, horizon, dt)  # (..., Nu, Nt, h, 2)
    state = np.repeat(uavs[..., None, :], len(sequences), axis=-2)  # (..., Nu, S, 5)
    h = uavs[..., 2][..., None, None]
    score = 0.0
    for t in range(horizon):
        state = fly(state, actions[sequences[:, t]], dt, g)
        ground = state[..., :2] + (t + 1) * dt * moved  # the air mass moved meanwhile
        delta = targets[..., None, :, t, :] - ground[..., :, None, :]  # (..., Nu, S, Nt, 2)
        d = np.sqrt(np.einsum("...k,...k->...", delta, delta) + h * h)
        score = score + discount**t * fisher_det(d, edge_range(h, sensor), sensor)
    score = np.swapaxes(score, -1, -2)  # (..., Nu, Nt, S)
    best = np.argmax(score, axis=-1)
    value = np.take_along_axis(score, best[..., None], axis=-1)[..., 0]
    return Plan(value=value, action=sequences[best, 0], sequence=best)
