"""Local estimation: one Kalman filter per (UAV, target), eqs. (22)-(25).

All functions broadcast over leading axes; states are ``(..., 4)`` = x, y, vx, vy and
covariances ``(..., 4, 4)``. The measurement is the converted position z^C = H s + v
(eq. 6) with H = [I_2 0].
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from .numerics.buffers import Buffers, take

if TYPE_CHECKING:
    from .config import TrackerModel


def transition(dt: float) -> np.ndarray:
    """State transition A of the nearly-constant-velocity model, eq. (14)."""
    A = np.eye(4)
    A[0, 2] = A[1, 3] = dt
    return A


def turn_transition(dt: float, omega: float) -> np.ndarray:
    """State transition of a coordinated turn at the known rate `omega` [rad/s] (the
    velocity rotates by omega dT; position integrates it exactly); the CV matrix at 0."""
    if omega == 0:
        return transition(dt)
    s, c = np.sin(omega * dt), np.cos(omega * dt)
    return np.array(
        [
            [1, 0, s / omega, -(1 - c) / omega],
            [0, 1, (1 - c) / omega, s / omega],
            [0, 0, c, -s],
            [0, 0, s, c],
        ]
    )


def process_noise(dt: float, sigma_1: float, sigma_2: float) -> np.ndarray:
    """Process noise Q for white acceleration noise, eq. (15), in the state order x, y, vx, vy.

    Per axis Q = sigma^2 [[dT^4/4, dT^3/2], [dT^3/2, dT^2]] (Gamma Gamma^T sigma^2 with
    Gamma = [dT^2/2, dT]^T). The printed eq. (15) writes dT^2/4, dT/2, 1 and orders the
    blocks (x, vx), (y, vy); at dT = 1 s both are the same matrix, and this form keeps
    sigma in m/s^2 for other time steps. The printed matrix is this one with sigma / dT
    (`Scenario.acceleration_std` under ``target.noise_form = "printed"``).
    """
    Q = np.zeros((4, 4))
    for pos, vel, sigma in ((0, 2, sigma_1), (1, 3, sigma_2)):
        var = sigma**2
        Q[pos, pos] = var * dt**4 / 4
        Q[pos, vel] = Q[vel, pos] = var * dt**3 / 2
        Q[vel, vel] = var * dt**2
    return Q


def predict(
    mean: np.ndarray,
    cov: np.ndarray,
    A: np.ndarray,
    Q: np.ndarray,
    buffers: Buffers | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Prediction, eq. (23): s(k|k-1) = A s(k-1), P(k|k-1) = A P(k-1) A^T + Q.

    All filters at once: vec(A P A^T) = (A kron A) vec(P), one matrix product per
    block of `BLOCK` filters (the block and its result stay in cache; every filter's
    numbers are the same whatever the block). buffers: a run's (`numerics.buffers`),
    into whose "predicted" arrays the results go; new arrays without.
    """
    shape = cov.shape
    moved = take(buffers, "predicted mean", mean.shape)
    np.matmul(mean.reshape(-1, 4), A.T, out=moved.reshape(-1, 4))
    mean = moved
    flat, kron, q = cov.reshape(-1, 16), _kron(A.tobytes()).T, Q.reshape(16)
    out = take(buffers, "predicted cov", shape).reshape(flat.shape)
    for start in range(0, flat.shape[0], BLOCK):
        block = out[start : start + BLOCK]
        np.matmul(flat[start : start + BLOCK], kron, out=block)
        block += q
    return mean, out.reshape(shape)


BLOCK = 8192
"""Filters processed at once by `predict` and `nees` on large stacks."""


@lru_cache(maxsize=8)
def _kron(A_bytes: bytes) -> np.ndarray:
    A = np.frombuffer(A_bytes).reshape(4, 4)
    return np.kron(A, A)


def update(
    mean: np.ndarray, cov: np.ndarray, z: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Measurement update with z = H s + v, v ~ N(0, R), eq. (25).

    The gain uses the predicted covariance, K = P H^T S^-1 with S = H P H^T + R (the
    printed eq. 25 shows the previous posterior in S; the standard filter is meant).
    The covariance is P - K S K^T = P - K (P H^T)^T, symmetrised, which keeps it
    symmetric positive definite; S^-1 is the closed-form 2 x 2 inverse.

    mean: (..., 4); cov: (..., 4, 4); z: (..., 2); R: (..., 2, 2).
    """
    PHt = cov[..., :, :2]  # (..., 4, 2) = P H^T
    s11 = cov[..., 0, 0] + R[..., 0, 0]
    s12 = cov[..., 0, 1] + R[..., 0, 1]
    s22 = cov[..., 1, 1] + R[..., 1, 1]
    inv_det = 1.0 / (s11 * s22 - s12 * s12)
    i11, i12, i22 = (
        (s22 * inv_det)[..., None],
        (-s12 * inv_det)[..., None],
        (s11 * inv_det)[..., None],
    )
    K0 = PHt[..., 0] * i11 + PHt[..., 1] * i12  # columns of K, (..., 4)
    K1 = PHt[..., 0] * i12 + PHt[..., 1] * i22
    nu = z - mean[..., :2]
    mean = mean + K0 * nu[..., 0, None] + K1 * nu[..., 1, None]
    KSKt = K0[..., :, None] * PHt[..., None, :, 0] + K1[..., :, None] * PHt[..., None, :, 1]
    cov = cov - 0.5 * (KSKt + np.swapaxes(KSKt, -1, -2))
    return mean, cov


def filter_step(
    mean: np.ndarray,
    cov: np.ndarray,
    observed: np.ndarray,
    z: np.ndarray,
    R: np.ndarray,
    A: np.ndarray | None,
    Q: np.ndarray | None,
    owned: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 2, lines 1-13: predict every filter, update those that observed.

    Unobserved pairs keep the prediction (eq. 24). A and Q may be None to skip the
    prediction (the first step, where the prior already refers to step 0).

    mean (..., 4), cov (..., 4, 4); observed (...) bool; z (K, 2) and R (K, 2, 2) the
    measurements of the K observing pairs, in the order of ``np.nonzero(observed)``.
    Returns (mean, cov) of the same shapes. owned: the caller gives up `mean` and `cov`
    (a run's last state): without a prediction they are updated in place, not copied.
    """
    if (A is None) != (Q is None):
        raise ValueError("A and Q are given together, or neither")
    if A is not None and Q is not None:
        mean, cov = predict(mean, cov, A, Q)  # new arrays: updated in place below
    elif z.shape[0] and not owned:
        mean, cov = mean.copy(), cov.copy()  # the caller's arrays stay as they were
    if z.shape[0]:
        mean[observed], cov[observed] = update(mean[observed], cov[observed], z, R)
    return mean, cov


def confidence(cov: np.ndarray) -> np.ndarray:
    """Perception confidence gamma = 1 / trace(P), eq. (22). cov: (..., 4, 4) -> (...).

    The diagonal is summed in order, as `numpy.trace` does, without its overhead."""
    if cov.shape[-2:] != (4, 4):
        return 1.0 / np.trace(cov, axis1=-2, axis2=-1)
    return 1.0 / (((cov[..., 0, 0] + cov[..., 1, 1]) + cov[..., 2, 2]) + cov[..., 3, 3])


def nees(mean: np.ndarray, cov: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared e^T P^-1 e, e = truth - mean. Returns (...).

    For the 4-D state it is computed elementwise by blocks: with P = [[A, B], [B^T, C]]
    (2 x 2 blocks) and e = (e1, e2), e^T P^-1 e = e1^T A^-1 e1 + f^T S^-1 f where
    f = e2 - B^T A^-1 e1 and S = C - B^T A^-1 B (the Schur complement).
    """
    e = truth - mean
    if e.shape[-1] != 4:
        e = np.broadcast_to(e, np.broadcast_shapes(e.shape, cov.shape[:-1]))
        return np.einsum("...i,...i->...", e, np.linalg.solve(cov, e[..., None])[..., 0])
    shape = np.broadcast_shapes(e.shape[:-1], cov.shape[:-2])
    P = np.broadcast_to(cov, shape + (4, 4)).reshape(-1, 16)
    e = np.broadcast_to(e, shape + (4,)).reshape(-1, 4)
    out = np.empty(P.shape[0])
    for start in range(0, P.shape[0], BLOCK):  # each block stays in cache
        out[start : start + BLOCK] = _nees(P[start : start + BLOCK], e[start : start + BLOCK])
    return out.reshape(shape)


def _nees(P: np.ndarray, e: np.ndarray) -> np.ndarray:
    """`nees` of filters P (n, 16) with errors e (n, 4)."""
    # component-major copies: each P_ij and e_i a contiguous row
    P = np.ascontiguousarray(P.T)
    e0, e1, e2, e3 = np.ascontiguousarray(e.T)
    a11, a12, a22 = P[0], P[1], P[5]
    p02, p12, p03, p13 = P[2], P[6], P[3], P[7]
    inv_det = 1.0 / (a11 * a22 - a12 * a12)

    def solve_a(x0: np.ndarray, x1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # A^-1 x
        return (a22 * x0 - a12 * x1) * inv_det, (a11 * x1 - a12 * x0) * inv_det

    u0, u1 = solve_a(e0, e1)  # A^-1 e1
    b0, b1 = solve_a(p02, p12)  # A^-1 B, first column
    c0, c1 = solve_a(p03, p13)  # second column
    f0 = e2 - (p02 * u0 + p12 * u1)
    f1 = e3 - (p03 * u0 + p13 * u1)
    s11 = P[10] - (p02 * b0 + p12 * b1)
    s12 = P[11] - (p02 * c0 + p12 * c1)
    s22 = P[15] - (p03 * c0 + p13 * c1)
    second = (s22 * f0 * f0 - 2.0 * s12 * f0 * f1 + s11 * f1 * f1) / (s11 * s22 - s12 * s12)
    return e0 * u0 + e1 * u1 + second


# ---------------------------------------------------------------- interacting multiple models


@dataclass(frozen=True)
class Modes:
    """The mode-conditioned estimates of an interacting multiple model (IMM) filter, for
    every (UAV, target): mean (..., M, 4), cov (..., M, 4, 4) and the mode
    probabilities prob (..., M), M modes. Between `imm_predict` and `imm_update` they
    are the predicted ones (prob the predicted mode probabilities, c-bar)."""

    mean: np.ndarray
    cov: np.ndarray
    prob: np.ndarray


Belief = tuple[np.ndarray, np.ndarray, Modes | None]
"""What a `Tracker` holds of each (UAV, target): combined mean (..., 4), cov (..., 4, 4)
and, for an IMM, its `Modes` (None for the Kalman filter)."""


def imm_start(mean: np.ndarray, cov: np.ndarray, prob: np.ndarray) -> Modes:
    """Every mode at the prior (mean (..., 4), cov (..., 4, 4)); prob (M,) the initial
    mode probabilities."""
    M = len(prob)
    return Modes(
        np.repeat(mean[..., None, :], M, axis=-2),
        np.repeat(cov[..., None, :, :], M, axis=-3),
        np.broadcast_to(np.asarray(prob, dtype=float), mean.shape[:-1] + (M,)).copy(),
    )


def combine(modes: Modes) -> tuple[np.ndarray, np.ndarray]:
    """The IMM's combined estimate: x = sum_j mu_j x_j, P = sum_j mu_j (P_j + d_j d_j^T)
    with d_j = x_j - x (the moment-matched Gaussian of the mixture)."""
    mu = modes.prob[..., None]
    mean = (mu * modes.mean).sum(axis=-2)
    d = modes.mean - mean[..., None, :]
    spread = modes.cov + d[..., :, None] * d[..., None, :]
    return mean, (mu[..., None] * spread).sum(axis=-3)


def imm_predict(modes: Modes, transition_matrix: np.ndarray, A: np.ndarray, Q: np.ndarray) -> Modes:
    """Interaction (mixing) and mode-matched prediction.

    With p_ij = P(mode j at k+1 | mode i at k) (`transition_matrix`, rows sum to 1):
    c_j = sum_i p_ij mu_i, w_ij = p_ij mu_i / c_j; each mode j restarts from the mix
    x0_j = sum_i w_ij x_i, P0_j = sum_i w_ij (P_i + (x_i - x0_j)(x_i - x0_j)^T) and is
    predicted with A (4, 4), or its own A_j (A: (M, 4, 4)), and its own Q_j (Q: (M, 4,
    4)). Returns the predicted modes with prob = c (the predicted mode probabilities).
    """
    T = np.asarray(transition_matrix, dtype=float)
    A = np.asarray(A)
    c = modes.prob @ T  # (..., M)
    w = T * modes.prob[..., :, None] / np.maximum(c, np.finfo(float).tiny)[..., None, :]
    mean0 = np.einsum("...ij,...ik->...jk", w, modes.mean)  # (..., M, 4)
    d = modes.mean[..., None, :, :] - mean0[..., :, None, :]  # (..., j, i, 4)
    spread = modes.cov[..., None, :, :, :] + d[..., :, None] * d[..., None, :]
    cov0 = np.einsum("...ij,...jikl->...jkl", w, spread)
    if A.ndim == 2:  # one model's motion for every mode, its own noise each
        mean, cov = predict(mean0, cov0, A, np.zeros((4, 4)))
    else:  # each mode its own motion (A: (M, 4, 4))
        parts = [
            predict(mean0[..., j, :], cov0[..., j, :, :], A[j], np.zeros((4, 4)))
            for j in range(len(A))
        ]
        mean = np.stack([p[0] for p in parts], axis=-2)
        cov = np.stack([p[1] for p in parts], axis=-3)
    return Modes(mean, cov + np.asarray(Q), c)


def imm_update(modes: Modes, observed: np.ndarray, z: np.ndarray, R: np.ndarray) -> Modes:
    """Mode-matched updates and the mode probabilities of the pairs that observed.

    Each mode is updated as `update` does; its likelihood is N(nu_j; 0, S_j) of its
    innovation nu_j = z - H x_j, S_j = H P_j H^T + R, and mu_j = c_j L_j / sum_i c_i L_i
    (in logarithms, so that no likelihood underflows to zero). Unobserved pairs keep
    their predictions (mu = c). observed (...) bool; z (K, 2), R (K, 2, 2) as in
    `filter_step`.
    """
    if not z.shape[0]:
        return modes
    mean, cov, prob = modes.mean.copy(), modes.cov.copy(), modes.prob.copy()
    m, P, c = mean[observed], cov[observed], prob[observed]  # (K, M, ...)
    S = P[..., :2, :2] + R[:, None]
    nu = z[:, None, :] - m[..., :2]
    det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
    quad = (
        S[..., 1, 1] * nu[..., 0] ** 2
        - 2 * S[..., 0, 1] * nu[..., 0] * nu[..., 1]
        + S[..., 0, 0] * nu[..., 1] ** 2
    ) / det
    log_l = -0.5 * quad - 0.5 * np.log(det) - np.log(2 * np.pi)
    log_post = np.log(np.maximum(c, np.finfo(float).tiny)) + log_l
    log_post -= log_post.max(axis=-1, keepdims=True)
    post = np.exp(log_post)
    mean[observed], cov[observed] = update(m, P, z[:, None, :], R[:, None])
    prob[observed] = post / post.sum(axis=-1, keepdims=True)
    return Modes(mean, cov, prob)


@dataclass(frozen=True, kw_only=True)
class Tracker:
    """The local filter of a run, as the cycle uses it: the paper's Kalman filter
    (`transition_matrix` None) or an IMM whose first mode is that filter.

    Its three stages take and return each (UAV, target)'s belief: the combined mean
    (..., 4) and cov (..., 4, 4), and for the IMM its `Modes`:

    * `start`: the prior at step 0;
    * `update`: the measurements of the cycle (Algorithm 2, lines 1-13);
    * `close`: after fusion, predicted to the next step (eq. 23). A pair whose fused
      estimate is not its own (adopted or intersected) restarts every mode from the
      fused estimate with its mode probabilities kept: what fusion loses is the spread
      of the modes, which a combined estimate cannot carry.
    """

    A: np.ndarray
    Q: np.ndarray
    transition_matrix: np.ndarray | None = None
    mode_Q: np.ndarray | None = None
    mode_A: np.ndarray | None = None  # each mode's motion, when they differ (turn modes)

    @classmethod
    def of(cls, dt: float, sigma: tuple[float, float], tracker: TrackerModel) -> Tracker:
        """From the time step, the targets' acceleration std per axis and a
        `config.TrackerModel`."""
        A, Q = transition(dt), process_noise(dt, *sigma)
        if tracker.model == "cv":
            return cls(A=A, Q=Q)
        extra = [process_noise(dt, s, s) for s in tracker.manoeuvre_std]
        rates = [r for rate in tracker.turn_rates_deg for r in (rate, -rate)]
        motions = [A] * (1 + len(extra)) + [turn_transition(dt, np.radians(r)) for r in rates]
        noises = [Q, *extra] + [Q] * len(rates)
        return cls(
            A=A,
            Q=Q,
            transition_matrix=np.array(tracker.transition, dtype=float),
            mode_Q=np.stack(noises),
            mode_A=np.stack(motions) if rates else None,  # None: every mode moves with A
        )

    def start(self, mean: np.ndarray, cov: np.ndarray) -> Belief:
        if self.transition_matrix is None:
            return mean, cov, None
        return mean, cov, imm_start(mean, cov, _stationary(self.transition_matrix))

    def update(
        self,
        mean: np.ndarray,
        cov: np.ndarray,
        modes: Modes | None,
        observed: np.ndarray,
        z: np.ndarray,
        R: np.ndarray,
        owned: bool = False,
    ) -> Belief:
        """Each filter's update on this cycle's measurements (`filter_step`). owned: the
        caller gives up `mean` and `cov` (a run's last state), which are then updated
        in place."""
        if modes is None:
            return (*filter_step(mean, cov, observed, z, R, None, None, owned), None)
        modes = imm_update(modes, observed, z, R)
        return (*combine(modes), modes)

    def close(
        self,
        mean: np.ndarray,
        cov: np.ndarray,
        modes: Modes | None,
        fused_mean: np.ndarray,
        fused_cov: np.ndarray,
        buffers: Buffers | None = None,
    ) -> Belief:
        """The estimates after fusion predicted to the next step (eq. 23; each mode's
        with the IMM). buffers: a run's, into which a Kalman filter's prediction goes."""
        if modes is None:
            return (*predict(fused_mean, fused_cov, self.A, self.Q, buffers), None)
        if self.transition_matrix is None or self.mode_Q is None:
            raise ValueError("modes given to a tracker without modes (a Kalman filter)")
        changed = (fused_mean != mean).any(axis=-1) | (fused_cov != cov).any(axis=(-2, -1))
        if changed.any():
            reset = changed[..., None]
            modes = Modes(
                np.where(reset[..., None], fused_mean[..., None, :], modes.mean),
                np.where(reset[..., None, None], fused_cov[..., None, :, :], modes.cov),
                modes.prob,
            )
        motion = self.A if self.mode_A is None else self.mode_A
        modes = imm_predict(modes, self.transition_matrix, motion, self.mode_Q)
        return (*combine(modes), modes)


def _stationary(T: np.ndarray) -> np.ndarray:
    """The stationary distribution of a Markov chain (the IMM's initial mode
    probabilities): the left eigenvector of T for eigenvalue 1, normalised."""
    values, vectors = np.linalg.eig(T.T)
    p = np.real(vectors[:, np.argmin(np.abs(values - 1.0))])
    return p / p.sum()
