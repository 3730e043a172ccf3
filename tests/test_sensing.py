import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uavtrack import SensorModel, sensing

GEOMETRIES = [  # (ground offset of the target from the UAV [m], altitude [m], half FOV [deg])
    ((3.0, 4.0), 500.0, 5.0),
    ((30.0, -12.0), 500.0, 5.0),
    ((-20.0, 38.0), 480.0, 5.0),
    ((90.0, 60.0), 520.0, 5.0),
    ((-250.0, 140.0), 500.0, 5.0),
    ((15.0, 25.0), 100.0, 20.0),
]


def log_likelihood(p_uav, h, target, z, sensor):
    """ln p(z | p_uav) of eq. (48) for a UAV at ground position p_uav (..., 2)."""
    delta = target - p_uav
    d = np.sqrt((delta**2).sum(-1) + h * h)
    theta = np.arctan2(delta[..., 1], delta[..., 0])
    sd, st = sensing.noise_std(d, sensing.edge_range(h, sensor), sensor)
    rd = z[..., 0] - d
    rt = (z[..., 1] - theta + np.pi) % (2 * np.pi) - np.pi
    return -np.log(sd * st) - 0.5 * (rd**2 / sd**2 + rt**2 / st**2)


def expected_negative_hessian(p0, h, target, sensor, step=1e-3):
    """E_z[-d^2 ln p / dp^2] by central finite differences, the expectation taken exactly
    with the symmetric sigma points of z (the Hessian is quadratic in z)."""
    delta = target - p0
    d0 = np.hypot(*delta) ** 2 + h * h
    d0 = np.sqrt(d0)
    mean = np.array([d0, np.arctan2(delta[1], delta[0])])
    sd, st = sensing.noise_std(d0, sensing.edge_range(h, sensor), sensor)
    L = np.diag([sd, st]) * np.sqrt(2.0)
    points = np.array([mean + L[:, 0], mean - L[:, 0], mean + L[:, 1], mean - L[:, 1]])
    E = np.eye(2) * step
    hess = np.zeros((2, 2))
    for m in range(2):
        for n in range(2):
            f = lambda dp: log_likelihood(p0 + dp, h, target, points, sensor)  # noqa: E731
            second = (f(E[m] + E[n]) - f(E[m] - E[n]) - f(-E[m] + E[n]) + f(-E[m] - E[n])) / (
                4 * step**2
            )
            hess[m, n] = second.mean()
    return -hess


@pytest.mark.parametrize("offset,h,fov", GEOMETRIES)
def test_fisher_information_equals_expected_hessian_of_log_likelihood(offset, h, fov):
    sensor = SensorModel(half_fov_deg=fov)
    p0 = np.array([12.0, -7.0])
    target = p0 + np.array(offset)
    G = sensing.fisher_information(np.array([*p0, h]), target, sensor)
    numeric = expected_negative_hessian(p0, h, target, sensor)
    assert np.allclose(G, G.T)
    assert np.allclose(numeric, G, rtol=1e-4, atol=1e-6 * np.abs(G).max())


def test_fisher_information_equals_score_covariance(rng):
    # G = E[score score^T], the score by finite differences, z sampled from the sensor
    sensor = SensorModel()
    p0, h, target = np.array([0.0, 0.0]), 500.0, np.array([25.0, 18.0])
    n = 400_000
    z = sensing.measure(
        np.broadcast_to([*p0, h], (n, 3)),
        np.broadcast_to(target, (n, 2)),
        sensor,
        rng.standard_normal((n, 2)),
    )
    step = 1e-4
    score = np.stack(
        [
            (
                log_likelihood(p0 + e, h, target, z, sensor)
                - log_likelihood(p0 - e, h, target, z, sensor)
            )
            / (2 * step)
            for e in np.eye(2) * step
        ],
        axis=-1,
    )
    G = sensing.fisher_information(np.array([*p0, h]), target, sensor)
    assert np.allclose(score.T @ score / n, G, rtol=0.02, atol=0.02 * np.abs(G).max())


def test_fisher_det_closed_form_and_broadcasting(rng):
    sensor = SensorModel()
    uav = np.concatenate([rng.uniform(-50, 50, (6, 1, 2)), rng.uniform(400, 600, (6, 1, 1))], -1)
    target = rng.uniform(-300, 300, (1, 5, 2))
    G = sensing.fisher_information(uav, target, sensor)
    assert G.shape == (6, 5, 2, 2)
    _, _, d = sensing.relative(uav, target)
    det = sensing.fisher_det(d, sensing.edge_range(uav[..., 2], sensor), sensor)
    assert np.allclose(np.linalg.det(G), det, rtol=1e-9)
    assert (np.linalg.eigvalsh(G) > 0).all()


def test_fisher_det_decreases_with_distance():
    sensor = SensorModel()
    d = np.linspace(500.0, 2000.0, 200)
    det = sensing.fisher_det(d, sensing.edge_range(500.0, sensor), sensor)
    assert np.isfinite(det).all() and (det > 0).all()
    assert (np.diff(det) < 0).all()


def test_observation_disk_radius():
    sensor = SensorModel(half_fov_deg=5.0)
    uav = np.array([0.0, 0.0, 500.0])
    r_o = 500.0 * np.tan(np.radians(5.0))
    assert sensing.observation_radius(500.0, sensor) == pytest.approx(r_o)
    assert sensing.in_view(uav, np.array([r_o - 1e-6, 0.0]), sensor)
    assert not sensing.in_view(uav, np.array([0.0, r_o + 1e-6]), sensor)


def test_noise_std_eq3():
    sensor = SensorModel()
    d_o = sensing.edge_range(500.0, sensor)
    sd, st = sensing.noise_std(d_o, d_o, sensor)
    assert sd == pytest.approx(2 * sensor.k_d) and st == pytest.approx(sensor.k_theta)
    sd, st = sensing.noise_std(0.5 * d_o, d_o, sensor)
    assert sd == pytest.approx(sensor.k_d * (1 + np.exp(-0.5 * sensor.k_r)))
    assert st == pytest.approx(0.5 * sensor.k_theta)


def test_measurement_noise_statistics(rng):
    sensor = SensorModel()
    uav, target = np.array([0.0, 0.0, 500.0]), np.array([20.0, -30.0])
    n = 200_000
    z = sensing.measure(
        np.broadcast_to(uav, (n, 3)),
        np.broadcast_to(target, (n, 2)),
        sensor,
        rng.standard_normal((n, 2)),
    )
    d = np.sqrt(20.0**2 + 30.0**2 + 500.0**2)
    sd, st = sensing.noise_std(d, sensing.edge_range(500.0, sensor), sensor)
    assert z[:, 0].mean() == pytest.approx(d, abs=4 * sd / np.sqrt(n))
    assert z[:, 1].mean() == pytest.approx(np.arctan2(-30.0, 20.0), abs=4 * st / np.sqrt(n))
    assert z.std(axis=0) == pytest.approx([sd, st], rel=0.01)


def test_conversion_is_exact_without_noise_and_R_is_J_C_Jt():
    sensor = SensorModel()
    uav = np.array([10.0, 20.0, 500.0])
    target = np.array([40.0, -5.0])
    z = sensing.measure(uav, target, sensor, np.zeros(2))
    zc, R = sensing.convert(uav, z, sensor)
    assert np.allclose(zc, target, atol=1e-9)
    d, theta = z
    r = np.sqrt(d * d - 500.0**2)
    J = np.array(
        [[d / r * np.cos(theta), -r * np.sin(theta)], [d / r * np.sin(theta), r * np.cos(theta)]]
    )  # eq. (10)
    sd, st = sensing.noise_std(d, sensing.edge_range(500.0, sensor), sensor)
    assert np.allclose(R, J @ np.diag([sd**2, st**2]) @ J.T, rtol=1e-12)


@pytest.mark.parametrize("ground_range", [0.0, 2.0, 8.0, 15.0, 30.0, 43.0])
def test_converted_measurement_is_consistent_at_every_ground_range(rng, ground_range):
    # e^T R^-1 e of the converted measurement averages 2 (a 2-D Gaussian) within 25%,
    # including at the nadir where the printed linearisation alone is unusable
    sensor = SensorModel()
    n = 100_000
    uav = np.broadcast_to([0.0, 0.0, 500.0], (n, 3))
    target = np.broadcast_to([ground_range * np.cos(0.4), ground_range * np.sin(0.4)], (n, 2))
    zc, R = sensing.convert(
        uav, sensing.measure(uav, target, sensor, rng.standard_normal((n, 2))), sensor
    )
    e = zc - target
    q = np.einsum("ni,ni->n", e, np.linalg.solve(R, e[..., None])[..., 0])
    assert 1.5 < q.mean() < 2.5
    assert (np.linalg.eigvalsh(R) > 0).all()


@settings(max_examples=200, deadline=None)
@given(
    st.floats(50, 2000),  # altitude
    st.floats(0, 20),  # k_r
    st.floats(0.01, 10),  # k_d
    st.floats(0.5, 30),  # half field of view
    st.floats(1.0, 20.0),  # d / h
    st.floats(0.0, 5.0),  # how much farther d' is
)
def test_the_det_g_bound_holds_at_every_farther_range(h, k_r, k_d, fov, ratio, farther):
    sensor = SensorModel(k_r=k_r, k_d=k_d, half_fov_deg=fov)
    d_edge = sensing.edge_range(h, sensor)
    d = h * ratio
    d_far = d * (1 + farther)
    bound = sensing.fisher_det_bound(np.array(d), d_edge, sensor)
    assert bound >= sensing.fisher_det(np.array(d_far), d_edge, sensor)
    assert bound >= sensing.fisher_det_bound(np.array(d_far), d_edge, sensor)  # non-increasing
