"""One UAV learns with PPO (Stable-Baselines3) while the rest of the paper's team flies
the paper's method: the single-agent Gymnasium Env ``uavtrack/SingleUAV-v0``.

    pip install ".[learn]"                      # install your torch build first
    python examples/single_ppo.py               # 20,000 steps, a few minutes on 2 cores
    python examples/single_ppo.py --steps 512 --trials 2   # a smoke run

Prints the learner's return and the team's observation rate on held-out seeds, for the
trained policy and for the UAV flying the paper's method itself.
"""

from __future__ import annotations

import argparse

import gymnasium
import numpy as np
from stable_baselines3 import PPO

import uavtrack.env  # noqa: F401  (registers uavtrack/SingleUAV-v0)

CYCLES = 100  # per episode
HELD_OUT = 1_000_000  # held-out trials are 10^6, 10^6 + 1, ...


def score(env, act, trials: int) -> tuple[float, float]:
    """Mean return of the learner and mean observation rate over held-out trials."""
    returns, rates = [], []
    for t in range(trials):
        observation, info = env.reset(seed=HELD_OUT + t)
        total, done = 0.0, False
        while not done:
            observation, reward, terminated, truncated, info = env.step(act(observation, info))
            total, done = total + reward, terminated or truncated
        returns.append(total)
        rates.append(env.unwrapped.result().observation_rate)
    return float(np.mean(returns)), float(np.mean(rates))


def main(argv: list[str] | None = None) -> dict[str, tuple[float, float]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="PPO's training steps")
    parser.add_argument("--trials", type=int, default=10, help="held-out trials")
    args = parser.parse_args(argv)
    env = gymnasium.make("uavtrack/SingleUAV-v0", max_cycles=CYCLES)
    model = PPO("MlpPolicy", env, n_steps=256, batch_size=64, seed=0, verbose=0)
    model.learn(total_timesteps=args.steps)
    scores = {
        "ppo": score(env, lambda o, i: int(model.predict(o, deterministic=True)[0]), args.trials),
        "paper": score(env, lambda o, i: i["paper_action"], args.trials),
    }
    for name, (ret, rate) in scores.items():
        print(f"{name:6s} return {ret:7.2f}  observation rate {rate:.3f}")
    return scores


if __name__ == "__main__":
    main()
