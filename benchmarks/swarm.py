"""The agent form over Zenoh: wall time of a cycle and traffic per UAV, by team size.

    python benchmarks/swarm.py [--steps N] [--sizes 5 20 50] [--json FILE]

Each size runs one trial of the default scenario grown to that team (`experiments.resized`
keeps the altitude band; the field grows with the team to keep the density) as one OS
process per UAV on this machine, then one trial paced at dt (--realtime) for 20 UAVs.
Times are wall-clock and depend on the machine; the first cycles include the programs'
warm-up, so the median is the figure to read.
"""

import argparse
import json
import math
import time

import numpy as np

import uavtrack
from uavtrack.agents import run_swarm
from uavtrack.experiments import resized


def team(n: int, steps: int) -> uavtrack.Scenario:
    base = uavtrack.Scenario(steps=steps)
    scenario = resized(base, n, max(1, round(n * 4 / 5)))
    return scenario.with_overrides({"field_size": 200.0 * math.sqrt(n / 5)})


def measure(n: int, steps: int, realtime: bool = False) -> dict:
    scenario = team(n, steps)
    start = time.perf_counter()
    out = run_swarm(
        scenario,
        "distributed",
        seed=0,
        transport="zenoh",
        realtime=realtime,
        trace=False,
        deadline=5.0,
    )
    total = time.perf_counter() - start
    cycles = np.asarray(out.traffic.cycle_seconds)
    steady = cycles[min(5, len(cycles) - 1) :]
    return {
        "uavs": n,
        "targets": scenario.n_targets,
        "steps": steps,
        "realtime": realtime,
        "cycle_ms_median": 1e3 * float(np.median(steady)),
        "cycle_ms_p90": 1e3 * float(np.percentile(steady, 90)),
        "radio_messages_per_uav_cycle": out.traffic.published / (n * steps),
        "bytes_per_uav_cycle": out.traffic.bytes / (n * steps),
        "protocol_messages_per_uav_cycle": out.result.messages / n,
        "overruns": len(out.traffic.overruns),
        "total_s": total,
        "observation_rate": out.result.observation_rate,
    }


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--sizes", type=int, nargs="+", default=[5, 20, 50])
    parser.add_argument("--json")
    args = parser.parse_args()
    rows = [measure(n, args.steps) for n in args.sizes]
    rows.append(measure(20, args.steps, realtime=True))
    print(
        "UAVs  targets  cycle median / p90 [ms]  radio msgs / bytes per UAV-cycle  "
        "protocol msgs per UAV-cycle  overruns"
    )
    for r in rows:
        print(
            f"{r['uavs']:4d} {r['targets']:8d}  "
            f"{r['cycle_ms_median']:8.1f} / {r['cycle_ms_p90']:7.1f}"
            f"  {r['radio_messages_per_uav_cycle']:10.1f} / {r['bytes_per_uav_cycle']:9.0f}"
            f"  {r['protocol_messages_per_uav_cycle']:18.1f}  "
            f"{r['overruns'] if r['realtime'] else '-'}{' (realtime)' if r['realtime'] else ''}"
        )
    if args.json:
        with open(args.json, "w") as out:
            json.dump(rows, out, indent=1)
