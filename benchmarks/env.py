"""Throughput of the multi-agent environment: agent-steps per second of the single
PettingZoo environment and of the vector environment at several batch sizes.

    python benchmarks/env.py [--steps 60] [--repeats 3] [--out FILE]

prints the figures and writes no file; ``--out FILE`` keeps them as JSON too, and
``--out benchmarks/env-2core.json`` is how the published figures are made anew.

The paper's scenario (5 UAVs, 4 targets), Box observations, team reward, actions drawn
at random (the same cost as any policy's). The vector environment is timed with the
method's planning (``paper_actions=True``, what the single environment always does,
for ``info["paper_action"]``) and without it (``paper_actions=False``, for agents that
choose every action). One process, BLAS pinned to one thread as ``import uavtrack``
does; each figure is the median of `repeats` runs of `steps` steps after one warm-up
step, in wall time, with the CPU time of the same runs beside it. The single
environment is timed between the vector runs, so that a drift of the machine's speed
shows in both.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

import uavtrack
from uavtrack import _files, _process
from uavtrack.env import parallel_env, vector_env
from uavtrack.errors import UsageError

BATCHES = (1, 16, 64, 256)


def timed(step, steps: int) -> tuple[float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        step()
    return time.perf_counter() - wall, time.process_time() - cpu


def single(steps: int) -> tuple[float, float]:
    env = parallel_env(steps=steps + 1)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    env.step({})  # warm-up
    return timed(lambda: env.step({a: int(rng.integers(3)) for a in env.agents}), steps)


def vector(trials: int, steps: int, planned: bool) -> tuple[float, float]:
    v = vector_env(trials, steps=steps + 1, paper_actions=planned)
    v.reset(seed=0)
    rng = np.random.default_rng(0)
    draw = lambda: rng.integers(0, 3, size=(trials, 5))  # noqa: E731
    v.step(draw())  # warm-up
    return timed(lambda: v.step(draw()), steps)


def rate(runs: list[tuple[float, float]], agent_steps: int) -> dict[str, float]:
    wall = statistics.median(r[0] for r in runs)
    cpu = statistics.median(r[1] for r in runs)
    return {
        "agent_steps_per_wall_s": agent_steps / wall,
        "agent_steps_per_cpu_s": agent_steps / cpu,
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description="Agent-steps per second of the single and the vector environment."
    )
    parser.add_argument("--steps", type=int, default=60, help="steps timed per run")
    parser.add_argument("--repeats", type=int, default=3, help="runs per figure (median)")
    parser.add_argument(
        "--out",
        type=Path,
        help="also write the figures as JSON here (default: no file; the published "
        "figures are benchmarks/env-2core.json)",
    )
    args = parser.parse_args()
    if args.steps < 1 or args.repeats < 1:
        parser.error("--steps and --repeats must be at least 1")
    if args.out is not None:  # refused before the timings, in one line (exit 2)
        try:
            _files.check_output(args.out, "--out")
        except UsageError as exc:
            parser.error(str(exc))
    single_runs, rows = [], []
    for trials in BATCHES:
        single_runs.append(single(args.steps))
        row = {"trials": trials}
        for planned in (True, False):
            runs = [vector(trials, args.steps, planned) for _ in range(args.repeats)]
            row["with_paper_actions" if planned else "agents_only"] = rate(
                runs, trials * 5 * args.steps
            )
        rows.append(row)
        print(
            f"{trials:4d} trials: {row['with_paper_actions']['agent_steps_per_wall_s']:9.0f} "
            f"agent-steps/s with the method's actions, "
            f"{row['agents_only']['agent_steps_per_wall_s']:9.0f} without",
            flush=True,
        )
    base = rate(single_runs, 5 * args.steps)
    print(f"single environment: {base['agent_steps_per_wall_s']:.0f} agent-steps/s")
    for row in rows:
        for key in ("with_paper_actions", "agents_only"):
            row[key]["times_single"] = (
                row[key]["agent_steps_per_wall_s"] / base["agent_steps_per_wall_s"]
            )
    out = {
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "blas_threads": _process.describe(),
            "uavtrack": uavtrack.__version__,
        },
        "scenario": "the paper's Sec. 7.1: 5 UAVs, 4 targets; Box observations, team reward",
        "steps": args.steps,
        "repeats": args.repeats,
        "single": base,
        "vector": rows,
        "note": "median wall (and CPU) seconds of `repeats` runs of `steps` steps, random "
        "actions, one process; times_single = vector / single agent-steps per wall second",
    }
    if args.out is not None:
        _files.write_text(args.out, json.dumps(out, indent=2) + "\n")
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
