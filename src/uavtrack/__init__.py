"""uavtrack: distributed multi-UAV cooperative multi-target tracking.

Implements the system of "Systemic design of distributed multi-UAV cooperative
decision-making for multi-target tracking" (Autonomous Agents and Multi-Agent
Systems, 2019): local Kalman filters, max-consensus fusion, Fisher-information
planning and neighbourhood Hungarian auctions, with centralized and greedy baselines.

    >>> import uavtrack
    >>> result = uavtrack.simulate(uavtrack.Scenario(steps=50), method="distributed", seed=0)
    >>> 0.0 <= result.observation_rate <= 1.0
    True
"""

import importlib
from typing import TYPE_CHECKING

from . import threads as _threads
from ._version import __version__

_threads.pin()  # BLAS threads for every entry point, before numpy loads (see `threads`)

# the public names load their module on first use, so that the command line answers
# bad input without loading numpy
_PUBLIC = {
    "EstimationModel": "config",
    "PlannerModel": "config",
    "Scenario": "config",
    "ScenarioError": "config",
    "SensorModel": "config",
    "TargetModel": "config",
    "UAVModel": "config",
    "METHODS": "methods",
    "Method": "methods",
    "BatchResult": "simulation",
    "Result": "simulation",
    "Trace": "simulation",
    "run": "simulation",
    "simulate": "simulation",
    "trial_seed": "simulation",
}
_MODULES = {
    "assignment",
    "bench",
    "config",
    "estimation",
    "experiments",
    "fusion",
    "metrics",
    "methods",
    "network",
    "planning",
    "plots",
    "report",
    "runner",
    "sensing",
    "simulation",
    "world",
}


def __getattr__(name: str):
    if name in _PUBLIC:
        value = getattr(importlib.import_module(f".{_PUBLIC[name]}", __name__), name)
    elif name in _MODULES:
        value = importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module 'uavtrack' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_PUBLIC) | _MODULES)


if TYPE_CHECKING:
    from .config import (
        EstimationModel,
        PlannerModel,
        Scenario,
        ScenarioError,
        SensorModel,
        TargetModel,
        UAVModel,
    )
    from .methods import METHODS, Method
    from .simulation import BatchResult, Result, Trace, run, simulate, trial_seed

__all__ = [  # noqa: RUF022 (grouped as above)
    "BatchResult",
    "EstimationModel",
    "METHODS",
    "Method",
    "PlannerModel",
    "Result",
    "Scenario",
    "ScenarioError",
    "SensorModel",
    "TargetModel",
    "Trace",
    "UAVModel",
    "__version__",
    "run",
    "simulate",
    "trial_seed",
]
