"""The PettingZoo ParallelEnv: every UAV an agent choosing its bank angle."""

from __future__ import annotations

from typing import Any, cast

import gymnasium
import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from ..config import Scenario, flatten
from ..methods import get
from ..records import Result, Trace
from ..simulation import Recorder, check_memory, finish, result_of
from .episodes import Episodes
from .spaces import Spaces, View, check_reward

RENDER_MODES = ("human", "rgb_array", "ansi")


def parallel_env(
    scenario: Scenario | None = None,
    method_for_others: str | None = None,
    render_mode: str | None = None,
    observation: str = "box",
    reward: str = "team",
    max_cycles: int | None = None,
    max_targets: int | None = None,
    max_neighbours: int | None = None,
    **overrides: Any,
) -> UAVTrackingEnv:
    """The ParallelEnv of `scenario` (default: the paper's Sec. 7.1) with `overrides`
    applied: scenario fields by name, nested parts as dicts (``steps=100``,
    ``sensor={"half_fov_deg": 8}``). `max_cycles` is the episode's length in cycles
    (PettingZoo's name for the scenario's ``steps``). See `uavtrack.env` for the rest."""
    return UAVTrackingEnv(
        scenario_of(scenario, max_cycles, overrides, "parallel_env"),
        method_for_others or "distributed",
        render_mode,
        observation=observation,
        reward=reward,
        max_targets=max_targets,
        max_neighbours=max_neighbours,
    )


def scenario_of(
    scenario: Scenario | None, max_cycles: int | None, overrides: dict, origin: str
) -> Scenario:
    """The scenario an environment constructor names: `scenario` or the paper's, with
    `overrides` and `max_cycles` (the steps) applied and validated."""
    if scenario is None:
        scenario = Scenario()
    elif not isinstance(scenario, Scenario):
        raise TypeError(f"scenario must be a uavtrack.Scenario, not {type(scenario).__name__}")
    if max_cycles is not None:
        if "steps" in overrides:
            raise ValueError("give max_cycles or steps, not both (they are the same)")
        overrides = {**overrides, "steps": max_cycles}
    if overrides:
        scenario = scenario.with_overrides(flatten(overrides), origin=origin)
    return scenario


def check_seed(seed: Any) -> None:
    """Refuse a seed that is not a non-negative integer or None, in one line."""
    if seed is None:
        return
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")


class UAVTrackingEnv(ParallelEnv):
    """See `uavtrack.env`."""

    metadata = {
        "name": "uavtrack_v1",
        "render_modes": list(RENDER_MODES),
        "render_fps": 2,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        scenario: Scenario,
        method: str = "distributed",
        render_mode: str | None = None,
        observation: str = "box",
        reward: str = "team",
        max_targets: int | None = None,
        max_neighbours: int | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(
                f"render_mode must be None or one of {RENDER_MODES}, got {render_mode!r}"
            )
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario must be a uavtrack.Scenario, not {type(scenario).__name__}")
        self.scenario, self.method, self.render_mode = scenario, get(method), render_mode
        self.reward = check_reward(reward, scenario)
        self.spaces = Spaces(scenario, observation, max_targets, max_neighbours)
        check_memory(scenario, 1, trace=True)  # refused now, not at the first step
        self.possible_agents = [f"uav_{i}" for i in range(scenario.n_uavs)]
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        self.agents: list[str] = []
        self.observation_spaces = {a: self.spaces.observation_space for a in self.possible_agents}
        self.action_spaces = {a: spaces.Discrete(3) for a in self.possible_agents}
        self.state_space = self.spaces.state_space
        self._run: Episodes | None = None
        self._figure = None

    def observation_space(self, agent: str) -> spaces.Space:
        return self.observation_spaces[self.possible_agents[self._agent(agent)]]

    def action_space(self, agent: str) -> spaces.Discrete:
        # PettingZoo declares action_spaces of any space; every one here is Discrete(3)
        return cast(spaces.Discrete, self.action_spaces[self.possible_agents[self._agent(agent)]])

    # ------------------------------------------------------------------ episode

    def reset(self, seed: int | None = None, options: dict | None = None):
        check_seed(seed)
        self._seed = seed
        seeds = [np.random.SeedSequence(seed)]
        self._run = Episodes(self.scenario, self.method, self.spaces, self.reward, seeds, True)
        alive = self._run.alive[0]
        self.agents = [a for a in self.possible_agents if alive[self._index[a]]]
        return self._observations(self.agents), self._infos(self.agents)

    def step(self, actions: dict[str, Any]):
        if self._run is None:
            raise RuntimeError("call reset() before step()")
        if not isinstance(actions, dict):
            raise TypeError(
                f"actions must be a dict of agent name -> action (an empty dict flies the "
                f"method's actions), not {type(actions).__name__}"
            )
        if not self.agents:
            raise RuntimeError("the episode is over: call reset()")
        flown = self._run.current.own.copy()
        for agent, action in actions.items():
            i = self._agent(agent)  # a name that never was an agent is a mistake: refused
            if agent not in self.agents:
                # PettingZoo's convention (its aec_to_parallel steps only env.agents):
                # wrappers that keep a fixed set of agents, such as TorchRL's, send an
                # action for every possible agent, a failed one's included
                continue
            if not self.action_spaces[agent].contains(action):
                raise ValueError(f"{agent}: action {action!r} is not in Discrete(3)")
            flown[0, i] = int(action)
        earned = self._run.step(flown)[0]
        acting = list(self.agents)
        done = self._run.done
        alive = self._run.alive[0]
        rewards = {a: float(earned[self._index[a]]) for a in acting}
        # the mission's end terminates every agent (its time left is in the observation,
        # so the end is part of the task) and truncates it (the scenario's steps ran out)
        terminations = {a: done or not alive[self._index[a]] for a in acting}
        truncations = {a: done for a in acting}
        self.agents = [a for a in acting if not terminations[a]]
        infos = self._infos(acting) if not done else {a: {} for a in acting}
        return self._observations(acting), rewards, terminations, truncations, infos

    def state(self) -> np.ndarray:
        """The team's global view (see `uavtrack.env.spaces.Spaces.state`)."""
        if self._run is None:
            raise RuntimeError("call reset() before state()")
        return self.spaces.state(self._run.view())[0]

    def result(self) -> Result:
        """The trial so far as `simulate` reports it: metrics and trace."""
        if self._run is None:
            raise RuntimeError("call reset() and step() before result()")
        if self._run.k == 0:
            raise RuntimeError("no step flown yet: call step() before result()")
        return result_of(self._run.batch_result(), self._seed)

    def render(self) -> np.ndarray | str | None:
        """The current step: drawn as `uavtrack animate` draws it ("rgb_array", and shown
        in a matplotlib window for "human"), or as a line of text ("ansi")."""
        if self.render_mode is None:
            gymnasium.logger.warn("render() without a render_mode draws nothing: pass one")
            return None
        if self._run is None:
            raise RuntimeError("call reset() before render()")
        if self.render_mode == "ansi":
            return self._text()
        image = self._image()
        if self.render_mode == "rgb_array":
            return image
        self._show(image)
        return None

    def close(self) -> None:
        if self._figure is not None:
            import matplotlib.pyplot as plt

            plt.close(self._figure)
            self._figure = None

    # ------------------------------------------------------------------ helpers

    def _agent(self, agent: str) -> int:
        try:
            return self._index[agent]
        except KeyError:
            raise ValueError(
                f"unknown agent {agent!r}; agents are {self.possible_agents}"
            ) from None

    def _started(self) -> Episodes:
        if self._run is None:
            raise RuntimeError("call reset() first")
        return self._run

    def _observations(self, agents: list[str]) -> dict[str, Any]:
        built = self.spaces.observe(self._started().view())
        if isinstance(built, dict):
            return {a: {key: x[0, self._index[a]] for key, x in built.items()} for a in agents}
        return {a: built[0, self._index[a]] for a in agents}

    def _infos(self, agents: list[str]) -> dict[str, dict]:
        run = self._started()
        p = run.current
        # with tracks: the team label followed, and the tracks its own scan met
        seen = p.observed if p.tracks is None else run.view().met
        assert seen is not None  # a tracked view carries what each UAV met
        return {
            a: {
                "paper_action": int(p.own[0, i]),
                "target": int(p.assigned.target[0, i]),
                "in_view": int(seen[0, i].sum()),
            }
            for a in agents
            for i in (self._index[a],)
        }

    def _trace(self) -> tuple[Trace, int]:
        run = self._started()
        if run.k == 0:  # after reset: the first cycle as the method would close it
            recorder = Recorder(1, timed=True)
            recorder.record(0, finish(run.state, run.current, run.ctx, fly=False)[1])
            return recorder.traces(run.trajectory.at(0)[:, None])[0], 0
        trace = self.result().trace
        assert trace is not None  # the episodes keep a record
        return trace, run.k - 1

    def _image(self) -> np.ndarray:
        from ..viz.scene import frame

        trace, k = self._trace()
        return frame(trace, self.scenario, k, f"{self.method.name} (env)")

    def _show(self, image: np.ndarray) -> None:
        import matplotlib.pyplot as plt

        if self._figure is None:
            self._figure = plt.figure(figsize=(10, 8))
            self._axes = self._figure.add_axes((0, 0, 1, 1))
            self._axes.set_axis_off()
            self._picture = self._axes.imshow(image)
        else:
            self._picture.set_data(image)
        self._figure.canvas.draw_idle()
        plt.pause(1 / self.metadata["render_fps"])

    def _text(self) -> str:
        view: View = self._started().view()
        seen = view.observed[0].any(axis=0)
        uavs = " ".join(
            f"{a}({u[0]:.0f},{u[1]:.0f})" + ("" if alive else "x")
            for a, u, alive in zip(self.possible_agents, view.uavs[0], view.alive[0], strict=True)
        )
        return f"step {view.k}/{self.scenario.steps} in view {int(seen.sum())}/{seen.size}: {uavs}"
