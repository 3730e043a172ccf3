"""The environment as a BenchMARL task: every UAV an agent of one group, trained by any of
BenchMARL's algorithms (MAPPO, IPPO, MASAC, QMIX, ...) with discrete actions.

    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models import MlpConfig
    from uavtrack.env.benchmarl import UAVTrackTask

    task = UAVTrackTask.TRACKING.get_task({"overrides": {"steps": 200}})
    Experiment(task, MappoConfig.get_from_yaml(), MlpConfig.get_from_yaml(),
               MlpConfig.get_from_yaml(), 0, ExperimentConfig.get_from_yaml()).run()

The task is the vector form (`vector_env`, ``paper_actions=False``) as `torchrl_env`
gives it to TorchRL: BenchMARL's ``num_envs`` trials as one batch, so no serial copies
of the single environment. The group ``"agents"`` holds ``uav_0 ... uav_{N-1}``; the
``"state"`` (the team's global view) goes to centralised critics. A UAV that fails stays
in its group with a zero observation and zero reward until the mission ends (SuperSuit's
"black death"), as every MARL algorithm with a fixed group expects; every trial ends at
the scenario's last step.

The config (`TaskConfig`, or a dict of its fields given to ``get_task``, or a YAML file
of them given to ``get_from_yaml``): ``scenario`` a scenario TOML file (None: the
paper's), ``overrides`` its fields by name (nested parts as dicts, as `vector_env` takes
them), ``reward``, ``max_targets`` and ``max_neighbours`` as `parallel_env` takes them,
``method_for_others`` the method whose planning the world runs, ``positions`` whether
each agent's observation also holds its ``position`` (`torchrl_env`), for BenchMARL's
graph networks (``GnnConfig(topology="from_pos", position_key="position")``).

Needs the learn extra (torch, torchrl, benchmarl).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..errors import install_hint

try:
    import yaml  # BenchMARL's own task files are YAML (PyYAML comes with its hydra-core)
    from benchmarl.environments import Task, TaskClass  # pyright: ignore[reportMissingImports]  (the learn extra)
    from benchmarl.experiment.callback import Callback  # pyright: ignore[reportMissingImports]
    from torchrl.data import Composite  # pyright: ignore[reportMissingImports]  (the learn extra)
    from torchrl.envs import EnvBase  # pyright: ignore[reportMissingImports]  (the learn extra)
except ImportError as exc:  # an optional extra
    raise ImportError(
        f"uavtrack.env.benchmarl needs benchmarl: {install_hint('learn')} ({exc})"
    ) from None

from ..config import Scenario
from .learn import torchrl_env
from .vector import vector_env

GROUP = "agents"

__all__ = [
    "GROUP", "Curve", "TaskConfig", "UAVTrackClass", "UAVTrackTask", "dense_radius_graph",
    "task_config", "use_dense_radius_graph",
]  # fmt: skip


@dataclass(kw_only=True)
class TaskConfig:
    """The settings of the uavtrack task (see the module)."""

    scenario: str | None = None
    overrides: dict[str, Any] = field(default_factory=dict)
    reward: str = "team"
    max_targets: int | None = None
    max_neighbours: int | None = None
    method_for_others: str = "distributed"
    positions: bool = False


def task_config(config: dict[str, Any] | None) -> dict[str, Any]:
    """`config` checked against `TaskConfig` and completed with its defaults; a setting
    it does not know is refused by name, in one line."""
    config = dict(config or {})
    known = [f.name for f in dataclasses.fields(TaskConfig)]
    unknown = sorted(set(config) - set(known))
    if unknown:
        raise ValueError(f"unknown uavtrack task settings {unknown}; the settings are {known}")
    return dataclasses.asdict(TaskConfig(**config))


class UAVTrackClass(TaskClass):
    """BenchMARL's view of the uavtrack task (see the module)."""

    def __init__(self, name: str, config: dict[str, Any] | None) -> None:
        super().__init__(name, task_config(config))
        probe = self._vector(1)  # a bad scenario or setting is refused when the task is made
        self.steps, self.agents = probe.scenario.steps, probe.num_agents

    def _vector(self, num_envs: int):
        c = self.config
        scenario = Scenario.from_toml(c["scenario"]) if c["scenario"] is not None else None
        return vector_env(
            num_envs,
            scenario,
            method_for_others=c["method_for_others"],
            reward=c["reward"],
            max_targets=c["max_targets"],
            max_neighbours=c["max_neighbours"],
            paper_actions=False,  # the agents fly every action: no planning to pay for
            **c["overrides"],
        )

    def get_env_fun(
        self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any
    ) -> Callable[[], EnvBase]:
        if continuous_actions:
            raise ValueError("the uavtrack task has discrete actions (a bank angle of three)")
        positions = self.config["positions"]
        return lambda: torchrl_env(self._vector(num_envs), seed, positions).to(device)

    def supports_continuous_actions(self) -> bool:
        return False

    def supports_discrete_actions(self) -> bool:
        return True

    def has_render(self, env: EnvBase) -> bool:
        return False  # a batch draws nothing; parallel_env renders one trial

    def max_steps(self, env: EnvBase) -> int:
        return self.steps

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        return {GROUP: [f"uav_{i}" for i in range(self.agents)]}

    def observation_spec(self, env: EnvBase) -> Composite:
        spec = env.full_observation_spec_unbatched.clone()
        del spec["state"]
        del spec[GROUP, "alive"]  # the observation's first entry says it too
        return spec

    def state_spec(self, env: EnvBase) -> Composite | None:
        return Composite(state=env.full_observation_spec_unbatched["state"].clone())

    def info_spec(self, env: EnvBase) -> Composite | None:
        return None

    def action_spec(self, env: EnvBase) -> Composite:
        return env.full_action_spec_unbatched

    def action_mask_spec(self, env: EnvBase) -> Composite | None:
        return None

    @staticmethod
    def env_name() -> str:
        return "uavtrack"


class UAVTrackTask(Task):
    """uavtrack's tasks for BenchMARL: ``TRACKING``, the cooperative tracking of the
    scenario's targets."""

    TRACKING = None

    @staticmethod
    def associated_class():
        return UAVTrackClass

    def get_from_yaml(self, path: str | None = None) -> TaskClass:
        """The task with the settings of the YAML file at `path` (None: the defaults of
        `TaskConfig`; BenchMARL's own folder of task files holds none for uavtrack)."""
        if path is None:
            return self.get_task(config={})
        with open(path, encoding="utf-8") as handle:
            config = yaml.safe_load(handle)
        if config is not None and not isinstance(config, dict):
            raise ValueError(f"{path}: the task's settings must be a mapping of setting: value")
        return self.get_task(config=config or {})


class Curve(Callback):
    """A learning curve: after each batch an experiment collects, the frames so far
    and the batch's mean reward (with the team reward, the training's observation
    rate); printed as it goes if `verbose`. A module's class: BenchMARL pickles its
    callbacks."""

    def __init__(self, verbose: bool = True) -> None:
        super().__init__()
        self.points: list[tuple[int, float]] = []
        self.verbose = verbose

    def on_batch_collected(self, batch: Any) -> None:
        frames = (self.points[-1][0] if self.points else 0) + int(batch.numel())
        reward = float(batch["next", GROUP, "reward"].mean())
        self.points.append((frames, reward))
        if self.verbose:
            print(f"{frames:,} frames: mean reward {reward:.3f}", flush=True)


def dense_radius_graph(x: Any, r: float, batch: Any = None, loop: bool = False, **_: Any) -> Any:
    """PyTorch Geometric's ``radius_graph`` for graphs of equal size, in plain torch:
    the edges (2, E) between nodes x (P, d) at most `r` apart within each graph of
    `batch` (P,), in its order (source row 0, target row 1), without self-loops unless
    `loop`. For a machine without pyg-lib or torch-cluster, which PyG's needs."""
    import torch  # pyright: ignore[reportMissingImports]  (the learn extra)

    P = x.shape[0]
    graphs = 1 if batch is None else int(batch.max()) + 1
    n = P // graphs
    pos = x.reshape(graphs, n, -1)
    near = torch.cdist(pos, pos) <= r
    if not loop:
        near &= ~torch.eye(n, dtype=torch.bool, device=x.device)
    b, i, j = near.nonzero(as_tuple=True)
    return torch.stack([b * n + j, b * n + i])


def use_dense_radius_graph() -> bool:
    """Put `dense_radius_graph` in PyTorch Geometric's place if its own cannot run here
    (no pyg-lib or torch-cluster); returns whether it did."""
    import torch  # pyright: ignore[reportMissingImports]  (the learn extra)
    import torch_geometric.nn.pool as pool  # pyright: ignore[reportMissingImports]

    try:
        pool.radius_graph(torch.zeros((2, 2)), r=1.0)
        return False
    except ImportError:
        pool.radius_graph = dense_radius_graph
        return True
