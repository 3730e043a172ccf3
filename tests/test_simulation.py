import json
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

import uavtrack
from uavtrack import _process, estimation, network, sensing, simulation, world
from uavtrack.testing import assert_same_trace

from . import reference as reference_check

DECISIONS = ("assignment", "action", "bids", "observed", "uavs", "mean", "cov")


def same_decisions(a, b):
    for name in ("assignment", "action", "observed", "uavs"):
        assert np.array_equal(getattr(a.trace, name), getattr(b.trace, name)), name


def test_same_seed_same_result(short):
    a = uavtrack.simulate(short, "distributed", seed=3)
    b = uavtrack.simulate(short, "distributed", seed=3)
    for name in DECISIONS + ("targets", "rounds", "messages"):
        assert np.array_equal(getattr(a.trace, name), getattr(b.trace, name)), name
    assert a.observation_rate == b.observation_rate
    c = uavtrack.simulate(short, "distributed", seed=4)
    assert not np.array_equal(a.trace.targets, c.trace.targets)


def test_complete_graph_distributed_decides_as_centralized(short):
    wide = short.model_copy(update={"comm_range": 1e5})
    d = uavtrack.simulate(wide, "distributed", seed=1)
    c = uavtrack.simulate(wide, "centralized", seed=1)
    same_decisions(d, c)
    assert np.array_equal(d.trace.mean, c.trace.mean)
    assert d.observation_rate == c.observation_rate


def test_no_radio_distributed_decides_as_greedy(short):
    deaf = short.model_copy(update={"comm_range": 0.0})
    d = uavtrack.simulate(deaf, "distributed", seed=2)
    g = uavtrack.simulate(deaf, "greedy", seed=2)
    same_decisions(d, g)
    assert (d.trace.rounds == 0).all() and (d.trace.messages == 0).all()


def test_methods_differ_when_the_radio_is_limited():
    scenario = uavtrack.Scenario(steps=150)
    runs = {m: uavtrack.simulate(scenario, m, seed=0) for m in uavtrack.METHODS}
    assert not np.array_equal(
        runs["distributed"].trace.assignment, runs["centralized"].trace.assignment
    )
    assert not np.array_equal(runs["distributed"].trace.assignment, runs["greedy"].trace.assignment)


def test_common_random_numbers_across_methods(short):
    runs = [uavtrack.simulate(short, m, seed=5) for m in uavtrack.METHODS]
    for r in runs[1:]:
        assert np.array_equal(r.trace.targets, runs[0].trace.targets)
        assert np.array_equal(r.trace.uavs[0], runs[0].trace.uavs[0])


def test_batch_equals_one_trial_at_a_time(short):
    seeds = [uavtrack.trial_seed(7, t) for t in range(3)]
    batch = uavtrack.run(short, "distributed", seeds, trace=True)
    for t, seed in enumerate(seeds):
        alone = uavtrack.simulate(short, "distributed", seed=seed)
        assert np.array_equal(batch.traces[t].assignment, alone.trace.assignment)
        assert np.array_equal(batch.traces[t].action, alone.trace.action)
        assert np.allclose(batch.traces[t].mean, alone.trace.mean, rtol=1e-12, atol=1e-9)
        assert batch.metrics["observation_rate"][t] == alone.observation_rate


@pytest.mark.parametrize("method", uavtrack.METHODS)
def test_a_tracked_trial_is_the_same_alone_and_in_a_batch(method):
    """With tracks the auction's columns are the labels of the batch: a trial with
    fewer pads them. It must decide over its own labels (each UAV over those it knows),
    so a trial of a batch equals the same trial alone (the batch is wide enough for
    the array paths of the auction, `assignment.FEW`)."""
    scenario = uavtrack.Scenario().with_overrides(
        {
            "tracker.association": "gnn",
            "sensor.detection_probability": 0.9,
            "sensor.clutter_rate": 2.0,
            "faults.loss": 0.2,
            "steps": 20,
        }
    )
    seeds = list(range(8))
    batch = uavtrack.run(scenario, method, seeds, trace=True)
    for t in (3, 5):
        alone = uavtrack.run(scenario, method, [seeds[t]], trace=True)
        ours, theirs = batch.traces[t], alone.traces[0]
        assert np.array_equal(ours.assignment, theirs.assignment)
        assert np.array_equal(ours.conflicts, theirs.conflicts)
        assert np.array_equal(ours.label, theirs.label)
        assert np.allclose(ours.uavs, theirs.uavs, rtol=1e-12, atol=1e-9)


def test_trial_seed_is_spawned_child():
    children = np.random.SeedSequence(11).spawn(4)
    for t, child in enumerate(children):
        assert np.array_equal(uavtrack.trial_seed(11, t).generate_state(4), child.generate_state(4))


def test_metrics_agree_with_trace(short):
    r = uavtrack.simulate(short, "centralized", seed=0)
    tr = r.trace
    # observation: target inside at least one UAV's disk (recomputed from the truth)
    inside = sensing.in_view(tr.uavs[:, :, None, :], tr.targets[:, None, :, :], short.sensor)
    assert np.array_equal(inside, tr.observed)
    assert np.allclose(r.per_target, inside.any(axis=1).mean(axis=0))
    assert r.observation_rate == pytest.approx(r.per_target.mean())
    err = tr.mean[..., :2] - tr.targets[:, None, :, :2]
    assert r.rmse == pytest.approx(np.sqrt((err**2).sum(-1).mean()))
    assert r.rounds == pytest.approx(tr.rounds.mean())


def test_trace_shapes_and_rounds_follow_the_radio(short):
    r = uavtrack.simulate(short, "distributed", seed=0)
    T, Nu, Nt = short.steps, short.n_uavs, short.n_targets
    tr = r.trace
    assert tr.targets.shape == (T, Nt, 4) and tr.uavs.shape == (T, Nu, 5)
    assert tr.mean.shape == (T, Nu, Nt, 4) and tr.cov.shape == (T, Nu, Nt, 4, 4)
    assert tr.observed.shape == (T, Nu, Nt) and tr.assignment.shape == (T, Nu)
    adj = network.adjacency(tr.uavs, short.comm_range)
    isolated = ~adj.any(axis=-1)
    assert (tr.rounds[isolated] == 0).all() and (tr.rounds[~isolated] >= 1).all()
    # altitudes: every UAV at its own constant altitude
    assert np.allclose(tr.uavs[:, :, 2], short.altitudes())
    assert len(set(short.altitudes())) == Nu


def test_more_uavs_than_targets_everyone_tracks():
    scenario = uavtrack.Scenario(n_uavs=6, n_targets=2, steps=40, comm_range=1e5)
    r = uavtrack.simulate(scenario, "distributed", seed=0)
    counts = np.stack([np.bincount(a, minlength=2) for a in r.trace.assignment])
    assert (counts == 3).all()  # Remark 2: rounds of assignment cover every UAV


def test_batch_result_metrics_shapes():
    batch = uavtrack.run(uavtrack.Scenario(steps=20), "greedy", [0, 1])
    assert batch.metrics["per_target"].shape == (2, 4)
    assert batch.metrics["observation_rate"].shape == (2,)
    assert batch.traces is None


def test_unknown_method_and_bad_scenario():
    with pytest.raises(ValueError, match="unknown method 'best'"):
        uavtrack.simulate(uavtrack.Scenario(steps=5), "best")
    with pytest.raises(TypeError, match="Scenario"):
        uavtrack.simulate({"steps": 5})


def test_initial_conditions_layout():
    scenario = uavtrack.Scenario()
    uavs, trajectory, prior, P0 = world.initial_conditions(scenario, np.random.default_rng(0))
    assert np.all(np.abs(uavs[:, :2] - 100.0) <= 10.0)
    assert trajectory.shape == (500, 4, 4)
    assert np.allclose(np.diag(P0), [25.0, 25.0, 1.0, 1.0])
    assert (prior[:, 2:] == 0).all()


def test_numpy_integer_seed_is_kept_and_bad_seeds_refused(short):
    r = uavtrack.simulate(short.model_copy(update={"steps": 5}), seed=np.int64(3), trace=False)
    assert r.seed == 3 and type(r.seed) is int
    assert (
        r.observation_rate
        == uavtrack.simulate(short.model_copy(update={"steps": 5}), seed=3).observation_rate
    )
    with pytest.raises(ValueError, match="seed must be >= 0"):
        uavtrack.simulate(short, seed=-1)
    with pytest.raises(TypeError, match="seed must be an integer"):
        uavtrack.simulate(short, seed=1.5)


def test_run_without_seeds_says_so(short):
    with pytest.raises(ValueError, match="seeds is empty"):
        uavtrack.run(short, "distributed", [])


def test_decision_time_is_measured_alone_never_in_a_batch():
    scenario = uavtrack.Scenario(steps=10)
    alone = uavtrack.run(scenario, "distributed", [0], trace=True)
    assert (alone.metrics["decision_time_ms"] > 0).all()
    assert (alone.traces[0].decision_time_ms > 0).all()
    assert (alone.traces[0].decision_wall_ms > 0).all()
    batch = uavtrack.run(scenario, "distributed", [0, 1], trace=True)
    assert np.isnan(batch.metrics["decision_time_ms"]).all()
    assert np.isnan(batch.traces[0].decision_time_ms).all()
    assert np.isnan(batch.traces[0].decision_wall_ms).all()


@pytest.mark.parametrize("method", ["distributed", "centralized", "greedy"])
def test_decision_time_is_cpu_time_with_wall_time_beside_it(method, monkeypatch):
    """A planner that waits (as on a machine busy with other work) costs wall time only."""
    plan = simulation._plan

    def waiting(*args, **kwargs):
        time.sleep(0.05)
        return plan(*args, **kwargs)

    monkeypatch.setattr(simulation, "_plan", waiting)
    trace = uavtrack.run(uavtrack.Scenario(steps=4), method, [0], trace=True).traces[0]
    share = 50.0 / (1 if method == "centralized" else 5)  # the wait, per deciding UAV [ms]
    assert (trace.decision_wall_ms >= share).all()
    assert (trace.decision_time_ms < share / 2).all()
    assert (trace.decision_time_ms > 0).all()


def test_best_estimate_metrics_agree_with_the_trace(short):
    r = uavtrack.simulate(short, "distributed", seed=1)
    tr = r.trace
    conf = 1.0 / np.trace(tr.cov, axis1=-2, axis2=-1)  # (T, Nu, Nt)
    best = np.argmax(conf, axis=1)
    steps, targets = np.meshgrid(np.arange(short.steps), np.arange(short.n_targets), indexing="ij")
    err = tr.mean[steps, best, targets, :2] - tr.targets[..., :2]
    assert r.rmse_best == pytest.approx(np.sqrt((err**2).sum(-1).mean()), rel=1e-12)
    q = estimation.nees(tr.mean[steps, best, targets], tr.cov[steps, best, targets], tr.targets)
    assert r.nees_best == pytest.approx(q.mean(), rel=1e-9)
    assert r.rmse_best <= r.rmse  # the most confident estimate is the one the team would use


def test_centralized_best_estimate_is_every_uavs_estimate(short):
    # the central node gives every UAV the team's most confident estimate
    r = uavtrack.simulate(short, "centralized", seed=2, trace=False)
    assert r.rmse_best == pytest.approx(r.rmse, rel=1e-12)
    assert r.nees_best == pytest.approx(r.nees, rel=1e-12)


def test_progress_is_called_once_per_step(short):
    calls = []
    uavtrack.simulate(short, trace=False, progress=calls.append)
    assert calls == list(range(1, short.steps + 1))


@pytest.mark.integration  # a large run's memory peak, measured
@pytest.mark.parametrize(
    "fields,batch,trace",
    [
        ({"n_uavs": 50, "n_targets": 50, "steps": 20, "uav": {"altitude_spacing": 0.4}}, 1, False),
        ({"n_uavs": 20, "n_targets": 20, "steps": 300, "uav": {"altitude_spacing": 1}}, 1, True),
        ({"n_uavs": 10, "n_targets": 4, "steps": 1000}, 4, False),
        ({"n_uavs": 30, "n_targets": 30, "steps": 5, "planner": {"horizon": 6}}, 1, False),
    ],
)
def test_memory_estimate_bounds_the_measured_peak(fields, batch, trace):
    scenario = uavtrack.Scenario(**fields)
    import scipy.optimize  # noqa: F401  (loaded on first use: its import is not the run's)

    tracemalloc.start()
    try:
        uavtrack.run(scenario, "distributed", list(range(batch)), trace=trace)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    estimate = sum(simulation.memory_estimate(scenario, batch, trace).values())
    assert 0.9 * peak <= estimate <= 4 * peak


def test_a_run_that_cannot_fit_is_refused_naming_the_field(monkeypatch):
    monkeypatch.setattr(_process, "available_memory", lambda: 50 * 2**20)
    big = uavtrack.Scenario(n_uavs=100, n_targets=100, uav={"altitude_spacing": 0.2})
    with pytest.raises(uavtrack.ScenarioError, match=r"needs about .* MiB .* reduce n_uavs"):
        uavtrack.simulate(big, trace=False)
    with pytest.raises(uavtrack.ScenarioError, match=r"reduce steps \(or run without a trace\)"):
        uavtrack.simulate(big)
    long = uavtrack.Scenario(steps=2_000_000)
    with pytest.raises(uavtrack.ScenarioError, match="reduce steps"):
        uavtrack.run(long, "distributed", [0, 1], trace=True)
    # without a trace the targets are drawn a block at a time: steps cost no memory,
    # except for manoeuvring targets, drawn whole
    estimate = simulation.memory_estimate
    assert estimate(long, 2) == estimate(uavtrack.Scenario(steps=2_000), 2)
    turning = long.with_overrides({"target.motion": "manoeuvring"})
    with pytest.raises(uavtrack.ScenarioError, match="reduce steps"):
        uavtrack.run(turning, "distributed", [0, 1])


def test_no_faults_reproduce_the_stored_results():
    # per-trial metrics and traces stored before the fault model existed: decisions and
    # counts exactly, floats to tests.reference.RTOL (another CPU rounds sums differently)
    reference = json.loads(
        (Path(__file__).parent / "data" / "reference_200_steps.json").read_text()
    )
    scenario = uavtrack.Scenario(steps=200)
    for method, stored in reference["trials"].items():
        seeds = [uavtrack.trial_seed(0, t) for t in range(8)]
        metrics = uavtrack.run(scenario, method, seeds).metrics
        for name, values in stored.items():
            computed, values = np.asarray(metrics[name]), np.asarray(values)
            if computed.dtype.kind in "iub":
                assert np.array_equal(computed, values), (method, name)
            else:
                np.testing.assert_allclose(
                    computed, values, rtol=reference_check.RTOL, atol=0, err_msg=f"{method} {name}"
                )
        trace = uavtrack.simulate(scenario, method, seed=0).trace
        for name, entry in reference["traces"][method].items():
            reference_check.check_field(f"{method} {name}", getattr(trace, name), entry)


def test_the_stored_comparison_sees_a_change_of_one_estimate():
    # the sketch of a float field moves when one value moves by far more than rounding
    reference = json.loads(
        (Path(__file__).parent / "data" / "reference_200_steps.json").read_text()
    )
    trace = uavtrack.simulate(uavtrack.Scenario(steps=200), "greedy", seed=0).trace
    mean = trace.mean.copy()
    reference_check.check_field("mean", mean, reference["traces"]["greedy"]["mean"])
    mean[150, 3, 2, 1] *= 1 + 1e-9
    with pytest.raises(AssertionError, match="mean: differs .* at step 150"):
        reference_check.check_field("mean", mean, reference["traces"]["greedy"]["mean"])
    action = trace.action.copy()
    action[17, 0] = -action[17, 0] if action[17, 0] else 0.1
    with pytest.raises(AssertionError, match="not the stored decisions"):
        reference_check.check_field("action", action, reference["traces"]["greedy"]["action"])


@pytest.mark.parametrize("method", ["distributed", "centralized", "greedy"])
def test_the_general_path_with_harmless_faults_equals_the_fault_free_path(short, method):
    # a round budget that never binds switches every stage to its fault-aware form
    general = short.with_overrides({"faults.round_budget": 1000})
    assert_same_trace(
        uavtrack.simulate(short, method, seed=2).trace,
        uavtrack.simulate(general, method, seed=2).trace,
        atol=0,
    )


def test_faults_do_not_change_targets_or_sensor_noise(short):
    lossy = short.with_overrides({"faults.loss": 0.3, "faults.position_std": 2.0})
    a = uavtrack.simulate(short, "greedy", seed=9).trace
    b = uavtrack.simulate(lossy, "greedy", seed=9).trace
    assert np.array_equal(a.targets, b.targets) and np.array_equal(a.uavs[0], b.uavs[0])


def test_in_view_std_is_the_spread_over_steps_of_the_fraction_in_view():
    result = uavtrack.simulate(uavtrack.Scenario(steps=120), "greedy", seed=2)
    fraction = result.trace.observed.any(axis=1).mean(axis=1)  # (T,)
    assert result.observation_rate == pytest.approx(fraction.mean())
    assert result.in_view_std == pytest.approx(fraction.std())
    assert 0 < result.in_view_std <= 0.5


def test_ospa_and_gospa_metrics_are_those_of_the_trace():
    from uavtrack.metrics import gospa, ospa

    scenario = uavtrack.Scenario(steps=80, evaluation={"ospa_cutoff": 6.0, "ospa_order": 2.0})
    result = uavtrack.simulate(scenario, "greedy", seed=5)
    t = result.trace
    truth = t.targets[..., :2]  # (T, Nt, 2)
    per_uav = [ospa(truth[k], t.mean[k, i, :, :2], 6.0, 2) for k in range(80) for i in range(5)]
    best = np.argmax(1.0 / np.trace(t.cov, axis1=-2, axis2=-1), axis=1)  # (T, Nt)
    best_mean = np.take_along_axis(t.mean[..., :2], best[:, None, :, None], axis=1)[:, 0]
    g = [gospa(truth[k], best_mean[k], 6.0, 2) for k in range(80)]
    assert result.ospa == pytest.approx(np.mean(per_uav), rel=1e-12)
    assert result.ospa_best == pytest.approx(
        np.mean([ospa(truth[k], best_mean[k], 6.0, 2) for k in range(80)]), rel=1e-12
    )
    assert result.gospa_best == pytest.approx(np.mean([x.distance for x in g]), rel=1e-12)
    assert result.gospa_missed_best == pytest.approx(np.mean([x.missed / 18 for x in g]))
    assert result.gospa_missed_best > 0  # greedy loses targets: some estimates drift off


def test_set_up_inside_a_timed_stage_is_left_out():
    from uavtrack import timing

    mark = timing.start()
    with timing.set_up():  # 50 ms of CPU, as a module loaded on first use
        until = time.thread_time() + 0.05
        while time.thread_time() < until:
            pass
    cpu, wall = timing.since(mark)
    assert 0 <= cpu < 0.005 and 0 <= wall < 0.05


@pytest.mark.parametrize("method", ["distributed", "centralized", "greedy"])
def test_the_cpu_clock_is_read_per_stage_not_per_uav(method, monkeypatch):
    """The thread's CPU clock is a system call: a cycle reads it at the start and end of
    its two timed stages (planning and assignment), whatever the team's size (and twice
    more for a one-time set-up: a large problem's first load of scipy's solver)."""
    import uavtrack

    reads = []
    real = time.thread_time
    monkeypatch.setattr(time, "thread_time", lambda: reads.append(1) or real())
    per_step = {}
    for team in ("5x4", "20x16"):
        n, m = (int(x) for x in team.split("x"))
        scenario = uavtrack.Scenario(steps=6, n_uavs=n, n_targets=m)
        reads.clear()
        result = uavtrack.run(scenario, method, [0], trace=True)
        per_step[team] = (len(reads) - 2 * ("scipy.optimize" in sys.modules)) / scenario.steps
        times = result.traces[0].decision_time_ms
        assert np.isfinite(times).all() and (times >= 0).all() and times.sum() > 0
    assert per_step["5x4"] <= 4 and per_step["20x16"] <= 4, per_step


@pytest.mark.integration
def test_no_decision_time_holds_a_module_loaded_on_first_use():
    code = (
        "import sys, uavtrack\n"
        "from uavtrack.numerics import lsap\n"
        "lsap.SMALL = 0  # every problem to scipy's solver, loaded on first use\n"
        "assert 'scipy.optimize' not in sys.modules\n"
        "t = uavtrack.run(uavtrack.Scenario(steps=5), 'distributed', [0], trace=True).traces[0]\n"
        "assert 'scipy.optimize' in sys.modules  # loaded during the run\n"
        "print(t.decision_time_ms.max())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert float(out.stdout) < 100.0  # loading scipy.optimize alone takes about 500 ms of CPU


@pytest.mark.integration
@pytest.mark.parametrize("association", ["known", "jpda", "gnn"])
def test_a_single_trial_loads_no_scipy(association):
    """scipy serves large problems only: a default trial (known association or tracks)
    solves its assignments and gates in plain Python (`uavtrack.numerics`)."""
    code = (
        "import sys, uavtrack\n"
        "s = uavtrack.Scenario.model_validate({'steps': 30, 'tracker': {'association':"
        f" {association!r}}}, 'sensor': {{'detection_probability': 0.9, 'clutter_rate': 2.0}}}})\n"
        "for method in ('distributed', 'centralized', 'greedy'):\n"
        "    uavtrack.run(s, method, [0], trace=True)\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.integration
def test_set_up_in_one_thread_is_not_left_out_of_another():
    """In the in-memory swarm every UAV is a thread: each loads the solver on first use."""
    code = (
        "import threading\n"
        "from uavtrack import assignment, timing\n"
        "out = []\n"
        "def uav():\n"
        "    mark = timing.start()\n"
        "    assignment.load_solver(timing)\n"
        "    out.append(timing.since(mark))\n"
        "threads = [threading.Thread(target=uav) for _ in range(3)]\n"
        "for t in threads: t.start()\n"
        "for t in threads: t.join()\n"
        "print(min(float(x.min()) for x in out))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert float(out.stdout) >= 0.0


@pytest.mark.integration
@pytest.mark.parametrize("signum", ["SIGINT", "SIGTERM"])
def test_set_up_is_not_interrupted_half_way_and_the_interrupt_still_comes(signum):
    """A Ctrl-C during `import scipy.optimize` could end it with ImportError: initialization
    failed (seen 1 in 40) instead of the interrupt the command line stops on."""
    code = (
        "import os, signal\n"
        "from uavtrack import timing\n"
        "def stop(number, frame):\n"
        "    raise KeyboardInterrupt\n"
        "signal.signal(signal.SIGTERM, stop)  # as the command line does\n"
        "done = False\n"
        "try:\n"
        "    with timing.set_up():\n"
        f"        os.kill(os.getpid(), signal.{signum})\n"
        "        for _ in range(200_000):  # bytecode runs: an interrupt would land here\n"
        "            pass\n"
        "        done = True\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted after the set-up:', done)\n"
        "print(signal.getsignal(signal.SIGTERM) is stop, signal.getsignal(signal.SIGINT)"
        " is signal.default_int_handler)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.splitlines() == ["interrupted after the set-up: True", "True True"]


@pytest.mark.parametrize(
    "overrides",
    [
        {},
        {"faults": {"loss": 0.2, "failures": [[1, 10]]}},
        {"faults": {"delay": 1}},
        {"tracker": {"model": "imm"}},
        {"robust": {"gate": 0.99}},
    ],
)
@pytest.mark.parametrize("method", ["distributed", "centralized", "greedy"])
def test_a_runs_reused_arrays_change_nothing(method, overrides, monkeypatch):
    """`run` owns its states: it updates them in place and writes its full-size results
    into arrays it reuses (`numerics.buffers`, every size pooled here); every recorded
    number equals that of a run that allocates each anew."""
    from uavtrack.numerics import buffers

    monkeypatch.setattr(buffers, "SMALLEST", 0)
    scenario = uavtrack.Scenario.model_validate({"steps": 30, **overrides})
    pooled = uavtrack.run(scenario, method, [0, 1], trace=True)
    monkeypatch.setattr(simulation, "Buffers", lambda: None)
    fresh = uavtrack.run(scenario, method, [0, 1], trace=True)
    assert pooled.metrics.keys() == fresh.metrics.keys()
    for name, value in pooled.metrics.items():
        if not name.startswith("decision"):
            assert np.array_equal(value, fresh.metrics[name], equal_nan=True), name
    for a, b in zip(pooled.traces, fresh.traces, strict=True):
        for name, value in a.arrays().items():
            if not name.startswith("decision"):
                assert np.array_equal(value, b.arrays()[name], equal_nan=True), name


def test_buffers_hand_each_role_two_arrays_in_turn():
    from uavtrack.numerics.buffers import SMALLEST, Buffers, take

    pool = Buffers()
    shape = (SMALLEST // 8 + 1,)
    first, second = pool.take("a", shape), pool.take("a", shape)
    assert first is not second and not np.shares_memory(first, second)
    assert pool.take("a", shape) is first and pool.take("a", shape) is second
    other = pool.take("b", shape)  # another role never gets a's arrays
    assert other is not first and other is not second
    assert pool.take("a", (3,)) is not pool.take("a", (3,))  # small: always new
    assert take(None, "a", shape).shape == shape


def test_a_run_writes_its_predictions_and_fusion_into_two_arrays_in_turn(monkeypatch):
    """The memory a large run reuses (page faults are measured by
    benchmarks/shipped.py, not here): from its third step on, the predicted and the
    fused covariances of every step are written into one of the same two arrays."""
    from uavtrack import _process, estimation, fusion
    from uavtrack.numerics import buffers

    monkeypatch.setattr(buffers, "SMALLEST", 0)
    written: dict[str, list[int]] = {"predicted": [], "fused": []}
    predict, gather = estimation.predict, fusion.gather

    def spy_predict(*args, **kwargs):
        out = predict(*args, **kwargs)
        written["predicted"].append(out[1].__array_interface__["data"][0])
        return out

    def spy_gather(source, values, out=None):
        got = gather(source, values, out)
        if values.ndim == 5:
            written["fused"].append(got.__array_interface__["data"][0])
        return got

    monkeypatch.setattr(estimation, "predict", spy_predict)
    monkeypatch.setattr(fusion, "gather", spy_gather)
    uavtrack.run(uavtrack.Scenario(steps=12), "distributed", [0])
    for role, addresses in written.items():
        assert len(addresses) == 12, role
        first, second = addresses[0], addresses[1]
        assert first != second, role
        assert addresses == [first, second] * 6, role
    assert _process.keep_freed_memory() == sys.platform.startswith("linux")
    assert _process.keep_freed_memory() == _process.keep_freed_memory()  # set once
