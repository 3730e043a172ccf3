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
import importlib.abc
import importlib.util
import sys
import warnings
from typing import TYPE_CHECKING

from . import _process

__version__ = "0.2.0"

_process.pin()  # BLAS threads for every entry point, before numpy loads (see `_process`)

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
    "BatchResult": "records",
    "Result": "records",
    "Trace": "records",
    "series": "tracks.scoring",
    "run": "simulation",
    "simulate": "simulation",
    "trial_seed": "simulation",
}
_MODULES = {
    "assignment",
    "config",
    "estimation",
    "experiments",
    "faults",
    "fusion",
    "metrics",
    "methods",
    "network",
    "planning",
    "radio",
    "records",
    "robust",
    "sensing",
    "simulation",
    "testing",
    "world",
}

_MOVED = {
    "uavtrack.bench": "uavtrack.experiments.bench",
    "uavtrack.equivalence": "uavtrack.testing",
    "uavtrack.files": "uavtrack._files",
    "uavtrack.flight.experiment": "uavtrack.experiments.flight",
    "uavtrack.flight.mavlink": "uavtrack.io.mavlink",
    "uavtrack.gate": "uavtrack.robust.gate",
    "uavtrack.lifeline": "uavtrack._process",
    "uavtrack.plausibility": "uavtrack.robust.plausibility",
    "uavtrack.plots": "uavtrack.experiments.figures uavtrack.viz.scene",
    "uavtrack.progress": "uavtrack._progress",
    "uavtrack.registry": "uavtrack.methods.registry",
    "uavtrack.report": "uavtrack.experiments.report uavtrack.experiments.statistics",
    "uavtrack.robustness": "uavtrack.experiments.robustness uavtrack.experiments.statistics",
    "uavtrack.runner": "uavtrack.experiments.store",
    "uavtrack.threads": "uavtrack._process",
    "uavtrack.trackers": "uavtrack.experiments.trackers uavtrack.experiments.statistics",
    "uavtrack.viewer": "uavtrack.viz.rerun",
}
"""The import paths of the layout before 0.2, served for one release with a
DeprecationWarning: old path -> the module(s) that hold its names now."""


class _Moved(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Serves an old import path: a module whose names are looked up in the new ones."""

    def find_spec(self, name, path=None, target=None):
        if name in _MOVED:
            return importlib.util.spec_from_loader(name, self)
        return None

    def create_module(self, spec):
        return None

    def exec_module(self, module) -> None:
        homes = [importlib.import_module(m) for m in _MOVED[module.__name__].split()]
        warnings.warn(
            f"{module.__name__} moved to {' and '.join(h.__name__ for h in homes)}; "
            "the old path goes in the next release",
            DeprecationWarning,
            stacklevel=2,
        )

        def find(name: str):  # named as ModuleType.__getattr__'s parameter
            for home in homes:
                if hasattr(home, name):
                    return getattr(home, name)
            raise AttributeError(f"module {module.__name__!r} has no attribute {name!r}")

        module.__getattr__ = find
        module.__doc__ = f"Moved to {', '.join(h.__name__ for h in homes)}."


if not any(isinstance(finder, _Moved) for finder in sys.meta_path):
    sys.meta_path.insert(0, _Moved())  # before the path finders: an old path is never a file


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
    from .records import BatchResult, Result, Trace
    from .simulation import run, simulate, trial_seed
    from .tracks.scoring import series

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
    "series",
    "simulate",
    "trial_seed",
]
