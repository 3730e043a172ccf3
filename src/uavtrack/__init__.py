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

from ._version import __version__
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

__all__ = [
    "METHODS",
    "BatchResult",
    "EstimationModel",
    "Method",
    "PlannerModel",
    "Result",
    "Scenario",
    "ScenarioError",
    "SensorModel",
    "TargetModel",
    "Trace",
    "UAVModel",
    "run",
    "simulate",
    "trial_seed",
    "__version__",
]
