"""A PettingZoo ParallelEnv of a scenario: every UAV an agent choosing its bank angle.

Each cycle runs the simulator's own stages (`simulation.decide`, then
`simulation.finish` with the agents' actions), so sensing, filtering, fusion, planning
and the method's assignment are exactly those of `simulate`; only the flown actions come
from the agents. Needs the env extra (pettingzoo, gymnasium).

Agents ``uav_0 ... uav_{N-1}``.

* **Observation** (a Dict) of what the UAV knows after fusion at the cycle:
  ``uav`` (5,) its own state as it believes it (x, y, altitude, speed, heading);
  ``estimates`` (Nt, 4) its fused estimate of every target (x, y, vx, vy);
  ``covariance`` (Nt, 3) their position variances and covariance (P_xx, P_yy, P_xy);
  ``neighbours`` (Nu,) 1 for each UAV within radio range.
* **Action**: ``Discrete(3)``, an index into the action set {-phi, 0, +phi} (bank
  angle; 0 turns one way, 1 flies straight, 2 turns the other way).
* **Reward** of an action at cycle k: the number of targets inside the UAV's observation
  disk at cycle k + 1, what the action led to (the paper's observation rate is the
  team's share of such target-steps); the last cycle's action earns 0, nothing follows.
* **Info**: ``paper_action``, the action the method (``method_for_others``, default
  "distributed") would fly; ``target``, the target its assignment gives the UAV;
  ``in_view``, the targets in its disk at this cycle.
* **Episodes** end by truncation after the scenario's steps; a UAV that fails (faults)
  terminates as an agent. An agent left out of an action dict flies the method's action,
  so a learner can act among teammates that follow the paper.

``reset(seed=s)`` draws the trial as ``simulate(scenario, method, seed=s)`` does, so
flying every ``paper_action`` reproduces ``simulate``'s trial exactly (`result()`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import install_hint

try:
    from gymnasium import spaces
    from pettingzoo import ParallelEnv
except ImportError as exc:  # an optional extra
    raise ImportError(
        f"uavtrack.env needs pettingzoo and gymnasium: {install_hint('env')} ({exc})"
    ) from None

from .config import Scenario, flatten
from .methods import get
from .metrics import Tally
from .simulation import (
    BatchResult,
    Context,
    Recorder,
    Result,
    check_memory,
    decide,
    finish,
    graph,
    initial_state,
    result_of,
    sensor_noise,
)


def parallel_env(
    scenario: Scenario | None = None,
    method_for_others: str | None = None,
    render_mode: str | None = None,
    **overrides: Any,
) -> UAVTrackingEnv:
    """The env of `scenario` (default: the paper's Sec. 7.1) with `overrides` applied:
    scenario fields by name, nested parts as dicts (``steps=100``,
    ``sensor={"half_fov_deg": 8}``). `method_for_others` (default "distributed") runs
    the fusion and assignment, and flies the agents given no action."""
    scenario = Scenario() if scenario is None else scenario
    if overrides:
        scenario = scenario.with_overrides(flatten(overrides), origin="parallel_env")
    return UAVTrackingEnv(scenario, method_for_others or "distributed", render_mode)


class UAVTrackingEnv(ParallelEnv):
    """See the module's documentation."""

    metadata = {"name": "uavtrack_v0", "render_modes": ["rgb_array"], "is_parallelizable": True}

    def __init__(
        self, scenario: Scenario, method: str = "distributed", render_mode: str | None = None
    ) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario must be a uavtrack.Scenario, not {type(scenario).__name__}")
        check_memory(scenario, 1, trace=True)  # as simulate does: refused now, not at step 1
        self.scenario, self.method, self.render_mode = scenario, get(method), render_mode
        nu, nt = scenario.n_uavs, scenario.n_targets
        self.possible_agents = [f"uav_{i}" for i in range(nu)]
        self.agents: list[str] = []
        box = lambda *shape: spaces.Box(-np.inf, np.inf, shape, np.float64)  # noqa: E731
        self._observation_space = spaces.Dict(
            {
                "uav": box(5),
                "estimates": box(nt, 4),
                "covariance": box(nt, 3),
                "neighbours": spaces.MultiBinary(nu),
            }
        )
        self._action_space = spaces.Discrete(3)

    def observation_space(self, agent: str) -> spaces.Dict:
        return self._observation_space

    def action_space(self, agent: str) -> spaces.Discrete:
        return self._action_space

    # ------------------------------------------------------------------ episode

    def reset(
        self, seed: int | None = None, options: dict | None = None
    ) -> tuple[dict[str, dict], dict[str, dict]]:
        s = self.scenario
        self._seeds = [np.random.SeedSequence(seed)]
        self._seed = seed
        self._ctx = Context.of(s, self.method, self._seeds)
        self._state, self._trajectory, rngs = initial_state(s, self._seeds)
        self._noises = sensor_noise(rngs, s.n_uavs, s.n_targets, s.steps)
        self._tally = Tally(
            1,
            s.n_uavs,
            s.n_targets,
            timed=True,
            cutoff=s.evaluation.ospa_cutoff,
            order=s.evaluation.ospa_order,
        )
        self._recorder = Recorder(s.steps, timed=True)
        self._pending = decide(self._state, self._trajectory[:, 0], next(self._noises), self._ctx)
        self.agents = [a for i, a in enumerate(self.possible_agents) if self._pending.alive[0, i]]
        return self._observations(), self._infos()

    def step(self, actions: dict[str, Any]):
        if not hasattr(self, "_state"):
            raise RuntimeError("call reset() before step()")
        if not isinstance(actions, dict):
            raise TypeError(
                f"actions must be a dict of agent name -> action (an empty dict flies the "
                f"method's actions), not {type(actions).__name__}"
            )
        if not self.agents:
            raise RuntimeError("the episode is over: call reset()")
        k = self._state.k
        flown = self._pending.own.copy()
        for agent, action in actions.items():
            i = self._index(agent)
            if not self._action_space.contains(action):
                raise ValueError(f"{agent}: action {action!r} is not in Discrete(3)")
            flown[0, i] = int(action)
        self._state, cycle = finish(self._state, self._pending, self._ctx, flown)
        self._tally.add(cycle, self._trajectory[:, k])
        self._recorder.record(k, cycle)
        acting = list(self.agents)
        done = k + 1 >= self.scenario.steps
        if done:
            in_view = np.zeros(self.scenario.n_uavs)
            alive = np.zeros(self.scenario.n_uavs, dtype=bool)
        else:
            self._pending = decide(
                self._state, self._trajectory[:, k + 1], next(self._noises), self._ctx
            )
            in_view = self._pending.observed[0].sum(axis=1)
            alive = self._pending.alive[0]
        rewards = {a: float(in_view[self._index(a)]) for a in acting}
        terminations = {a: not done and not alive[self._index(a)] for a in acting}
        truncations = {a: done for a in acting}
        self.agents = [a for a in acting if not (terminations[a] or truncations[a])]
        observations = self._observations(acting) if not done else self._last(acting)
        infos = self._infos(acting) if not done else {a: {} for a in acting}
        return observations, rewards, terminations, truncations, infos

    def result(self) -> Result:
        """The trial so far as `simulate` reports it: metrics and trace."""
        if not hasattr(self, "_state"):
            raise RuntimeError("call reset() and step() before result()")
        k = self._state.k
        if k == 0:
            raise RuntimeError("no step flown yet")
        traces = self._recorder.traces(self._trajectory[:, :k])  # the steps flown
        batch = BatchResult(self.method.name, self.scenario, self._tally.summary(), traces)
        return result_of(batch, self._seed)

    def render(self) -> np.ndarray | None:
        """The current step drawn as `uavtrack animate` draws it (rgb_array)."""
        if self.render_mode is None:
            return None
        from .plots import frame

        if not hasattr(self, "_state"):
            raise RuntimeError("call reset() before render()")
        k = self._state.k
        if k == 0:  # after reset: the first cycle as the method would close it
            recorder = Recorder(1, timed=True)
            recorder.record(0, finish(self._state, self._pending, self._ctx, fly=False)[1])
            trace = recorder.traces(self._trajectory[:, :1])[0]
            return frame(trace, self.scenario, 0, f"{self.method.name} (env)")
        return frame(self.result().trace, self.scenario, k - 1, f"{self.method.name} (env)")

    def close(self) -> None:
        pass

    # ------------------------------------------------------------------ helpers

    def _index(self, agent: str) -> int:
        try:
            return self.possible_agents.index(agent)
        except ValueError:
            raise ValueError(
                f"unknown agent {agent!r}; agents are {self.possible_agents}"
            ) from None

    def _observations(self, agents: list[str] | None = None) -> dict[str, dict]:
        p = self._pending
        return self._observed(
            agents if agents is not None else self.agents,
            p.believed[0],
            p.fused.mean[0],
            p.fused.cov[0],
            graph(p.uavs, p.alive, self.scenario)[0],
        )

    def _last(self, agents: list[str]) -> dict[str, dict]:
        """Observations after the last step: the state flown to, the last estimates."""
        state = self._state
        links = graph(state.uavs, state.alive, self.scenario)[0]
        return self._observed(agents, state.uavs[0], state.mean[0], state.cov[0], links)

    def _observed(self, agents, uavs, mean, cov, links) -> dict[str, dict]:
        """Each agent's observation from the team's UAV states (Nu, 5), estimates
        (Nu, Nt, 4), covariances (Nu, Nt, 4, 4) and radio adjacency (Nu, Nu)."""
        out = {}
        for agent in agents:
            i = self._index(agent)
            P = cov[i]
            out[agent] = {  # copies: the agent's code may change them, never the trial
                "uav": np.array(uavs[i], dtype=np.float64),
                "estimates": np.array(mean[i], dtype=np.float64),
                "covariance": np.stack([P[:, 0, 0], P[:, 1, 1], P[:, 0, 1]], axis=-1),
                "neighbours": links[i].astype(np.int8),
            }
        return out

    def _infos(self, agents: list[str] | None = None) -> dict[str, dict]:
        p = self._pending
        return {
            a: {
                "paper_action": int(p.own[0, i]),
                "target": int(p.assigned.target[0, i]),
                "in_view": int(p.observed[0, i].sum()),
            }
            for a in (agents if agents is not None else self.agents)
            for i in (self._index(a),)
        }
