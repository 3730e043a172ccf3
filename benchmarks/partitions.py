"""The swarm across hosts when the network splits it: what a cut link, a partition and a
flapping link cost the method, against the batch simulator with the fault model's
version of the same loss.

    sudo python benchmarks/partitions.py [--seeds 5] [--steps 200] [--out FILE]

prints the figures and writes no file; ``--out FILE`` keeps them as JSON too, and
``--out benchmarks/partitions-2core.json`` is how the published figures are made anew.
It needs root (Linux network namespaces), iproute2 and eclipse-zenoh, and runs from the
root of a checkout: the hosts are those of the tests (``tests/netns.py``), the world
(``uavtrack swarm --no-spawn``) on one network namespace and each UAV program
(``uavtrack agent``) on its own, joined through a router namespace.

The default scenario (5 UAVs, 4 targets) with `steps` steps, seeds 1 .. `seeds`, cycles
as fast as they go (not paced: a cut stops the world's clock anyway). Each cut begins
once the world has run 20 cycles; a cut drops what the cut host sends and is sent,
without a word; a flapping link goes down 0.5 s and up 0.5 s from then to the end.

* clean: nothing cut; the trace must equal the simulator's.
* cut 5 s: UAV 1's host cut from every other for 5 s.
* world from UAVs 1, 2: the world's host cut from those two UAVs' hosts for 5 s.
* flapping: UAV 2's link, every second.
* cut past the lease: UAV 1's host cut for the Zenoh session's lease + 5 s.

For each, the swarm's observation rate beside the simulator's without faults and with
the fault model's version of the loss: for a program the world lost at step k, the
failure of that UAV at k (``faults.failures``); otherwise the same share of radio
messages lost, independently (``faults.loss`` = lost / sent over the run, from the
trace's ``messages`` and ``delivered``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the tests' namespace harness

import numpy as np  # noqa: E402
from tests import netns  # noqa: E402

import uavtrack  # noqa: E402
from uavtrack import _files  # noqa: E402
from uavtrack.agents.transport import zenoh_config  # noqa: E402
from uavtrack.errors import UsageError  # noqa: E402
from uavtrack.testing import differences  # noqa: E402

UAVS = 5
AT = 20
"""Cycles the world runs before a cut."""
CUT = 5.0


def lease() -> float:
    """The Zenoh session's lease [s]."""
    return json.loads(zenoh_config([], []).get_json("transport/link/tx/lease")) / 1e3


def cut(hosts, seconds, between=None):
    def act(network, swarm):
        if not swarm.reached(AT):
            raise RuntimeError(f"the world stopped before cycle {AT}: {swarm.said[-300:]}")
        for h in hosts:
            network.cut(h, between)
        time.sleep(seconds)
        for h in hosts:
            network.restore(h, between)

    return act


def flapping(host):
    def act(network, swarm):
        if not swarm.reached(AT):
            raise RuntimeError(f"the world stopped before cycle {AT}: {swarm.said[-300:]}")
        with network.flapping(host, 0.5, 0.5):
            swarm.finished()

    return act


CASES = {  # hosts: the world's is 0, UAV I's is I + 1
    "clean": None,
    "cut 5 s": lambda: cut([2], CUT),
    "world from UAVs 1, 2": lambda: cut([2, 3], CUT, between=0),
    "flapping": lambda: flapping(3),
    "cut past the lease": lambda: cut([2], lease() + 5.0),
}


def one(case: str, seed: int, steps: int) -> dict:
    """One run of a case: the swarm's figures and the simulator's beside them."""
    args = ["--set", f"steps={steps}", "--seed", str(seed)]
    with tempfile.TemporaryDirectory() as folder, netns.Network(UAVS + 1) as network:
        swarm = netns.Swarm(network, UAVS, Path(folder), args)
        swarm.join()
        if CASES[case] is not None:
            CASES[case]()(network, swarm)
        code, out, programs = swarm.finish(programs=10.0)
        wall = swarm.times[-1] - swarm.times[0]  # the first cycle's end to the last's
        if code != 0:
            raise RuntimeError(f"{case}, seed {seed}: the world exited {code}: {swarm.said}")
        with np.load(swarm.trace) as arrays:
            trace = types.SimpleNamespace(**{name: arrays[name] for name in arrays.files})
    result = json.loads(out)
    scenario = uavtrack.Scenario(steps=steps)
    clean = uavtrack.simulate(scenario, "distributed", seed=seed)
    lost = {int(k): v for k, v in result["swarm"]["lost"].items()}
    sent, delivered = int(trace.messages.sum()), int(trace.delivered.sum())
    if lost:
        fault = {"faults.failures": sorted([uav, step] for uav, step in lost.items())}
    else:
        fault = {"faults.loss": (sent - delivered) / sent}
    faulty = uavtrack.simulate(scenario.with_overrides(fault), "distributed", seed=seed)
    return {
        "seed": seed,
        "swarm": result["observation_rate"],
        "simulator": clean.observation_rate,
        "simulator_same_loss": faulty.observation_rate,
        "fault": fault,
        "equal_to_simulator": not differences(trace, clean.trace),
        "messages_lost": sent - delivered,
        "messages_sent": sent,
        "lost": lost,
        "longest_cycle_s": result["swarm"]["cycle_ms_max"] / 1e3,
        "wall_s": wall,
        "programs_exit": [c for c, _ in programs],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description="What network partitions cost a swarm.")
    parser.add_argument("--seeds", type=int, default=5, help="runs per case (seeds 1..N)")
    parser.add_argument("--steps", type=int, default=200, help="steps per run")
    parser.add_argument(
        "--out",
        type=Path,
        help="also write the figures as JSON here (default: no file; the published "
        "figures are benchmarks/partitions-2core.json)",
    )
    args = parser.parse_args()
    if args.seeds < 1 or args.steps <= AT:
        parser.error(f"--seeds must be at least 1 and --steps more than {AT}")
    if args.out is not None:
        try:
            _files.check_output(args.out, "--out")
        except UsageError as exc:
            parser.error(str(exc))
    reason = netns.unavailable()
    if reason is not None:
        parser.exit(1, f"partitions.py: no network namespaces here: {reason}\n")
    rows = {}
    for case in CASES:
        runs = [one(case, seed, args.steps) for seed in range(1, args.seeds + 1)]
        mean = {
            key: float(np.mean([r[key] for r in runs]))
            for key in ("swarm", "simulator", "simulator_same_loss", "messages_lost", "wall_s")
        }
        mean["longest_cycle_s"] = float(np.median([r["longest_cycle_s"] for r in runs]))
        mean["programs_lost"] = sum(len(r["lost"]) for r in runs)
        mean["equal_to_simulator"] = sum(r["equal_to_simulator"] for r in runs)
        mean["rate_as_same_loss"] = sum(  # rates are multiples of 1 / (steps x targets)
            abs(r["swarm"] - r["simulator_same_loss"]) < 1e-12 for r in runs
        )
        rows[case] = {"mean": mean, "runs": runs}
        print(
            f"{case:22s} observation rate {mean['swarm']:.4f} (simulator {mean['simulator']:.4f}"
            f", same loss {mean['simulator_same_loss']:.4f}); messages lost "
            f"{mean['messages_lost']:.1f}; programs lost {mean['programs_lost']}; longest "
            f"cycle {mean['longest_cycle_s']:.1f} s; cycles 2 to the last "
            f"{mean['wall_s']:.1f} s; equal to the simulator {mean['equal_to_simulator']} of "
            f"{len(runs)}, rate as with the same loss {mean['rate_as_same_loss']} of {len(runs)}",
            flush=True,
        )
    out = {
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "uavtrack": uavtrack.__version__,
        },
        "scenario": f"the default scenario (5 UAVs, 4 targets), {args.steps} steps",
        "seeds": args.seeds,
        "cut_after_cycles": AT,
        "lease_s": lease(),
        "cases": rows,
        "note": "means over the seeds (longest cycle: the median); wall_s: from the end of "
        "the world's first cycle to the end of its last; same loss: the "
        "simulator with faults.failures for a lost program, else faults.loss = the share "
        "of radio messages the swarm lost",
    }
    if args.out is not None:
        _files.write_text(args.out, json.dumps(out, indent=2) + "\n")
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
