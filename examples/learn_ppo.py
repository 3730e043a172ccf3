"""A baseline that learns: PPO with one policy shared by every UAV (Stable-Baselines3),
trained on the vector environment, then scored on held-out seeds against random bank
angles, circling (always bank +phi) and the paper's method.

    pip install ".[learn]"                       # install your torch build first
    python examples/learn_ppo.py                 # about 20 minutes on 2 cores
    python examples/learn_ppo.py --via supersuit # the same through SuperSuit's wrappers

Writes learn-ppo/ (the model, summary.json and table.md). The scenario is the paper's
Sec. 7.1 with 200-step episodes (more episodes per minute than 500; held-out trials use
the same length). Rewards are the default team reward (see uavtrack.env).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from uavtrack.env import parallel_env, vector_env
from uavtrack.env.learn import sb3_vec_env

STEPS = 200  # cycles per episode
TRAIN_SEED = 1_000  # training trials are 1000, 1001, ...; held-out ones start at 10^6
HELD_OUT = 1_000_000


def training_env(via: str, trials: int):
    if via == "vector":
        return sb3_vec_env(vector_env(trials, steps=STEPS, paper_actions=False), seed=TRAIN_SEED)
    import supersuit as ss

    env = ss.black_death_v3(parallel_env(steps=STEPS))  # failed UAVs stay, as zeros
    env = ss.pettingzoo_env_to_vec_env_v1(env)
    # SuperSuit's SB3 wrapper cannot pass seeds on (it has no seed()): fresh trials
    return ss.concat_vec_envs_v1(env, trials, num_cpus=0, base_class="stable_baselines3")


def evaluate(policies: dict, trials: int) -> dict[str, dict[str, float]]:
    """Each policy on the same held-out trials: the team's return per episode (every
    agent earns the same) and the observation rate, mean and standard deviation."""
    out = {}
    for name, policy in policies.items():
        v = vector_env(trials, steps=STEPS)
        observations, info = v.reset(seed=HELD_OUT)
        total = np.zeros(trials)
        for _ in range(STEPS):
            actions = policy(v, observations, info)
            observations, rewards, terminated, truncated, info = v.step(actions)
            total += rewards[:, 0]
        rate = info["observation_rate"]
        out[name] = {
            "return_mean": float(total.mean()),
            "return_std": float(total.std(ddof=1)),
            "rate_mean": float(rate.mean()),
            "rate_std": float(rate.std(ddof=1)),
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--timesteps", type=int, default=12_000_000, help="agent-steps to train")
    parser.add_argument("--minutes", type=float, default=28.0, help="stop training by then")
    parser.add_argument("--trials", type=int, default=32, help="trials stepped as one batch")
    parser.add_argument("--eval-trials", type=int, default=50, help="held-out trials")
    parser.add_argument("--via", choices=("vector", "supersuit"), default="vector")
    parser.add_argument("--out", type=Path, default=Path("learn-ppo"))
    parser.add_argument("--seed", type=int, default=0, help="PPO's seed")
    args = parser.parse_args()
    if args.timesteps < 1 or args.trials < 1 or args.eval_trials < 2 or args.minutes <= 0:
        parser.error("--timesteps, --trials, --minutes must be positive, --eval-trials >= 2")

    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.utils import set_random_seed

    torch.set_num_threads(1)  # the environment and the learner share 2 cores

    class Deadline(BaseCallback):
        def __init__(self, seconds: float) -> None:
            super().__init__()
            self.end = time.monotonic() + seconds

        def _on_step(self) -> bool:
            return time.monotonic() < self.end

    env = training_env(args.via, args.trials)
    set_random_seed(args.seed)  # not PPO(seed=): SuperSuit's wrapper cannot take env.seed()
    model = PPO(
        "MlpPolicy",
        env,
        n_steps=128,
        batch_size=4096,
        n_epochs=4,
        learning_rate=3e-4,
        gamma=0.99,
        gae_lambda=0.95,
        ent_coef=0.01,
        policy_kwargs={"net_arch": [128, 128]},
        verbose=0,
    )
    start = time.monotonic()
    model.learn(args.timesteps, callback=Deadline(60 * args.minutes))
    minutes = (time.monotonic() - start) / 60
    trained = int(model.num_timesteps)
    env.close()
    print(f"trained {trained:,} agent-steps in {minutes:.1f} min via {args.via}")

    rng = np.random.default_rng(0)
    policies = {
        "random": lambda v, o, info: rng.integers(0, 3, size=o.shape[:2]),
        "circling (always +phi)": lambda v, o, info: np.full(o.shape[:2], 2),
        "PPO (shared policy)": lambda v, o, info: model.predict(
            o.reshape(-1, o.shape[-1]), deterministic=True
        )[0].reshape(o.shape[:2]),
        "paper (distributed)": lambda v, o, info: info["paper_action"],
    }
    scores = evaluate(policies, args.eval_trials)
    args.out.mkdir(parents=True, exist_ok=True)
    model.save(args.out / "model.zip")
    import stable_baselines3

    summary = {
        "versions": {"torch": torch.__version__, "sb3": stable_baselines3.__version__},
        "trained_agent_steps": trained,
        "training_minutes": round(minutes, 1),
        "via": args.via,
        "episode_steps": STEPS,
        "held_out_seeds": [HELD_OUT, HELD_OUT + args.eval_trials - 1],
        "scores": scores,
    }
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    lines = [
        f"{args.eval_trials} held-out trials (seeds {HELD_OUT}-{HELD_OUT + args.eval_trials - 1}),"
        f" {STEPS} steps; PPO trained {trained:,} agent-steps in {minutes:.1f} min",
        "",
        "| policy | team return per episode | observation rate |",
        "|---|---|---|",
    ]
    for name, s in scores.items():
        lines.append(
            f"| {name} | {s['return_mean']:.1f} ± {s['return_std']:.1f} "
            f"| {s['rate_mean']:.3f} ± {s['rate_std']:.3f} |"
        )
    (args.out / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
