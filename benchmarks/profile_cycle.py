"""Where one trial's time goes: microseconds per step in each stage of the cycle.

    python benchmarks/profile_cycle.py [method] [trials-in-the-batch] [NxM] [FIELD=VALUE ...]

Runs the default scenario's 500 steps (or the scenario grown to N UAVs x M targets,
`Scenario.scaled`, and FIELD=VALUE overrides such as steps=10) through `simulation.run`
under cProfile and charges each stage function's cumulative time to its stage, less
the calls another stage function made directly (profiling adds its own overhead, about
a third, spread over the stages). With tracks (tracker.association=jpda) the stages of
the track pipeline are named: the scan, the tracking (association and management), the
agreement (the team's track fusion) and the label columns of the auction. A stage the
run never reached is not printed.
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
    "scan": (("tracks/scan", "clutter"), ("tracks/scan", "assemble"), ("tracks/scan", "detected")),
    "filter": (("estimation", "filter_step"),),
    "confidence": (("estimation", "confidence"),),
    "fusion": (("methods/base", "fuse"), ("methods/centralized", "fuse")),
    "tracking": (("tracks/manage", "scan"),),
    "agreement": (("tracks/team", "agree"), ("tracks/manage", "after_fusion")),
    "columns": tuple(
        ("tracks/columns", name) for name in ("of", "bids", "holds", "slot_of", "relabel")
    ),
    "planning": (("simulation", "_plan"), ("tracks/manage", "weighed")),
    "auction": tuple(
        (f"methods/{name}", "assign") for name in ("distributed", "centralized", "greedy")
    ),
    "control": (("flight/unicycle", "fly"), ("flight/jsbsim", "fly")),
    "prediction": (("simulation", "close"),),
    "metrics": (("metrics", "add"), ("tracks/scoring", "add")),
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
    staged = {
        key: stage
        for key in stats
        for stage, names in STAGES.items()
        for module, function in names
        if key[2] == function and key[0].endswith(f"uavtrack/{module}.py")
    }
    out = dict.fromkeys(STAGES, 0.0)
    for key, stage in staged.items():  # each call charged once: not when a stage called it
        callers = stats[key][4]
        out[stage] += sum(part[3] for caller, part in callers.items() if caller not in staged)
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
        if us == 0:
            continue
        print(f"  {stage:10s} {us:8.1f}  {100 * us / total:4.0f}%")
    print(f"  {'total':10s} {total:8.1f}  per step")
