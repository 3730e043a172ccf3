"""Speed as shipped: the commands a user types, timed as separate processes, this checkout
beside another version of the source.

    python benchmarks/shipped.py [--before SRC] [--json FILE] [--figure FILE] [--quick]

Each case runs ``uavtrack ...`` through the console entry point that the tree's
pyproject.toml names, in a fresh interpreter with that tree's ``src`` first on the path
and the environment as it is (no thread variables set here: each version sets BLAS
threads as it ships). Versions alternate, case by case, so a drift in the machine's
speed hits both alike. Times are medians: wall time (``time.perf_counter`` around the
process) and CPU time (user + system of the process and its children, from
``getrusage``). The cost of one decision cycle as shipped is the difference between a
run of S2 and one of S1 steps, divided by S2 - S1, so start-up and set-up cancel.

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


def once(src: Path, args: list[str]) -> tuple[float, float]:
    """(wall, CPU) seconds of one ``uavtrack args`` with `src` first on the path."""
    env = dict(os.environ, PYTHONPATH=str(src))
    with tempfile.TemporaryDirectory() as fresh:
        args = [str(Path(fresh) / "out") if a == FRESH else a for a in args]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        done = subprocess.run(command(src, args), env=env, capture_output=True, text=True)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"uavtrack {' '.join(args)} failed in {src}:\n{done.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def case(trees: dict[str, Path], args: list[str], repeats: int) -> dict[str, dict]:
    """Median wall and CPU seconds of `args` per tree, the trees alternating."""
    seen: dict[str, list[tuple[float, float]]] = {name: [] for name in trees}
    for _ in range(repeats):
        for name, src in trees.items():
            seen[name].append(once(src, args))
    return {
        name: {
            "wall_s": statistics.median(w for w, _ in runs),
            "cpu_s": statistics.median(c for _, c in runs),
            "runs": len(runs),
        }
        for name, runs in seen.items()
    }


def cycle(trees: dict[str, Path], n: int, repeats: int) -> dict[str, dict]:
    """CPU and wall seconds of one distributed cycle of an n x n team, as shipped."""
    short, long = (
        (2, 6) if n >= 1000 else (5, 25) if n >= 300 else (10, 60) if n >= 100 else (20, 320)
    )
    team = ["run", "--team", f"{n}x{n}", "--json"]
    a = case(trees, team + ["--steps", str(short)], repeats)
    b = case(trees, team + ["--steps", str(long)], repeats)
    return {
        name: {
            "cpu_s": (b[name]["cpu_s"] - a[name]["cpu_s"]) / (long - short),
            "wall_s": (b[name]["wall_s"] - a[name]["wall_s"]) / (long - short),
            "steps": [short, long],
        }
        for name in trees
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=Path, help="src folder of the version to compare with")
    parser.add_argument("--json", type=Path, help="write the results here")
    parser.add_argument("--figure", type=Path, help="draw the cycle's cost against team size")
    parser.add_argument("--quick", action="store_true", help="fewer repeats, no full reproduce")
    options = parser.parse_args()
    trees = {"this": HERE}
    if options.before is not None:
        if not (options.before / "uavtrack").is_dir():
            parser.error(f"--before {options.before}: not a src folder holding uavtrack")
        trees = {"before": options.before.resolve(), "this": HERE}
    few = 1 if options.quick else 3
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
        shown = "; ".join(
            f"{tree} {v['cpu_s'] * 1e3:.0f} ms CPU, {v['wall_s'] * 1e3:.0f} ms wall"
            for tree, v in row.items()
        )
        print(f"{name}: {shown}", file=sys.stderr)

    say("uavtrack --version", case(trees, ["--version"], 5))
    say("uavtrack run --help", case(trees, ["run", "--help"], 5))
    say("uavtrack run (one default trial)", case(trees, ["run", "--json"], few + 2))
    for n in TEAMS:
        say(f"distributed cycle, {n}x{n}", cycle(trees, n, few))
    say("uavtrack reproduce --quick", case(trees, ["reproduce", "--quick", "--out", FRESH], few))
    if not options.quick:
        say("uavtrack reproduce", case(trees, ["reproduce", "--out", FRESH], 1))
    if options.json is not None:
        options.json.write_text(json.dumps(results, indent=1) + "\n")
        print(f"wrote {options.json}", file=sys.stderr)
    if options.figure is not None:
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
