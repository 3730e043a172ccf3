"""The PettingZoo environment with two policies side by side: random bank angles, and
the paper's method (each agent flies its `paper_action`). Trains nothing.

    pip install "uavtrack[env]"
    python examples/env_policies.py
"""

import numpy as np

from uavtrack.env import parallel_env


def episode(env, policy, seed):
    observations, infos = env.reset(seed=seed)
    reward = 0.0
    while env.agents:
        actions = {a: policy(a, observations[a], infos[a]) for a in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)
        reward += sum(rewards.values())
    return reward, env.result().observation_rate


if __name__ == "__main__":
    rng = np.random.default_rng(0)
    env = parallel_env(steps=200)
    policies = {
        "random": lambda agent, obs, info: int(rng.integers(3)),
        "paper": lambda agent, obs, info: info["paper_action"],
    }
    print("policy  seed  team reward (targets in view, summed)  observation rate")
    for name, policy in policies.items():
        for seed in range(3):
            reward, rate = episode(env, policy, seed)
            print(f"{name:7s} {seed:4d}  {reward:37.0f}  {rate:16.3f}")
