"""The vector environment: many trials as one batch, equal to the single environment."""

import numpy as np
import pytest

import uavtrack

pytest.importorskip("pettingzoo")
from uavtrack.env import parallel_env, vector_env  # noqa: E402


def single(seed, actions, **settings):
    """Observations, rewards and the rate of one trial flown by the parallel env with the
    actions (T, Nu); a failed UAV's rows stay zeros, as the vector env keeps them."""
    env = parallel_env(**settings)
    nu = len(env.possible_agents)
    observations, _ = env.reset(seed=seed)
    size = env.observation_space("uav_0").shape
    seen = [_dense(observations, env.possible_agents, size)]
    earned = []
    for chosen in actions:
        act = {a: int(chosen[i]) for i, a in enumerate(env.possible_agents) if a in env.agents}
        observations, rewards, *_ = env.step(act)
        seen.append(_dense(observations, env.possible_agents, size))
        earned.append([rewards.get(f"uav_{i}", 0.0) for i in range(nu)])
    return np.array(seen), np.array(earned), env.result().observation_rate


def test_a_failed_uav_earns_nothing_in_the_batch():
    v = vector_env(2, steps=12, faults={"failures": [[1, 5]]})
    v.reset(seed=0)
    earned = np.array([v.step(v.paper_actions())[1] for _ in range(12)])
    assert not earned[5:, :, 1].any() and earned[5:-1, :, 0].any()


def _dense(observations, agents, size):
    return np.stack([observations.get(a, np.zeros(size, np.float32)) for a in agents])


@pytest.mark.parametrize(
    "settings",
    [
        {},
        {"faults": {"failures": [[1, 8]], "loss": 0.2}},
        {"faults": {"failures": [[3, 5]]}, "reward": "information"},
        {
            "tracker": {"model": "imm"},
            "fusion": {"rule": "covariance_intersection"},
            "reward": "difference",
        },
        {
            "tracker": {"association": "jpda"},
            "sensor": {"detection_probability": 0.9, "clutter_rate": 2},
            "faults": {"failures": [[2, 6]]},
            "reward": "difference",
        },
    ],
    ids=["paper", "faults", "failure-information", "imm-difference", "jpda-clutter"],
)
def test_every_trial_is_the_single_environments(settings):
    B, T = 4, 20
    v = vector_env(B, steps=T, **settings)
    observations, info = v.reset(seed=11)
    actions = np.random.default_rng(0).integers(0, 3, size=(T, B, 5))
    got, earned = [observations], []
    for k in range(T):
        observations, rewards, terminated, truncated, info = v.step(actions[k])
        got.append(info["final_observation"] if k == T - 1 else observations)
        earned.append(rewards)
    got, earned = np.array(got), np.array(earned)
    for b in range(B):
        seen, reward, rate = single(11 + b, actions[:, b], steps=T, **settings)
        assert np.array_equal(got[:, b], seen), b
        assert np.array_equal(earned[:, b], reward), b  # a failed UAV earns 0
        assert info["observation_rate"][b] == rate


def test_the_next_episode_starts_with_the_next_seeds():
    v = vector_env(3, steps=4)
    v.reset(seed=5)
    assert v.seeds == [5, 6, 7]
    for _ in range(4):
        observations, rewards, terminated, truncated, info = v.step(v.paper_actions())
    assert terminated.all() and truncated.all()
    assert list(info["seeds"]) == [5, 6, 7] and v.seeds == [8, 9, 10]
    fresh, _ = vector_env(3, steps=4).reset(seed=8)
    assert np.array_equal(observations, fresh)  # the new episode's first observations
    assert np.array_equal(info["final_state"][:, 0], np.ones(3))  # progress 4/4


def test_paper_actions_reproduce_simulate_trial_by_trial():
    v = vector_env(3, steps=15)
    v.reset(seed=20)
    for _ in range(15):
        *_, info = v.step(v.paper_actions())
    for b in range(3):
        reference = uavtrack.simulate(uavtrack.Scenario(steps=15), "distributed", seed=20 + b)
        assert info["observation_rate"][b] == reference.observation_rate


def test_paper_actions_reproduce_simulate_with_tracks_trial_by_trial():
    tracked = {"tracker": {"association": "gnn"}, "sensor": {"clutter_rate": 2}}
    v = vector_env(3, steps=15, **tracked)
    v.reset(seed=30)
    for _ in range(15):
        *_, info = v.step(v.paper_actions())
    scenario = uavtrack.Scenario(steps=15, **tracked)
    for b in range(3):
        reference = uavtrack.simulate(scenario, "distributed", seed=30 + b)
        assert info["observation_rate"][b] == pytest.approx(reference.observation_rate, rel=1e-12)


def test_without_paper_actions_the_agents_trial_is_the_same():
    actions = np.random.default_rng(1).integers(0, 3, size=(12, 2, 5))
    runs = []
    for planned in (True, False):
        v = vector_env(2, steps=12, paper_actions=planned)
        out = [v.reset(seed=3)[0]]
        for k in range(12):
            observations, rewards, *_, info = v.step(actions[k])
            out.append(rewards)
        runs.append((out, info["observation_rate"]))
    (a, rate_a), (b, rate_b) = runs
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert np.array_equal(rate_a, rate_b)
    with pytest.raises(RuntimeError, match="paper_actions=False"):
        v.paper_actions()


def test_the_count_is_num_envs_as_in_gymnasium_and_vmas():
    v = vector_env(num_envs=3, steps=4)
    observations, _ = v.reset(seed=0)
    assert v.num_envs == 3 and observations.shape[:2] == (3, 5) and v.seeds == [0, 1, 2]


def test_dict_observations_batch_too():
    v = vector_env(2, steps=5, observation="dict")
    observations, _ = v.reset(seed=0)
    assert observations["estimates"].shape == (2, 5, 4, 4)
    assert v.state().shape == (2, v.state_space.shape[0])


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="num_envs must be at least 1"):
        vector_env(0)
    with pytest.raises(TypeError, match="num_envs must be an integer"):
        vector_env(2.5)
    v = vector_env(2, steps=5)
    with pytest.raises(RuntimeError, match=r"call reset\(\) before step"):
        v.step(np.ones((2, 5), int))
    with pytest.raises(RuntimeError, match=r"call reset\(\) first"):
        v.state()
    v.reset(seed=0)
    with pytest.raises(TypeError, match="not None"):
        v.step(None)
    with pytest.raises(ValueError, match=r"shape \(2, 5\)"):
        v.step(np.ones((5,), int))
    with pytest.raises(ValueError, match="0, 1 or 2"):
        v.step(np.full((2, 5), 3))
    with pytest.raises(ValueError, match="seed must be"):
        v.reset(seed=-1)
