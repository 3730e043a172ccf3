"""Where an aircraft sits: an autopilot takes each cycle's decision (a bank angle per UAV)
and flies the UAVs through the cycle.

    decision (bank angle) -> autopilot -> aircraft -> the UAV's state at the next cycle

`unicycle.Unicycle` is the paper's eq. (1) (the bank angle turns the heading at once);
`jsbsim.Fleet` flies each UAV as a JSBSim fixed-wing aircraft whose autopilot holds the
bank angle, the altitude and the airspeed, in wind and turbulence; `mavlink` turns the same
decision into the setpoints a real autopilot accepts (`uavtrack.io.mavlink`). The world
owns the autopilots; the planner keeps the unicycle model whatever flies the UAVs (the
mismatch is the point). Whether JSBSim can fly a scenario's aircraft is checked where a
flight starts (`check`), never while a scenario is built or read: a JSBSim scenario loads,
and its traces export, on a machine without JSBSim.

Every autopilot answers `fly(uavs, bank, alive)`: the UAV states (B, Nu, 5) x, y, h, V,
heading after one cycle of dt with the bank angles (B, Nu) [rad] held (positive: turn
to the left, counterclockwise, as in eq. 1), a failed UAV (alive False) left where it is.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from ..config import Scenario
from ..errors import ScenarioError


class Autopilot(Protocol):
    """Flies B x Nu UAVs through one cycle at a time."""

    def fly(self, uavs: np.ndarray, bank: np.ndarray, alive: np.ndarray) -> np.ndarray:
        """The UAV states (B, Nu, 5) after one cycle with bank angles (B, Nu) [rad]."""
        ...


def start(
    scenario: Scenario, seeds: Sequence[np.random.SeedSequence], uavs: np.ndarray
) -> tuple[Autopilot, np.ndarray]:
    """The autopilot of a run of `scenario` with one trial per seed, its UAVs placed at
    the drawn initial states `uavs` (B, Nu, 5); returns it and the UAV states it starts
    from (for the unicycle, `uavs` itself; for JSBSim, the trimmed aircraft's)."""
    if scenario.uav.dynamics == "jsbsim":
        from .jsbsim import Fleet

        check(scenario)
        fleet = Fleet(scenario, seeds, uavs)
        return fleet, fleet.states()
    from .unicycle import Unicycle

    return Unicycle(scenario.dt), uavs


def check(scenario: Scenario) -> None:
    """Refuse (ScenarioError, one line) a scenario whose UAVs cannot be flown: with
    ``uav.dynamics = jsbsim``, JSBSim missing, an aircraft that does not load, has no
    uavtrack autopilot or cannot fly level at the scenario's airspeed and altitudes. The
    unicycle flies anything the scenario admits."""
    if scenario.uav.dynamics != "jsbsim":
        return
    from . import jsbsim

    try:
        jsbsim.check(scenario)
    except ValueError as exc:
        raise ScenarioError(str(exc)) from None
