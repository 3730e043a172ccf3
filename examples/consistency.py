"""Where the filter is consistent, and why the scenario's mean NEES is larger.

1. The converted measurement (eq. 5-12): mean e^T R^-1 e against ground range, with the
   nadir floor of `sensing.convert` and with the printed Jacobian alone (2 is ideal).
2. A default trial (centralized, seed 0): NEES while a target is observed and has not
   bounced off a wall in the last 15 steps, against the rest (4 is ideal).

    python examples/consistency.py
"""

import numpy as np

import uavtrack
from uavtrack import SensorModel, estimation, sensing

sensor = SensorModel()
h = uavtrack.Scenario().uav.altitude
rng = np.random.default_rng(1)
n = 200_000
print(f"converted measurement at altitude {h:.0f} m: mean e^T R^-1 e (2 if consistent)")
print(" ground range [m]   with floor   printed J only")
for r in (0, 2, 5, 10, 15, 20, 25, 30, 35):
    uav = np.broadcast_to([0.0, 0.0, h], (n, 3))
    target = np.broadcast_to([r * np.cos(0.3), r * np.sin(0.3)], (n, 2))
    z = sensing.measure(uav, target, sensor, rng.standard_normal((n, 2)))
    zc, R = sensing.convert(uav, z, sensor)
    e = zc - target
    floored = np.einsum("ni,ni->n", e, np.linalg.solve(R, e[..., None])[..., 0]).mean()
    # the printed eq. (10)-(12) evaluated at the measured ground range (1 mm at least)
    d, theta = z[:, 0], z[:, 1]
    rm = np.sqrt(np.maximum(d * d - h * h, 1e-6))
    sd, st = sensing.noise_std(d, sensing.edge_range(h, sensor), sensor)
    c, s = np.cos(theta), np.sin(theta)
    er, et = e[:, 0] * c + e[:, 1] * s, -e[:, 0] * s + e[:, 1] * c
    printed = (er**2 / (d / rm * sd) ** 2 + et**2 / (rm * st) ** 2).mean()
    print(f" {r:16.0f} {floored:12.2f} {printed:16.3g}")

scenario = uavtrack.Scenario()
trace = uavtrack.simulate(scenario, "centralized", seed=0).trace
q = estimation.nees(trace.mean, trace.cov, trace.targets[:, None])[:, 0]  # UAV 0 holds the fused
observed = trace.observed.any(axis=1)
v = trace.targets[..., 2:]
flip = np.zeros_like(observed)
flip[1:] = ((np.sign(v[1:]) != np.sign(v[:-1])) & (np.abs(v[1:]) > 0.5)).any(-1)
recent = np.array([flip[max(0, k - 15) : k + 1].any(axis=0) for k in range(len(flip))])
print("\ndefault trial, centralized, seed 0: NEES of the fused estimate (4 if consistent)")
for name, mask in (
    ("observed, no wall in the last 15 steps", observed & ~recent),
    ("observed, after a wall", observed & recent),
    ("not observed", ~observed),
):
    print(f"  {name:40s} {q[mask].mean():8.2f}  ({mask.sum()} target-steps)")
print(f"  {'all':40s} {q.mean():8.2f}")
