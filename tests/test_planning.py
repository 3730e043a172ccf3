import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uavtrack import SensorModel, planning, sensing, world
from uavtrack.config import G


def random_case(rng, batch=(), nu=3, nt=4):
    uavs = np.empty(batch + (nu, 5))
    uavs[..., :2] = rng.uniform(0, 200, batch + (nu, 2))
    uavs[..., 2] = rng.uniform(450, 550, batch + (nu,))
    uavs[..., 3] = 15.0
    uavs[..., 4] = rng.uniform(-np.pi, np.pi, batch + (nu,))
    mean = np.concatenate(
        [rng.uniform(0, 200, batch + (nu, nt, 2)), rng.normal(0, 3, batch + (nu, nt, 2))], axis=-1
    )
    return uavs, mean


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    horizon=st.integers(2, 5),
    bank=st.floats(10, 70),
    discount=st.sampled_from([1.0, 0.9, 0.5]),
)
def test_tree_planner_equals_exhaustive_search(seed, horizon, bank, discount):
    rng = np.random.default_rng(seed)
    uavs, mean = random_case(rng, batch=(2,))
    sensor = SensorModel()
    args = (sensor, np.radians(bank), horizon, 1.0, discount)
    fast, slow = planning.plan(uavs, mean, *args), planning.plan_exhaustive(uavs, mean, *args)
    assert np.array_equal(fast.action, slow.action)
    assert np.array_equal(fast.sequence, slow.sequence)
    assert np.allclose(fast.value, slow.value, rtol=1e-12, atol=0)


def test_exhaustive_matches_a_plain_loop_over_sequences(rng):
    # the reference itself against the most literal reading of Algorithm 1, line 2
    uavs, mean = random_case(rng, nu=2, nt=2)
    sensor, bank, h = SensorModel(), np.radians(45.0), 3
    ref = planning.plan_exhaustive(uavs, mean, sensor, bank, h, 1.0)
    actions = planning.action_set(bank)
    for i in range(2):
        for j in range(2):
            best, best_seq = -np.inf, None
            for seq in itertools.product(range(3), repeat=h):
                state, target, total = uavs[i].copy(), mean[i, j].copy(), 0.0
                for a in seq:
                    state = world.fly(state, actions[a], 1.0)
                    target = target + np.array([target[2], target[3], 0, 0])
                    total += np.linalg.det(sensing.fisher_information(state, target, sensor))
                if total > best * (1 + 1e-12):
                    best, best_seq = total, seq
            assert ref.value[i, j] == pytest.approx(best, rel=1e-9)
            assert ref.action[i, j] == best_seq[0]


def test_rollout_tree_size_and_positions(rng):
    uavs, _ = random_case(rng, nu=2)
    actions = planning.action_set(np.radians(45.0))
    for h in range(1, 6):
        nodes = planning.rollout_nodes(uavs, actions, h, 1.0, G)
        assert nodes.shape == (2, (3**h - 1) // 2, 2)
    # the deepest node reached by actions (2, 0) equals flying them with eq. (1)
    nodes = planning.rollout_nodes(uavs, actions, 3, 1.0, G)
    state = uavs[0]
    for a in (2, 0, 1):
        state = world.fly(state, actions[a], 1.0)
    assert np.allclose(nodes[0, 1 + 3 + 2 * 3 + 0], state[:2])


def test_planner_turns_toward_a_target_behind():
    sensor = SensorModel()
    uav = np.array([[100.0, 100.0, 500.0, 15.0, 0.0]])  # heading +x
    for side, expected in ((1.0, 2), (-1.0, 0)):  # target behind-left -> +phi, behind-right -> -phi
        mean = np.array([[[40.0, 100.0 + side * 60.0, 0.0, 0.0]]])
        plan = planning.plan(uav, mean, sensor, np.radians(45.0), 3, 1.0)
        assert plan.action[0, 0] == expected
        assert plan.value[0, 0] > 0


def test_bids_prefer_nearer_targets(rng):
    sensor = SensorModel()
    uav = np.array([[100.0, 100.0, 500.0, 15.0, 0.5]])
    mean = np.array([[[110.0, 95.0, 0, 0], [250.0, 100.0, 0, 0], [100.0, 500.0, 0, 0]]])
    value = planning.plan(uav, mean, sensor, np.radians(45.0), 3, 1.0).value[0]
    assert value[0] > value[1] > value[2] > 0


def test_planning_in_blocks_of_uavs_equals_one_pass(monkeypatch):
    rng = np.random.default_rng(3)
    uavs, mean = random_case(rng, batch=(2,), nu=7, nt=5)
    args = (SensorModel(), np.radians(45), 4, 0.5)
    whole = planning.plan(uavs, mean, *args)
    # a working memory of one UAV's pairs forces a block per UAV
    monkeypatch.setattr(planning, "CHUNK_BYTES", 5 * planning.floats_per_pair(3, 4) * 8)
    blocks = planning.plan(uavs, mean, *args)
    for name in ("value", "action", "sequence"):
        assert np.array_equal(getattr(whole, name), getattr(blocks, name)), name


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    nu=st.integers(1, 6),
    nt=st.integers(1, 40),
    field=st.sampled_from([200.0, 1000.0, 4000.0]),
    discount=st.sampled_from([1.0, 0.8]),
)
def test_pruned_planner_scores_every_bid_an_assignment_can_read(seed, nu, nt, field, discount):
    rng = np.random.default_rng(seed)
    uavs, mean = random_case(rng, batch=(2,), nu=nu, nt=nt)
    uavs[..., :2] *= field / 200
    mean[..., :2] *= field / 200
    top = rng.integers(1, nu + 3, size=(2, nu))
    args = (SensorModel(), np.radians(45), 3, 1.0, discount)
    full = planning.plan(uavs, mean, *args)
    part = planning.plan(uavs, mean, *args, top=top)
    scored = ~np.isnan(part.value)
    # what is scored is scored exactly, bit for bit
    assert np.array_equal(part.value[scored], full.value[scored])
    assert np.array_equal(part.action[scored], full.action[scored])
    assert np.array_equal(part.sequence[scored], full.sequence[scored])
    assert (part.action[~scored] == -1).all() and (part.sequence[~scored] == -1).all()
    # every target at or above a UAV's top-th best full value is scored (ties included)
    k = np.minimum(top, nt)
    kth = np.take_along_axis(-np.sort(-full.value, axis=-1), k[..., None] - 1, axis=-1)
    assert scored[full.value >= kth].all()
    # a UAV's scored set depends on its own data only: planned alone, the same
    alone = planning.plan(uavs[:1, :1], mean[:1, :1], *args, top=top[:1, :1])
    assert np.array_equal(alone.value[0, 0], part.value[0, 0], equal_nan=True)


def test_pruned_planner_skips_targets_out_of_reach():
    rng = np.random.default_rng(5)
    uavs, mean = random_case(rng, nu=2, nt=60)
    mean[..., :2] *= 20  # targets over 4 km, the UAVs near the corner
    mean[:, :3, :2] = uavs[:, None, :2] + 30.0  # three targets close to the UAVs
    args = (SensorModel(), np.radians(45), 3, 1.0)
    part = planning.plan(uavs, mean, *args, top=np.array([1, 2]))
    scored = (~np.isnan(part.value)).sum(axis=-1)
    assert (scored < 60).all() and (scored >= 3).all()
    full = planning.plan(uavs, mean, *args)
    assert np.array_equal(np.nanargmax(part.value, axis=-1), full.value.argmax(axis=-1))


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    horizon=st.integers(2, 4),
    speed=st.floats(0.5, 12.0),
    direction=st.floats(0, 2 * np.pi),
)
def test_planning_in_a_moving_air_mass_equals_flying_each_sequence(seed, horizon, speed, direction):
    # the wind-aware planner (planner.wind): eq. (1) through the air, plus the drift
    rng = np.random.default_rng(seed)
    uavs, mean = random_case(rng, batch=(2,), nu=3, nt=6)
    drift = speed * np.array([np.cos(direction), np.sin(direction)])
    air = planning.air_relative(uavs, drift)
    args = (SensorModel(), np.radians(45), horizon, 0.5, 1.0)
    fast = planning.plan(air, mean, *args, drift=drift)
    slow = planning.plan_exhaustive(air, mean, *args, drift=drift)
    assert np.array_equal(fast.action, slow.action)
    assert np.allclose(fast.value, slow.value, rtol=1e-12, atol=0)
    # the pruned planner's bound covers the drift: what it must score, it scores exactly
    top = rng.integers(1, 4, size=(2, 3))
    part = planning.plan(air, mean, *args, top=top, drift=drift)
    scored = ~np.isnan(part.value)
    assert np.array_equal(part.value[scored], fast.value[scored])
    kth = np.take_along_axis(-np.sort(-fast.value, axis=-1), top[..., None] - 1, axis=-1)
    assert scored[fast.value >= kth].all()


def test_air_relative_states_add_the_drift_back_to_the_ground_velocity(rng):
    uavs, _ = random_case(rng, nu=5)
    drift = np.array([4.0, -3.0])
    air = planning.air_relative(uavs, drift)
    ground = uavs[:, 3, None] * np.stack([np.cos(uavs[:, 4]), np.sin(uavs[:, 4])], axis=-1)
    through_air = air[:, 3, None] * np.stack([np.cos(air[:, 4]), np.sin(air[:, 4])], axis=-1)
    assert np.allclose(through_air + drift, ground)
    assert np.array_equal(air[:, :3], uavs[:, :3])
    assert np.allclose(planning.air_relative(uavs, np.zeros(2)), uavs)
