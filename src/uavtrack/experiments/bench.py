"""Speed measurements (`uavtrack bench`), each case beside its reference in the same run.

Every case checks that ours and the reference compute the same thing, then times
them after a warm-up in blocks of consecutive calls, alternating ours and the
reference, and reports medians, so that a machine whose speed drifts affects both
alike. BLAS threads are
pinned to 1 (`uavtrack bench` sets the environment before numpy loads).
"""

from __future__ import annotations

import itertools
import json
import os
import platform
import statistics
import time
import timeit
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np

from .. import _process, estimation, planning, sensing, world
from ..config import Scenario
from ..errors import install_hint
from ..methods import get
from ..simulation import (
    Context,
    initial_stream,
    memory_estimate,
    run,
    sensor_noise,
    simulate,
    step,
    trial_seed,
)
from .reproduce import resized


def timed(*functions: Callable[[], Any], repeats: int, block: float = 0.05) -> list[float]:
    """Median seconds per call of each function.

    Each sample is a block of consecutive calls lasting about `block` seconds (sized
    from a warm-up call), as a function called every cycle runs; samples of the
    functions alternate, so a drift of the machine's speed affects all alike.
    """
    runs = []
    for fn in functions:
        start = time.perf_counter()
        fn()  # warm-up, and the size of a block
        runs.append((fn, max(1, round(block / max(time.perf_counter() - start, 1e-9))), []))
    for _ in range(repeats):
        for fn, number, times in runs:
            start = time.perf_counter()
            for _ in range(number):
                fn()
            times.append((time.perf_counter() - start) / number)
    return [statistics.median(times) for _, _, times in runs]


def case(
    name: str,
    ours_s: float,
    reference_s: float | None = None,
    per: float = 1.0,
    unit: str = "call",
    **extra: Any,
) -> dict[str, Any]:
    """One result: median seconds per `unit`, with the reference's and the speedup."""
    out: dict[str, Any] = {"name": name, "median_s": ours_s / per, "unit": unit}
    if reference_s is not None:
        out["reference_median_s"] = reference_s / per
        out["speedup"] = reference_s / ours_s
    out.update(extra)
    return out


def team(n_uavs: int, n_targets: int, **fields: Any) -> Scenario:
    """The default scenario with another team size, keeping its altitude spread."""
    return resized(Scenario(**fields), n_uavs, n_targets)


# ------------------------------------------------------------------ cases


def kalman_case(n_filters: int, repeats: int) -> dict[str, Any]:
    """One predict + update of n filters: ours batched against filterpy, one object each."""
    from filterpy.kalman import KalmanFilter

    rng = np.random.default_rng(0)
    A, Q = estimation.transition(0.5), estimation.process_noise(0.5, 0.16, 0.16)
    mean = rng.normal(0, 50, (n_filters, 4))
    L = rng.normal(size=(n_filters, 4, 4))
    cov = L @ np.swapaxes(L, -1, -2) + np.eye(4)
    z = mean[:, :2] + rng.normal(size=(n_filters, 2))
    M = rng.normal(size=(n_filters, 2, 2))
    R = M @ np.swapaxes(M, -1, -2) + 0.1 * np.eye(2)
    filters = []
    for _ in range(n_filters):
        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.F, kf.Q, kf.H = A, Q, np.eye(2, 4)
        filters.append(kf)

    def ours():
        return estimation.update(*estimation.predict(mean, cov, A, Q), z, R)

    def reference():
        out_x, out_P = np.empty_like(mean), np.empty_like(cov)
        for k, kf in enumerate(filters):
            kf.x, kf.P = mean[k].copy(), cov[k].copy()
            kf.predict()
            kf.update(z[k], R=R[k])
            out_x[k], out_P[k] = kf.x, kf.P
        return out_x, out_P

    (m1, P1), (m2, P2) = ours(), reference()
    equal = bool(
        np.allclose(m1, m2, rtol=1e-9, atol=1e-9) and np.allclose(P1, P2, rtol=1e-9, atol=1e-9)
    )
    if not equal:
        raise AssertionError("Kalman filter and filterpy disagree")
    t_ours, t_ref = timed(ours, reference, repeats=repeats)
    return case(
        f"kalman predict+update, {n_filters} filters",
        t_ours,
        t_ref,
        per=n_filters,
        unit="filter",
        reference="filterpy.kalman.KalmanFilter",
        equal_outputs=equal,
    )


def set_distance_cases(repeats: int) -> list[dict[str, Any]]:
    """OSPA and GOSPA: one 1000 x 1000 pair of point sets, and a step's per-UAV scoring
    of 25 trials of the default team (all n! matchings at once against one assignment
    solve per set)."""
    from .. import metrics

    rng = np.random.default_rng(0)
    X, Y = rng.uniform(0, 200, (2, 1000, 2))
    (t_big,) = timed(lambda: metrics.ospa_and_gospa(X, Y, 20.0, 1.0), repeats=repeats)
    truth = rng.uniform(0, 200, (25, 1, 4, 2))
    estimates = truth + rng.normal(0, 15, (25, 5, 4, 2))
    small = metrics.SMALL_SETS

    def by_solver():
        metrics.SMALL_SETS = 0
        try:
            return metrics.ospa_and_gospa(truth, estimates, 20.0, 1.0)
        finally:
            metrics.SMALL_SETS = small

    fast, slow = metrics.ospa_and_gospa(truth, estimates, 20.0, 1.0), by_solver()
    if not np.allclose(fast[0], slow[0], rtol=1e-12, atol=1e-12):
        raise AssertionError("the two ways of matching small sets disagree")
    t_ours, t_ref = timed(
        lambda: metrics.ospa_and_gospa(truth, estimates, 20.0, 1.0), by_solver, repeats=repeats
    )
    return [
        case("OSPA and GOSPA, one 1000 x 1000 pair of sets", t_big, unit="pair"),
        case(
            "OSPA and GOSPA per UAV, 25 trials x 5 UAVs x 4 targets (a step)",
            t_ours,
            t_ref,
            unit="step",
            reference="scipy linear_sum_assignment per set",
            equal_outputs=True,
        ),
    ]


def plan_by_sequence(uavs, mean, sensor, bank_angle, horizon, dt, g=9.81):
    """Reference: a plain loop over the |A|^h sequences, each flown step by step with eq. (1)
    (vectorised over UAVs and targets)."""
    actions = planning.action_set(bank_angle)
    best = np.full(mean.shape[:-1], -np.inf)
    first = np.zeros(mean.shape[:-1], dtype=np.int64)
    h = uavs[..., 2, None]
    for sequence in itertools.product(range(len(actions)), repeat=horizon):
        state, total = uavs, 0.0
        for t, a in enumerate(sequence):
            state = world.fly(state, np.full(uavs.shape[:-1], actions[a]), dt, g)
            target = mean[..., :2] + (t + 1) * dt * mean[..., 2:]
            d = np.sqrt(((target - state[..., None, :2]) ** 2).sum(-1) + h * h)
            total = total + sensing.fisher_det(d, sensing.edge_range(h, sensor), sensor)
        better = total > best
        best = np.where(better, total, best)
        first = np.where(better, sequence[0], first)
    return best, first


def planner_case(
    n_uavs: int, n_targets: int, repeats: int, horizon: int = 3
) -> list[dict[str, Any]]:
    """Planner per sequence-step against a per-sequence loop and the exhaustive search."""
    scenario = team(n_uavs, n_targets, steps=12)
    trace = simulate(scenario, "distributed", seed=1).trace
    assert trace is not None  # simulate keeps the trace by default
    uavs, mean = trace.uavs[-1], trace.mean[-1]
    args = (scenario.sensor, np.radians(scenario.uav.bank_angle_deg), horizon, scenario.dt)
    ours = planning.plan(uavs, mean, *args)
    loop_value, loop_first = plan_by_sequence(uavs, mean, *args)
    exhaustive = planning.plan_exhaustive(uavs, mean, *args)
    equal = bool(
        np.array_equal(ours.action, loop_first)
        and np.array_equal(ours.action, exhaustive.action)
        and np.allclose(ours.value, loop_value, rtol=1e-12)
    )
    if not equal:
        raise AssertionError("planner choices differ from exhaustive search")
    per = n_uavs * n_targets * 3**horizon * horizon
    t_ours, t_loop, t_exh = timed(
        lambda: planning.plan(uavs, mean, *args),
        lambda: plan_by_sequence(uavs, mean, *args),
        lambda: planning.plan_exhaustive(uavs, mean, *args),
        repeats=repeats,
    )
    size = f"{n_uavs} UAVs x {n_targets} targets, h = {horizon}"
    return [
        case(
            f"planner vs per-sequence loop, {size}",
            t_ours,
            t_loop,
            per=per,
            unit="sequence-step",
            reference="loop over the 3^h sequences",
            equal_choices=equal,
        ),
        case(
            f"planner vs vectorised exhaustive, {size}",
            t_ours,
            t_exh,
            per=per,
            unit="sequence-step",
            reference="planning.plan_exhaustive",
            equal_choices=equal,
        ),
    ]


def mid_run(scenario: Scenario, k: int = 20):
    """The state of one distributed trial after k steps, with the targets and sensor
    noise of step k: where a cycle is timed (the estimates have converged, the team has
    spread out)."""
    seeds = [trial_seed(0, 0)]
    ctx = Context.of(scenario, get("distributed"), seeds)
    state, targets, rngs = initial_stream(scenario, seeds)
    noises = sensor_noise(rngs, scenario.n_uavs, scenario.n_targets, k + 1)
    for j, noise in zip(range(k), noises, strict=False):
        state, _ = step(state, targets.at(j), noise, ctx)
    return state, targets.at(k), next(noises)


def cycle_cases(sizes, methods, repeats: int, scaled: bool = False) -> list[dict[str, Any]]:
    """One decision cycle (step) of each method, from a state in the middle of a run.

    scaled: each team in `Scenario.scaled` (the field grows with the team, the density
    stays); else in the default field (`team`), denser as the team grows."""
    out = []
    for n_uavs, n_targets in sizes:
        if scaled:
            scenario = Scenario(steps=24).scaled(n_uavs, n_targets)
        else:
            scenario = team(n_uavs, n_targets, steps=24)
        state, targets, noise = mid_run(scenario)
        for name in methods:
            ctx = Context.of(scenario, get(name), [trial_seed(0, 0)])
            cycle = partial(step, state, targets, noise, ctx)
            (t,) = timed(cycle, repeats=repeats)
            where = ", default density" if scaled else ""
            out.append(
                case(
                    f"decision cycle, {name}, {n_uavs} UAVs x {n_targets} targets{where}",
                    t,
                    unit="cycle",
                    method=name,
                    n_uavs=n_uavs,
                    n_targets=n_targets,
                    scaled=scaled,
                    real_time_factor=scenario.dt / t,
                )
            )
    return out


PEAK = """
import json, time
import uavtrack
scenario = uavtrack.Scenario(steps={steps}).scaled({n_uavs}, {n_targets})
start = time.perf_counter()
uavtrack.run(scenario, {method!r}, [0])
seconds = time.perf_counter() - start
status = open("/proc/self/status").read().split("VmHWM:")[1].split()
print(json.dumps({{"seconds": seconds, "peak_bytes": int(status[0]) * 1024}}))
"""


def run_case(n_uavs: int, n_targets: int, steps: int, method: str = "distributed"):
    """A whole run without a trace (metrics only) of a scaled team, in a process of its
    own: its time per step and its memory peak (the process's maximum resident set,
    VmHWM of Linux's /proc/self/status, Python and the libraries included; not
    getrusage's, which a child inherits from the process that started it). Without a
    trace nothing grows with the steps (`simulation.memory_estimate`), so a short run
    has a long one's peak."""
    import subprocess
    import sys

    code = PEAK.format(steps=steps, n_uavs=n_uavs, n_targets=n_targets, method=method)
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=3600, check=False
    )
    if done.returncode != 0:
        raise RuntimeError(f"the {n_uavs}x{n_targets} run failed: {done.stderr.strip()[-500:]}")
    measured = json.loads(done.stdout)
    scenario = Scenario(steps=steps).scaled(n_uavs, n_targets)
    estimate = sum(memory_estimate(scenario).values())
    return case(
        f"{steps}-step run, no trace, {method}, {n_uavs} UAVs x {n_targets} targets",
        measured["seconds"],
        per=steps,
        unit="step",
        method=method,
        n_uavs=n_uavs,
        n_targets=n_targets,
        steps=steps,
        peak_bytes=measured["peak_bytes"],
        estimate_bytes=estimate,
    )


def trial_case(repeats: int) -> dict[str, Any]:
    """A full default trial, one at a time."""
    scenario = Scenario()
    (t,) = timed(lambda: simulate(scenario, "distributed", seed=0, trace=False), repeats=repeats)
    return case(
        f"default trial, distributed, {scenario.steps} steps",
        t,
        unit="trial",
        steps_per_second=scenario.steps / t,
    )


def batch_case(trials: int, steps: int, repeats: int) -> dict[str, Any]:
    """A configuration of trials as one batch against the same trials one at a time."""
    scenario = Scenario(steps=steps)
    seeds = [trial_seed(0, t) for t in range(trials)]
    batched = run(scenario, "distributed", seeds).metrics
    alone = [run(scenario, "distributed", [s]).metrics for s in seeds]
    equal = bool(
        all(
            np.array_equal(batched["per_target"][t], alone[t]["per_target"][0])
            for t in range(trials)
        )
    )
    if not equal:
        raise AssertionError("batched and one-at-a-time trials disagree")
    t_batch, t_alone = timed(
        lambda: run(scenario, "distributed", seeds),
        lambda: [run(scenario, "distributed", [s]) for s in seeds],
        repeats=repeats,
    )
    return case(
        f"{trials} trials x {steps} steps, batched vs one at a time",
        t_batch,
        t_alone,
        unit="configuration",
        equal_results=equal,
    )


# ------------------------------------------------------------------ the whole bench

SCALING = (10, 30, 100, 300, 1000)
"""Team sizes (N UAVs x N targets, `Scenario.scaled`) of the scaling figure."""


def machine() -> dict[str, Any]:
    import scipy

    try:
        blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]["name"]
    except Exception:  # numpy < 2 or a build without the record
        blas = "unknown"
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count()
    from .. import __version__

    tiny = np.ones(20)
    call = min(timeit.repeat(lambda: tiny + tiny, number=20000, repeat=5)) / 20000
    return {
        "numpy_call_s": call,  # one small numpy call: scales every absolute time here
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cores": cores,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "blas": blas,
        "uavtrack": __version__,
        "threads": {name: os.environ.get(name) for name in _process.THREAD_VARIABLES[:3]},
        "blas_threads": _process.describe(),
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
    }


def bench(quick: bool = False, progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run every case; returns {'machine': ..., 'cases': [...]}."""
    say = progress or (lambda _: None)
    repeats = 3 if quick else 9
    cases: list[dict[str, Any]] = []
    try:
        import filterpy  # noqa: F401

        say("Kalman filter against filterpy")
        cases.append(kalman_case(100, repeats))
    except ImportError:
        cases.append(
            {
                "name": "kalman predict+update, 100 filters",
                "skipped": f"filterpy is not installed ({install_hint('bench')})",
            }
        )
    say("OSPA and GOSPA")
    cases.extend(set_distance_cases(repeats))
    say("planner")
    for size in ((5, 4), (20, 20)) if quick else ((5, 4), (20, 20), (100, 100)):
        cases.extend(planner_case(*size, repeats=repeats))
    say("decision cycles")
    sizes = (
        ((5, 4), (20, 20), (100, 100))
        if quick
        else ((5, 4), (10, 10), (20, 20), (50, 50), (100, 100))
    )
    methods = ("distributed", "centralized", "greedy")
    cases.extend(cycle_cases(sizes, methods, repeats))
    say("large teams at the default density")
    teams = SCALING if not quick else tuple(n for n in SCALING if n <= 300)
    cases.extend(cycle_cases([(n, n) for n in teams], methods, 5 if quick else 7, scaled=True))
    for n in (300,) if quick else (300, 1000):
        say(f"a {n} x {n} run and its memory peak")
        cases.append(run_case(n, n, steps=40))
    say("a default trial")
    cases.append(trial_case(3 if quick else 5))
    say("batched trials")
    cases.append(batch_case(10, 100, 2) if quick else batch_case(50, 500, 3))
    return {"machine": machine(), "quick": quick, "cases": cases}
