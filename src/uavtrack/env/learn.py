"""The vector environment in the shapes two learning libraries take as they are.

* `sb3_vec_env(vector)`: a Stable-Baselines3 ``VecEnv`` whose envs are the agents of
  all trials (its ``num_envs`` is ``vector.num_envs`` x Nu, trial by trial), for one
  policy shared by every agent (parameter sharing), as SuperSuit's
  ``pettingzoo_env_to_vec_env_v1`` and ``concat_vec_envs_v1`` make of a ParallelEnv,
  without the copies and processes.
* `torchrl_env(vector)`: a TorchRL ``EnvBase`` of batch size [num_envs] in TorchRL's
  multi-agent layout: ``("agents", "observation")`` (num_envs, Nu, size),
  ``("agents", "action")`` (num_envs, Nu), ``("agents", "reward")`` (num_envs, Nu, 1),
  ``"state"`` (num_envs, state size) for centralised critics, ``done``/``terminated``/
  ``truncated`` per trial.

`uavtrack.env.benchmarl` makes `torchrl_env` a BenchMARL task. Needs the learn extra
(torch, stable-baselines3, torchrl).
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from ..errors import install_hint
from .spaces import BOUND
from .vector import VectorEnv


def sb3_vec_env(vector: VectorEnv, seed: int | None = None):
    """`vector` as a Stable-Baselines3 VecEnv (see the module). The first reset starts
    trials `seed`, `seed` + 1, ... (None: fresh entropy, or what ``.seed()`` set)."""
    try:
        from stable_baselines3.common.vec_env import VecEnv  # pyright: ignore[reportMissingImports]  (the learn extra)
    except ImportError as exc:
        raise ImportError(
            f"sb3_vec_env needs stable-baselines3: {install_hint('learn')} ({exc})"
        ) from None
    if vector.spaces.form != "box":
        raise ValueError("sb3_vec_env needs observation='box'")

    class AgentsVecEnv(VecEnv):
        """Every agent of every trial an env of one VecEnv; the trials end together."""

        def __init__(self) -> None:
            self.vector, self.render_mode = vector, None
            self.shape = (vector.num_envs, vector.num_agents)
            super().__init__(
                vector.num_envs * vector.num_agents, vector.observation_space, vector.action_space
            )
            self._base = seed
            self._actions: np.ndarray | None = None

        def reset(self):
            first = self._seeds[0] if self._seeds and self._seeds[0] is not None else self._base
            self._reset_seeds()
            observations, _ = vector.reset(seed=first)
            return observations.reshape(self.num_envs, -1)

        def step_async(self, actions: np.ndarray) -> None:
            self._actions = np.asarray(actions).reshape(self.shape).astype(np.int64)

        def step_wait(self):
            observations, rewards, terminated, truncated, info = vector.step(self._actions)
            n = self.num_envs
            dones = (terminated | truncated).reshape(n)
            infos: list[dict[str, Any]] = [{} for _ in range(n)]
            if dones.all():  # the mission's end is a terminal state: no bootstrapping
                final = info["final_observation"].reshape(n, -1)
                rate = np.repeat(info["observation_rate"], self.shape[1])
                for i in range(n):
                    infos[i] = {
                        "terminal_observation": final[i],
                        "TimeLimit.truncated": False,
                        "observation_rate": float(rate[i]),
                    }
            return observations.reshape(n, -1), rewards.reshape(n).astype(np.float32), dones, infos

        def close(self) -> None:
            vector.close()

        def get_attr(self, attr_name: str, indices=None) -> list[Any]:
            return [getattr(vector, attr_name) for _ in self._get_indices(indices)]

        def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
            raise AttributeError(f"the agents of one batch share their attributes: {attr_name}")

        def env_method(self, method_name: str, *args, indices=None, **kwargs) -> list[Any]:
            method = getattr(vector, method_name)
            return [method(*args, **kwargs) for _ in self._get_indices(indices)]

        def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
            return [False for _ in self._get_indices(indices)]

    return AgentsVecEnv()


def torchrl_env(vector: VectorEnv, seed: int | None = None, positions: bool = False):
    """`vector` as a TorchRL EnvBase of batch size [num_envs] (see the module); with
    `positions`, each agent's ``("agents", "position")`` (`Spaces.positions`: where its
    observation says it is, in half-fields), from which a graph network builds the
    radio graph."""
    try:
        import torch  # pyright: ignore[reportMissingImports]  (the learn extra)
        from tensordict import TensorDict  # pyright: ignore[reportMissingImports]  (the learn extra)
        from torchrl.data import Bounded, Categorical, Composite, Unbounded  # pyright: ignore[reportMissingImports]  (the learn extra)
        from torchrl.envs import EnvBase  # pyright: ignore[reportMissingImports]  (the learn extra)
    except ImportError as exc:
        raise ImportError(f"torchrl_env needs torchrl: {install_hint('learn')} ({exc})") from None
    if vector.spaces.form != "box":
        raise ValueError("torchrl_env needs observation='box'")
    B, N = vector.num_envs, vector.num_agents
    observed, state = vector.observation_space.shape, vector.state_space.shape
    assert observed is not None and state is not None  # boxes have shapes
    D, S = observed[0], state[0]

    class TrialsEnv(EnvBase):
        """num_envs trials of Nu agents; every trial ends at the same step."""

        def __init__(self) -> None:
            super().__init__(batch_size=torch.Size([B]), device="cpu")
            self.vector = vector
            agents = lambda **specs: Composite(**specs, shape=(B, N))  # noqa: E731
            box = lambda *shape: Bounded(-BOUND, BOUND, torch.Size(shape), dtype=torch.float32)  # noqa: E731
            self.observation_spec = Composite(
                agents=agents(
                    observation=box(B, N, D),
                    alive=Categorical(2, torch.Size((B, N, 1)), dtype=torch.bool),
                    **({"position": box(B, N, 3)} if positions else {}),
                ),
                state=box(B, S),
                shape=(B,),
            )
            self.action_spec = Composite(
                agents=agents(action=Categorical(3, torch.Size((B, N)), dtype=torch.int64)),
                shape=(B,),
            )
            self.reward_spec = Composite(
                agents=agents(reward=Unbounded(torch.Size((B, N, 1)), dtype=torch.float32)),
                shape=(B,),
            )
            flag = lambda: Categorical(2, torch.Size((B, 1)), dtype=torch.bool)  # noqa: E731
            self.done_spec = Composite(done=flag(), terminated=flag(), truncated=flag(), shape=(B,))
            self._seed = seed
            self._fresh = False  # an episode started by the step that ended the last

        def _set_seed(self, seed: int | None) -> None:
            self._seed = seed

        def _reset(self, tensordict=None, **kwargs):
            if tensordict is not None and "_reset" in tensordict.keys():
                mask = tensordict["_reset"]
                if not bool(mask.all()):
                    raise ValueError("the trials of one batch end together: reset all or none")
            if not self._fresh:
                vector.reset(seed=self._seed)
                if self._seed is not None:
                    self._seed += B  # the next reset plays the next trials
            self._fresh = False
            false = torch.zeros((B, 1), dtype=torch.bool)
            return self._out(false, false)

        def _step(self, tensordict):
            action = cast(torch.Tensor, tensordict["agents", "action"])  # a leaf: a tensor
            actions = action.cpu().numpy().astype(np.int64)
            _, rewards, terminated, truncated, info = vector.step(actions)
            done = bool(terminated.all())
            observations = info["final_observation"] if done else None
            state = info["final_state"] if done else None
            self._fresh = done
            flags = torch.full((B, 1), done, dtype=torch.bool)
            out = self._out(flags, flags, observations, state)
            reward = torch.from_numpy(rewards.astype(np.float32)).reshape(B, N, 1)
            out.set(("agents", "reward"), reward)
            return out

        def _out(self, terminated, truncated, observations=None, state=None):
            observations = vector.observations() if observations is None else observations
            state = vector.state() if state is None else state
            alive = observations[..., 0:1] > 0  # the observation's first entry: alive
            agents = {
                "observation": torch.from_numpy(observations),
                "alive": torch.from_numpy(alive),
            }
            if positions:
                agents["position"] = torch.from_numpy(vector.spaces.positions(observations))
            return TensorDict(
                {
                    "agents": TensorDict(agents, batch_size=(B, N)),
                    "state": torch.from_numpy(state),
                    "done": terminated | truncated,
                    "terminated": terminated,
                    "truncated": truncated,
                },
                batch_size=(B,),
            )

    return TrialsEnv()
