"""Range-bearing sensing: observation disk, noise (eq. 2-4), conversion (eq. 5-12), FIM (eq. 47-51).

A UAV at altitude h with half field of view alpha sees the ground disk of radius
r_O = h tan(alpha) around its ground position; its slant range to the disk's edge is
d_O = h / cos(alpha). A target inside the disk yields z^P = (d, theta) + omega with

    sigma_d = k_d (1 + exp(k_r (d / d_O - 1))),    sigma_theta = k_theta d / d_O     (3)

where d is the 3-D range and theta the bearing in the inertial frame.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

import numpy as np

from .config import SensorModel


def edge_range(altitude: np.ndarray, sensor: SensorModel) -> np.ndarray:
    """Slant range d_O = h / cos(alpha) to the edge of the observation disk [m]."""
    return altitude / np.cos(sensor.alpha)


def observation_radius(altitude: np.ndarray, sensor: SensorModel) -> np.ndarray:
    """Ground radius r_O = h tan(alpha) of the observation disk [m] (Fig. 2)."""
    return altitude * np.tan(sensor.alpha)


def relative(uav: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ground offset and ranges from UAVs to targets.

    uav: (..., >=3) = x, y, h, ...; target: (..., >=2) = x, y, ... (broadcast together).
    Returns (delta (..., 2) target minus UAV, ground range r, slant range d).
    """
    delta = target[..., :2] - uav[..., :2]
    r2 = delta[..., 0] ** 2 + delta[..., 1] ** 2
    return delta, np.sqrt(r2), np.sqrt(r2 + uav[..., 2] ** 2)


def in_view(uav: np.ndarray, target: np.ndarray, sensor: SensorModel) -> np.ndarray:
    """Whether each target is inside each UAV's observation disk X_i (Sec. 4)."""
    dx, dy = target[..., 0] - uav[..., 0], target[..., 1] - uav[..., 1]
    return dx * dx + dy * dy <= observation_radius(uav[..., 2], sensor) ** 2


def noise_std(
    d: np.ndarray, d_edge: np.ndarray, sensor: SensorModel
) -> tuple[np.ndarray, np.ndarray]:
    """Range and bearing standard deviations [m], [rad] at slant range d, eq. (3)."""
    ratio = d / d_edge
    # the exponent is capped so that far, unobserved pairs give a huge std, not inf
    sigma_d = sensor.k_d * (1.0 + np.exp(np.minimum(sensor.k_r * (ratio - 1.0), 600.0)))
    sigma_theta = sensor.k_theta * ratio
    return sigma_d, sigma_theta


def measure(
    uav: np.ndarray, target: np.ndarray, sensor: SensorModel, noise: np.ndarray
) -> np.ndarray:
    """Noisy range-bearing measurement z^P = (d, theta) + omega, eqs. (2)-(4).

    noise: (..., 2) standard normal draws, scaled here by the true-geometry stds.
    Returns (..., 2) = (d [m], theta [rad]).
    """
    delta, _, d = relative(uav, target)
    sigma_d, sigma_theta = noise_std(d, edge_range(uav[..., 2], sensor), sensor)
    z = np.empty(d.shape + (2,))
    z[..., 0] = d + sigma_d * noise[..., 0]
    z[..., 1] = np.arctan2(delta[..., 1], delta[..., 0]) + sigma_theta * noise[..., 1]
    return z


def convert(uav: np.ndarray, z: np.ndarray, sensor: SensorModel) -> tuple[np.ndarray, np.ndarray]:
    """Polar-to-Cartesian conversion and its covariance, eqs. (5)-(12).

    z^C = p^u + r (cos theta, sin theta) with r = sqrt(d^2 - h^2) (eq. 5), and
    R = J C J^T with the Jacobian J of eq. (10) and C of eq. (2), evaluated at the
    noisy measurement (the filter does not know the true range).

    Near the nadir eq. (10) is not a usable linearisation: d/r grows without bound, and
    a measured range shorter than the altitude has no real ground range at all. J is
    therefore evaluated at r_J = max(r, sqrt(2 h sigma_d)), the ground range whose
    slant-range excess over h equals one range std (the sensor's ground-range
    resolution at the nadir, 14 m at h = 500 m), and r = 0 when d < h. With this floor
    the converted measurement stays consistent (mean e^T R^-1 e between 1.6 and 2.4
    at every ground range, against 2 for a consistent 2-D measurement); without it
    the printed form gives values above 10^5 within 20 m of the nadir.

    uav: (..., >=3); z: (..., 2). Returns (z^C (..., 2), R (..., 2, 2)).
    """
    h = uav[..., 2]
    d, theta = z[..., 0], z[..., 1]
    r = np.sqrt(np.maximum(d * d - h * h, 0.0))
    cos, sin = np.cos(theta), np.sin(theta)
    zc = np.empty(z.shape)
    zc[..., 0] = uav[..., 0] + r * cos
    zc[..., 1] = uav[..., 1] + r * sin
    sigma_d, sigma_theta = noise_std(d, edge_range(h, sensor), sensor)
    r_lin = np.maximum(r, np.sqrt(2.0 * h * sigma_d))
    # J = [[d/r cos, -r sin], [d/r sin, r cos]] (eq. 10); R = J diag(sd^2, st^2) J^T (eq. 12)
    radial = (d / r_lin * sigma_d) ** 2
    tangential = (r_lin * sigma_theta) ** 2
    R = np.empty(z.shape[:-1] + (2, 2))
    R[..., 0, 0] = radial * cos * cos + tangential * sin * sin
    R[..., 1, 1] = radial * sin * sin + tangential * cos * cos
    R[..., 0, 1] = R[..., 1, 0] = (radial - tangential) * cos * sin
    return zc, R


def fisher_information(uav: np.ndarray, target: np.ndarray, sensor: SensorModel) -> np.ndarray:
    """Fisher information of one measurement w.r.t. the UAV's ground position, eq. (51).

    With u = grad d = -(dx, dy) / d and w = grad theta = (dy, -dx) / r^2 (gradients
    w.r.t. the UAV position; dx, dy the target minus the UAV), C = diag(sigma_d^2,
    sigma_theta^2) depending on p^u only through d, eq. (51) gives

        G = a u u^T + b w w^T,
        a = 1/sigma_d^2 + 2 (sigma_d'/sigma_d)^2 + 2 (sigma_theta'/sigma_theta)^2,
        b = 1/sigma_theta^2,

    where ' is d/dd: sigma_d' = k_d k_r / d_O exp(k_r (d/d_O - 1)) and
    sigma_theta'/sigma_theta = 1/d. The first term of each coefficient is the mean's
    sensitivity, the others come from the noise's dependence on the distance. (The
    printed eqs. 52-54 differ from this: r^2 for r^4 in the bearing terms of all three;
    in eq. 53's bearing term (y-y)(y-y) for (x-x)(y-y), its minus sign being right; and
    eq. 54 labelled [G]_11 for [G]_22.) The bearing is undefined straight under the UAV
    (r = 0), where this returns the range term only.

    uav: (..., >=3); target: (..., >=2). Returns (..., 2, 2).
    """
    delta, r, d = relative(uav, target)
    d_edge = edge_range(uav[..., 2], sensor)
    a, _ = _range_coefficient(d, d_edge, sensor)
    b = (d_edge / (sensor.k_theta * d)) ** 2
    u = -delta / d[..., None]
    r2 = np.where(r > 0, r * r, 1.0)
    w = np.stack([delta[..., 1], -delta[..., 0]], axis=-1) / r2[..., None]
    return a[..., None, None] * u[..., :, None] * u[..., None, :] + b[..., None, None] * (
        w[..., :, None] * w[..., None, :]
    )


def fisher_det(d: np.ndarray, d_edge: np.ndarray, sensor: SensorModel) -> np.ndarray:
    """det G as a function of the slant range alone.

    u is orthogonal to w, |u|^2 = r^2/d^2 and |w|^2 = 1/r^2, so
    det G = a b / d^2 (also the limit at r = 0), with b = (d_O / (k_theta d))^2.
    """
    a, d2 = _range_coefficient(d, d_edge, sensor)
    np.multiply(d2, d2, out=d2)
    np.multiply(a, (d_edge / sensor.k_theta) ** 2, out=a)
    np.divide(a, d2, out=a)
    return a if a.shape else a[()]


def fisher_det_bound(d: np.ndarray, d_edge: np.ndarray, sensor: SensorModel) -> np.ndarray:
    """An upper bound of det G at every slant range d' >= d: non-increasing in d.

    det G = a b / d^2 with a = (1 - grow)^2 / k_d^2 + 2 (k_r/d_O)^2 grow^2 + 2/d^2,
    b = (d_O / (k_theta d))^2, grow = expit(k_r (d/d_O - 1)) (`_range_coefficient`).
    grow rises with d from 0 to 1, so (1 - grow)^2 falls, and grow^2 <= 1: replacing
    grow^2 by 1 leaves a sum of non-increasing terms, times the falling b / d^2. The
    bound is tight far from the UAV, where grow is 1, which is where the planner uses
    it (`planning.plan` with ``top``). A relative margin of 1e-9 covers round-off.
    """
    d = np.asarray(d, dtype=float)
    e = np.exp(np.minimum(sensor.k_r - d * (sensor.k_r / d_edge), 700.0))
    falling = (e / (1.0 + e)) / sensor.k_d  # (1 - grow) / k_d
    a = falling * falling + 2.0 * (sensor.k_r / d_edge) ** 2 + 2.0 / (d * d)
    return a * (d_edge / sensor.k_theta) ** 2 / (d * d) ** 2 * (1.0 + 1e-9)


def _range_coefficient(
    d: np.ndarray, d_edge: np.ndarray, sensor: SensorModel
) -> tuple[np.ndarray, np.ndarray]:
    """a = 1/sigma_d^2 + 2 (sigma_d'/sigma_d)^2 + 2/d^2 of `fisher_information`, and d^2.

    With e = exp(-x), x = k_r (d/d_O - 1): 1/sigma_d = (1 - grow)/k_d and
    sigma_d'/sigma_d = k_r/d_O grow, where grow = 1/(1+e) = expit(x) and 1 - grow =
    e grow, finite however far the target is. Computed in place, as the planner calls
    this on large arrays; both results are new arrays (0-d for scalar input).
    """
    k_r = sensor.k_r
    shape = np.broadcast_shapes(np.shape(d), np.shape(d_edge))
    a, grow, d2 = np.empty(shape), np.empty(shape), np.empty(shape)
    np.multiply(d, k_r / d_edge, out=a)
    np.subtract(k_r, a, out=a)
    np.minimum(a, 700.0, out=a)
    np.exp(a, out=a)  # e
    np.add(a, 1.0, out=grow)
    np.reciprocal(grow, out=grow)
    np.multiply(a, grow, out=a)  # 1 - grow
    np.multiply(a, 1.0 / sensor.k_d, out=a)
    np.square(a, out=a)  # 1 / sigma_d^2
    np.square(grow, out=grow)
    np.multiply(grow, 2.0 * (k_r / d_edge) ** 2, out=grow)  # 2 (sigma_d' / sigma_d)^2
    np.add(a, grow, out=a)
    np.multiply(d, d, out=d2)
    np.add(a, np.divide(2.0, d2, out=grow), out=a)
    return a, d2
