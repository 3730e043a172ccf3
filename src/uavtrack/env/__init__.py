"""A multi-agent environment of a scenario: every UAV an agent choosing its bank angle.

Three forms of one loop (`episodes.Episodes`, the simulator's own `decide` and
`finish` with the agents' actions), so sensing, filtering, fusion and the method's
assignment are exactly those of `simulate`; only the flown actions come from the agents:

* `parallel_env()`: a PettingZoo ParallelEnv;
* `env()`: the same as a PettingZoo AEC env (agents act in turn, the cycle runs when
  the last has acted);
* `vector_env(num_envs)`: that many trials as one batch, arrays (trials, agents, ...);
  `uavtrack.env.learn` makes it a Stable-Baselines3 VecEnv or a TorchRL EnvBase;
* `SingleUAVEnv`: one UAV learns, the others fly the method or a given policy, a
  Gymnasium Env registered as ``uavtrack/SingleUAV-v0``.

Modules: `parallel` (the ParallelEnv and the AEC env), `vector` (the batch), `single`
(one learner), `episodes` (the loop), `spaces` (observations, state, rewards), `learn`
(Stable-Baselines3 and TorchRL), `benchmarl` (a BenchMARL task), `policy` (a learned
policy flown as a method: ``--method policy:FILE``).

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
  fly), ``target`` (its assignment), ``in_view`` (the targets in its disk).
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

**Tracks of unknown association** (``tracker.association`` gnn or jpda): a UAV knows
no target index, so its target rows are its *confirmed* tracks after fusion, nearest
first, and "in view now" is whether one of its own measurements of this scan lies in
the track's gate (`episodes.in_view_now`), never the truth's disk. `max_targets`
defaults to the number of targets (the count the team is briefed on; more confirmed
tracks are false or duplicates) and may rise to the track slots. The Dict form gives
every slot with its team label (``"labels"``, -1 for a slot not confirmed). The state
holds per team label the most confident living UAV's estimate, lowest label first, as
many rows as `max_targets` (`spaces.team_tracks`). "team" and "difference" stay on the
truth; "information" is refused (one filter per target is what its gain compares).
Info ``target`` is the team label followed (-1: none), ``in_view`` the tracks its own
scan met.
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

import gymnasium

from .parallel import UAVTrackingEnv, parallel_env
from .single import ID, SingleUAVEnv
from .spaces import REWARDS, Spaces, View
from .vector import VectorEnv, vector_env

__all__ = [
    "ID",
    "REWARDS",
    "SingleUAVEnv",
    "Spaces",
    "UAVTrackingEnv",
    "VectorEnv",
    "View",
    "env",
    "parallel_env",
    "vector_env",
]

if ID not in gymnasium.registry:  # gymnasium.make("uavtrack/SingleUAV-v0")
    gymnasium.register(id=ID, entry_point="uavtrack.env.single:SingleUAVEnv")


def env(**kwargs: Any):
    """The AEC form of `parallel_env(**kwargs)` (PettingZoo's conversion, with its
    order checks); ``.unwrapped`` is the ParallelEnv (``result()``)."""
    return parallel_to_aec(parallel_env(**kwargs))
