"""The track consensus on a radio of few bytes: the compact encoding and the trigger list
the slots they carry (`tracks.team.Listing`), the agents admit exactly that layout, and
a limited radio's shares bound what tracks put on the air."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import uavtrack
from uavtrack import fusion
from uavtrack.agents.messages import VERSION, Part, Radio, Spec, packed
from uavtrack.numerics.codec import COMPACT
from uavtrack.radio import upper, wire_cov, wire_mean
from uavtrack.tracks import team

from .test_team import GATE, connected_graph, empty, put, spd

TRACKED = {
    "tracker.association": "jpda", "sensor.detection_probability": 0.9,
    "sensor.clutter_rate": 2.0,
}  # fmt: skip


def random_team(seed: int) -> tuple[np.ndarray, team.TrackSet, np.ndarray]:
    """A connected team of 2 to 8 UAVs, each holding some of up to 4 targets under labels
    of its own (confirmed or tentative), and rounds of any number up to N - 1."""
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(2, 9)), int(rng.integers(1, 5))
    K = m + 2
    adjacency = connected_graph(rng, n, int(rng.integers(0, 5)))
    truth = rng.uniform(0, 3000, size=(m, 4))
    truth[:, 2:] = 0
    holds = rng.random((n, m)) < 0.6
    labels = rng.choice(10**6, size=(n, m), replace=False)
    tracks = empty(1, n, K)
    for i in range(n):
        slots = rng.permutation(K)
        for j in np.flatnonzero(holds[i]):
            P = spd(rng, scale=rng.uniform(0.5, 3.0))
            error = np.linalg.cholesky(P) @ rng.uniform(-1.5, 1.5, size=4)
            status = int(rng.choice([team.TENTATIVE, team.CONFIRMED, team.CONFIRMED]))
            put(tracks, 0, i, slots[j], truth[j] + error, P, labels[i, j], status=status)
    return adjacency, tracks, rng.integers(0, n, size=(1, n))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10**6), form=st.sampled_from(["dense", "edges"]))
def test_a_round_that_lists_the_confirmed_slots_is_the_full_exchange(seed, form):
    # a receiver reads only confirmed offers: one round of the listed exchange is the full
    # exchange's, exactly. (Later rounds list only what changed, and the association reads
    # which labels a sender offers in the round: there the two may part, as measured by
    # `uavtrack bandwidth` on tracks.)
    adjacency, tracks, rounds = random_team(seed)
    rounds = np.minimum(rounds, 1)
    full = team.agree(fusion.perfect_radio(adjacency[None], form), tracks, rounds, GATE)
    listed = team.agree(
        fusion.perfect_radio(adjacency[None], form), tracks, rounds, GATE, listing=team.Listing()
    )
    for name in ("label", "status", "mean", "cov"):
        assert np.array_equal(getattr(listed.tracks, name), getattr(full.tracks, name)), name
    assert np.array_equal(listed.changed, full.changed)
    assert listed.carried is not None
    # round 1 carries every confirmed slot; no round carries more
    confirmed = (tracks.status == team.CONFIRMED).sum(axis=-1)
    assert np.array_equal(listed.carried[0], confirmed)
    assert all((c <= tracks.status.shape[-1]).all() for c in listed.carried)


def two_uavs(status: int = team.CONFIRMED) -> team.TrackSet:
    """UAV 0 holds one track (label 7), UAV 1 none; they hear each other."""
    rng = np.random.default_rng(1)
    tracks = empty(1, 2, 3)
    put(tracks, 0, 0, 1, np.array([100.0, 200.0, 1.0, -1.0]) / 3, spd(rng), 7, status=status)
    return tracks


def test_a_slot_not_listed_in_the_first_round_and_unchanged_is_never_offered():
    radio = lambda: fusion.perfect_radio(np.ones((1, 2, 2), dtype=bool))  # noqa: E731
    tracks, rounds = two_uavs(), np.full((1, 2), 3)
    quiet = team.Listing(first=np.zeros((1, 2, 3), dtype=bool))
    out = team.agree(radio(), tracks, rounds, GATE, listing=quiet)
    assert (out.tracks.status[0, 1] == team.EMPTY).all()  # UAV 1 never got it
    assert all((c == 0).all() for c in out.carried or [])
    assert np.isnan(out.told).all() and (out.told_labels == -1).all()
    heard = team.agree(radio(), tracks, rounds, GATE, listing=team.Listing())
    assert heard.tracks.label[0, 1].max() == 7
    assert heard.told is not None and heard.told_labels is not None
    assert heard.told_labels[0, 0, 1] == 7 and np.isfinite(heard.told[0, 0, 1])


def test_a_tentative_track_is_never_listed():
    out = team.agree(
        fusion.perfect_radio(np.ones((1, 2, 2), dtype=bool)),
        two_uavs(team.TENTATIVE),
        np.full((1, 2), 2),
        GATE,
        listing=team.Listing(),
    )
    assert all((c == 0).all() for c in out.carried or [])


def test_the_compact_encoding_delivers_float32_values_and_a_symmetric_covariance():
    tracks = two_uavs()
    out = team.agree(
        fusion.perfect_radio(np.ones((1, 2, 2), dtype=bool)),
        tracks,
        np.ones((1, 2), dtype=int),
        GATE,
        listing=team.Listing(codec=COMPACT),
    )
    adopted = int(np.flatnonzero(out.tracks.label[0, 1] == 7)[0])
    sent_mean, sent_cov = tracks.mean[0, 0, 1], tracks.cov[0, 0, 1]
    assert np.array_equal(out.tracks.mean[0, 1, adopted], wire_mean(sent_mean))
    assert np.array_equal(out.tracks.cov[0, 1, adopted], wire_cov(sent_cov))
    assert not np.array_equal(out.tracks.mean[0, 1, adopted], sent_mean)  # it was rounded
    assert np.array_equal(out.tracks.mean[0, 0, 1], sent_mean)  # the sender keeps its own


def test_a_trigger_lists_a_slot_whose_label_changed_or_whose_confidence_moved():
    tracks = two_uavs()
    gamma = 1.0 / np.trace(tracks.cov[0, 0, 1])
    told = np.full((1, 2, 3), np.nan)
    told[0, 0, 1] = gamma
    labels = np.full((1, 2, 3), -1)
    labels[0, 0, 1] = 7
    first = team.triggered(tracks, told, labels, k=1, trigger=0.1, refresh=10)
    assert first is not None and not first[0, 0, 1]  # as sent: quiet
    labels[0, 0, 1] = 9
    first = team.triggered(tracks, told, labels, k=1, trigger=0.1, refresh=10)
    assert first is not None and first[0, 0, 1]  # another label in the slot: sent
    labels[0, 0, 1], told[0, 0, 1] = 7, gamma * 1.2
    first = team.triggered(tracks, told, labels, k=1, trigger=0.1, refresh=10)
    assert first is not None and first[0, 0, 1]  # moved by more than 10 %: sent
    assert team.triggered(tracks, told, labels, k=10, trigger=0.1, refresh=10) is None


def run(overrides: dict, seed: int = 4) -> uavtrack.Result:
    case = uavtrack.Scenario(steps=40).with_overrides(TRACKED | overrides)
    return uavtrack.simulate(case, "distributed", seed=seed)


def test_compact_and_trigger_put_a_quarter_of_the_full_track_consensus_on_the_air():
    full, compact = run({}), run({"radio.encoding": "compact"})
    both = run({"radio.encoding": "compact", "fusion.trigger": 0.1})
    assert full.trace is not None and compact.trace is not None and both.trace is not None
    # the same first cycle's decisions: compact rounds values, it does not drop tracks
    assert np.array_equal(full.trace.rounds[0], compact.trace.rounds[0])
    assert both.bytes < compact.bytes < 0.5 * full.bytes
    assert both.bytes <= 0.25 * full.bytes


def test_an_ample_radio_changes_nothing_with_tracks():
    paper, ample = run({}), run({"radio.bandwidth_bps": 1e9})
    assert paper.trace is not None and ample.trace is not None
    assert uavtrack.testing.differences(ample.trace, paper.trace, atol=0.0) == []


def test_a_radio_with_no_room_leaves_every_uav_with_its_own_tracks():
    starved = run({"radio.bandwidth_bps": 1.0})
    alone = uavtrack.simulate(
        uavtrack.Scenario(steps=40).with_overrides(TRACKED).model_copy(update={"comm_range": 1e-3}),
        "distributed",
        seed=4,
    )
    assert starved.trace is not None and alone.trace is not None
    assert starved.trace.bytes.sum() == 0 and starved.trace.messages.sum() == 0
    assert uavtrack.testing.differences(starved.trace, alone.trace, atol=0.0) == []


# ------------------------------------------------------------ what the agents admit


def listed_message(content: dict) -> Radio:
    part = Part("consensus", 1, -1, packed(content))
    return Radio(version=VERSION, run="r" * 12, k=3, sender=1, parts=[part])


@pytest.mark.parametrize("compact", [False, True])
def test_a_listed_track_message_with_bad_slots_or_labels_is_dropped_by_reason(compact):
    overrides = {"radio.encoding": "compact"} if compact else {"fusion.trigger": 0.1}
    case = uavtrack.Scenario().with_overrides(TRACKED | overrides)
    spec = Spec.of(case, central=False)
    K = spec.slots
    rng = np.random.default_rng(0)
    A = rng.normal(size=(2, 4, 4))
    cov = A @ np.swapaxes(A, -1, -2) + 5 * np.eye(4)
    f, i, u = ("<f4", "<i4", "<u2") if compact else ("<f8", "<i8", "<i8")
    good = {
        "slots": np.array([0, 2], dtype=u),
        "mean": np.full((2, 4), 10.0, dtype=f),
        "cov": (upper(cov) if compact else cov).astype(f),
        "label": np.array([1, 3], dtype="<u4" if compact else "<i8"),
        "stamp": np.array([3, 2], dtype=i),
        "tombs": np.full((K, 2), -1, dtype=i),
    }
    assert not isinstance(spec.radio(listed_message(good), 3), str)
    for name, value, reason in (
        ("slots", np.array([2, 2], dtype=u), "index out of range"),
        ("slots", np.array([0, K], dtype=u), "index out of range"),
        ("label", good["label"][[0, 0]], "labels not distinct"),
        ("label", np.array([1, spec.labels], dtype=good["label"].dtype), "index out of range"),
        ("stamp", np.array([3, 4], dtype=i), "stamp out of range"),
        ("cov", -good["cov"], "covariance"),
        ("mean", np.full((2, 4), np.nan, dtype=f), "not finite"),
    ):
        got = spec.radio(listed_message(dict(good, **{name: value})), 3)
        assert isinstance(got, str) and reason in got, (name, got)
    buried = good["tombs"].copy()
    buried[0] = (3, 3)  # a tombstone of label 3 after the stamp of its track (2)
    got = spec.radio(listed_message(dict(good, tombs=buried)), 3)
    assert got == "tombstone of a track it holds"
    too_many = {n: np.concatenate([v] * (K + 1)) for n, v in good.items() if n != "tombs"}
    assert spec.radio(listed_message(too_many | {"tombs": good["tombs"]}), 3) == (
        "wrong shape or type"
    )


# ------------------------------------------------------------ late tracks, and the agents


def test_tracks_that_arrive_late_are_predicted_to_the_scan_they_meet():
    from uavtrack.methods.base import forwarded

    case = uavtrack.Scenario().with_overrides(TRACKED | {"faults.delay": 2})
    setting = uavtrack.simulation.Context.of(
        case, uavtrack.methods.get("distributed"), [np.random.SeedSequence(0)]
    ).setting
    rng = np.random.default_rng(2)
    mean, cov = rng.normal(size=(3, 4)) * 50, np.stack([spd(rng) for _ in range(3)])
    A = np.eye(4)
    A[0, 2] = A[1, 3] = case.dt
    late_mean, late_cov = forwarded(setting, mean, cov, sent=5, k=7)
    once_mean, once_cov = forwarded(setting, mean, cov, sent=5, k=6)
    assert np.allclose(late_mean, mean @ np.linalg.matrix_power(A, 2).T)
    again = forwarded(setting, once_mean, once_cov, sent=6, k=7)  # two steps: one and one
    assert np.allclose(again[0], late_mean) and np.allclose(again[1], late_cov)
    assert (np.trace(late_cov, axis1=1, axis2=2) > np.trace(cov, axis1=1, axis2=2)).all()
    same = forwarded(setting, mean, cov, sent=7, k=7)
    assert np.array_equal(same[0], mean) and np.array_equal(same[1], cov)


def test_the_compact_encoding_refuses_a_run_whose_labels_outgrow_32_bits():
    long = {"tracker.association": "jpda", "radio.encoding": "compact", "steps": 10**7}
    with pytest.raises(uavtrack.errors.ScenarioError, match="32 bits"):
        uavtrack.Scenario().with_overrides(long | {"n_uavs": 50})
    case = uavtrack.Scenario().with_overrides(TRACKED | {"radio.encoding": "compact"})
    assert case.labels < 2**31 and Spec.of(case, central=False).labels == case.labels


def test_under_faults_that_lose_nothing_the_central_node_assigns_as_without_faults():
    # under faults the node assigns the UAVs it heard from to its labels, from the states
    # they reported (it had sent no label, and each UAV chose alone); losing nothing,
    # that is the fault-free assignment, decision for decision
    case = uavtrack.Scenario(steps=60).with_overrides(TRACKED)
    clean = uavtrack.simulate(case, "centralized", seed=1)
    faulty = uavtrack.simulate(case.with_overrides({"faults.loss": 1e-12}), "centralized", seed=1)
    assert clean.trace is not None and faulty.trace is not None
    assert uavtrack.testing.differences(faulty.trace, clean.trace, atol=1e-9) == []


def test_the_central_node_takes_the_scans_that_arrive_late():
    late = uavtrack.Scenario(steps=80).with_overrides(TRACKED | {"faults.delay": 2})
    result = uavtrack.simulate(late, "centralized", seed=1)
    assert result.trace is not None and result.trace.label is not None
    # the first downloads arrive at k = 2, with the node's tracks of the start
    assert (result.trace.label[:2] == result.trace.label[0]).all()
    clean = uavtrack.simulate(late.with_overrides({"faults.delay": 0}), "centralized", seed=1)
    assert result.observation_rate > clean.observation_rate - 0.25  # late, not lost


def test_bids_that_arrive_late_keep_the_labels_they_were_sent_for():
    from uavtrack.methods.distributed import relabelled
    from uavtrack.tracks import columns

    # two cycles ago UAV 0 bid for labels 3 and 7; now only label 3 and a new 9 are held
    sent = {
        "labels": np.array([[3, 7]]),
        "bids": np.array([[[0.5, 0.25], [0.0, 0.0]]]),
        "holds": np.array([[[True, True], [False, False]]]),
    }
    label = np.array([[[3, -1], [9, -1]]])
    confirmed = label >= 0
    now = columns.of(label, confirmed, more=sent["labels"])
    assert now.labels.tolist() == [[3, 7, 9]]  # the late bids' label 7 is a column
    bids, holds = relabelled(sent, now.labels)
    assert bids.tolist() == [[[0.5, 0.25, 0.0], [0.0, 0.0, 0.0]]]
    assert holds.tolist() == [[[True, True, False], [False, False, False]]]
    alone = columns.of(label, confirmed)  # without them label 7's bid would be lost
    assert relabelled(sent, alone.labels)[0].tolist() == [[[0.5, 0.0], [0.0, 0.0]]]


SWARMS = {
    "delay": ({"faults.delay": 1}, 12, 3),
    "delay-loss": ({"faults.delay": 2, "faults.loss": 0.2}, 12, 3),
    # bids held of a sender whose message was lost, under labels of two cycles ago: a
    # receiver knows the labels it holds now (the batch had read those it held then)
    "delay-loss-held": ({"faults.delay": 2, "faults.loss": 0.3}, 80, 3),
    # a late bid's label nobody holds any more is no target without a follower
    "delay-loss-conflicts": ({"faults.delay": 2, "faults.loss": 0.3}, 45, 2),
    "delay-compact-trigger-capacity": (
        {
            "faults.delay": 1, "radio.encoding": "compact", "fusion.trigger": 0.1,
            "radio.bandwidth_bps": 1e5,
        },
        12,
        3,
    ),
    "smallest-loss-capacity": (
        {
            "faults.loss": 0.2, "radio.encoding": "quantized", "fusion.trigger": 0.1,
            "radio.frames": "broadcast", "radio.bandwidth_bps": 1e5,
        },
        12,
        3,
    ),
}  # fmt: skip


LATE = [
    pytest.param(method, *case, id=f"{method}-{name}")
    for name, case in SWARMS.items()
    for method in ("distributed", "greedy", "centralized")
    if method != "centralized" or "radio.encoding" not in case[0]  # (it sends whole tables)
    if case[1] <= 12 or method == "distributed"  # the long ones: the bids by label
]


@pytest.mark.integration  # a swarm of programs
@pytest.mark.parametrize(("method", "overrides", "steps", "seed"), LATE)
def test_a_swarm_with_late_tracks_decides_as_the_batch(method, overrides, steps, seed):
    from uavtrack.agents import run_swarm
    from uavtrack.testing import assert_same_trace

    case = uavtrack.Scenario(steps=steps).with_overrides(TRACKED | overrides)
    batch = uavtrack.simulate(case, method, seed=seed)
    swarm = run_swarm(case, method, seed=seed, transport="memory")
    assert batch.trace is not None and swarm.result.trace is not None
    assert_same_trace(swarm.result.trace, batch.trace)
    assert swarm.traffic.drops == {}
