"""Where one trial's time goes: microseconds per step in each stage of the cycle.

    python benchmarks/profile_cycle.py [method] [trials-in-the-batch] [NxM] [FIELD=VALUE ...]

Runs the default scenario's 500 steps (or the scenario grown to N UAVs x M targets,
`Scenario.scaled`, and FIELD=VALUE overrides such as steps=10) through `simulation.run`
under cProfile and charges each stage function's cumulative time to its stage
(profiling adds its own overhead, about a third, spread over the stages).
"""

import cProfile
import pstats
import sys
import time

import uavtrack
from uavtrack.config import parse_value

STAGES = {  # stage: (module path, function) of the cycle whose cumulative time is the stage's
    "graph": (("network", "radio_links"),),
    "sensing": (("simulation", "observe"), ("simulation", "convert")),
    "filter": (("estimation", "filter_step"),),
    "confidence": (("estimation", "confidence"),),
    "fusion": (("methods/base", "fuse"), ("methods/centralized", "fuse")),
    "planning": (("simulation", "_plan"),),
    "auction": tuple(
        (f"methods/{name}", "assign") for name in ("distributed", "centralized", "greedy")
    ),
    "control": (("flight/unicycle", "fly"), ("flight/jsbsim", "fly")),
    "prediction": (("estimation", "close"),),
    "metrics": (("metrics", "add"),),
    "noise": (("simulation", "sensor_noise"),),
}
"""A module path is relative to the package (``methods/base`` is uavtrack/methods/base.py)."""


def profile(
    method: str = "distributed", batch: int = 1, overrides=None, team=None
) -> dict[str, float]:
    scenario = uavtrack.Scenario()
    if team is not None:
        scenario = scenario.scaled(*team)
    scenario = scenario.with_overrides(overrides or {})
    seeds = [uavtrack.trial_seed(0, t) for t in range(batch)]
    profiler = cProfile.Profile()
    start = time.perf_counter()
    profiler.runcall(uavtrack.run, scenario, method, seeds)
    total = time.perf_counter() - start
    stats = pstats.Stats(profiler).stats
    out = {}
    for stage, names in STAGES.items():
        out[stage] = sum(
            cumulative
            for (path, _, name), (_, _, _, cumulative, _) in stats.items()
            for module, function in names
            if name == function and path.endswith(f"uavtrack/{module}.py")
        )
    out["other"] = max(total - sum(out.values()), 0.0)  # the rest of step and run
    return {stage: 1e6 * s / scenario.steps for stage, s in out.items()}


if __name__ == "__main__":
    method = sys.argv[1] if len(sys.argv) > 1 else "distributed"
    batch = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    rest = sys.argv[3:]
    team = None
    if rest and "=" not in rest[0]:
        team = tuple(int(n) for n in rest.pop(0).lower().split("x"))
    overrides = dict(
        (name, parse_value(value)) for name, _, value in (a.partition("=") for a in rest)
    )
    profile(method, batch, overrides, team)  # warm-up
    stages = profile(method, batch, overrides, team)
    total = sum(stages.values())
    print(f"{method}, {batch} trial(s) per batch: microseconds per step (under cProfile)")
    for stage, us in sorted(stages.items(), key=lambda kv: -kv[1]):
        print(f"  {stage:10s} {us:8.1f}  {100 * us / total:4.0f}%")
    print(f"  {'total':10s} {total:8.1f}  per step")
