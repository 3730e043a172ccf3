"""Local estimation: one Kalman filter per (UAV, target), eqs. (22)-(25).

All functions broadcast over leading axes; states are ``(..., 4)`` = x, y, vx, vy and
covariances ``(..., 4, 4)``. The measurement is the converted position z^C = H s + v
(eq. 6) with H = [I_2 0].
"""

from __future__ import annotations

import numpy as np


def transition(dt: float) -> np.ndarray:
    """State transition A of the nearly-constant-velocity model, eq. (14)."""
    A = np.eye(4)
    A[0, 2] = A[1, 3] = dt
    return A


def process_noise(dt: float, sigma_1: float, sigma_2: float) -> np.ndarray:
    """Process noise Q for white acceleration noise, eq. (15), in the state order x, y, vx, vy.

    Per axis Q = sigma^2 [[dT^4/4, dT^3/2], [dT^3/2, dT^2]] (Gamma Gamma^T sigma^2 with
    Gamma = [dT^2/2, dT]^T). The printed eq. (15) writes dT^2/4, dT/2, 1 and orders the
    blocks (x, vx), (y, vy); at dT = 1 s both are the same matrix, and this form keeps
    sigma in m/s^2 for other time steps.
    """
    Q = np.zeros((4, 4))
    for pos, vel, sigma in ((0, 2, sigma_1), (1, 3, sigma_2)):
        var = sigma**2
        Q[pos, pos] = var * dt**4 / 4
        Q[pos, vel] = Q[vel, pos] = var * dt**3 / 2
        Q[vel, vel] = var * dt**2
    return Q


def predict(
    mean: np.ndarray, cov: np.ndarray, A: np.ndarray, Q: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Prediction, eq. (23): s(k|k-1) = A s(k-1), P(k|k-1) = A P(k-1) A^T + Q."""
    mean = mean @ A.T
    cov = A @ cov @ A.T + Q
    return mean, cov


def update(
    mean: np.ndarray, cov: np.ndarray, z: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Measurement update with z = H s + v, v ~ N(0, R), eq. (25).

    The gain uses the predicted covariance, K = P H^T (H P H^T + R)^-1 (the printed
    eq. 25 shows the previous posterior there; the standard filter is meant), and the
    covariance is updated in Joseph form (I - KH) P (I - KH)^T + K R K^T, which keeps
    it symmetric positive definite.

    mean: (..., 4); cov: (..., 4, 4); z: (..., 2); R: (..., 2, 2).
    """
    S = cov[..., :2, :2] + R
    K = np.swapaxes(np.linalg.solve(S, np.swapaxes(cov[..., :, :2], -1, -2)), -1, -2)
    innovation = z - mean[..., :2]
    mean = mean + np.einsum("...ij,...j->...i", K, innovation)
    IKH = np.broadcast_to(np.eye(4), cov.shape).copy()
    IKH[..., :, :2] -= K
    cov = IKH @ cov @ np.swapaxes(IKH, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)
    return mean, cov


def filter_step(
    mean: np.ndarray,
    cov: np.ndarray,
    observed: np.ndarray,
    z: np.ndarray,
    R: np.ndarray,
    A: np.ndarray | None,
    Q: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 2, lines 1-13: predict every filter, update those that observed.

    Unobserved pairs keep the prediction (eq. 24). A and Q may be None to skip the
    prediction (the first step, where the prior already refers to step 0).

    mean (..., 4), cov (..., 4, 4); observed (...) bool; z (K, 2) and R (K, 2, 2) the
    measurements of the K observing pairs, in the order of ``np.nonzero(observed)``.
    Returns (mean, cov) of the same shapes.
    """
    if A is not None:
        mean, cov = predict(mean, cov, A, Q)
    if z.shape[0]:
        mean, cov = mean.copy(), cov.copy()
        mean[observed], cov[observed] = update(mean[observed], cov[observed], z, R)
    return mean, cov


def confidence(cov: np.ndarray) -> np.ndarray:
    """Perception confidence gamma = 1 / trace(P), eq. (22). cov: (..., 4, 4) -> (...)."""
    return 1.0 / np.trace(cov, axis1=-2, axis2=-1)


def nees(mean: np.ndarray, cov: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared e^T P^-1 e, e = truth - mean. Returns (...)."""
    e = truth - mean
    return np.einsum("...i,...i->...", e, np.linalg.solve(cov, e[..., None])[..., 0])
