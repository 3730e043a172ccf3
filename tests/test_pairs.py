"""Every pair of the feature switches runs: a short scenario of each pair in the batch for
the three methods, a sample of them in the agent form against the batch. A pair is
refused only where the documentation lists it, with its reason (docs/how-to/pairs.md):
the test reads that list and holds it equal to what the code refuses."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import numpy as np
import pytest

import uavtrack
from uavtrack.errors import ScenarioError

FEATURES = {
    "tracks": {"tracker.association": "jpda"},
    "clutter": {"sensor.detection_probability": 0.9, "sensor.clutter_rate": 2.0},
    "imm": {"tracker.model": "imm"},
    "ci": {"fusion.rule": "covariance_intersection"},
    "manoeuvring": {"target.motion": "manoeuvring"},
    "loss": {"faults.loss": 0.2},
    "bursty": {"faults.loss": 0.2, "faults.burst_length": 4.0},
    "delay": {"faults.delay": 1},
    "failures": {"faults.failures": ((1, 3),)},
    "gps": {"faults.position_std": 5.0},
    "robust": {"robust.gate": 0.9999, "robust.stale": True, "robust.extra_rounds": 1},
    "compact": {"radio.encoding": "compact"},
    "quantized": {"radio.encoding": "quantized"},
    "trigger": {"fusion.trigger": 0.1},
    "capacity": {"radio.bandwidth_bps": 1e5},
    "broadcast": {"radio.frames": "broadcast"},
    "avoidance": {"planner.avoidance": "loiter", "uav.altitude_spacing": 0, "uav.separation": 10},
    "airspeed": {
        "uav.min_speed": 10.0,
        "planner.avoidance": "loiter",
        "uav.altitude_spacing": 0,
        "uav.separation": 10,
    },
    "births": {"target.stay": 30.0, "tracker.association": "jpda"},
    "jsbsim": {"uav.dynamics": "jsbsim"},
}
"""The feature switches, each at a setting that turns it on (targets that come and go
need tracks to be found: births turn tracks on)."""
IMPLIES = {"births": "tracks"}
METHODS = ("distributed", "greedy", "centralized")
STEPS = 6
PAGE = Path(__file__).resolve().parents[1] / "docs" / "how-to" / "pairs.md"


def combined(*names: str) -> dict:
    out: dict = {}
    for name in names:
        out |= FEATURES[name]
    return out


def outcome(names: tuple[str, ...], method: str) -> str | None:
    """None if the pair runs for `method`, else the refusal's message."""
    try:
        case = uavtrack.Scenario(steps=STEPS).with_overrides(combined(*names))
        result = uavtrack.simulate(case, method, seed=1)
    except ScenarioError as error:
        return str(error)
    assert result.trace is not None
    assert 0.0 <= result.observation_rate <= 1.0
    assert np.isfinite(result.trace.uavs).all()
    return None


def documented() -> dict[tuple[str, str, str], str]:
    """The refusals the page lists: (switch, switch or "*": any, method or "all") ->
    reason."""
    rows = re.findall(r"^\| `(\w+)` \| `([\w*]+)` \| (\w+) \| (.+) \|$", PAGE.read_text(), re.M)
    return {(a, b, method): reason for a, b, method, reason in rows}


def refused_by_page(names: tuple[str, ...], method: str) -> bool:
    """Whether the page lists these switches (with what they imply) as refused for
    `method`."""
    on = set(names) | {IMPLIES[n] for n in names if n in IMPLIES}
    return any(
        a in on and (b == "*" or b in on) and m in ("all", method) for a, b, m in documented()
    )


def check(selected: list[tuple[str, ...]]) -> None:
    assert documented(), f"no refusals read from {PAGE}"
    wrong = []
    for names in selected:
        for method in METHODS:
            why = outcome(names, method)
            if (why is not None) != refused_by_page(names, method):
                wrong.append((names, method, why or "runs, but the page lists it as refused"))
    assert not wrong, wrong


def pairs(jsbsim: bool) -> list[tuple[str, ...]]:
    every = itertools.combinations(FEATURES, 2)
    return [p for p in every if ("jsbsim" in p) == jsbsim]


def test_every_pair_of_switches_runs_or_is_a_documented_refusal():
    check(pairs(jsbsim=False))


def test_each_switch_alone_runs_or_is_a_documented_refusal():
    check([(name,) for name in FEATURES if name != "jsbsim"])


@pytest.mark.integration  # JSBSim flies the aircraft
def test_every_pair_with_jsbsim_runs_or_is_a_documented_refusal():
    pytest.importorskip("jsbsim")
    check([("jsbsim",), *pairs(jsbsim=True)])


def test_every_listed_refusal_is_one_the_code_makes():
    # a row the code no longer refuses must leave the page: each is met by some pair
    for a, b, method in documented():
        names = (a,) if b == "*" else (a, b)
        methods = METHODS if method == "all" else (method,)
        assert all(outcome(names, m) is not None for m in methods), (a, b, method)


SAMPLE = [
    (names, METHODS[i % len(METHODS)])
    for i, names in enumerate(pairs(jsbsim=False)[::9])
    if not refused_by_page(names, METHODS[i % len(METHODS)])
]
"""Every ninth pair, the methods in turn: what the agent form runs against the batch."""


@pytest.mark.integration  # a swarm of programs
@pytest.mark.parametrize(("names", "method"), SAMPLE, ids=lambda x: str(x))
def test_a_sample_of_the_pairs_runs_in_the_agent_form_as_in_the_batch(names, method):
    from uavtrack.agents import run_swarm
    from uavtrack.testing import assert_same_trace

    case = uavtrack.Scenario(steps=STEPS).with_overrides(combined(*names))
    batch = uavtrack.simulate(case, method, seed=2)
    swarm = run_swarm(case, method, seed=2, transport="memory")
    assert batch.trace is not None and swarm.result.trace is not None
    assert_same_trace(swarm.result.trace, batch.trace)
