"""The methods under faults: what each fault does to each method's decisions."""

import numpy as np
import pytest

import uavtrack
from uavtrack import fusion, network
from uavtrack.testing import assert_same_trace, differences


@pytest.fixture(scope="module")
def scenario():
    return uavtrack.Scenario(steps=80)


def test_total_loss_makes_distributed_decide_exactly_as_greedy(scenario):
    deaf = scenario.with_overrides({"faults.loss": 1.0})
    d = uavtrack.simulate(deaf, "distributed", seed=3)
    g = uavtrack.simulate(deaf, "greedy", seed=3)
    assert_same_trace(d.trace, g.trace, counters=False)
    assert (d.trace.delivered == 0).all() and (d.trace.messages > 0).any()
    assert (d.trace.rounds == 0).all()


def test_a_failed_uav_never_observes_or_sends_and_the_others_go_on(scenario):
    s = scenario.with_overrides({"faults.failures": [[2, 30]], "comm_range": 80.0})
    r = uavtrack.simulate(s, "distributed", seed=1)
    tr = r.trace
    assert tr.alive[:30, 2].all() and not tr.alive[30:, 2].any()
    assert tr.alive[:, [0, 1, 3, 4]].all()
    assert not tr.observed[30:, 2].any() and (tr.assignment[30:, 2] == -1).all()
    assert (tr.uavs[31:, 2] == tr.uavs[30, 2]).all()  # down where it failed
    # nothing travels through it: the others' rounds are the eccentricities without it
    for k in range(30, s.steps):
        adj = network.adjacency(tr.uavs[k], s.comm_range)
        adj[2, :] = adj[:, 2] = False
        depth, _ = fusion.eccentricity(adj)
        assert np.array_equal(tr.rounds[k, [0, 1, 3, 4]], depth[[0, 1, 3, 4]]), k
    assert tr.observed[30:, [0, 1, 3, 4]].any()
    assert r.failed == 1.0
    # every other method drops it the same way
    for method in ("centralized", "greedy"):
        other = uavtrack.simulate(s, method, seed=1).trace
        assert not other.observed[30:, 2].any() and (other.assignment[30:, 2] == -1).all()


@pytest.mark.parametrize(
    "faults",
    [{}, {"faults.round_budget": 2}, {"faults.failure_rate": 0.005}, {"faults.position_std": 3.0}],
)
def test_robust_options_change_no_decision_without_delay_and_loss(scenario, faults):
    plain = scenario.with_overrides(faults)
    robust = plain.with_overrides({"robust.extra_rounds": 2, "robust.stale": True})
    for method in ("distributed", "centralized", "greedy"):
        a = uavtrack.simulate(plain, method, seed=4).trace
        b = uavtrack.simulate(robust, method, seed=4).trace
        assert_same_trace(a, b, counters=False)


def test_extra_rounds_help_under_loss_and_cost_messages(scenario):
    lossy = scenario.with_overrides({"faults.loss": 0.4})
    a = uavtrack.simulate(lossy, "distributed", seed=2, trace=True)
    b = uavtrack.simulate(lossy.with_overrides({"robust.extra_rounds": 3}), "distributed", seed=2)
    assert b.trace.rounds.mean() > a.trace.rounds.mean()
    assert b.messages > a.messages
    assert differences(a.trace, b.trace, counters=False)  # the estimates differ


def test_delay_makes_information_stale_and_stale_option_predicts_it(scenario):
    late = scenario.with_overrides({"faults.delay": 2})
    a = uavtrack.simulate(late, "distributed", seed=5)
    b = uavtrack.simulate(late.with_overrides({"robust.stale": True}), "distributed", seed=5)
    on_time = uavtrack.simulate(scenario, "distributed", seed=5)
    assert differences(a.trace, on_time.trace, counters=False)
    assert differences(a.trace, b.trace, counters=False)
    # the first two cycles hear nobody: every UAV decides alone, as greedy does
    g = uavtrack.simulate(late, "greedy", seed=5)
    assert np.array_equal(a.trace.assignment[:2], g.trace.assignment[:2])


def test_centralized_lost_downloads_keep_the_previous_target(scenario):
    lossy = scenario.with_overrides({"faults.loss": 0.5})
    tr = uavtrack.simulate(lossy, "centralized", seed=6).trace
    changed = (tr.assignment[1:] != tr.assignment[:-1]).mean()
    perfect = uavtrack.simulate(scenario, "centralized", seed=6).trace
    assert changed < (perfect.assignment[1:] != perfect.assignment[:-1]).mean() + 0.05
    assert (tr.delivered < tr.messages).any()
    total = uavtrack.simulate(scenario.with_overrides({"faults.loss": 1.0}), "centralized", seed=6)
    # no download ever arrives: every UAV keeps the target it chose alone at the start
    assert (total.trace.assignment == total.trace.assignment[0]).all()


def test_conflicts_count_doubled_targets_while_one_is_free():
    from uavtrack.simulation import conflicts

    target = np.array([[0, 0, 1, 1, 2], [0, 1, 2, 3, 0], [0, 0, 0, 1, -1]])
    alive = np.array([[True] * 5, [True] * 5, [True] * 4 + [False]])
    # trial 0: targets 0 and 1 doubled while 3 is free; trial 1: every target covered;
    # trial 2: target 0 tripled while 2 and 3 are free
    assert conflicts(target, alive, 4).tolist() == [2, 0, 1]


def test_the_registry_serves_plugins_and_registered_methods(monkeypatch):
    from uavtrack import methods
    from uavtrack.methods import registry

    class Sticky(methods.Distributed):
        name = "sticky-test"

        @staticmethod
        def solve(bids):
            return np.zeros(bids.shape[0], dtype=np.int64)  # everyone on target 0

    assert registry.names()[:3] == ["distributed", "centralized", "greedy"]
    with pytest.raises(ValueError, match="unknown method 'sticky-test'; choose one of"):
        methods.get("sticky-test")
    monkeypatch.setattr(registry, "_REGISTERED", dict(registry._REGISTERED))
    methods.register(Sticky())
    assert "sticky-test" in registry.names()
    r = uavtrack.simulate(uavtrack.Scenario(steps=20, comm_range=1e5), "sticky-test", seed=0)
    assert (r.trace.assignment[1:] == 0).all()
    # a plugin names its class by entry point; it loads on first use
    monkeypatch.setattr(registry, "_plugins", lambda: {"greedy-again": "uavtrack.methods:Greedy"})
    assert isinstance(methods.get("greedy-again"), methods.Greedy)
    with pytest.raises(TypeError, match="must be a uavtrack.methods.Method"):
        methods.register(object())


def test_a_rule_may_be_an_ordinary_method_with_state():
    from uavtrack import methods

    class FirstTarget(methods.Distributed):
        name = "first-target-test"

        def __init__(self, target):
            self.target = target

        def solve(self, bids):  # an instance method, using the instance's state
            return np.full(bids.shape[0], self.target)

    r = uavtrack.simulate(uavtrack.Scenario(steps=10, comm_range=1e5), FirstTarget(1), seed=0)
    assert (r.trace.assignment == 1).all()


def test_a_download_its_measurement_contradicts_is_not_taken():
    # robust.gate: UAV 0 measured target 0 30 m from the central node's estimate (keeps
    # its own), target 1 near it (takes it), and target 2 long ago (takes it)
    from uavtrack.methods import take_download
    from uavtrack.robust import gate

    scenario = uavtrack.Scenario(steps=40).with_overrides({"robust.gate": 0.9999})
    setting = uavtrack.simulation.Context.of(
        scenario, uavtrack.methods.get("distributed"), [np.random.SeedSequence(0)]
    ).setting
    own_mean = np.zeros((1, 1, 3, 4))
    own_cov = np.broadcast_to(np.eye(4), (1, 1, 3, 4, 4)).copy()
    got = fusion.Estimates(
        gamma=np.full((1, 1, 3), 0.25),
        mean=np.zeros((1, 1, 3, 4)) + [[[[30.0, 0, 0, 0], [1.0, 0, 0, 0], [50.0, 0, 0, 0]]]],
        cov=own_cov.copy(),
        stamp=np.zeros((1, 1, 3), dtype=np.int64),
    )
    z = np.array([[0.0, 0.0], [1.5, 0.0]])  # targets 0 and 1, in nonzero order
    observed = np.array([[[True, True, False]]])
    recent = gate.recent(np.array([[[0, 0, 0]]]), 20, 8, (1, 1, 3))
    measured = gate.Measured.of(observed, z, np.broadcast_to(np.eye(2), (2, 2, 2)), recent)
    arrived = np.ones((1, 1), dtype=bool)
    mean, _ = take_download(own_mean, own_cov, got, arrived, setting, 20, measured)
    assert mean[0, 0, :, 0].tolist() == [0.0, 1.0, 50.0]
    unchecked = take_download(own_mean, own_cov, got, arrived, setting, 20)[0]
    assert unchecked[0, 0, :, 0].tolist() == [30.0, 1.0, 50.0]
    recent = gate.recent(np.array([[[0, 0, 19]]]), 20, 8, (1, 1, 3))  # target 2 just seen
    measured = gate.Measured.of(observed, z, np.broadcast_to(np.eye(2), (2, 2, 2)), recent)
    mean, _ = take_download(own_mean, own_cov, got, arrived, setting, 20, measured)
    assert mean[0, 0, 2, 0] == 0.0  # 50 m from its own estimate of 1 m std: kept its own


@pytest.mark.parametrize("association", ["known", "jpda"])
def test_a_plugin_of_its_own_assignment_rule_runs_with_tracks(association):
    """`examples/nearest_track.py`: each UAV follows its nearest estimate. With tracks its
    bids come by label column and its estimates by track slot; `Inputs.columns` maps one
    to the other, and every UAV follows the label of its nearest confirmed track."""
    import runpy
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    method = runpy.run_path(str(root / "examples" / "nearest_track.py"))["NearestTrack"]()
    scenario = uavtrack.Scenario(steps=40)
    if association != "known":
        scenario = scenario.with_overrides(
            {"tracker.association": association, "sensor.detection_probability": 0.9,
             "sensor.clutter_rate": 2.0}
        )  # fmt: skip
    trace = uavtrack.simulate(scenario, method, seed=2).trace
    checked = 0
    for k, i in np.ndindex(trace.assignment.shape):
        held = trace.status[k, i] == 2 if association != "known" else np.ones(4, dtype=bool)
        if not held.any():
            continue
        distance = np.hypot(*(trace.mean[k, i, :, :2] - trace.uavs[k, i, :2]).T)
        nearest = np.argmin(np.where(held, distance, np.inf))
        want = trace.label[k, i, nearest] if association != "known" else nearest
        assert trace.assignment[k, i] == want, (k, i)
        checked += 1
    assert checked >= 150


def test_the_agent_form_refuses_a_method_whose_assign_it_would_not_run():
    """Each UAV program runs a method's neighbourhood rule (`solve`); a method with an
    `assign` of its own would silently run as the paper's auction there: refused."""
    import runpy
    from pathlib import Path

    from uavtrack.agents import run_swarm
    from uavtrack.agents.agent import check_method
    from uavtrack.errors import UsageError

    root = Path(__file__).resolve().parents[1] / "examples"
    nearest = runpy.run_path(str(root / "nearest_track.py"))["NearestTrack"]()
    sequential = runpy.run_path(str(root / "custom_method.py"))["SequentialAuction"]()
    for method in ("distributed", "greedy", "centralized", sequential):
        check_method(uavtrack.methods.get(method))  # built on the paper's: runs
    with pytest.raises(UsageError, match="replaces assign, which the agent form does not run"):
        run_swarm(uavtrack.Scenario(steps=2), nearest)
