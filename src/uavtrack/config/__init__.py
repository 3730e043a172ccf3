"""Scenario: every parameter of a run, validated, documented, loadable from TOML.

`Scenario` (`config.scenario`) holds the run's sizes, times and ranges and one part per
concern (`config.parts`: the sensor, the UAVs, wind, the targets, the tracker, fusion,
evaluation, estimation, the planner, faults and robustness); `config.toml` reads and
writes it. Each field states its unit and its source: a paper equation or section, or
"assumed" with the reason. This package imports nothing from the rest of uavtrack but
its errors: a scenario is built and read without numpy, JSBSim or any engine.
"""

from ..errors import ScenarioError
from .parts import (
    MAX_ALTITUDE,
    Bool,
    EstimationModel,
    EvaluationModel,
    FaultModel,
    Float,
    FusionModel,
    G,
    Int,
    ManoeuvreModel,
    PlannerModel,
    RadioModel,
    RobustModel,
    SensorModel,
    TargetModel,
    TrackerModel,
    UAVModel,
    WindModel,
)
from .scenario import Scenario
from .toml import (
    closest,
    describe_errors,
    dump_toml,
    flatten,
    parse_overrides,
    parse_value,
    read_toml,
    set_dotted,
)

__all__ = [  # noqa: RUF022
    "Bool",
    "EstimationModel",
    "EvaluationModel",
    "FaultModel",
    "Float",
    "FusionModel",
    "G",
    "Int",
    "MAX_ALTITUDE",
    "ManoeuvreModel",
    "PlannerModel",
    "RadioModel",
    "RobustModel",
    "Scenario",
    "ScenarioError",
    "SensorModel",
    "TargetModel",
    "TrackerModel",
    "UAVModel",
    "WindModel",
    "closest",
    "describe_errors",
    "dump_toml",
    "flatten",
    "parse_overrides",
    "parse_value",
    "read_toml",
    "set_dotted",
]
