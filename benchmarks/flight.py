"""Speed of real flight: simulated seconds per wall second with every UAV a JSBSim
aircraft and the distributed method running, for teams of 5, 20 and 50 UAVs.

    python benchmarks/flight.py [--steps 60] [--out FILE]

prints the figures and writes no file; ``--out FILE`` keeps them as JSON too, and
``--out benchmarks/flight-2core.json`` is how the published figures are made anew.

One trial per team (`Scenario.scaled`, dt 0.5 s), in this process, BLAS pinned to one
thread as `import uavtrack` does. Each run is timed in wall and CPU time, split into the
aircraft (JSBSim and its autopilot, `Fleet.fly`), the start (loading and trimming the
aircraft) and the rest of the cycle (sensing, filters, fusion, planning, auction). The
unicycle run of the same trial is timed beside it. Real time means one simulated second
per wall second: the rate a world program needs to fly its UAVs live.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import time
from pathlib import Path

import uavtrack
from uavtrack import Scenario, _files, _process
from uavtrack.errors import UsageError
from uavtrack.flight import jsbsim as flight
from uavtrack.simulation import run

TEAMS = ((5, 4), (20, 16), (50, 40))


class Clock:
    """Wall and CPU seconds spent inside a wrapped function."""

    def __init__(self) -> None:
        self.wall = self.cpu = 0.0

    def wrap(self, fn):
        def timed(*args, **kwargs):
            wall, cpu = time.perf_counter(), time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                self.wall += time.perf_counter() - wall
                self.cpu += time.process_time() - cpu

        return timed


def measure(scenario: Scenario, seed: int = 0) -> dict[str, float]:
    """One trial of `scenario`, timed."""
    fly, start = Clock(), Clock()
    original_fly, original_init = flight.Fleet.fly, flight.Fleet.__init__
    flight.Fleet.fly = fly.wrap(original_fly)
    flight.Fleet.__init__ = start.wrap(original_init)
    try:
        wall, cpu = time.perf_counter(), time.process_time()
        result = run(scenario, "distributed", [uavtrack.trial_seed(seed, 0)])
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    finally:
        flight.Fleet.fly, flight.Fleet.__init__ = original_fly, original_init
    simulated = scenario.steps * scenario.dt
    cycle_wall = wall - start.wall
    return {
        "observation_rate": float(result.metrics["observation_rate"][0]),
        "simulated_s": simulated,
        "wall_s": wall,
        "cpu_s": cpu,
        "start_wall_s": start.wall,
        "aircraft_wall_s": fly.wall,
        "method_wall_s": cycle_wall - fly.wall,
        "realtime_factor": simulated / cycle_wall,
        "aircraft_seconds_per_wall_second": simulated * scenario.n_uavs / max(fly.wall, 1e-9),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument(
        "--out",
        type=Path,
        help="also write the figures as JSON here (default: no file; the published "
        "figures are benchmarks/flight-2core.json)",
    )
    args = parser.parse_args()
    if args.out is not None:  # refused before the timings, in one line (exit 2)
        try:
            _files.check_output(args.out, "--out")
        except UsageError as exc:
            parser.error(str(exc))
    warm = Scenario(steps=3)  # one-time imports and set-ups, outside the timings
    measure(warm.with_overrides({"uav.dynamics": "jsbsim"}))
    measure(warm)
    rows = []
    for n_uavs, n_targets in TEAMS:
        base = Scenario().scaled(n_uavs, n_targets).with_overrides({"steps": args.steps})
        real = measure(base.with_overrides({"uav.dynamics": "jsbsim"}))
        paper = measure(base)
        rows.append({"team": f"{n_uavs}x{n_targets}", "jsbsim": real, "unicycle": paper})
        print(
            f"{n_uavs:3d}x{n_targets:<3d} jsbsim: {real['realtime_factor']:6.1f}x real time "
            f"(aircraft {real['aircraft_wall_s']:.2f} s, method {real['method_wall_s']:.2f} s, "
            f"start {real['start_wall_s']:.2f} s for {real['simulated_s']:g} s simulated; "
            f"{real['aircraft_seconds_per_wall_second']:.0f} aircraft-s per s); "
            f"unicycle: {paper['realtime_factor']:.1f}x",
            flush=True,
        )
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    out = {
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "blas_threads": _process.describe(),
            "jsbsim": __import__("jsbsim").__version__,
            "uavtrack": uavtrack.__version__,
        },
        "steps": args.steps,
        "dt": Scenario().dt,
        "rate_hz": Scenario().uav.jsbsim_rate_hz,
        "peak_rss_mib": peak_mib,
        "teams": rows,
        "note": "wall seconds of one trial in one process; realtime_factor = simulated "
        "seconds / wall seconds of the cycles (the start excluded)",
    }
    print(f"peak RSS {peak_mib:.0f} MiB")
    if args.out is not None:
        _files.write_text(args.out, json.dumps(out, indent=2) + "\n")
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
