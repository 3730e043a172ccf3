import numpy as np
import pytest

import uavtrack
from uavtrack import estimation, world
from uavtrack.config import G


def circumradius(p):
    """Radius of the circle through three points (..., 3, 2)."""
    a = np.linalg.norm(p[1] - p[2])
    b = np.linalg.norm(p[0] - p[2])
    c = np.linalg.norm(p[0] - p[1])
    u, v = p[1] - p[0], p[2] - p[0]
    area2 = abs(u[0] * v[1] - u[1] * v[0])
    return a * b * c / (2 * area2)


def orbit(bank, dt, steps, speed=15.0):
    state = np.array([0.0, 0.0, 500.0, speed, 0.3])
    path = [state]
    for _ in range(steps):
        state = world.fly(state, np.asarray(bank), dt)
        path.append(state)
    return np.array(path)


@pytest.mark.parametrize("bank_deg", [20.0, 45.0, 60.0])
def test_turn_radius_continuous_limit(bank_deg):
    bank = np.radians(bank_deg)
    path = orbit(bank, dt=0.001, steps=3000)
    radius = circumradius(path[[0, 1000, 2000], :2])
    assert radius == pytest.approx(world.turn_radius(15.0, bank), rel=1e-3)
    assert world.turn_radius(15.0, bank) == pytest.approx(15.0**2 / (G * np.tan(bank)))


def test_discrete_orbit_is_regular_polygon():
    # with dT = 1 s each step is a chord of length V dT subtending omega dT
    bank, dt, speed = np.radians(45.0), 1.0, 15.0
    omega = G * np.tan(bank) / speed
    path = orbit(bank, dt, 12)
    expected = speed * dt / (2 * np.sin(omega * dt / 2))
    for k in range(0, 9):
        assert circumradius(path[[k, k + 1, k + 3], :2]) == pytest.approx(expected, rel=1e-9)


def test_speed_altitude_constant_and_straight_flight():
    state = np.array([10.0, -5.0, 480.0, 15.0, 0.7])
    path = orbit(np.array(0.0), 1.0, 20)
    steps = np.diff(path[:, :2], axis=0)
    assert np.allclose(np.linalg.norm(steps, axis=1), 15.0)
    assert np.allclose(path[:, 2], 500.0) and np.allclose(path[:, 3], 15.0)
    out = world.fly(state, np.array(0.0), 2.0)
    assert np.allclose(out[:2], state[:2] + 30.0 * np.array([np.cos(0.7), np.sin(0.7)]))


def test_bank_angle_first_moves_the_uav_one_step_later():
    # eq. (1): x(k+1) uses psi(k); phi(k) changes psi(k+1)
    state = np.array([0.0, 0.0, 500.0, 15.0, 0.0])
    left, right = world.fly(state, np.array(0.5), 1.0), world.fly(state, np.array(-0.5), 1.0)
    assert np.array_equal(left[:2], right[:2])
    assert not np.allclose(
        world.fly(left, np.array(0.0), 1.0)[:2], world.fly(right, np.array(0.0), 1.0)[:2]
    )


def test_fly_broadcasts_over_leading_axes(rng):
    states = np.concatenate(
        [
            rng.uniform(0, 100, (3, 4, 2)),
            np.full((3, 4, 1), 500.0),
            np.full((3, 4, 1), 15.0),
            rng.uniform(-3, 3, (3, 4, 1)),
        ],
        axis=-1,
    )
    bank = rng.choice([-0.7, 0.0, 0.7], (3, 4))
    batched = world.fly(states, bank, 1.0)
    for i in range(3):
        for j in range(4):
            assert np.array_equal(batched[i, j], world.fly(states[i, j], bank[i, j], 1.0))


def test_targets_follow_constant_velocity_without_noise():
    start = np.array([[50.0, 60.0, 1.5, -0.5]])
    path = world.target_trajectories(start, np.zeros((10, 1, 2)), 1.0, 200.0)
    A = estimation.transition(1.0)
    for k in range(11):
        assert np.allclose(path[k, 0], np.linalg.matrix_power(A, k) @ start[0])


def test_target_process_noise_matches_filter_Q(rng):
    # one-step deviations of the truth from A s have covariance Q (eq. 15)
    n, dt = 200_000, 0.5
    start = np.tile([100.0, 100.0, 0.3, -0.2], (n, 1))
    accel = rng.standard_normal((n, 2)) * [0.16, 0.3]
    dev = world.move_targets(start, accel, dt, 1e6) - start @ estimation.transition(dt).T
    Q = estimation.process_noise(dt, 0.16, 0.3)
    # the deviation has rank 2 (one acceleration per axis): whiten each axis' pair
    for pos, vel in ((0, 2), (1, 3)):
        block = np.ix_([pos, vel], [pos, vel])
        assert np.linalg.matrix_rank(Q[block]) == 1
        gamma = np.array([dt**2 / 2, dt])  # Q = sigma^2 Gamma Gamma^T
        sigma2 = Q[block][1, 1] / dt**2
        assert np.allclose(Q[block], sigma2 * np.outer(gamma, gamma))
        assert np.allclose(dev[:, [pos, vel]] @ np.array([1.0, -dt / 2]), 0.0, atol=1e-12)
        assert np.var(dev[:, vel]) == pytest.approx(Q[vel, vel], rel=0.02)
    assert abs(np.corrcoef(dev[:, 2], dev[:, 3])[0, 1]) < 0.01


def test_targets_stay_in_field_and_walls_reflect(rng):
    start = np.column_stack([rng.uniform(0, 50, (20, 2)), rng.normal(0, 6, (20, 2))])
    accel = rng.normal(0, 0.5, (400, 20, 2))
    path = world.target_trajectories(start, accel, 1.0, 50.0)
    assert (path[..., :2] >= 0).all() and (path[..., :2] <= 50.0).all()
    # a target leaving through x = 0 comes back mirrored with reversed vx
    out = world.move_targets(np.array([1.0, 25.0, -3.0, 0.0]), np.zeros(2), 1.0, 50.0)
    assert np.allclose(out, [2.0, 25.0, 3.0, 0.0])
    out = world.move_targets(np.array([49.0, 25.0, 3.0, 1.0]), np.zeros(2), 1.0, 50.0)
    assert np.allclose(out, [48.0, 26.0, -3.0, 1.0])


def test_trajectories_equal_step_model_until_a_wall(rng):
    start = np.column_stack([rng.uniform(400, 600, (5, 2)), rng.normal(0, 1, (5, 2))])
    accel = rng.normal(0, 0.16, (30, 5, 2))
    path = world.target_trajectories(start, accel, 0.5, 1000.0)
    state = start
    for k in range(30):
        state = world.move_targets(state, accel[k], 0.5, 1000.0)
        assert np.allclose(path[k + 1], state, atol=1e-9)


def test_trajectories_are_the_fold_of_the_free_path(rng):
    start = np.array([[10.0, 190.0, -4.0, 3.0]])
    accel = rng.normal(0, 0.3, (200, 1, 2))
    folded = world.target_trajectories(start, accel, 1.0, 200.0)
    free = world.target_trajectories(start, accel, 1.0, 1e9)  # no wall within reach
    fold = np.mod(free[..., :2], 400.0)
    assert np.allclose(folded[..., :2], np.where(fold > 200.0, 400.0 - fold, fold))
    assert np.allclose(np.abs(folded[..., 2:]), np.abs(free[..., 2:]))
    assert (folded[..., :2] >= 0).all() and (folded[..., :2] <= 200.0).all()


# ---------------------------------------------------------------- manoeuvring targets


def manoeuvring(rng, T=400, **fields):
    from uavtrack.config import ManoeuvreModel

    m = ManoeuvreModel(**fields)
    initial = np.array([[100.0, 100.0, 1.0, 0.5], [50.0, 150.0, -0.5, 1.0]])
    accel = np.zeros((T - 1, 2, 2))  # no white noise: the manoeuvres alone
    return world.manoeuvring_trajectories(initial, accel, 0.5, 200.0, m, rng), m


def test_manoeuvring_targets_stay_in_the_field_within_their_limits(rng):
    path, m = manoeuvring(rng)
    assert (path[..., :2] >= 0).all() and (path[..., :2] <= 200).all()
    speed = np.hypot(path[..., 2], path[..., 3])
    assert speed.max() <= m.speed_max + 1e-9
    # the speed changes by at most acceleration_max per second
    assert np.abs(np.diff(speed, axis=0)).max() <= m.acceleration_max * 0.5 + 1e-9


def test_turns_are_coordinated_at_most_at_the_largest_rate(rng):
    path, m = manoeuvring(rng, turn_probability=1.0, stop_probability=0.0, speed_max=1.0)
    v = path[..., 2:]
    heading = np.arctan2(v[..., 1], v[..., 0])
    turn = np.angle(np.exp(1j * np.diff(heading, axis=0)))  # wrapped
    # away from the walls (a reflection flips a component), |rate| <= the bound
    inside = (np.abs(path[1:, :, :2] - 100) < 90).all(axis=-1) & (
        np.abs(path[:-1, :, :2] - 100) < 90
    ).all(axis=-1)
    assert np.abs(turn[inside]).max() <= np.radians(m.turn_rate_max_deg) * 0.5 + 1e-9
    assert np.abs(turn[inside]).max() > np.radians(m.turn_rate_max_deg) * 0.5 * 0.5  # it turns


def test_targets_that_always_stop_come_to_rest(rng):
    path, _ = manoeuvring(rng, stop_probability=1.0, interval=2.0)
    assert np.hypot(path[-1, :, 2], path[-1, :, 3]).max() < 1e-9


def test_manoeuvring_leaves_the_papers_draws_alone():
    s = uavtrack.Scenario()
    m = s.with_overrides({"target.motion": "manoeuvring"})
    a = world.initial_conditions(s, world.streams(0)[0])
    b = world.initial_conditions(m, world.streams(0)[0])
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[2], b[2])  # UAVs, prior
    assert np.array_equal(a[1][0], b[1][0])  # the same start
    assert not np.array_equal(a[1], b[1])
    c = world.initial_conditions(m, world.streams(0)[0])
    assert np.array_equal(b[1], c[1])  # deterministic


@pytest.mark.parametrize(
    "overrides",
    [{}, {"n_targets": 7, "field_size": 60.0}, {"target.motion": "manoeuvring"}, {"steps": 1}],
    ids=["paper", "many-walls", "manoeuvring", "one-step"],
)
@pytest.mark.parametrize("block", [1, 7, 1024])
def test_targets_drawn_a_block_at_a_time_are_the_whole_run_bit_for_bit(
    monkeypatch, overrides, block
):
    """`world.Targets` continues the closed form's sums block to block: the states equal
    `target_trajectories` on the accelerations drawn at once, for every block size."""
    monkeypatch.setattr(world.Targets, "BLOCK", block)
    scenario = uavtrack.Scenario(steps=100).with_overrides(overrides)
    seeds = [np.random.SeedSequence(3), np.random.SeedSequence(4)]

    def at_once(seed):  # every acceleration drawn at once, then the whole closed form
        rng = world.streams(seed)[0]
        start = world.draw_start(scenario, rng)[0]
        nt, dt, L = scenario.n_targets, scenario.dt, scenario.field_size
        accel = rng.standard_normal((scenario.steps - 1, nt, 2)) * scenario.acceleration_std()
        if scenario.target.motion == "manoeuvring":
            m = scenario.target.manoeuvre
            return world.manoeuvring_trajectories(start, accel, dt, L, m, rng)
        return world.target_trajectories(start, accel, dt, L)

    whole = np.stack([at_once(s) for s in seeds])
    rngs = [world.streams(s)[0] for s in seeds]
    starts = [world.draw_start(scenario, rng)[0] for rng in rngs]
    streamed = world.Targets(np.stack(starts), rngs, scenario)  # keeps one block
    steps = np.stack([streamed.at(k) for k in range(scenario.steps)], axis=1)
    assert np.array_equal(steps, whole)
    if scenario.steps > block + 1:
        with pytest.raises(IndexError, match="keep no steps|gone"):
            streamed.whole()


def test_a_run_without_a_trace_holds_no_more_memory_for_more_steps(monkeypatch):
    """Without a trace the targets are drawn a block at a time: 8 times the steps, the
    same peak of memory (the whole run would hold 8 times the targets' states)."""
    import tracemalloc

    monkeypatch.setattr(world.Targets, "BLOCK", 50)
    small = uavtrack.Scenario(n_uavs=2, n_targets=40, steps=200)
    uavtrack.simulation.run(small, "greedy", [0])  # what a first run imports and caches
    peaks = []
    for steps in (200, 1600):
        tracemalloc.start()
        uavtrack.simulation.run(small.with_overrides({"steps": steps}), "greedy", [0])
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    grown = peaks[1] - peaks[0]
    whole = (1600 - 200) * 40 * 4 * 8  # the targets' states of the steps added, at least
    assert grown < 0.25 * whole, peaks
