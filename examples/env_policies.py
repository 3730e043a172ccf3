"""Three fixed policies in the environment, scored on held-out seeds under each reward:
random bank angles, circling (always bank +phi) and the paper's method (each agent flies
its ``paper_action``). Trains nothing.

    pip install ".[env]"
    python examples/env_policies.py [--trials 20] [--steps 200]

Every policy flies the same trials (seeds 1000000, 1000001, ...) through the vector
environment; the table gives each reward's return per agent and episode (mean over the
trials and the agents, with its standard deviation over the trials) and the observation
rate.
"""

from __future__ import annotations

import argparse

import numpy as np

from uavtrack.env import REWARDS, vector_env

HELD_OUT = 1_000_000


def score(policy, reward: str, trials: int, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Per trial: the return per agent and the observation rate."""
    v = vector_env(trials, steps=steps, reward=reward)
    observations, info = v.reset(seed=HELD_OUT)
    total = np.zeros((trials, v.num_agents))
    for _ in range(steps):
        observations, rewards, terminated, truncated, info = v.step(policy(observations, info))
        total += rewards
    return total.mean(axis=1), info["observation_rate"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--steps", type=int, default=200)
    args = parser.parse_args()
    if args.trials < 2 or args.steps < 2:
        parser.error("--trials and --steps must be at least 2")
    policies = {
        "random": lambda rng: lambda o, info: rng.integers(0, 3, size=o.shape[:2]),
        "circling": lambda rng: lambda o, info: np.full(o.shape[:2], 2),
        "paper": lambda rng: lambda o, info: info["paper_action"],
    }
    names = sorted(REWARDS, key=list(REWARDS).index)
    print(f"{args.trials} held-out trials, {args.steps} steps: return per agent and episode")
    print(f"{'policy':9s}" + "".join(f"{n:>22s}" for n in names) + f"{'observation rate':>20s}")
    for name, make in policies.items():
        cells, rate = [], None
        for reward in names:
            returns, rates = score(make(np.random.default_rng(0)), reward, args.trials, args.steps)
            cells.append(f"{returns.mean():10.2f} ± {returns.std(ddof=1):8.2f}")
            rate = rates
        print(f"{name:9s}" + "".join(f"{c:>22s}" for c in cells), end="")
        print(f"{rate.mean():12.3f} ± {rate.std(ddof=1):.3f}")


if __name__ == "__main__":
    main()
