"""One UAV learns while the team flies on: a Gymnasium Env over `parallel_env`.

The learner is one UAV (``learner``, default 0) of the multi-agent environment; every
other UAV flies the method's action (``method_for_others``, default the paper's
distributed method) or what a given policy says from its own observation (``others``).
Observation, action, reward and info are the learner's, as `uavtrack.env` describes
them. Registered as ``uavtrack/SingleUAV-v0`` when `uavtrack.env` is imported::

    import gymnasium
    env = gymnasium.make("uavtrack.env:uavtrack/SingleUAV-v0", max_cycles=100)

Episodes: ``reset(seed=s)`` draws the trial as ``simulate(scenario, method, seed=s)``
does, so flying the info's ``paper_action`` reproduces that trial exactly
(``result()``); ``reset()`` without a seed draws one from the Env's generator, a trial
in which the learner flies at step 0 (a given seed whose trial fails it is refused). The
mission's end terminates and truncates the episode (as in the multi-agent form: the
time left is in the observation); the learner's failure (faults) terminates it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from ..config import Scenario
from ..records import Result
from .parallel import RENDER_MODES, UAVTrackingEnv, parallel_env

__all__ = ["ID", "SingleUAVEnv"]

ID = "uavtrack/SingleUAV-v0"
"""The Env's Gymnasium id."""

DRAWS = 100
"""Trials a seedless reset draws, at most, for one in which the learner is alive at
step 0 (under ``faults.failure_rate`` a UAV may fail before the first cycle)."""

Policy = Callable[[Any], int]
"""A policy of the other UAVs: an action in {0, 1, 2} from a UAV's observation."""


class SingleUAVEnv(gymnasium.Env):
    """See the module: one UAV of `parallel_env(scenario, **kwargs)` learns."""

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 2}

    def __init__(
        self,
        scenario: Scenario | None = None,
        learner: int = 0,
        others: Policy | None = None,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        self.team: UAVTrackingEnv = parallel_env(scenario, render_mode=render_mode, **kwargs)
        n = self.team.scenario.n_uavs
        if isinstance(learner, bool) or not isinstance(learner, int | np.integer):
            raise TypeError(f"learner must be a UAV index, not {type(learner).__name__}")
        if not 0 <= learner < n:
            raise ValueError(f"learner {learner} is not a UAV: give 0 to {n - 1}")
        if others is not None and not callable(others):
            raise TypeError(
                "others must be a policy (a UAV's observation -> action) or None (the "
                f"method's actions), not {type(others).__name__}"
            )
        self.learner, self.others = int(learner), others
        self.name = self.team.possible_agents[self.learner]
        self.observation_space = self.team.observation_space(self.name)
        self.action_space = spaces.Discrete(3)
        self.render_mode = render_mode
        self._observations: dict[str, Any] = {}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        for _ in range(DRAWS):
            trial = seed if seed is not None else int(self.np_random.integers(0, 2**31 - 1))
            observations, infos = self.team.reset(seed=trial, options=options)
            if self.name in observations:
                self._observations = observations
                return observations[self.name], infos[self.name]
            if seed is not None:
                raise ValueError(
                    f"the learner {self.name} has failed at step 0 of trial {seed} (faults): "
                    "give another seed, or reset() to draw a trial where it flies"
                )
        raise RuntimeError(
            f"the learner {self.name} failed at step 0 of {DRAWS} trials drawn in a row: "
            "lower the scenario's failure rate"
        )

    def step(self, action: Any):
        if self.name not in self.team.agents:
            raise RuntimeError("the episode is over: call reset()")
        actions = {self.name: action}
        if self.others is not None:
            for agent in self.team.agents:
                if agent != self.name:
                    actions[agent] = int(self.others(self._observations[agent]))
        observations, rewards, terminations, truncations, infos = self.team.step(actions)
        self._observations = observations
        me = self.name
        return observations[me], rewards[me], terminations[me], truncations[me], infos[me]

    def result(self) -> Result:
        """The trial so far as `simulate` reports it: metrics and trace."""
        return self.team.result()

    def render(self):
        return self.team.render()

    def close(self) -> None:
        self.team.close()
