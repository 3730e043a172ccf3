"""Many trials stepped as one batch through the simulator's batched stages.

`VectorEnv` holds num_envs trials of Nu agents each and speaks in arrays with leading
axes (trials, agents), in the conventions of Stable-Baselines3's vector environments
(the episode that ends is reset in the same step, its last observation in the info).
`uavtrack.env.learn` turns it into a Stable-Baselines3 `VecEnv` (agents as envs, one
shared policy) or a TorchRL `EnvBase` with batch size [num_envs]. Trial b of an episode
started by ``reset(seed=s)`` is the trial ``parallel_env(...).reset(seed=s + b)`` plays:
the same numbers, step for step (a test).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from ..config import Scenario
from ..methods import get
from ..simulation import check_memory
from .episodes import Episodes
from .parallel import check_seed, scenario_of
from .spaces import Spaces, check_reward


def vector_env(
    num_envs: int,
    scenario: Scenario | None = None,
    method_for_others: str | None = None,
    observation: str = "box",
    reward: str = "team",
    max_cycles: int | None = None,
    max_targets: int | None = None,
    max_neighbours: int | None = None,
    paper_actions: bool = True,
    **overrides: Any,
) -> VectorEnv:
    """num_envs trials of `scenario` with `overrides`, as `parallel_env` takes them."""
    return VectorEnv(
        scenario_of(scenario, max_cycles, overrides, "vector_env"),
        num_envs,
        method_for_others or "distributed",
        observation=observation,
        reward=reward,
        max_targets=max_targets,
        max_neighbours=max_neighbours,
        paper_actions=paper_actions,
    )


class VectorEnv:
    """num_envs trials of a scenario, every UAV an agent, stepped as one batch.

    Every trial lasts the scenario's steps, so all end together; a UAV that fails
    stays in the arrays with zeros for its observation and 0 reward until the episode
    ends (SuperSuit's "black death"); ``info["alive"]`` tells which.

    paper_actions=False skips the method's planning and assignment, which only the
    method's actions (``paper_actions()``, ``info["paper_action"]``) need: for agents
    that choose every action it is the same trial, faster.
    """

    def __init__(
        self,
        scenario: Scenario,
        num_envs: int,
        method: str = "distributed",
        observation: str = "box",
        reward: str = "team",
        max_targets: int | None = None,
        max_neighbours: int | None = None,
        paper_actions: bool = True,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer):
            raise TypeError(f"num_envs must be an integer, not {type(num_envs).__name__}")
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario must be a uavtrack.Scenario, not {type(scenario).__name__}")
        check_memory(scenario, int(num_envs))  # refused now, not at the first step
        self.scenario, self.method = scenario, get(method)
        self.reward = check_reward(reward, scenario)
        self.spaces = Spaces(scenario, observation, max_targets, max_neighbours)
        self.num_envs, self.num_agents = int(num_envs), scenario.n_uavs
        self.observation_space = self.spaces.observation_space  # one agent's
        self.state_space = self.spaces.state_space  # one trial's
        self.action_space = spaces.Discrete(3)
        self.render_mode = None  # a batch draws nothing; `parallel_env` renders a trial
        self.planned = bool(paper_actions)
        self._run: Episodes | None = None
        self._next_seed = 0

    @property
    def seeds(self) -> list[int]:
        """The seeds of the trials of the current episode, trial by trial."""
        if self._run is None:
            raise RuntimeError("call reset() first")
        return list(self._seeds)

    def reset(self, seed: int | None = None) -> tuple[Any, dict[str, np.ndarray]]:
        """Start trials seed, seed + 1, ... seed + num_envs - 1 (None: from fresh
        entropy). Returns the observations (num_envs, Nu, ...) and the info."""
        check_seed(seed)
        if seed is None:
            seed = int(np.random.SeedSequence().generate_state(1, np.uint32)[0])
        self._start(int(seed))
        return self.observations(), self._info()

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Fly `actions` (num_envs, Nu) indices into {-phi, 0, +phi}; returns
        observations, rewards (num_envs, Nu), terminated and truncated (num_envs, Nu),
        and the info. When the episode ends (both flags set for every agent) the next
        episode starts at once: the observations are its first, and the info holds the
        ending one's ``final_observation``, ``final_state`` and ``observation_rate``."""
        if self._run is None:
            raise RuntimeError("call reset() before step()")
        shape = (self.num_envs, self.num_agents)
        if actions is None:
            raise TypeError(f"actions must be an array of shape {shape}, not None")
        chosen = np.asarray(actions)
        if chosen.shape != shape or not np.issubdtype(chosen.dtype, np.integer):
            raise ValueError(
                f"actions must be integers of shape {shape}, got {chosen.dtype} {chosen.shape}"
            )
        if chosen.min() < 0 or chosen.max() > 2:
            raise ValueError("actions must be 0, 1 or 2 (indices into {-phi, 0, +phi})")
        earned = self._run.step(chosen)
        done = self._run.done
        flags = np.full(shape, done)
        if not done:
            return self.observations(), earned, flags, flags.copy(), self._info()
        ending = {
            "final_observation": self.observations(),
            "final_state": self.state(),
            "observation_rate": self._run.observation_rate(),
            "seeds": np.array(self._seeds),
        }
        self._start(self._next_seed)
        return self.observations(), earned, flags, flags.copy(), {**self._info(), **ending}

    def observations(self) -> Any:
        """Every agent's observation now (num_envs, Nu, ...)."""
        return self.spaces.observe(self._started().view())

    def state(self) -> np.ndarray:
        """Every trial's global state now (num_envs, state size)."""
        return self.spaces.state(self._started().view())

    def paper_actions(self) -> np.ndarray:
        """(num_envs, Nu) the actions the method would fly now."""
        if not self.planned:
            raise RuntimeError("made with paper_actions=False: the method does not plan")
        return self._started().current.own.copy()

    def observation_rate(self) -> np.ndarray:
        """(num_envs,) each trial's observation rate over the steps flown this episode."""
        return self._started().observation_rate()

    def close(self) -> None:
        self._run = None

    def _started(self) -> Episodes:
        if self._run is None:
            raise RuntimeError("call reset() first")
        return self._run

    def _start(self, seed: int) -> None:
        self._seeds = list(range(seed, seed + self.num_envs))
        self._next_seed = seed + self.num_envs
        sequences = [np.random.SeedSequence(s) for s in self._seeds]
        self._run = Episodes(
            self.scenario, self.method, self.spaces, self.reward, sequences, plan=self.planned
        )

    def _info(self) -> dict[str, np.ndarray]:
        run = self._started()
        info = {"alive": run.alive.copy()}
        if self.planned:
            info["paper_action"] = run.current.own.copy()
        return info
