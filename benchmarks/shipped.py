"""Speed as shipped: the commands a user types, timed as separate processes, this checkout
beside another version of the source.

    python benchmarks/shipped.py [--before SRC] [--json FILE] [--figure FILE] [--quick]
                                 [--only CASE ...]

Each case runs ``uavtrack ...`` through the console entry point that the tree's
pyproject.toml names, in a fresh interpreter with that tree's ``src`` first on the path
and the environment as it is (no thread variables set here: each version sets BLAS
threads as it ships). Versions alternate, case by case, so a drift in the machine's
speed hits both alike. Times are medians: wall time (``time.perf_counter`` around the
process) and CPU time (user + system of the process and its children, from
``getrusage``). The cost of one decision cycle as shipped is the difference between a
run of S2 and one of S1 steps, divided by S2 - S1, so start-up and set-up cancel.
Each tree's sources are compiled to bytecode first (``compileall``), as ``pip install``
does, so that no version pays for compiling its modules in every run.

Besides the commands: the single PettingZoo environment (agent-steps per CPU second of a
script stepping ``parallel_env`` with random actions, by the same difference of two
lengths) and the vector environment at 256 trials; the 5 x 4 swarm over Zenoh (one
process per UAV), its CPU per cycle and each program's start-up (the swarm's CPU
extrapolated to zero cycles, over its N + 1 programs); and at 1000 x 1000 one trial's
steady state (`STEADY_SCRIPT`: CPU, wall and minor page faults per step after its first
five steps, read by a progress callback) and the peak resident memory of its process.

--before SRC: the ``src`` folder of the version to compare with, for example a
worktree of the commit before a change (``git worktree add /tmp/before <commit>``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib
from collections.abc import Callable
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent / "src"

TEAMS = (10, 30, 100, 300, 1000)
"""Square teams N UAVs x N targets at the default density (``--team NxN``)."""


def entry(src: Path) -> str:
    """The ``module:function`` of the tree's ``uavtrack`` console script."""
    project = tomllib.loads((src.parent / "pyproject.toml").read_text())
    return project["project"]["scripts"]["uavtrack"]


def command(src: Path, args: list[str]) -> list[str]:
    module, _, function = entry(src).partition(":")
    code = (
        "import sys; sys.argv[0] = 'uavtrack'; "
        f"from {module} import {function} as main; sys.exit(main())"
    )
    return [sys.executable, "-c", code, *args]


FRESH = "{fresh}"
"""An argument replaced by a new empty folder for each run (removed after it)."""


SCRIPT = "{script}"
"""A first argument that runs the rest as a Python script (``python -c``), not uavtrack."""


def once(src: Path, args: list[str]) -> dict[str, float]:
    """Wall and CPU seconds and minor page faults of one ``uavtrack args`` (or script:
    `SCRIPT`) with `src` first on the path, of the process and its children."""
    env = dict(os.environ, PYTHONPATH=str(src))
    with tempfile.TemporaryDirectory() as fresh:
        args = [str(Path(fresh) / "out") if a == FRESH else a for a in args]
        argv = [sys.executable, "-c", *args[1:]] if args[0] == SCRIPT else command(src, args)
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        done = subprocess.run(argv, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv[:4])} ... failed in {src}:\n{done.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu, "minor_faults": after.ru_minflt - before.ru_minflt}


def case(trees: dict[str, Path], args: list[str], repeats: int) -> dict[str, dict]:
    """Median wall and CPU seconds (and minor faults) of `args` per tree, the trees
    alternating, and the peak resident memory."""
    seen: dict[str, list[dict[str, float]]] = {name: [] for name in trees}
    for _ in range(repeats):
        for name, src in trees.items():
            seen[name].append(once(src, args))
    return {
        name: {
            "wall_s": statistics.median(r["wall_s"] for r in runs),
            "cpu_s": statistics.median(r["cpu_s"] for r in runs),
            "minor_faults": statistics.median(r["minor_faults"] for r in runs),
            "runs": len(runs),
        }
        for name, runs in seen.items()
    }


def per_unit(
    trees: dict[str, Path],
    make: Callable[[int], list[str]],
    lengths: tuple[int, int],
    repeats: int,
    units: int = 1,
) -> dict[str, dict]:
    """CPU and wall seconds (and minor faults) per step, of `make(steps)` run at two
    lengths, by their difference (start-up and set-up cancel), over `units` per step;
    and what a run of zero steps would cost (`start_cpu_s`: the start-up)."""
    short, long = lengths
    a = case(trees, make(short), repeats)
    b = case(trees, make(long), repeats)
    out = {}
    for name in trees:
        each = {
            key: (b[name][key] - a[name][key]) / ((long - short) * units)
            for key in ("cpu_s", "wall_s", "minor_faults")
        }
        each["start_cpu_s"] = a[name]["cpu_s"] - each["cpu_s"] * short * units
        each["steps"] = [short, long]
        out[name] = each
    return out


ENV_SCRIPT = """
import time, numpy as np
from uavtrack.env import {make}
steps = {steps}
{setup}
for _ in range(steps):
    {step}
"""


def single_env(steps: int) -> list[str]:
    """A script stepping the single `parallel_env` (5 agents) with random actions."""
    return [SCRIPT, ENV_SCRIPT.format(
        make="parallel_env", steps=steps,
        setup="env = parallel_env(steps=steps + 1); env.reset(seed=0); "
        "rng = np.random.default_rng(0)",
        step="env.step({a: int(rng.integers(3)) for a in env.agents})",
    )]  # fmt: skip


def vector_env(steps: int, trials: int = 256) -> list[str]:
    """A script stepping `vector_env` of `trials` with random actions (paper actions on)."""
    return [SCRIPT, ENV_SCRIPT.format(
        make="vector_env", steps=steps,
        setup=f"v = vector_env({trials}, steps=steps + 1); v.reset(seed=0); "
        "rng = np.random.default_rng(0)",
        step=f"v.step(rng.integers(0, 3, size=({trials}, 5)))",
    )]  # fmt: skip


def swarm(steps: int) -> list[str]:
    """The default 5 x 4 trial as a swarm over Zenoh, one process per UAV."""
    return ["swarm", "--transport", "zenoh", "--steps", str(steps), "--json"]


def cycle(trees: dict[str, Path], n: int, repeats: int) -> dict[str, dict]:
    """CPU and wall seconds (and minor page faults) of one distributed cycle of an n x n
    team, as shipped; at 1000 x 1000 also the peak resident memory of the longer run."""
    lengths = (3, 13) if n >= 1000 else (5, 35) if n >= 300 else (10, 60) if n >= 100 else (20, 320)
    team = ["run", "--team", f"{n}x{n}", "--json"]
    return per_unit(trees, lambda steps: team + ["--steps", str(steps)], lengths, repeats)


STEADY_SCRIPT = """
import json, resource, time, uavtrack
s = uavtrack.Scenario().scaled({n}, {n}).model_copy(update={{"steps": {steps}}})
marks = []
def progress(k):
    use = resource.getrusage(resource.RUSAGE_SELF)
    marks.append((time.process_time(), time.perf_counter(), use.ru_minflt))
begun = (time.process_time(), time.perf_counter())
uavtrack.run(s, "distributed", [0], progress=progress)
steady = marks[{warm} - 1:]
span = len(steady) - 1
print(json.dumps({{
    "cpu_s": (steady[-1][0] - steady[0][0]) / span,
    "wall_s": (steady[-1][1] - steady[0][1]) / span,
    "minor_faults": (steady[-1][2] - steady[0][2]) / span,
    "first_steps_cpu_s": marks[{warm} - 1][0] - begun[0],
    "max_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
}}))
"""
"""One trial of n x n through `uavtrack.run` with a progress callback: the CPU and wall
seconds and minor page faults per step after the first `warm` steps (each version's
one-time set-up: the first arrays of a run, the solver's load), and the peak resident
memory of the process."""


def steady(trees: dict[str, Path], n: int, repeats: int, steps: int = 20, warm: int = 5) -> dict:
    """Medians over `repeats` alternating runs of `STEADY_SCRIPT`, per tree."""
    seen: dict[str, list[dict]] = {name: [] for name in trees}
    code = STEADY_SCRIPT.format(n=n, steps=steps, warm=warm)
    for _ in range(repeats):
        for name, src in trees.items():
            env = dict(os.environ, PYTHONPATH=str(src))
            done = subprocess.run(
                [sys.executable, "-c", code], env=env, capture_output=True, text=True
            )
            if done.returncode != 0:
                raise SystemExit(f"the steady-state run of {n}x{n} failed in {src}:\n{done.stderr}")
            seen[name].append(json.loads(done.stdout))
    return {
        name: {key: statistics.median(r[key] for r in runs) for key in runs[0]}
        | {"runs": len(runs), "steps": steps, "warm": warm}
        for name, runs in seen.items()
    }


def write_json(path: Path, results: dict) -> None:
    """`results` as indented JSON at `path`, replaced whole (a new file renamed over it)."""
    part = path.with_name(path.name + ".part")
    part.write_text(json.dumps(results, indent=1) + "\n")
    part.replace(path)


def compiled(src: Path) -> None:
    """Compile a tree's sources to bytecode, as an install does."""
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(src / "uavtrack")], check=True)


GROUPS = {
    "commands": "--version, run --help, the start-up and one default trial",
    "env": "the single and the vector environment",
    "swarm": "the 5 x 4 swarm over Zenoh: CPU per cycle and each program's start-up",
    "teams": "one distributed cycle of 10 x 10 to 1000 x 1000, page faults and peak memory",
    "reproduce": "uavtrack reproduce, --quick and in full",
}
"""The groups of cases (``--only``)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=Path, help="src folder of the version to compare with")
    parser.add_argument("--json", type=Path, help="write the results here")
    parser.add_argument("--figure", type=Path, help="draw the cycle's cost against team size")
    parser.add_argument("--quick", action="store_true", help="fewer repeats, no full reproduce")
    parser.add_argument(
        "--only", nargs="+", metavar="CASE", choices=sorted(GROUPS),
        help=f"these groups of cases alone: {', '.join(sorted(GROUPS))}",
    )  # fmt: skip
    options = parser.parse_args()
    trees = {"this": HERE}
    if options.before is not None:
        if not (options.before / "uavtrack").is_dir():
            parser.error(f"--before {options.before}: not a src folder holding uavtrack")
        trees = {"before": options.before.resolve(), "this": HERE}
    few = 1 if options.quick else 3
    wanted = set(options.only or GROUPS)
    for path in (options.json, options.figure):
        if path is not None and not path.resolve().parent.is_dir():
            parser.error(f"{path}: its folder does not exist")
    if options.figure is not None and "teams" not in wanted:
        parser.error("--figure draws the teams' cycles: give it with the teams group")
    for src in trees.values():
        compiled(src)
    results: dict = {
        "machine": {
            "cores": os.cpu_count(),
            "platform": platform.platform(),
            "python": platform.python_version(),
            "thread_variables": {
                k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")
            },
            "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        },
        "trees": {name: str(src) for name, src in trees.items()},
        "cases": {},
    }
    cases = results["cases"]

    def say(name: str, row: dict) -> None:
        cases[name] = row
        if options.json is not None:  # after every case: a later failure loses nothing
            write_json(options.json, results)

        def one(v: dict) -> str:
            text = f"{v['cpu_s'] * 1e3:.4g} ms CPU, {v['wall_s'] * 1e3:.4g} ms wall"
            if "start_cpu_s" in v:
                text += f", start-up {v['start_cpu_s'] * 1e3:.4g} ms CPU"
            if "max_rss_mib" in v:
                text += f", {v['minor_faults']:.0f} minor faults, peak {v['max_rss_mib']:.0f} MiB"
            return text

        shown = "; ".join(f"{tree} {one(v)}" for tree, v in row.items())
        print(f"{name}: {shown}", file=sys.stderr)

    if "commands" in wanted:
        say("uavtrack --version", case(trees, ["--version"], 5))
        say("uavtrack run --help", case(trees, ["run", "--help"], 5))
        start = ["run", "--set", "steps=1", "--json"]
        say("uavtrack run --set steps=1 (start-up)", case(trees, start, few + 4))
        say("uavtrack run (one default trial)", case(trees, ["run", "--json"], few + 4))
    if "env" in wanted:
        say(
            "single parallel_env, per agent-step",
            per_unit(trees, single_env, (20, 1020), few + 2, 5),
        )
        say("vector_env 256 trials, per agent-step", per_unit(
            trees, vector_env, (5, 45), few + 2, 256 * 5
        ))  # fmt: skip
    if "swarm" in wanted:
        say("swarm 5x4 over Zenoh, per cycle", per_unit(trees, swarm, (5, 205), few + 2, 1))
    if "teams" in wanted:
        for n in TEAMS:
            say(f"distributed cycle, {n}x{n}", cycle(trees, n, few))
        say("distributed cycle, 1000x1000, steady state", steady(trees, 1000, few))
    if "reproduce" in wanted:
        say(
            "uavtrack reproduce --quick", case(trees, ["reproduce", "--quick", "--out", FRESH], few)
        )
        if not options.quick:
            say("uavtrack reproduce", case(trees, ["reproduce", "--out", FRESH], 1))
    if options.json is not None:
        print(f"wrote {options.json}", file=sys.stderr)
    if options.figure is not None and "teams" in wanted:
        figure(results, options.figure)
        print(f"wrote {options.figure}", file=sys.stderr)


def figure(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for tree, style in (("before", "o--"), ("this", "o-")):
        points = [
            (n, results["cases"][f"distributed cycle, {n}x{n}"][tree]["cpu_s"] * 1e3)
            for n in TEAMS
            if tree in results["cases"][f"distributed cycle, {n}x{n}"]
        ]
        if points:
            label = "this version" if tree == "this" else "before"
            ax.plot(*zip(*points, strict=True), style, label=label)
    ns = list(TEAMS)
    ax.plot(ns, [0.2 * n for n in ns], ":", color="grey", label="linear (0.2 ms per UAV)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("team: N UAVs x N targets (default density)")
    ax.set_ylabel("CPU time per distributed cycle [ms]")
    ax.set_title("One decision cycle as shipped (uavtrack run --team NxN),\nmetrics included")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
