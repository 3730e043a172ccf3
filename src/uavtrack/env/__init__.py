"""A multi-agent environment of a scenario: every UAV an agent choosing its bank angle.

Three forms of one loop (`episodes.Episodes`, the simulator's own `decide` and
`finish` with the agents' actions), so sensing, filtering, fusion and the method's
assignment are exactly those of `simulate`; only the flown actions come from the agents:

* `parallel_env()`: a PettingZoo ParallelEnv;
* `env()`: the same as a PettingZoo AEC env (agents act in turn, the cycle runs when
  the last has acted);
* `vector_env(num_envs)`: that many trials as one batch, arrays (trials, agents, ...);
  `uavtrack.env.learn` makes it a Stable-Baselines3 VecEnv or a TorchRL EnvBase.

Agents ``uav_0 ... uav_{N-1}``. Needs the env extra (pettingzoo, gymnasium).

* **Observation** (``observation="box"``, the default): a flat float32 Box in
  [-10, 10] of what the UAV knows after fusion, egocentric and scaled (see
  `spaces`): its own part (alive, position from the field's centre, heading, speed,
  altitude, progress k/T), one row per target (present, bearing in its heading frame,
  log distance, velocity in its frame, log standard deviation, in view now), nearest
  first, and one row per UAV within radio range (present, bearing, log distance,
  relative heading), nearest first. `max_targets` and `max_neighbours` cap the rows
  (default: all targets, all other UAVs); a missing row is zeros. `Spaces.layout()`
  names the slices. ``observation="dict"`` gives the raw Dict of earlier versions
  (own state, estimates, covariances, radio neighbours in world units).
* **State** (``state()``, ``state_space``): the team's global view in the same scaled
  form: the step, every UAV's true state, the team's best estimate of every target.
* **Action**: ``Discrete(3)``, an index into {-phi, 0, +phi} (1 flies straight).
* **Reward** (``reward=``, see `spaces.REWARDS`): an action at cycle k earns what the
  next cycle shows; "team" (default) the share of targets inside at least one UAV's
  disk, the same for all (its mean over an episode is the paper's observation rate,
  less the first step's); "difference" the share only this UAV sees; "information"
  the information its own measurements bring. The last cycle's action earns 0.
* **Info**: ``paper_action`` (what ``method_for_others``, default "distributed", would
  fly), ``target`` (its assignment), ``in_view``.
* **Episodes** last the scenario's steps (``max_cycles``): at the end every agent is
  terminated (the time left is in the observation, so the end is part of the task)
  and truncated (the steps ran out). A UAV that fails (faults) terminates as an agent
  and leaves ``agents``; the others fly on to the mission's end. As PettingZoo's
  conversions do, an action given for an agent that has left is ignored (TorchRL's
  ``PettingZooWrapper`` sends one for every possible agent: give it ``use_mask=True,
  done_on_any=False`` so that a failure does not end the episode); a name that was
  never an agent is refused. SuperSuit's ``black_death_v3`` keeps a failed UAV as
  zeros. An agent left out of the action dict flies the method's action.

``reset(seed=s)`` draws the trial as ``simulate(scenario, method, seed=s)`` does, so
flying every ``paper_action`` reproduces ``simulate``'s trial exactly (``result()``).
"""

from __future__ import annotations

from typing import Any

from ..errors import install_hint

try:
    from pettingzoo.utils.conversions import parallel_to_aec
except ImportError as exc:  # an optional extra
    raise ImportError(
        f"uavtrack.env needs pettingzoo and gymnasium: {install_hint('env')} ({exc})"
    ) from None

from .parallel import UAVTrackingEnv, parallel_env
from .spaces import REWARDS, Spaces, View
from .vector import VectorEnv, vector_env

__all__ = [
    "REWARDS",
    "Spaces",
    "UAVTrackingEnv",
    "VectorEnv",
    "View",
    "env",
    "parallel_env",
    "vector_env",
]


def env(**kwargs: Any):
    """The AEC form of `parallel_env(**kwargs)` (PettingZoo's conversion, with its
    order checks); ``.unwrapped`` is the ParallelEnv (``result()``)."""
    return parallel_to_aec(parallel_env(**kwargs))
