"""Fewer bytes on the air: the compact encoding (``radio.encoding``) and the
event-triggered consensus (``fusion.trigger``), in the batch and in the agents."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import uavtrack
from tests.test_fusion import component_max_index, geometric_graphs
from uavtrack import fusion, radio
from uavtrack.errors import ScenarioError
from uavtrack.testing import assert_same_trace, differences


def consensus(adj, confidence, form, sending=None, first=None):
    """fusion.consensus over one graph for D_i rounds; returns (outcome, rounds)."""
    n, m = confidence.shape
    perfect = fusion.perfect_radio(adj[None], form)
    depth = fusion.learn_depth(perfect, np.ones((1, n), dtype=bool))
    tuples = fusion.Estimates(
        gamma=confidence[None], source=fusion.identity((1, n, m)), stamp=np.zeros((1, n, m))
    )
    how = None if sending is None else fusion.Sending(first=first, changes=sending)
    radio_ = fusion.perfect_radio(adj[None], form)
    return fusion.consensus(radio_, tuples, depth.depth, sending=how), depth.depth


@pytest.mark.parametrize("form", ["dense", "edges"])
@settings(max_examples=120, deadline=None)
@given(case=geometric_graphs(), ties=st.booleans())
def test_later_rounds_that_leave_out_what_did_not_change_lose_nothing(form, case, ties):
    # without losses a tuple left out of round r was offered in round r - 1 and lost
    # there: every UAV ends with the confidence sending everything gives, its component's
    # maximum, and the same tuple unless confidences tie (a re-offered tuple of equal
    # confidence from a lower index would take the place of the receiver's)
    adj, confidence = case
    if ties:  # many equal confidences
        confidence = np.round(confidence * 2) / 2
    full, _ = consensus(adj, confidence, form)
    fewer, _ = consensus(adj, confidence, form, sending=True)
    assert np.array_equal(fewer.tuples.gamma, full.tuples.gamma)
    if not ties:
        for name, value in full.tuples.items():
            assert np.array_equal(getattr(fewer.tuples, name), value), name
    assert fewer.carried is not None
    sent = sum(int(c.sum()) for c in fewer.carried)
    assert sent <= confidence.size * len(fewer.carried)
    source = fusion.required(fewer.tuples.source, "source")[0]
    if not ties:
        assert np.array_equal(source, component_max_index(confidence, adj))


@pytest.mark.parametrize("form", ["dense", "edges"])
@settings(max_examples=80, deadline=None)
@given(case=geometric_graphs(), seed=st.integers(0, 2**31))
def test_a_tuple_not_sent_in_the_first_round_is_never_offered(form, case, seed):
    # each UAV ends with the best of its own tuple and the component's tuples sent in
    # round 1, when the best sent one reaches it (max-consensus over what was sent)
    adj, confidence = case
    first = np.random.default_rng(seed).random(confidence.shape) < 0.5
    out, rounds = consensus(adj, confidence, form, sending=True, first=first[None])
    source = fusion.required(out.tuples.source, "source")[0]
    n, m = confidence.shape
    for i in range(n):
        for j in range(m):
            q = source[i, j]
            assert q == i or first[q, j]  # only its own, or a tuple that was sent
            assert confidence[q, j] >= confidence[i, j]
    # where every UAV sent everything, the component's maximum
    everyone = np.ones_like(first)
    full, _ = consensus(adj, confidence, form, sending=True, first=everyone[None])
    assert np.array_equal(
        fusion.required(full.tuples.source, "source")[0], component_max_index(confidence, adj)
    )


def test_the_wire_keeps_float32_values_and_a_symmetric_covariance(rng):
    A = rng.normal(size=(3, 4, 4))
    cov = A @ np.swapaxes(A, -1, -2) + np.eye(4)
    cov[0, 0, 1] += 1e-9  # a filter's covariance need not be exactly symmetric
    wired = radio.wire_cov(cov)
    assert np.array_equal(wired, np.swapaxes(wired, -1, -2))
    upper = np.triu_indices(4)
    assert np.array_equal(wired[:, *upper], cov[:, *upper].astype(np.float32))
    assert np.array_equal(radio.wire_cov(wired), wired)  # a second trip changes nothing
    assert np.allclose(wired, cov, rtol=1e-6)


def scenario(**overrides):
    return uavtrack.Scenario(steps=60).with_overrides(overrides)


def test_the_compact_encoding_changes_values_by_float32_rounding_only():
    paper = uavtrack.simulate(scenario(), "distributed", seed=2)
    compact = uavtrack.simulate(scenario(**{"radio.encoding": "compact"}), "distributed", seed=2)
    assert paper.trace is not None and compact.trace is not None
    # the decisions are the paper's; the estimates within float32's rounding
    assert differences(compact.trace, paper.trace, atol=1e-3, counters=False) == []
    assert not np.array_equal(compact.trace.mean, paper.trace.mean)  # rounded on the way
    assert compact.bytes < 0.6 * paper.bytes


def test_a_trigger_of_zero_refreshed_every_cycle_is_the_papers_exchange():
    paper = uavtrack.simulate(scenario(), "distributed", seed=2)
    every = uavtrack.simulate(
        scenario(**{"fusion.trigger": 0.0, "fusion.refresh": 1}), "distributed", seed=2
    )
    assert paper.trace is not None and every.trace is not None
    assert differences(every.trace, paper.trace, atol=0.0, counters=False) == []
    assert np.array_equal(every.trace.messages, paper.trace.messages)
    assert every.bytes < paper.bytes  # only the later rounds' changes, listed


def test_a_trigger_sends_less_and_refreshes():
    paper = uavtrack.simulate(scenario(), "distributed", seed=2)
    lazy = uavtrack.simulate(
        scenario(**{"fusion.trigger": 0.5, "fusion.refresh": 20}), "distributed", seed=2
    )
    assert lazy.trace is not None and paper.trace is not None
    assert lazy.bytes < 0.7 * paper.bytes
    # a refresh cycle sends every tuple: more bytes than the cycles around it
    per_step = lazy.trace.bytes.sum(axis=1)
    assert per_step[20] > np.median(per_step[21:39])
    assert per_step[40] > np.median(per_step[41:59])


def test_the_centralized_method_refuses_what_it_does_not_encode():
    for overrides in ({"radio.encoding": "compact"}, {"fusion.trigger": 0.1}):
        with pytest.raises(ScenarioError, match="centralized"):
            uavtrack.simulate(scenario(**overrides), "centralized", seed=0)
    with pytest.raises(ScenarioError, match="fusion.refresh"):
        scenario(**{"fusion.refresh": 3})


@pytest.mark.integration  # a swarm of programs
@pytest.mark.parametrize(
    "overrides",
    [
        {"radio.encoding": "compact"},
        {"fusion.trigger": 0.1, "fusion.refresh": 4},
        {"fusion.trigger": 0.1, "radio.encoding": "compact", "faults.loss": 0.3},
        {"fusion.trigger": 0.05, "faults.delay": 1, "robust.stale": True},
        {"radio.encoding": "compact", "fusion.rule": "covariance_intersection"},
        {"fusion.trigger": 0.1, "radio.encoding": "compact", "robust.gate": 0.9999},
        {
            "fusion.trigger": 0.1,
            "radio.encoding": "quantized",
            "radio.frames": "broadcast",
            "faults.loss": 0.3,
            "faults.delay": 1,
            "robust.stale": True,
        },
        {
            "radio.encoding": "quantized",
            "fusion.rule": "covariance_intersection",
            "robust.gate": 0.9999,
        },
    ],
    ids=[
        "compact",
        "trigger",
        "both-lossy",
        "trigger-delay",
        "compact-ci",
        "both-gate",
        "smallest-lossy-delay",
        "quantized-ci-gate",
    ],
)
@pytest.mark.parametrize("method", ["distributed", "greedy"])
def test_a_swarm_sends_and_decides_as_the_batch(method, overrides):
    from uavtrack.agents import run_swarm

    case = uavtrack.Scenario(steps=12).with_overrides(overrides)
    batch = uavtrack.simulate(case, method, seed=3)
    swarm = run_swarm(case, method, seed=3, transport="memory")
    assert batch.trace is not None and swarm.result.trace is not None
    assert_same_trace(swarm.result.trace, batch.trace)  # bytes among the counters
    assert swarm.traffic.drops == {}


def test_the_listed_layouts_are_what_the_agents_admit():
    from uavtrack.agents.messages import Spec

    for overrides, kind in (
        ({"fusion.trigger": 0.1}, "listed"),
        ({"radio.encoding": "compact"}, "compact"),
        ({"radio.encoding": "compact", "fusion.trigger": 0.1}, "compact"),
    ):
        for tracked in (False, True):
            case = uavtrack.Scenario().with_overrides(overrides | (TRACKED if tracked else {}))
            spec = Spec.of(case, central=False)
            assert spec.tuples == kind
            admitted = spec.contents("consensus")
            assert admitted is not None
            slots = case.track_slots if tracked else 0
            layout = radio.layout("consensus", case.n_uavs, case.n_targets, slots, tuples=kind)
            assert {name: k[:2] for name, k in admitted.items()} == layout
            assert ("slots" in layout) == tracked  # tracks list slots, tuples targets


def test_a_listed_message_with_bad_targets_is_dropped_by_reason():
    from uavtrack.agents.messages import VERSION, Part, Radio, Spec, packed

    case = uavtrack.Scenario().with_overrides({"radio.encoding": "compact"})
    spec = Spec.of(case, central=False)
    rng = np.random.default_rng(0)
    A = rng.normal(size=(2, 4, 4))
    cov = A @ np.swapaxes(A, -1, -2) + 5 * np.eye(4)
    good = {
        "targets": np.array([0, 2], dtype="<u2"),
        "mean": np.full((2, 4), 10.0, dtype="<f4"),
        "cov": cov[:, *np.triu_indices(4)].astype("<f4"),
        "stamp": np.array([3, 3], dtype="<i4"),
        "origin": np.array([1, 1], dtype="<u2"),
    }

    def message(content):
        part = Part("consensus", 1, -1, packed(content))
        return Radio(version=VERSION, run="r" * 12, k=3, sender=1, parts=[part])

    assert not isinstance(spec.radio(message(good), 3), str)
    for name, value, reason in (
        ("targets", np.array([2, 2], dtype="<u2"), "index out of range"),
        ("targets", np.array([0, 9], dtype="<u2"), "index out of range"),
        ("targets", np.array([0, 1], dtype="<i8"), "wrong shape or type"),
        ("cov", -good["cov"], "covariance"),
        ("mean", np.full((2, 4), np.nan, dtype="<f4"), "not finite"),
    ):
        bad = dict(good, **{name: value})
        got = spec.radio(message(bad), 3)
        assert isinstance(got, str) and reason in got, (name, got)
    too_many = {n: np.concatenate([v] * 3) for n, v in good.items()}  # 6 rows of 4 targets
    assert spec.radio(message(too_many), 3) == "wrong shape or type"


def test_links_of_no_one_send_no_bytes_whatever_the_encoding():
    alone = scenario(**{"radio.encoding": "compact", "fusion.trigger": 0.1})
    alone = alone.model_copy(update={"comm_range": 1e-3})
    result = uavtrack.simulate(alone, "distributed", seed=0)
    assert result.bytes == 0


# ------------------------------------------------------------ a radio of limited capacity


def test_a_radio_with_no_room_is_no_radio():
    # nothing fits: every UAV decides alone, as with nobody in range
    for method in ("distributed", "greedy", "centralized"):
        starved = uavtrack.simulate(scenario(**{"radio.bandwidth_bps": 1.0}), method, seed=1)
        alone = uavtrack.simulate(
            scenario().model_copy(update={"comm_range": 1e-3}), method, seed=1
        )
        assert starved.trace is not None and alone.trace is not None
        assert starved.trace.bytes.sum() == 0
        if method != "centralized":  # (the centralized counts as messages what it offered)
            assert starved.trace.messages.sum() == 0
            assert differences(starved.trace, alone.trace, atol=0.0) == []


def test_an_ample_radio_changes_nothing():
    for method in ("distributed", "centralized"):
        paper = uavtrack.simulate(scenario(), method, seed=1)
        ample = uavtrack.simulate(scenario(**{"radio.bandwidth_bps": 1e9}), method, seed=1)
        assert paper.trace is not None and ample.trace is not None
        assert differences(ample.trace, paper.trace, atol=0.0) == []


@settings(max_examples=25, deadline=None)
@given(
    bps=st.floats(1e3, 1e6),
    method=st.sampled_from(["distributed", "greedy", "centralized"]),
    seed=st.integers(0, 1000),
    compact=st.booleans(),
    tracked=st.booleans(),
    avoid=st.booleans(),
)
def test_no_program_sends_more_than_its_share(bps, method, seed, compact, tracked, avoid):
    from uavtrack import network

    overrides = {"radio.bandwidth_bps": bps}
    if compact and method != "centralized":
        overrides["radio.encoding"] = "compact"
    if tracked:  # track slots on the air, and with the centralized method scans
        overrides |= TRACKED
    if avoid:  # every method's beacons
        overrides |= AVOID
    case = uavtrack.Scenario(steps=15).with_overrides(overrides)
    result = uavtrack.simulate(case, method, seed=seed)
    assert result.trace is not None
    channel = bps * case.dt / 8
    for k in range(case.steps):
        adjacency = network.adjacency(result.trace.uavs[k], case.comm_range)
        receivers = (adjacency & ~np.eye(case.n_uavs, dtype=bool)).sum(axis=0)
        contenders = case.n_uavs + 1 if method == "centralized" else receivers + 1
        share = np.floor(channel / contenders)
        sent = result.trace.bytes[k]
        assert (sent <= share).all(), (k, sent, share)
        assert result.trace.node_bytes[k] <= np.floor(channel / (case.n_uavs + 1))


AVOID = {"planner.avoidance": "loiter", "uav.altitude_spacing": 0, "uav.separation": 10}
TRACKED = {
    "tracker.association": "jpda", "sensor.detection_probability": 0.9,
    "sensor.clutter_rate": 2.0,
}  # fmt: skip
SHARES = [
    {"radio.bandwidth_bps": 1e5},
    {"radio.bandwidth_bps": 2e5, "faults.loss": 0.2},
    {"radio.bandwidth_bps": 3e5, "faults.delay": 1},
]
TRIGGERED = {"radio.bandwidth_bps": 1e5, "fusion.trigger": 0.1, "radio.encoding": "compact"}


@pytest.mark.integration  # a swarm of programs
@pytest.mark.parametrize(
    ("method", "overrides"),
    [(m, o) for m in ("distributed", "greedy", "centralized") for o in SHARES]
    + [(m, TRIGGERED) for m in ("distributed", "greedy")]
    + [(m, TRIGGERED | TRACKED) for m in ("distributed", "greedy")]
    + [("centralized", {"radio.bandwidth_bps": 3e4, "faults.loss": 0.2} | TRACKED)]
    + [(m, {"radio.bandwidth_bps": 1e5} | AVOID | TRACKED) for m in ("greedy", "centralized")],
)
def test_a_swarm_keeps_the_same_shares_as_the_batch(method, overrides):
    from uavtrack.agents import run_swarm

    case = uavtrack.Scenario(steps=12).with_overrides(overrides)
    batch = uavtrack.simulate(case, method, seed=3)
    swarm = run_swarm(case, method, seed=3, transport="memory")
    assert batch.trace is not None and swarm.result.trace is not None
    assert_same_trace(swarm.result.trace, batch.trace)
    assert swarm.traffic.drops == {}
    assert not swarm.result.trace.late.any()  # nobody waited for a frame never sent


def test_the_refusals_of_a_limited_radio():
    with pytest.raises(ScenarioError, match="bandwidth_bps"):
        scenario(**{"radio.bandwidth_bps": 0})


def test_every_methods_beacons_go_in_its_share():
    # greedy sends its beacon alone as its first priority, centralized beside its upload
    one = {"radio.bandwidth_bps": 1e5} | AVOID
    for method in ("greedy", "centralized", "distributed"):
        limited = uavtrack.simulate(scenario(**one), method, seed=0)
        assert limited.trace is not None and limited.bytes > 0
        starved = uavtrack.simulate(
            scenario(**(one | {"radio.bandwidth_bps": 1.0})), method, seed=0
        )
        assert starved.trace is not None and starved.trace.bytes.sum() == 0
