"""The agent form with unknown association: each UAV program gets its scan unlabelled,
holds track slots, agrees on them with its neighbours by messages that carry labels,
status, stamps and tombstones, and bids by label (or, centralized, uploads its scan to
one multi-sensor tracker and downloads its tracks); the swarm's trace equals the batch
simulator's, tracks, labels and scans included."""

from __future__ import annotations

import pytest

import uavtrack
from uavtrack.agents import run_swarm
from uavtrack.testing import assert_same_trace

pytest.importorskip("msgspec")

pytestmark = pytest.mark.integration  # the agent form against real deadlines

SENSOR = {"sensor.detection_probability": 0.9, "sensor.clutter_rate": 2.0}
"""The sensor of the goal: P_D 0.9, two false measurements a scan."""


def tracked(association: str = "jpda", steps: int = 40, **more) -> uavtrack.Scenario:
    changes = {"tracker.association": association, "steps": steps, **SENSOR, **more}
    return uavtrack.Scenario().with_overrides(changes)


@pytest.mark.parametrize(
    "method,faults",
    [
        ("distributed", {}),
        ("distributed", {"faults.loss": 0.2}),
        ("greedy", {"faults.loss": 0.2}),
        ("distributed", {"faults.loss": 0.2, "faults.failures": [[1, 12]]}),
        ("centralized", {}),
        ("centralized", {"faults.loss": 0.2, "faults.failures": [[1, 12]]}),
    ],
    ids=["no-faults", "loss", "greedy-loss", "loss-failure", "central", "central-faults"],
)
def test_memory_swarm_with_tracks_equals_the_simulator(method, faults):
    scenario = tracked(**faults)
    swarm = run_swarm(scenario, method, seed=3, transport="memory")
    reference = uavtrack.simulate(scenario, method, seed=3)
    trace = reference.trace
    # the run has what makes tracks hard: clutter, misses, births and confirmations
    assert (trace.scan_origin == -1).any() and (trace.status == 1).any()
    assert (trace.label >= scenario.n_targets).any()  # tracks born in flight
    assert_same_trace(swarm.result.trace, trace)
    assert swarm.result.observation_rate == reference.observation_rate
    assert swarm.result.gospa == pytest.approx(reference.gospa, rel=1e-9)
    assert swarm.result.switches == reference.switches
    assert swarm.traffic.published > 0 and swarm.traffic.dropped == 0


@pytest.mark.parametrize(
    "association,more",
    [
        ("gnn", {"tracker.model": "imm"}),
        ("jpda", {"fusion.rule": "covariance_intersection"}),
        ("jpda", {"tracker.confirmation": "existence", "tracker.merge": 2}),
        ("gnn", {"tracker.confirmation": "m_of_n"}),
        ("jpda", {"tracker.briefing": False}),
        ("jpda", {"target.stay": 8, "target.away": 5, "planner.existence": True}),
    ],
    ids=[
        "gnn-imm",
        "jpda-ci",
        "jpda-existence-merge",
        "gnn-m-of-n",
        "jpda-unbriefed",
        "jpda-births-weighed",
    ],  # fmt: skip
)
@pytest.mark.parametrize("method", ["distributed", "centralized"])
def test_memory_swarm_with_tracks_equals_the_simulator_in_every_setting(method, association, more):
    scenario = tracked(association, steps=30, **more)
    swarm = run_swarm(scenario, method, seed=1, transport="memory")
    assert_same_trace(swarm.result.trace, uavtrack.simulate(scenario, method, seed=1).trace)


def test_a_uav_program_is_told_no_target_index():
    """The Sense of a UAV with tracks names no target: its measurements come as a
    set in the scan's order, the clutter among them."""
    from uavtrack.agents.tracked import TrackedUav

    seen = []
    cycle = TrackedUav.cycle

    def spy(self, k, sense, central=True):
        seen.append((sense["observed"].shape, sense["z"].shape))
        return cycle(self, k, sense, central)

    scenario = tracked(steps=6)
    patch = pytest.MonkeyPatch()
    patch.setattr(TrackedUav, "cycle", spy)
    try:
        swarm = run_swarm(scenario, "distributed", seed=2, transport="memory")
    finally:
        patch.undo()
    assert seen and all(observed == (0,) for observed, _ in seen)
    trace = swarm.result.trace
    per_step = trace.scan_valid.sum(axis=(1, 2))
    assert sum(z[0] for _, z in seen) == per_step.sum()  # every measurement, clutter too


@pytest.mark.parametrize("method", ["distributed", "centralized"])
def test_zenoh_swarm_of_processes_with_tracks_equals_run(method):
    pytest.importorskip("zenoh")
    scenario = tracked(steps=15, **{"faults.loss": 0.2})
    swarm = run_swarm(scenario, method, seed=4, transport="zenoh")
    reference = uavtrack.simulate(scenario, method, seed=4)
    assert_same_trace(swarm.result.trace, reference.trace)
    assert swarm.transport == "zenoh" and swarm.traffic.dropped == 0
