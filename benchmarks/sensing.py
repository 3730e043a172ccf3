"""What unknown association costs: CPU time of a run with JPDA at P_D 0.9 and 2 false
measurements per scan against the same run with known association (the paper's).

    python benchmarks/sensing.py [--steps 500] [--trials 1] [--team-steps 20] [--out FILE]

prints the figures and writes no file; ``--out FILE`` keeps them as JSON too, and
``--out benchmarks/sensing-2core.json`` is how the published figures are made anew.

Two cases: the paper's scenario (5 UAVs, 4 targets), `--trials` trials of `--steps`
steps as one batch; and a 100 x 100 team (`Scenario.scaled`, the distributed method),
one trial of `--team-steps` steps. Each figure is the CPU time of the whole run
(``time.process_time``, one process, BLAS pinned to one thread as ``import uavtrack``
does), the median of `--repeats` runs, known and JPDA alternating so that a drift of the
machine's speed affects both alike; the ratio is JPDA's over known's.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from pathlib import Path

import uavtrack
from uavtrack import _files

SENSING = {"sensor.detection_probability": 0.9, "sensor.clutter_rate": 2.0}


def cpu_seconds(scenario: uavtrack.Scenario, trials: int) -> float:
    seeds = [uavtrack.trial_seed(0, t) for t in range(trials)]
    start = time.process_time()
    uavtrack.run(scenario, "distributed", seeds)
    return time.process_time() - start


def compare(name: str, known: uavtrack.Scenario, trials: int, repeats: int) -> dict:
    tracked = known.with_overrides({**SENSING, "tracker.association": "jpda"})
    times: dict[str, list[float]] = {"known": [], "jpda": []}
    for _ in range(repeats):
        times["known"].append(cpu_seconds(known, trials))
        times["jpda"].append(cpu_seconds(tracked, trials))
    k, j = statistics.median(times["known"]), statistics.median(times["jpda"])
    return {
        "case": name,
        "trials": trials,
        "steps": known.steps,
        "known_cpu_s": k,
        "jpda_cpu_s": j,
        "ratio": j / k,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=500)
    parser.add_argument("--trials", type=int, default=1)
    parser.add_argument("--team-steps", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    if min(args.steps, args.trials, args.team_steps, args.repeats) < 1:
        parser.error("--steps, --trials, --team-steps and --repeats must be at least 1")
    paper = uavtrack.Scenario(steps=args.steps)
    team = uavtrack.Scenario(steps=args.team_steps).scaled(100, 100)
    results = [
        compare("paper's scenario (5 x 4)", paper, args.trials, args.repeats),
        compare("100 x 100 team", team, 1, args.repeats),
    ]
    for r in results:
        print(
            f"{r['case']}: {r['trials']} trial(s) x {r['steps']} steps, CPU known "
            f"{r['known_cpu_s']:.2f} s, jpda {r['jpda_cpu_s']:.2f} s, ratio {r['ratio']:.2f}"
        )
    if args.out is not None:
        out = {
            "machine": {"python": platform.python_version(), "processor": platform.machine()},
            "uavtrack": uavtrack.__version__,
            "results": results,
        }
        _files.write_text(args.out, json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
