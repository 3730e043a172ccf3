"""Learned teams against the paper's planner: train a policy, evaluate it paired.

Each row of the benchmark is one command with its seed, CPU only, on the scenario given
(default: the paper's 5 x 4): ``python -m uavtrack.experiments.learned ROW --seed S --out
FILE`` trains the row, evaluates it and records both in the file.

* ``bc``: behaviour cloning of the paper's method with DAgger (Ross, Gordon and
  Bagnell, 2011). Round 0 flies the planner's actions and records (observation, the
  planner's action) for every living UAV; each later round flies the policy learned so
  far and records what the planner would have flown in the states the policy reached.
  One multilayer perceptron, shared by every UAV, is fitted to all the rounds' records
  by cross-entropy. Written as a policy file (`policy`).
* ``evaluate``: the policy and the paper's method on the same held-out trials (trial t
  of seed 0, as ``uavtrack compare`` draws them; training draws trials from
  `TRAIN_SEED` on, which these never are): the observation rate with a 95 % interval,
  and the paired difference to the planner, written into the file (``record``);
* ``report``: the results page of evaluated files, and their learning curves.

The training's own random draws (initial weights, minibatch order) come from the seed,
so a seed gives the same weights on one CPU (another may round the sums differently).
NumPy only: no learning library is needed to train, fly or evaluate this row.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..config import Scenario, ScenarioError, flatten, parse_overrides
from ..env.policy import Policy
from ..env.spaces import Spaces
from ..env.vector import vector_env
from ..errors import UsageError, install_hint

__all__ = [
    "FINE_TUNE_SEED", "MARL", "MARL_SEED", "ROWS", "ROWS_OF_THE_OBSERVATION", "TRAIN_SEED",
    "FineTuning", "Imitation", "Marl", "evaluate", "fine_tune", "imitate", "main", "marl",
    "marl_experiment", "policy_of", "ppo_from", "record", "report",
]  # fmt: skip

TRAIN_SEED = 1_000_000
"""The first trial seed of training (``vector_env``'s reset seeds, one per trial): far
from the evaluation's trials, which are children of seed 0 (`world.trial_seed`)."""


@dataclass(frozen=True, kw_only=True)
class Imitation:
    """The settings of ``bc``: DAgger rounds, the trials of each, the hidden layers'
    width and count, the observation's rows, epochs and minibatch of each fit, the
    learning rate."""

    rounds: int = 12
    trials: int = 32
    hidden: int = 256
    layers: int = 2
    max_targets: int = 4
    max_neighbours: int = 4
    epochs: int = 10
    batch: int = 1024
    learning_rate: float = 1e-3


def _collect(
    scenario: Scenario, settings: Imitation, policy: Policy | None, seed: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """One round: `settings.trials` trials from trial seed `seed`, flown by `policy`
    (None: the planner). Returns every living UAV's observations (S, size), the planner's
    actions (S,) and the trials' mean observation rate."""
    env = vector_env(
        settings.trials, scenario, max_targets=settings.max_targets,
        max_neighbours=settings.max_neighbours,
    )  # fmt: skip
    observation, info = env.reset(seed=seed)
    seen, labels = [], []
    while True:
        alive = info["alive"]
        seen.append(observation[alive])
        labels.append(info["paper_action"][alive])
        flown = info["paper_action"] if policy is None else policy.act(observation)
        observation, _, done, _, info = env.step(np.where(alive, flown, 1).astype(np.int64))
        if done.all():
            rate = float(np.mean(info["observation_rate"]))
            return np.concatenate(seen), np.concatenate(labels), rate


def _fit(x: np.ndarray, y: np.ndarray, settings: Imitation, seed: int, log: Any) -> Policy:
    """A tanh perceptron (`Imitation`'s hidden layers) fitted to the actions y (S,) of
    observations x (S, size) by softmax cross-entropy, Adam on minibatches (NumPy,
    float32): initial weights and minibatch order drawn from `seed`."""
    rng = np.random.default_rng(seed)
    sizes = [x.shape[1]] + [settings.hidden] * settings.layers + [3]
    params: list[np.ndarray] = []
    for a, b in zip(sizes[:-1], sizes[1:], strict=True):  # as torch.nn.Linear draws them
        bound = 1.0 / np.sqrt(a)
        params += [rng.uniform(-bound, bound, (a, b)), rng.uniform(-bound, bound, b)]
    params = [p.astype(np.float32) for p in params]
    moments = [np.zeros_like(p) for p in params]
    squares = [np.zeros_like(p) for p in params]
    beta1, beta2, eps, t = 0.9, 0.999, 1e-8, 0
    x, onehot = x.astype(np.float32), np.eye(3, dtype=np.float32)[y]
    total = np.nan  # the last epoch's summed cross-entropy
    for epoch in range(settings.epochs):
        total = 0.0
        order = rng.permutation(len(x))
        for start in range(0, len(x), settings.batch):
            rows = order[start : start + settings.batch]
            h, hs = x[rows], []
            for i in range(0, len(params), 2):
                hs.append(h)
                h = h @ params[i] + params[i + 1]
                if i + 2 < len(params):
                    h = np.tanh(h)
            h = h - h.max(axis=1, keepdims=True)
            p = np.exp(h)
            p /= p.sum(axis=1, keepdims=True)
            total += float(-np.log(np.maximum((p * onehot[rows]).sum(1), 1e-30)).sum())
            grad = (p - onehot[rows]) / len(rows)  # of the mean loss by the logits
            grads: list[np.ndarray] = [np.empty(0)] * len(params)
            for i in range(len(params) - 2, -1, -2):
                grads[i], grads[i + 1] = hs[i // 2].T @ grad, grad.sum(0)
                if i:
                    grad = (grad @ params[i].T) * (1.0 - hs[i // 2] ** 2)  # tanh' = 1 - tanh^2
            t += 1
            step = settings.learning_rate * np.sqrt(1 - beta2**t) / (1 - beta1**t)
            for p_, g, m, v in zip(params, grads, moments, squares, strict=True):
                m *= beta1
                m += (1 - beta1) * g
                v *= beta2
                v += (1 - beta2) * g * g
                p_ -= step * m / (np.sqrt(v) + eps)
        log(f"  epoch {epoch + 1}: cross-entropy {total / len(x):.4f}")
    layers = [(params[i], params[i + 1]) for i in range(0, len(params), 2)]
    return Policy(
        layers=layers, activation="tanh", max_targets=settings.max_targets,
        max_neighbours=settings.max_neighbours, meta={"loss": total / len(x)},
    )  # fmt: skip


def imitate(
    scenario: Scenario, settings: Imitation = Imitation(), seed: int = 0, log: Any = print
) -> Policy:
    """``bc``: the policy DAgger fits to the paper's method (see the module), with its
    record in ``meta``: row, seed, settings, frames (UAV-steps recorded), CPU seconds,
    each round's rate on its training trials (round 0: the planner's) and each fit's
    final cross-entropy."""
    start = time.process_time()
    xs, ys, rates, losses = [], [], [], []
    policy: Policy | None = None
    for r in range(settings.rounds):
        first = TRAIN_SEED + r * settings.trials
        x, y, rate = _collect(scenario, settings, policy, first)
        xs.append(x)
        ys.append(y)
        rates.append(rate)
        flown = "the planner" if policy is None else "the policy"
        log(f"round {r}: {len(x)} samples, {flown} flew rate {rate:.3f}")
        policy = _fit(np.concatenate(xs), np.concatenate(ys), settings, seed + r, log)
        losses.append(policy.meta["loss"])
    assert policy is not None
    meta = {
        "row": "bc",
        "seed": seed,
        "settings": vars(settings),
        "frames": int(sum(len(x) for x in xs)),
        "round_rates": rates,
        "round_losses": losses,
        "cpu_seconds": time.process_time() - start,
        "scenario": scenario.model_dump(mode="json", exclude_defaults=True),
    }
    return replace(policy, meta=meta)


def evaluate(
    scenario: Scenario, policy: str, trials: int = 50, seed: int = 0, against: str = "distributed"
) -> dict[str, Any]:
    """The policy (a method name, ``policy:FILE``) and `against` on the same `trials`
    trials of `seed`: each one's observation rate (mean, 95 % half-width) and the paired
    difference, policy minus `against`."""
    from .. import simulation
    from ..world import trial_seed
    from .statistics import ci95, paired

    seeds = [trial_seed(seed, t) for t in range(trials)]
    rates = {
        name: simulation.run(scenario, name, seeds).metrics["observation_rate"]
        for name in (policy, against)
    }
    return {
        "trials": trials,
        "seed": seed,
        "rate": {k: {"mean": float(v.mean()), "ci95": ci95(v)} for k, v in rates.items()},
        "difference": paired(rates[policy], rates[against]),
        "per_trial": {k: v.tolist() for k, v in rates.items()},
    }


def record(
    path: Path, scenario: Scenario | None = None, trials: int = 50, seed: int = 0
) -> dict[str, Any]:
    """Evaluate the policy file at `path` (`evaluate`) on the scenario it was trained on
    (its ``meta["scenario"]``; `scenario` only for a file that records none) and write the
    result, with that scenario, into its meta as ``evaluation``: the file carries the
    rate it reached."""
    policy = Policy.load(path)
    if "scenario" in policy.meta:
        scenario = Scenario.model_validate(policy.meta["scenario"])
    scenario = Scenario() if scenario is None else scenario
    result = evaluate(scenario, f"policy:{path}", trials, seed)
    renamed = lambda d: {("policy" if k.startswith("policy:") else k): v for k, v in d.items()}  # noqa: E731
    result["rate"], result["per_trial"] = renamed(result["rate"]), renamed(result["per_trial"])
    result["scenario"] = scenario.model_dump(mode="json", exclude_defaults=True)
    replace(policy, meta={**policy.meta, "evaluation": result}).save(path)
    return result


@dataclass(frozen=True, kw_only=True)
class FineTuning:
    """The settings of ``bc-ppo``: agent-steps of PPO, of them the first ones with the
    policy frozen (the critic learns the value of the imitation first), trials stepped
    as one batch, PPO's learning rate and clip range."""

    frames: int = 4_000_000
    warm: int = 500_000
    trials: int = 32
    learning_rate: float = 3e-5
    clip: float = 0.1


FINE_TUNE_SEED = 2_000_000
"""The first trial seed of fine-tuning: apart from imitation's and evaluation's."""


def ppo_from(
    scenario: Scenario, start: Policy, settings: FineTuning = FineTuning(), seed: int = 0
) -> tuple[Any, list[Any]]:
    """A Stable-Baselines3 PPO on the vector environment of `scenario` whose actor is
    `start`'s perceptron, copied weight for weight (its greedy action is the policy's),
    and its critic of the same shape; returns (model, the actor's linear layers)."""
    if start.activation != "tanh":  # refused before the learning libraries load
        raise UsageError(f"bc-ppo starts from a tanh perceptron, not {start.activation}")
    if start.graph is not None:
        raise UsageError("bc-ppo starts from a perceptron, not a graph policy")
    try:
        import torch  # pyright: ignore[reportMissingImports]  (the learn extra)
        from stable_baselines3 import PPO  # pyright: ignore[reportMissingImports]
    except ImportError as exc:
        hint = install_hint("learn")
        raise UsageError(f"bc-ppo needs torch and stable-baselines3: {hint} ({exc})") from None
    from ..env.learn import sb3_vec_env

    torch.set_num_threads(1)
    vector = vector_env(
        settings.trials, scenario, max_targets=start.max_targets,
        max_neighbours=start.max_neighbours, paper_actions=False,
    )  # fmt: skip
    hidden = [int(W.shape[1]) for W, _ in start.layers[:-1]]
    model = PPO(
        "MlpPolicy", sb3_vec_env(vector, seed=FINE_TUNE_SEED), n_steps=128, batch_size=4096,
        n_epochs=4, learning_rate=settings.learning_rate, gamma=0.99, gae_lambda=0.95,
        ent_coef=0.0, clip_range=settings.clip, seed=seed, verbose=0,
        policy_kwargs={"net_arch": {"pi": hidden, "vf": hidden}, "activation_fn": torch.nn.Tanh},
    )  # fmt: skip
    actor = [*_linears(model.policy.mlp_extractor.policy_net), model.policy.action_net]
    with torch.no_grad():
        for linear, (W, b) in zip(actor, start.layers, strict=True):
            linear.weight.copy_(torch.as_tensor(W.T))
            linear.bias.copy_(torch.as_tensor(b))
    return model, actor


def fine_tune(
    scenario: Scenario,
    start: Policy,
    settings: FineTuning = FineTuning(),
    seed: int = 0,
    log: Any = print,
) -> Policy:
    """``bc-ppo``: PPO (Stable-Baselines3, `ppo_from`) from the policy `start` on the team
    reward: the critic learns alone for ``settings.warm`` agent-steps, then both learn.
    Needs the learn extra (torch, stable-baselines3)."""
    begin = time.process_time()
    model, actor = ppo_from(scenario, start, settings, seed)
    for linear in actor:
        linear.requires_grad_(False)
    model.learn(settings.warm)
    log(f"critic alone: {model.num_timesteps:,} agent-steps")
    for linear in actor:
        linear.requires_grad_(True)
    model.learn(settings.frames - settings.warm, reset_num_timesteps=False)
    log(f"actor and critic: {model.num_timesteps:,} agent-steps")
    layers = [
        (m.weight.detach().numpy().T.astype(np.float32), m.bias.detach().numpy().astype(np.float32))
        for m in actor
    ]
    model.get_env().close()
    meta = {
        "row": "bc-ppo",
        "seed": seed,
        "settings": vars(settings),
        "start": start.meta.get("command", ""),
        "frames": int(start.meta.get("frames", 0)) + int(model.num_timesteps),
        "round_rates": start.meta.get("round_rates", []),
        "cpu_seconds": float(start.meta.get("cpu_seconds", 0.0)) + time.process_time() - begin,
        "scenario": scenario.model_dump(mode="json", exclude_defaults=True),
    }
    return Policy(
        layers=layers, activation="tanh", max_targets=start.max_targets,
        max_neighbours=start.max_neighbours, meta=meta,
    )  # fmt: skip


MARL_SEED = 3_000_000
"""Added to a BenchMARL row's seed: the experiment's seed, which seeds torch and the
trials it trains on (`vector_env` trials from it on), apart from the others'."""

MARL = {"mappo": "MappoConfig", "ippo": "IppoConfig", "mappo-gnn": "MappoConfig"}
"""BenchMARL's algorithms of the MARL rows, by row name."""


@dataclass(frozen=True, kw_only=True)
class Marl:
    """The settings of a BenchMARL row (`MARL`): frames (trial-steps, as
    BenchMARL counts them: every UAV acts in each), trials stepped as one batch, frames
    per iteration, the hidden layers' width and count (tanh, the actor's and the
    critic's), the learning rate; the rest is BenchMARL's default configuration."""

    frames: int = 600_000
    trials: int = 10
    batch: int = 6_000
    hidden: int = 256
    layers: int = 2
    learning_rate: float = 5e-5


def _marl_classes() -> Any:
    """BenchMARL's modules, or a one-line `UsageError` saying how to install them."""
    try:
        import benchmarl.algorithms as algorithms  # pyright: ignore[reportMissingImports]
        import benchmarl.experiment as experiment  # pyright: ignore[reportMissingImports]
        import benchmarl.models as models  # pyright: ignore[reportMissingImports]
        import torch  # pyright: ignore[reportMissingImports]  (the learn extra)
    except ImportError as exc:
        raise UsageError(f"the MARL rows need benchmarl: {install_hint('learn')} ({exc})") from None
    return algorithms, experiment, models, torch


ROWS_OF_THE_OBSERVATION = {"max_targets": 4, "max_neighbours": 4}
"""The observation's rows of the MARL rows, as ``bc``'s."""


def marl_experiment(
    scenario: Scenario, row: str, settings: Marl, seed: int, folder: str, callbacks: Any = ()
) -> Any:
    """The BenchMARL experiment of a MARL row (`MARL`), not yet run, saving in `folder`
    (see `marl`)."""
    algorithms, experiment, models, torch = _marl_classes()
    from ..env.benchmarl import UAVTrackTask

    config = experiment.ExperimentConfig.get_from_yaml()
    config.max_n_frames, config.max_n_iters = settings.frames, None
    config.on_policy_collected_frames_per_batch = settings.batch
    config.on_policy_n_envs_per_worker = settings.trials
    config.lr = settings.learning_rate
    config.evaluation, config.render, config.loggers = False, False, []
    config.create_json, config.checkpoint_at_end = False, False
    config.save_folder = folder
    model = models.MlpConfig.get_from_yaml()
    model.num_cells = [settings.hidden] * settings.layers
    model.activation_class = torch.nn.Tanh
    graph = row == "mappo-gnn"
    actor = _graph_actor(scenario, settings, models, torch) if graph else model
    overrides = scenario.model_dump(mode="json", exclude_defaults=True)
    tracking: Any = UAVTrackTask.TRACKING  # an enum member once BenchMARL made the class
    task = tracking.get_task(
        {"overrides": overrides, "positions": graph, **ROWS_OF_THE_OBSERVATION}
    )
    algorithm = getattr(algorithms, MARL[row]).get_from_yaml()
    return experiment.Experiment(
        task=task, algorithm_config=algorithm, model_config=actor, critic_model_config=model,
        seed=MARL_SEED + seed, config=config, callbacks=list(callbacks),
    )  # fmt: skip


def policy_of(run: Any, row: str, settings: Marl, meta: dict[str, Any] | None = None) -> Policy:
    """The shared actor of a MARL row's experiment `run` as a policy file's layers:
    BenchMARL's perceptron, after a graph row's GraphConv layer (lin_root, no bias, and
    lin_rel with its bias)."""
    found = {k: v.detach().numpy() for k, v in run.policy.named_parameters()}
    graph = row == "mappo-gnn"
    first = None
    if graph:
        pick = lambda end: next(v for k, v in found.items() if k.endswith(end))  # noqa: E731
        first = (pick("lin_root.weight").T.copy(), pick("lin_rel.weight").T.copy(),
                 pick("lin_rel.bias").copy())  # fmt: skip
    layers = _actor_layers(found, settings.layers - int(graph) + 1)
    return Policy(
        layers=layers, activation="tanh", meta=meta or {}, graph=first,
        **ROWS_OF_THE_OBSERVATION,
    )  # fmt: skip


def marl(
    scenario: Scenario, row: str, settings: Marl = Marl(), seed: int = 0, log: Any = print
) -> Policy:
    """A BenchMARL row (`MARL`: MAPPO, IPPO, MAPPO with a graph layer) trained from
    scratch on the task (`env.benchmarl`, the team reward), CPU, one thread; its shared
    actor written as a policy whose greedy action is the actor's most likely one
    (`policy_of`). Its ``meta`` records each iteration's mean team reward on its own
    trials (sampling actions: the training's observation rate) against the frames."""
    torch = _marl_classes()[3]
    from ..env.benchmarl import Curve

    torch.set_num_threads(1)
    begin = time.process_time()
    curve = Curve(verbose=log is print)
    with tempfile.TemporaryDirectory() as folder:
        run = marl_experiment(scenario, row, settings, seed, folder, [curve])
        run.run()
    meta = {
        "row": row,
        "seed": seed,
        "settings": vars(settings),
        "frames": int(run.total_frames) * scenario.n_uavs,  # UAV-steps, as the other rows
        "curve": curve.points,
        "cpu_seconds": time.process_time() - begin,
        "scenario": scenario.model_dump(mode="json", exclude_defaults=True),
    }
    return policy_of(run, row, settings, meta)


def _graph_actor(scenario: Scenario, settings: Marl, models: Any, torch: Any) -> Any:
    """``mappo-gnn``'s actor: one GraphConv layer (PyTorch Geometric, sum over the UAVs
    within r_C, `Spaces.positions`) to the hidden width, then the perceptron's other
    hidden layers (tanh) to the three logits."""
    from torch_geometric.nn import GraphConv  # pyright: ignore[reportMissingImports]

    from ..env.benchmarl import use_dense_radius_graph

    use_dense_radius_graph()  # PyG's needs pyg-lib or torch-cluster, which PyPI lacks

    gnn = models.GnnConfig(
        topology="from_pos", self_loops=False, gnn_class=GraphConv,
        gnn_kwargs={"aggr": "add"}, position_key="position", pos_features=3,
        exclude_pos_from_node_features=True,
        edge_radius=scenario.comm_range / (scenario.field_size / 2),
    )  # fmt: skip
    mlp = models.MlpConfig.get_from_yaml()
    mlp.num_cells = [settings.hidden] * (settings.layers - 1)
    mlp.activation_class = torch.nn.Tanh
    return models.SequenceModelConfig(
        model_configs=[gnn, mlp], intermediate_sizes=[settings.hidden]
    )


def _actor_layers(found: dict[str, np.ndarray], count: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The `count` linear layers of BenchMARL's shared MLP actor among its parameters
    `found` by name, as (W, b) with x @ W + b (its linear layers are every other
    module, between them the activations)."""
    layers = []
    for i in range(count):
        (w,) = [v for k, v in found.items() if k.endswith(f"mlp.params.{2 * i}.weight")]
        (b,) = [v for k, v in found.items() if k.endswith(f"mlp.params.{2 * i}.bias")]
        layers.append((w.T.copy(), b.copy()))
    return layers


def _linears(net: Any) -> list[Any]:
    import torch  # pyright: ignore[reportMissingImports]  (the learn extra)

    return [m for m in net if isinstance(m, torch.nn.Linear)]


ROWS = {
    "bc": "behaviour cloning of the planner (DAgger), NumPy",
    "bc-ppo": "bc fine-tuned by PPO on the team reward (Stable-Baselines3)",
    "mappo": "MAPPO from scratch on the team reward (BenchMARL), shared actor, central critic",
    "mappo-gnn": "MAPPO whose actor's first layer sums over the radio graph (GraphConv)",
    "ippo": "IPPO from scratch on the team reward (BenchMARL), shared actor, local critic",
}
"""The rows this module trains, by name."""


def report(paths: Sequence[Path], figure: Path | None = None, page: Path | None = None) -> str:
    """The results page (markdown) of evaluated policy files: per row its frames, CPU
    hours, observation rate with its 95 % interval, the paired difference to the planner
    and the command that made it; with `figure`, the learning curves drawn there and
    linked from where the page will be written (`page`)."""
    from .statistics import ci

    lines = [
        "# Learned teams against the paper's planner",
        "",
        "Each row: a policy file made by the command in its last column "
        "(`uavtrack.experiments.learned`), flown as `--method policy:FILE` and paired "
        "with the paper's method (distributed) on the same held-out trials (0 to N - 1 of "
        "seed 0, which training never sees). Rates are means with a 95 % t interval; "
        "CPU hours are the training's (one thread), frames the UAV-steps it recorded. "
        "Goal: a policy within 0.02 of the planner; beyond it, above it with the paired "
        "interval above 0.",
        "",
        "| row | scenario | frames | CPU hours | trials | observation rate | planner "
        "| policy - planner (95% CI) | within 0.02 | command |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    curves = []
    for path in paths:
        meta = Policy.load(path).meta
        ev = meta.get("evaluation")
        if ev is None:
            raise UsageError(f"{path} holds no evaluation: run 'evaluate {path}' first")
        rate, planner, d = ev["rate"]["policy"], ev["rate"]["distributed"], ev["difference"]
        changed = ", ".join(f"{k}={v}" for k, v in flatten(meta.get("scenario", {})).items())
        lines.append(
            f"| {meta['row']} ({path.stem}) | {changed or 'the paper'} | {meta['frames']:,} | "
            f"{meta['cpu_seconds'] / 3600:.2f} | {ev['trials']} | "
            f"{rate['mean']:.3f} ± {rate['ci95']:.3f} | {planner['mean']:.3f} ± "
            f"{planner['ci95']:.3f} | {ci(d, digits=3)} | "
            f"{'yes' if d['mean'] >= -0.02 else 'no'} | `{meta.get('command', '')}` |"
        )
        if meta["row"] == "bc" or meta.get("curve"):  # DAgger's rounds, or BenchMARL's
            curves.append((path.stem, meta))
    if figure is not None:
        _curves(curves, figure)
        link = Path(os.path.relpath(figure, page.parent)).as_posix() if page else figure.name
        lines += [
            "",
            f"![learning curves]({link})",
            "",
            "The curves: the rate on each row's own training trials against the UAV-steps "
            "it has seen. DAgger (bc): each round's policy flying (round 0, the dashed "
            "line, is the planner). BenchMARL's rows: each iteration's mean team reward, "
            "its actions sampled from the actor (the table's rates fly the most likely "
            "action). The team reward at step k is the share of targets seen at k + 1, so "
            "a trial's team return is its steps times its observation rate, to one step.",
        ]
    return "\n".join(lines) + "\n"


def _curves(curves: list[tuple[str, dict[str, Any]]], figure: Path) -> None:
    """Each row's rate on its training trials against the UAV-steps it had seen: for
    DAgger each round's (round 0 is the planner flying, dashed), for a BenchMARL row
    each iteration's mean team reward under sampled actions."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.2, 4.0))
    seen = False  # whether any curve has a point
    for name, meta in curves:
        if meta["row"] == "bc":
            per_round = meta["frames"] / max(len(meta["round_rates"]), 1)
            frames = per_round * np.arange(1, len(meta["round_rates"]))
            seen = seen or frames.size > 0
            (line,) = ax.plot(frames, meta["round_rates"][1:], marker="o", label=name)
            ax.axhline(meta["round_rates"][0], ls="--", color=line.get_color(), lw=1)
            continue
        n = Scenario.model_validate(meta.get("scenario", {})).n_uavs
        points = np.asarray(meta["curve"], dtype=float)
        seen = True
        ax.plot(points[:, 0] * n, points[:, 1], lw=1.2, label=f"{name} (sampling)")
    if seen:  # frames span decades: DAgger's thousands to PPO's millions
        ax.set_xscale("log")
    ax.set_xlabel("UAV-steps seen")
    ax.set_ylabel("observation rate, training trials")
    ax.set_title("Learning curves (dashed: the planner, DAgger's round 0)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    part = figure.with_name(figure.name + ".part.png")
    fig.savefig(part, dpi=120)
    plt.close(fig)
    part.replace(figure)


def main(argv: Sequence[str] | None = None) -> int:
    """The command line (see the module); a bad input is one line and exit code 2, an
    interruption one line and exit code 130, and neither leaves a file."""
    try:
        return _main(argv)
    except (UsageError, ScenarioError) as exc:
        print(f"learned: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("learned: interrupted; nothing written", file=sys.stderr)
        return 130


def _writable(path: Path, option: str, force: bool = True) -> None:
    """Refuse an output path that cannot be written whole, in one line."""
    if path.is_dir():
        raise UsageError(f"{option} {path} is a folder; give a file")
    if not path.parent.is_dir():
        raise UsageError(f"{option} {path}: no folder {path.parent}")
    if not force and path.exists():
        raise UsageError(f"{option} {path} exists; give --force to replace it")


def _main(argv: Sequence[str] | None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m uavtrack.experiments.learned", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    parser.add_argument("row", choices=(*ROWS, "evaluate", "report"))
    parser.add_argument("paths", nargs="*", type=Path, help="evaluate, report: policy files")
    parser.add_argument("--seed", type=int, default=0, help="the training's seed")
    parser.add_argument("--out", type=Path, help="bc: the policy file; report: the page")
    parser.add_argument("--force", action="store_true", help="bc: replace --out if it exists")
    parser.add_argument("--figure", type=Path, help="report: the learning curves' PNG")
    parser.add_argument("--trials", type=int, default=50, help="held-out trials evaluated")
    defaults = Imitation()
    for name, kind in (("rounds", int), ("trials_per_round", int), ("hidden", int),
                       ("layers", int), ("epochs", int), ("learning_rate", float)):  # fmt: skip
        key = "trials" if name == "trials_per_round" else name
        parser.add_argument(
            f"--{name.replace('_', '-')}", type=kind, default=getattr(defaults, key),
            help=f"bc: {key} of `Imitation` [%(default)s]",
        )  # fmt: skip
    parser.add_argument("--start", help="bc-ppo: the policy it starts from (file or name)")
    parser.add_argument(
        "--frames", type=int, help=f"bc-ppo: agent-steps of PPO [{FineTuning().frames}]; "
        f"mappo, ippo, mappo-gnn: trial-steps, BenchMARL's frames [{Marl().frames}]",
    )  # fmt: skip
    parser.add_argument("--warm", type=int, default=FineTuning().warm,
                        help="bc-ppo: of them, with the policy frozen [%(default)s]")  # fmt: skip
    parser.add_argument(
        "--config", help="a row's scenario TOML file (default: the paper's; bc-ppo: its start's)"
    )
    parser.add_argument(
        "--set", action="append", default=[], metavar="FIELD=VALUE", dest="changes",
        help="a row's scenario field, dotted, its value read as TOML (repeatable)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    if args.trials < 2:
        raise UsageError(f"--trials must be at least 2 (an interval needs two), got {args.trials}")
    if args.row in ROWS:
        return _train(args, argv)
    if not args.paths:
        raise UsageError(f"{args.row} needs policy files")
    if args.row == "evaluate":
        if args.config is not None or args.changes:
            raise UsageError(
                "evaluate flies the scenario each file was trained on (its meta): no --config "
                "or --set"
            )
        for path in args.paths:
            if not path.is_file():  # a shipped policy by name is read-only
                raise UsageError(f"evaluate writes into the file: no file {path}")
        for path in args.paths:
            print(json.dumps({str(path): record(path, trials=args.trials)}, indent=1))
        return 0
    for option, path in (("--out", args.out), ("--figure", args.figure)):
        if path is not None:
            _writable(path, option)
    page = report(args.paths, args.figure, args.out)
    if args.out is None:
        print(page, end="")
    else:
        part = args.out.with_name(args.out.name + ".part")
        part.write_text(page)
        part.replace(args.out)
    return 0


def _train(args: argparse.Namespace, argv: Sequence[str] | None) -> int:
    """A row's command: train, evaluate and write the policy file whole."""
    scenario = Scenario() if args.config is None else Scenario.from_toml(args.config)
    changes = parse_overrides(args.changes)
    if changes:
        scenario = scenario.with_overrides(changes)
    if args.out is None or args.paths:
        raise UsageError(f"{args.row} writes one policy file: give --out FILE, no paths")
    _writable(args.out, "--out", args.force)
    given = list(argv) if argv is not None else sys.argv[1:]
    command = "python -m uavtrack.experiments.learned " + shlex.join(given)
    if args.row in MARL:
        tuning = Marl() if args.frames is None else Marl(frames=args.frames)
        if tuning.frames < tuning.batch:
            raise UsageError(f"--frames must be one batch ({tuning.batch}) or more: {args.frames}")
        try:  # the observation must fit the team, before any work
            Spaces(scenario, "box", 4, 4)
        except ValueError as exc:
            raise UsageError(f"the scenario's team does not fill the observation: {exc}") from None
        return _write(marl(scenario, args.row, tuning, args.seed), command, args)
    if args.row == "bc-ppo":
        if args.start is None:
            raise UsageError("bc-ppo fine-tunes a policy: give --start FILE (or a shipped name)")
        start = Policy.load(args.start)
        if args.config is None and not changes:  # the scenario the start was trained on
            scenario = Scenario.model_validate(start.meta.get("scenario", {}))
        frames = FineTuning().frames if args.frames is None else args.frames
        tuning = FineTuning(frames=frames, warm=args.warm)
        if not 0 <= tuning.warm < tuning.frames:
            raise UsageError(f"--warm must be in [0, --frames), got {tuning.warm}")
        if start.spaces(scenario).size != start.inputs:  # refuses a team that does not fit
            raise UsageError("the start policy does not fit the scenario")
        policy = fine_tune(scenario, start, tuning, args.seed)
        return _write(policy, command, args)
    settings = Imitation(
        rounds=args.rounds, trials=args.trials_per_round, hidden=args.hidden,
        layers=args.layers, epochs=args.epochs, learning_rate=args.learning_rate,
    )  # fmt: skip
    for field_, value in vars(settings).items():
        if not (math.isfinite(value) and value > 0):
            raise UsageError(f"--{field_.replace('_', '-')} must be above 0, got {value}")
    try:  # the observation must fit the team, before any work
        Spaces(scenario, "box", settings.max_targets, settings.max_neighbours)
    except ValueError as exc:
        raise UsageError(f"the scenario's team does not fill the observation: {exc}") from None
    policy = imitate(scenario, settings, args.seed)
    return _write(policy, command, args)


def _write(policy: Policy, command: str, args: argparse.Namespace) -> int:
    """Evaluate a trained policy and write its file whole, with its command."""
    policy = replace(policy, meta={**policy.meta, "command": command})
    training = args.out.with_name(args.out.name + ".training.npz")  # moved once evaluated
    try:
        policy.save(training)
        result = record(training, trials=args.trials)
        training.replace(args.out)
    finally:
        training.unlink(missing_ok=True)
    d = result["difference"]
    print(
        f"wrote {args.out}: rate {result['rate']['policy']['mean']:.3f}, planner "
        f"{result['rate']['distributed']['mean']:.3f}, difference {d['mean']:+.3f} "
        f"({d['ci_low']:+.3f}, {d['ci_high']:+.3f}) on {args.trials} held-out trials; "
        f"{policy.meta['cpu_seconds']:.0f} s of CPU to train"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
