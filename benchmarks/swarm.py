"""The agent form over Zenoh: a cycle's wall and CPU time, traffic per UAV, and what
signing costs, by team size.

    python benchmarks/swarm.py [--steps N] [--sizes 5 20 50] [--json FILE]

Each size is the default scenario grown to that team at the same density (`--team NxM`,
`Scenario.scaled`: M = 4N/5 targets), one trial, one OS process per UAV on this machine,
with messages signed (the default) and, for 5 and 20 UAVs, unsigned (`--no-sign`), to
measure what authentication costs; then 20 UAVs paced at dt (`--realtime`). Wall times
depend on the machine and its load: the median over the cycles after the first five
(the programs' warm-up) is the figure to read; CPU time is that of every process of the
swarm (the world and its programs, user + system) over the same cycles, per cycle. BLAS
is pinned to one thread in every process (the programs inherit the environment).

It also times the gate alone: sealing and opening one consensus message of 16 targets
(keyed BLAKE2b over pairwise keys), against verifying an Ed25519 signature of the same
message, the public-key design this replaces on the radio path.
"""

import argparse
import json
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import uavtrack  # noqa: E402
from uavtrack.agents import run_swarm  # noqa: E402

WARM = 5
"""Cycles left out of the figures: the programs' warm-up."""
TICK = os.sysconf("SC_CLK_TCK")


def swarm_cpu() -> float:
    """CPU time so far of this process and its running children (user + system) [s]."""
    total = 0.0
    me = os.getpid()
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as handle:
                fields = handle.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(entry) == me or int(fields[1]) == me:
            total += (int(fields[11]) + int(fields[12])) / TICK
    return total


def measure(n: int, steps: int, sign: bool = True, realtime: bool = False) -> dict:
    scenario = uavtrack.Scenario().scaled(n, max(1, round(n * 4 / 5)))
    scenario = scenario.with_overrides({"steps": steps})
    marks = {}

    def progress(k: int) -> None:  # CPU of the steady cycles, read at their ends
        if k in (WARM, steps):
            marks[k] = swarm_cpu()

    start = time.perf_counter()
    out = run_swarm(
        scenario,
        "distributed",
        seed=0,
        transport="zenoh",
        realtime=realtime,
        trace=False,
        sign=sign,
        progress=progress,
    )
    total = time.perf_counter() - start
    cpu = (marks[steps] - marks[WARM]) / (steps - WARM)
    cycles = np.asarray(out.traffic.cycle_seconds)
    steady = cycles[WARM:]
    per = n * steps
    return {
        "uavs": n,
        "targets": scenario.n_targets,
        "steps": steps,
        "signed": sign,
        "realtime": realtime,
        "cycle_ms_median": 1e3 * float(np.median(steady)),
        "cycle_ms_p90": 1e3 * float(np.percentile(steady, 90)),
        "cpu_ms_per_cycle": 1e3 * cpu,
        "published_per_uav_cycle": out.traffic.published / per,
        "received_per_uav_cycle": out.traffic.received / per,
        "bytes_per_uav_cycle": out.traffic.bytes / per,
        "protocol_messages_per_uav_cycle": out.result.messages / n,
        "overruns": len(out.traffic.overruns),
        "dropped": out.traffic.dropped,
        "total_s": total,
        "observation_rate": out.result.observation_rate,
    }


def gate_costs(repeat: int = 2000) -> dict:
    """Microseconds to seal and to open one consensus message of 16 targets, and to
    verify an Ed25519 signature of it."""
    from cryptography.hazmat.primitives.asymmetric import ed25519

    from uavtrack.agents.agent import part
    from uavtrack.agents.messages import VERSION, Radio, encode
    from uavtrack.agents.security import Gate, Keyring

    m = 16
    state = {
        "gamma": np.ones(m),
        "mean": np.ones((m, 4)),
        "cov": np.ones((m, 4, 4)),
        "stamp": np.zeros(m, dtype=np.int64),
        "origin": np.zeros(m, dtype=np.int64),
    }
    body = encode(
        Radio(
            version=VERSION, run="0123456789ab", k=0, sender=0, parts=[part("consensus", 1, state)]
        )
    )
    ring = Keyring("0123456789ab", 2)
    sender, receiver = (
        Gate(run="0123456789ab", me=0, programs=2, credential=ring.credential(0)),
        None,
    )
    receiver = Gate(run="0123456789ab", me=1, programs=2, credential=ring.credential(1))
    for gate in (sender, receiver):
        gate.learn(ring.public())
    start = time.perf_counter()
    sealed = [sender.seal(1, body) for _ in range(repeat)]
    seal = (time.perf_counter() - start) / repeat
    start = time.perf_counter()
    for payload in sealed:
        receiver.open(payload)
    open_ = (time.perf_counter() - start) / repeat
    key = ed25519.Ed25519PrivateKey.generate()
    signature, public = key.sign(body), key.public_key()
    start = time.perf_counter()
    for _ in range(repeat):
        public.verify(signature, body)
    verify = (time.perf_counter() - start) / repeat
    return {
        "message_bytes": len(body),
        "seal_us": 1e6 * seal,
        "open_us": 1e6 * open_,
        "ed25519_verify_us": 1e6 * verify,
    }


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--sizes", type=int, nargs="+", default=[5, 20, 50])
    parser.add_argument("--json")
    args = parser.parse_args()
    gate = gate_costs()
    rows = []
    for n in args.sizes:
        rows.append(measure(n, args.steps))
        if n <= 20:
            rows.append(measure(n, args.steps, sign=False))
    rows.append(measure(20, args.steps, realtime=True))
    print(
        f"gate, one consensus message of {gate['message_bytes']} bytes: seal "
        f"{gate['seal_us']:.1f} us, open {gate['open_us']:.1f} us "
        f"(Ed25519 verify alone {gate['ed25519_verify_us']:.1f} us)"
    )
    print(
        "UAVs  targets  signed  cycle median / p90 [ms]  CPU per cycle [ms]  "
        "published / received per UAV-cycle  protocol msgs per UAV-cycle  overruns"
    )
    for r in rows:
        print(
            f"{r['uavs']:4d} {r['targets']:8d}  {'yes' if r['signed'] else 'no ':>6}  "
            f"{r['cycle_ms_median']:8.1f} / {r['cycle_ms_p90']:7.1f}  {r['cpu_ms_per_cycle']:14.1f}"
            f"  {r['published_per_uav_cycle']:10.1f} / {r['received_per_uav_cycle']:5.1f}"
            f"  {r['protocol_messages_per_uav_cycle']:22.1f}  "
            f"{r['overruns'] if r['realtime'] else '-'}{' (realtime)' if r['realtime'] else ''}"
        )
    if args.json:
        with open(args.json, "w") as handle:
            json.dump({"gate": gate, "runs": rows}, handle, indent=1)
