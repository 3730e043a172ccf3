"""Where one trial's time goes: microseconds per step in each stage of the cycle.

    python benchmarks/profile_cycle.py [method] [trials-in-the-batch]

Runs the default scenario's 500 steps through the same stage functions as
`simulation.step`, timing each stage (timer overhead, ~0.1 us per stage, included).
"""

import sys
import time
from collections import defaultdict

import numpy as np

import uavtrack
from uavtrack import estimation, fusion, metrics, network, planning, simulation, world


def profile(method_name: str = "distributed", batch: int = 1) -> dict[str, float]:
    scenario = uavtrack.Scenario()
    method = uavtrack.methods.get(method_name)
    const = simulation.Constants.of(scenario)
    seeds = [uavtrack.trial_seed(0, t) for t in range(batch)]
    streams = [simulation.streams(s) for s in seeds]
    drawn = [simulation.initial_conditions(scenario, truth) for truth, _ in streams]
    nu, nt = scenario.n_uavs, scenario.n_targets
    trajectory = np.stack([d[1] for d in drawn])
    prior = np.stack([d[2] for d in drawn])[:, None]
    state = simulation.State(
        0,
        np.stack([d[0] for d in drawn]),
        np.broadcast_to(prior, (batch, nu, nt, 4)).copy(),
        np.broadcast_to(drawn[0][3], (batch, nu, nt, 4, 4)).copy(),
    )
    tally = metrics.Tally(batch, nu, nt)
    spent: dict[str, float] = defaultdict(float)
    clock = time.perf_counter
    block = simulation.NOISE_BLOCK
    for k in range(scenario.steps):
        t = clock()
        if k % block == 0:
            noise = np.stack([s.standard_normal((block, nu, nt, 2)) for _, s in streams], axis=1)
        targets = trajectory[:, k]
        spent["noise"] += -t + (t := clock())
        graph = network.adjacency(state.uavs, scenario.comm_range)
        spent["graph"] += -t + (t := clock())
        observed, z, R = simulation.sense(state.uavs, targets, noise[k % block], scenario)
        spent["sensing"] += -t + (t := clock())
        mean, cov = estimation.filter_step(
            state.mean, state.cov, observed, z, R, *((const.A, const.Q) if k else (None, None))
        )
        spent["filter"] += -t + (t := clock())
        fused = method.fuse(estimation.confidence(cov), graph)
        if fused.rounds.any():
            mean, cov = fusion.gather(fused.source, mean), fusion.gather(fused.source, cov)
        spent["fusion"] += -t + (t := clock())
        plan = planning.plan(
            state.uavs,
            mean,
            scenario.sensor,
            np.radians(scenario.uav.bank_angle_deg),
            scenario.planner.horizon,
            scenario.dt,
        )
        spent["planning"] += -t + (t := clock())
        target, seconds = method.assign(plan.value, graph)
        spent["auction"] += -t + (t := clock())
        action = np.take_along_axis(plan.action, target[..., None], axis=-1)[..., 0]
        state = simulation.State(
            k + 1, world.fly(state.uavs, const.actions[action], scenario.dt), mean, cov
        )
        spent["control"] += -t + (t := clock())
        tally.add(observed, targets, mean, cov, fused.rounds, fused.messages, seconds)
        spent["metrics"] += -t + (t := clock())
    tally.summary()
    return {stage: 1e6 * s / scenario.steps for stage, s in spent.items()}


if __name__ == "__main__":
    method = sys.argv[1] if len(sys.argv) > 1 else "distributed"
    batch = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    profile(method, batch)  # warm-up
    stages = profile(method, batch)
    total = sum(stages.values())
    print(f"{method}, {batch} trial(s) per batch: microseconds per step")
    for stage, us in sorted(stages.items(), key=lambda kv: -kv[1]):
        print(f"  {stage:10s} {us:8.1f}  {100 * us / total:4.0f}%")
    print(f"  {'total':10s} {total:8.1f}  -> {total * 500 / 1e6:.3f} s for 500 steps")
