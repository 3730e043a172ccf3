"""A receiver's check of avoidance beacons (`airspace.beacons`): every beacon of an
honest team passes it, a phantom placed next to a receiver does not."""

from __future__ import annotations

import numpy as np
import pytest

import uavtrack
from uavtrack.airspace import beacons
from uavtrack.world import wrap_angle

ONE_ALTITUDE = uavtrack.Scenario.from_toml("one-altitude")


def refused(scenario: uavtrack.Scenario, seed: int) -> tuple[dict[str, int], int, float]:
    """Every beacon of an honest run checked as its receivers check it (a sender heard at
    k - 1 against that beacon, else for its first): the reasons refused, the beacons
    checked, and the largest heading change per step as a share of the limit."""
    trace = uavtrack.simulate(scenario, "distributed", seed=seed).trace
    U, limits = trace.uavs, beacons.Limits.of(scenario)
    T, N, _ = U.shape
    apart = np.linalg.norm(U[:, :, None, :3] - U[:, None, :, :3], axis=-1)  # (T, N, N)
    heard = (apart <= scenario.comm_range) & ~np.eye(N, dtype=bool)
    out: dict[str, int] = {}
    checked, turned = 0, 0.0
    for k, i, q in zip(*np.nonzero(heard), strict=True):
        before = (U[k - 1, q], k - 1) if k > 0 and heard[k - 1, i, q] else None
        why = beacons.believable(limits, int(q), U[k, q], int(k), before, U[k, i])
        checked += 1
        if why is not None:
            out[why] = out.get(why, 0) + 1
        if before is not None:
            rate = abs(wrap_angle(U[k, q, 4] - U[k - 1, q, 4])) / (limits.turn * limits.dt)
            turned = max(turned, float(rate))
    return out, checked, turned


@pytest.mark.parametrize("comm_range", [50.0, 162.0])
@pytest.mark.parametrize("seed", [0, 1])
def test_every_beacon_of_an_honest_team_is_believable(comm_range, seed):
    scenario = ONE_ALTITUDE.with_overrides({"steps": 200, "comm_range": comm_range})
    out, checked, turned = refused(scenario, seed)
    assert out == {} and checked > 500
    assert 0.2 < turned <= 0.5 + 1e-9  # the unicycle turns at the limit's 1 / TURN_MARGIN


@pytest.mark.integration  # JSBSim
@pytest.mark.parametrize("wind", [0.0, 8.0])
def test_every_beacon_of_an_honest_jsbsim_team_is_believable(wind):
    pytest.importorskip("jsbsim")
    scenario = ONE_ALTITUDE.with_overrides(
        {"steps": 120, "uav.dynamics": "jsbsim", "wind.speed": wind}
    )
    out, checked, turned = refused(scenario, 0)
    assert out == {} and checked > 300
    assert turned < 0.8  # JSBSim's roll overshoot stays within the margin


def test_a_phantom_next_to_the_receiver_is_refused_by_reason():
    scenario = ONE_ALTITUDE.with_overrides({"steps": 50})
    limits = beacons.Limits.of(scenario)
    me = limits.start[0].copy()
    start = limits.start[1]
    # at step 0 the start grid is known: a sender elsewhere is refused
    assert beacons.believable(limits, 1, start, 0, None, me) is None
    near = me + [5.0, 0, 0, 0, 0]
    assert beacons.believable(limits, 1, near, 0, None, me) == "beacon not at its start"
    # later, first heard: out of range at k - 1, so not deep inside it now
    assert beacons.believable(limits, 1, near, 7, None, me) == (
        "beacon appears inside the radio range"
    )
    edge = me + [scenario.comm_range - 1.0, 0, 0, 0, 0]
    assert beacons.believable(limits, 1, edge, 7, None, me) is None
    # against its beacon of k - 1: a jump, a turn or a climb no aircraft makes
    step = scenario.uav.speed * scenario.dt
    last = edge - [step, 0, 0, 0, 0]
    assert beacons.believable(limits, 1, edge, 8, (last, 7), me) is None
    jump = last + [limits.speed * scenario.dt + limits.slack + 1.0, 0, 0, 0, 0]
    turn = edge + [0, 0, 0, 0, 1.5]
    climb = edge + [0, 0, 30.0, 0, 0]
    for lie in (jump, turn, climb):
        assert beacons.believable(limits, 1, lie, 8, (last, 7), me) == (
            "beacon beyond the aircraft's limits"
        )
    # where beacons can be lost, a sender not heard may have been in range: believed
    lossy = beacons.Limits.of(scenario.with_overrides({"faults.loss": 0.1}))
    assert beacons.believable(lossy, 1, near, 7, None, me) is None


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_a_member_placing_phantoms_next_to_each_uav_is_refused_and_counted():
    """`examples/quiet_lies.py --lie beacons`: a beacon 5 m ahead of each receiver. The
    receivers refuse it, count it, and finish."""
    import runpy
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / "quiet_lies.py"
    example = runpy.run_path(str(path), run_name="quiet_lies")
    scenario = example["scenario_of"]("beacons", 40)
    rates, drops = example["lying_runs"]("beacons", scenario, 1)
    assert drops.get("beacon appears inside the radio range", 0) > 20, drops
    assert np.isfinite(rates).all()
