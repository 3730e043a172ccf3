"""Where one trial's time goes: microseconds per step in each stage of the cycle.

    python benchmarks/profile_cycle.py [method] [trials-in-the-batch] [FIELD=VALUE ...]

Runs the default scenario's 500 steps through `simulation.run` under cProfile and
charges each stage function's cumulative time to its stage (profiling adds its own
overhead, about a third, spread over the stages).
"""

import cProfile
import pstats
import sys
import time

import uavtrack
from uavtrack.config import parse_value

STAGES = {  # stage: functions of the cycle whose cumulative time is the stage's
    "graph": ("graph", "links"),
    "sensing": ("sense",),
    "filter": ("filter_step", "predict"),
    "fusion": ("fuse",),
    "planning": ("_plan",),
    "auction": ("assign",),
    "control": ("fly",),
    "metrics": ("add",),
    "noise": ("standard_normal",),
}


def profile(method: str = "distributed", batch: int = 1, overrides=None) -> dict[str, float]:
    scenario = uavtrack.Scenario().with_overrides(overrides or {})
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
            if name in names and ("uavtrack" in path or name == "standard_normal")
        )
    out["other"] = max(total - sum(out.values()), 0.0)  # the rest of step and run
    return {stage: 1e6 * s / scenario.steps for stage, s in out.items()}


if __name__ == "__main__":
    method = sys.argv[1] if len(sys.argv) > 1 else "distributed"
    batch = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    overrides = dict(
        (name, parse_value(value)) for name, _, value in (a.partition("=") for a in sys.argv[3:])
    )
    profile(method, batch, overrides)  # warm-up
    stages = profile(method, batch, overrides)
    total = sum(stages.values())
    print(f"{method}, {batch} trial(s) per batch: microseconds per step (under cProfile)")
    for stage, us in sorted(stages.items(), key=lambda kv: -kv[1]):
        print(f"  {stage:10s} {us:8.1f}  {100 * us / total:4.0f}%")
    print(f"  {'total':10s} {total:8.1f}  -> {total * 500 / 1e6:.3f} s for 500 steps")
