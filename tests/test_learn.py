"""The environment in the learning libraries' own hands (the learn extra: torch,
Stable-Baselines3, SuperSuit, TorchRL); skipped where they are not installed."""

import numpy as np
import pytest

pytest.importorskip("pettingzoo")
torch = pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")
ss = pytest.importorskip("supersuit")
pytest.importorskip("torchrl")

from stable_baselines3 import PPO  # noqa: E402
from torchrl.envs.libs.pettingzoo import PettingZooWrapper  # noqa: E402
from torchrl.envs.utils import check_env_specs  # noqa: E402

from uavtrack.env import parallel_env, vector_env  # noqa: E402
from uavtrack.env.learn import sb3_vec_env, torchrl_env  # noqa: E402

FAILING = {"faults": {"failures": [[1, 4]]}}


def test_torchrl_check_env_specs_with_state():
    env = torchrl_env(vector_env(3, steps=6, **FAILING), seed=0)
    check_env_specs(env)
    rollout = env.rollout(13, break_when_any_done=False)  # two episodes and a bit
    done = rollout["next", "done"][:, :, 0]  # (trials, steps)
    assert done[:, 5].all() and done[:, 11].all() and done.sum() == 2 * 3
    state = rollout["next", "state"]
    assert state.shape == (3, 13, env.vector.state_space.shape[0])
    alive = rollout["next", "agents", "alive"][..., 0]
    assert not alive[:, 4, 1].any() and alive[:, 4, 0].all()  # UAV 1 fails at step 4
    assert not rollout["next", "agents", "observation"][:, 4, 1].any()  # and sees nothing


def test_torchrl_pettingzoo_wrapper_with_state():
    env = PettingZooWrapper(parallel_env(steps=8), return_state=True, use_mask=True)
    check_env_specs(env)
    assert env.rollout(5)["state"].shape[-1] == parallel_env().state_space.shape[0]


def test_supersuit_black_death_keeps_failed_uavs_through_episodes():
    env = ss.black_death_v3(parallel_env(steps=6, **FAILING))
    vec = ss.pettingzoo_env_to_vec_env_v1(env)
    vec = ss.concat_vec_envs_v1(vec, 2, num_cpus=0, base_class="stable_baselines3")
    observations = vec.reset()
    assert observations.shape == (10, env.observation_space("uav_0").shape[0])
    ends = 0
    for k in range(13):
        observations, rewards, dones, infos = vec.step(np.ones(10, dtype=np.int64))
        if k % 6 >= 4 and not dones.any():  # UAV 1 of each copy has failed: black death
            assert not observations[[1, 6]].any() and not rewards[[1, 6]].any()
        ends += dones.all()
    assert ends == 2  # both episodes ended and reset
    PPO("MlpPolicy", vec, n_steps=12, batch_size=60, n_epochs=1).learn(120)  # no seed():
    # SuperSuit's SB3 wrapper has none to pass one on


def test_sb3_vec_env_ends_episodes_as_terminal_states():
    vec = sb3_vec_env(vector_env(2, steps=5), seed=3)
    observations = vec.reset()
    assert observations.shape == (10, vec.observation_space.shape[0])
    for _ in range(5):
        observations, rewards, dones, infos = vec.step(np.full(10, 2))
    assert dones.all() and infos[0]["TimeLimit.truncated"] is False
    assert infos[7]["terminal_observation"].shape == observations[7].shape
    model = PPO("MlpPolicy", vec, n_steps=5, batch_size=50, n_epochs=1, seed=0)
    model.learn(100)
    assert model.num_timesteps == 100
