"""The measurement gate (``robust.gate``): a UAV adopts no estimate its own measurement
contradicts.

Max-consensus (eq. 27) adopts, per target, the most confident tuple a UAV hears; a
member that claims more confidence than anyone else takes every target over, wherever
it says the target is. Against that a UAV has one thing no neighbour can forge: its own
measurement of the target this cycle. An estimate (x, P) of a target agrees with a
measurement z^C of noise R (eqs. 5-12) when

    nu^T (H P H^T + R)^-1 nu <= g,    nu = z^C - H x,

the test of a Kalman filter's innovation; for an honest estimate nu is zero-mean with
that covariance (the two errors are independent: the sender's estimate does not hold
this measurement), so the squared distance is chi-square with 2 degrees of freedom and
the gate g = -2 ln(1 - p) (`threshold`) passes it with probability p. An estimate that
fails the gate is not adopted for that target, the UAV's own included (a UAV whose
filter took in a lie earlier is then steered back by an honest neighbour who sees the
target); a UAV that did not measure the target gates nothing, and one whose every
candidate fails keeps its own.

`admitted` builds the mask of what each receiver may adopt from each sender in the
layout of `network.Links` (dense (B, N, N, M) or one row per edge, (E, M)), which
`fusion.adopt`, `fusion.intersect_round` and the consensus driver take.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import network
from ..config import SensorModel
from ..sensing import in_view


def threshold(probability: float) -> float:
    """The gate g on a 2-D squared Mahalanobis distance passed with `probability`: the
    chi-square quantile with 2 degrees of freedom, -2 ln(1 - p)."""
    return -2.0 * math.log1p(-probability)


def distance(mean: np.ndarray, cov: np.ndarray, z: np.ndarray, R: np.ndarray) -> np.ndarray:
    """nu^T (H P H^T + R)^-1 nu with nu = z - H x, H = [I 0]: mean (..., 4), cov (..., 4,
    4), z (..., 2), R (..., 2, 2). Returns (...); the 2 x 2 inverse in closed form."""
    s11 = cov[..., 0, 0] + R[..., 0, 0]
    s12 = cov[..., 0, 1] + R[..., 0, 1]
    s22 = cov[..., 1, 1] + R[..., 1, 1]
    n0, n1 = z[..., 0] - mean[..., 0], z[..., 1] - mean[..., 1]
    return (s22 * n0 * n0 - 2.0 * s12 * n0 * n1 + s11 * n1 * n1) / (s11 * s22 - s12 * s12)


@dataclass(frozen=True)
class Measured:
    """What each UAV measured, per target: observed (B, N, M) bool, this cycle; the
    converted measurements z (B, N, M, 2) and their noise R (B, N, M, 2, 2) (0 and I
    where not observed); recent (B, N, M) bool: measured within the last
    ``robust.gate_memory`` cycles but not in this one."""

    observed: np.ndarray
    z: np.ndarray
    R: np.ndarray
    recent: np.ndarray

    @classmethod
    def of(cls, observed: np.ndarray, z: np.ndarray, R: np.ndarray, recent: np.ndarray) -> Measured:
        """From the K observing pairs in the order of ``np.nonzero(observed)`` (as
        `simulation.sense` gives them): z (K, 2), R (K, 2, 2)."""
        full_z = np.zeros(observed.shape + (2,))
        full_R = np.broadcast_to(np.eye(2), observed.shape + (2, 2)).copy()
        full_z[observed], full_R[observed] = z, R
        return cls(observed, full_z, full_R, recent & ~observed)


def seen(last: np.ndarray | None, observed: np.ndarray, k: int) -> np.ndarray:
    """The step each UAV last measured each target, after cycle k: `last` (B, N, M)
    where not `observed`, k where observed. None: the run's start, where the initial
    cue of every target (the prior, ``estimation.initial_position_std``) counts as a
    measurement at step 0."""
    before = np.zeros(observed.shape, dtype=np.int64) if last is None else last
    return np.where(observed, k, before)


def recent(last: np.ndarray | None, k: int, memory: int, shape: tuple[int, ...]) -> np.ndarray:
    """Whether each UAV measured each target within the `memory` cycles before k, from
    `last` (`seen`; None: only the initial cue, at step 0). Returns `shape` (B, N, M)."""
    if last is None:
        return np.full(shape, k <= memory)
    return k - last <= memory


def agreeing(
    mean: np.ndarray,
    cov: np.ndarray,
    measured: Measured,
    gate: float,
    own: tuple[np.ndarray, np.ndarray],
) -> np.ndarray:
    """Whether each UAV may take an estimate of each target offered to it alone (the
    central node's download), by the rule of `admitted`: against its measurement,
    else, if it measured the target recently, against its own estimate `own`. mean
    (B, N, M, 4), cov (B, N, M, 4, 4). Returns (B, N, M)."""
    far = distance(mean, cov, measured.z, measured.R) > gate
    apart = distance(mean, cov, own[0][..., :2], own[1][..., :2, :2]) > gate
    return np.where(measured.observed, ~far, ~(measured.recent & apart))


def admitted(
    links: network.Links,
    own: tuple[np.ndarray, np.ndarray],
    offered: tuple[np.ndarray, np.ndarray],
    measured: Measured,
    gate: float,
    claimed: np.ndarray | None = None,
) -> np.ndarray:
    """Per link (receiver i, sender q) and target j, whether i may adopt q's estimate
    of j: it agrees with i's measurement of j within `gate`; where i did not measure j
    this cycle but did recently, it agrees with i's own current estimate (its position
    error covariance the sum of the two); where i has not measured j recently, always.
    The self-link carries the receiver's own current estimate.

    own, offered: (mean (B, N, M, 4), cov (B, N, M, 4, 4)), the receivers' current
    estimates and what the senders offered; claimed (B, N, M): which offered estimates a
    sender claims (None: all; a target a listed message leaves out, ``fusion.trigger`` or
    the compact encoding, is no claim and cannot catch its sender). Returns (B, N, N, M)
    in the dense form, (E, M) in the edge form."""
    t, i, q = links.pairs()
    self_link = links.own[:, None] if links.edges else (i == q)[..., None]
    mine_mean, mine_cov = own[0][t, i], own[1][t, i]
    mean = np.where(self_link[..., None], mine_mean, offered[0][t, q])
    cov = np.where(self_link[..., None, None], mine_cov, offered[1][t, q])
    observed = measured.observed[t, i]
    far = distance(mean, cov, measured.z[t, i], measured.R[t, i]) > gate
    # measured recently: against its own estimate, the position covariances summed
    apart = distance(mean, cov, mine_mean[..., :2], mine_cov[..., :2, :2]) > gate
    caught = ((observed & far) | (measured.recent[t, i] & apart)) & ~self_link
    if claimed is not None:
        caught &= claimed[t, q]
    # a sender caught on one target is believed on none this round
    return ~(caught.any(axis=-1, keepdims=True) | (observed & far))


@dataclass(frozen=True, kw_only=True)
class Scanned:
    """What the gate reads of each receiver's own scan, with tracks: z (R, Z, 2), R (R,
    Z, 2, 2), valid (R, Z) its converted measurements, uav (R, 5) where it believes it
    is, and recent (R, K) which of its slots its own scans met within the last
    ``robust.gate_memory`` cycles (this one included); R receivers in `row` order."""

    z: np.ndarray
    R: np.ndarray
    valid: np.ndarray
    uav: np.ndarray
    recent: np.ndarray


def tracks_admitted(
    row: np.ndarray,
    sender: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    slot: np.ndarray,
    own: tuple[np.ndarray, np.ndarray],
    scanned: Scanned,
    sensor: SensorModel,
    gate: float,
) -> np.ndarray:
    """Which offered tracks each receiver may take, the rule of `admitted` with tracks.

    An offer of a label the receiver holds, in a slot its own scans met recently, must
    agree with that slot's estimate (position covariances summed). Any other offer must
    agree with one of the receiver's measurements this scan, unless it lies outside the
    receiver's view (where it saw nothing, it can refute nothing). A sender caught
    against a recently met slot is believed on nothing more in this round.

    row (O,) each offer's receiver (a row of `scanned`), sender (O,), mean (O, 4), cov
    (O, 4, 4); slot (O,) the receiver's slot holding the offer's label in `own`, flat
    (-1: none; slot k of a receiver is some multiple of K plus k); own: the receivers'
    current slots, flat (mean (S, 4), cov (S, 4, 4)). Returns (O,) bool."""
    at = np.maximum(slot, 0)
    checked = (slot >= 0) & scanned.recent[row, at % scanned.recent.shape[-1]]
    apart = distance(mean, cov, own[0][at, :2], own[1][at, :2, :2]) > gate
    near = (
        scanned.valid[row]
        & (distance(mean[:, None], cov[:, None], scanned.z[row], scanned.R[row]) <= gate)
    ).any(axis=-1)
    unseen = ~in_view(scanned.uav[row], mean, sensor)
    caught = checked & apart
    key = row * (int(sender.max(initial=0)) + 1) + sender
    liar = np.isin(key, key[caught])
    return np.where(checked, ~apart, near | unseen) & ~liar
