"""Whatever a UAV program adopts from its neighbours, its own state passes its own
checks: the invariant of the team's track round in the agent form (`agents.tracked`).

A member with valid keys may send any consensus content the run's rule admits
(`messages.Spec`). An honest receiver runs its rounds of `team.agree_round` on it, the
book after fusion, and its next scan with births; the tracks it then offers and the
report it then sends must pass the same rule, or its neighbours and the world refuse
them and the honest program is lost. The labels are where this broke: a member offering
a label of the receiver's own that the receiver had not issued yet made the receiver
issue it again at a later birth, holding it twice."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import uavtrack
from uavtrack import radio
from uavtrack.agents.messages import Spec
from uavtrack.agents.tracked import listed_slots
from uavtrack.methods.base import scanned_tracks
from uavtrack.numerics.codec import CODECS
from uavtrack.tracks import manage, team

from .test_hostile import consensus_message

pytest.importorskip("cryptography")

SCENARIO = uavtrack.Scenario(steps=40).with_overrides(
    {"tracker.association": "gnn", "sensor.detection_probability": 0.9}
)
ME, SENDERS = 2, (1, 3)


def tracked_receiver(scenario, me: int):
    """UAV `me`'s tracked program on a bus of its own (nothing is sent anywhere)."""
    from uavtrack.agents.security import Gate
    from uavtrack.agents.tracked import TrackedUav
    from uavtrack.agents.transport import Bus, Link, Mailbox, MemoryTransport
    from uavtrack.faults import Faults

    n, m = scenario.n_uavs, scenario.n_targets
    gate = Gate(run="r", me=me, programs=n, credential=None)
    link = Link(MemoryTransport(Bus()), gate)
    mailbox = Mailbox(gate, Spec.of(scenario, False))
    faults = Faults(scenario.faults, np.zeros((1, 2), dtype=np.uint32), n)
    prior = (np.full((m, 4), 200.0), np.broadcast_to(25.0 * np.eye(4), (m, 4, 4)).copy())
    return TrackedUav(me, scenario, "distributed", faults, link, mailbox, 1.0, prior)


def labels_of(spec: Spec, serial: int) -> list[int]:
    """Labels worth drawing: the briefed targets', those of the receiver issued and not
    yet issued, other UAVs', and the largest the run admits."""
    n, m = spec.n, spec.m
    own = [m + s * n + ME for s in range(serial + 3)]
    other = [m + s * n + q for s in range(3) for q in SENDERS]
    return sorted({*range(m), *own, *other, spec.labels - 1})


@st.composite
def track_content(draw, spec: Spec, k: int, serial: int, points: np.ndarray):
    """A consensus content the rule admits: K slots of any status, distinct labels from
    `labels_of`, estimates at (or near) a few shared points so that they gate with the
    receiver's, covariances between the run's floor and a few hundred m^2, stamps and
    tombstones anywhere in [0, k]."""
    K, b = spec.slots, spec.bounds
    status = np.array(draw(st.lists(st.integers(0, 2), min_size=K, max_size=K)))
    pool = labels_of(spec, serial)
    live = int((status != 0).sum())
    chosen = draw(st.permutations(pool))[:live]
    status[np.flatnonzero(status != 0)[len(chosen) :]] = 0  # fewer labels than slots
    label = np.full(K, -1)
    label[status != 0] = chosen
    where = np.array(draw(st.lists(st.integers(0, len(points) - 1), min_size=K, max_size=K)))
    jitter = np.array(draw(st.lists(st.floats(-3, 3), min_size=4 * K, max_size=4 * K)))
    mean = points[where] + jitter.reshape(K, 4)
    scale = np.array(draw(st.lists(st.floats(0, 6), min_size=K, max_size=K)))
    cov = np.array([b.floor * 2 * np.exp(s) * np.eye(4) for s in scale])
    stamp = np.array(draw(st.lists(st.integers(0, k), min_size=K, max_size=K)))
    tombed = draw(st.permutations(pool))[: draw(st.integers(0, K))]
    tombs = np.full((K, 2), -1)
    tombs[: len(tombed), 0] = tombed
    tombs[: len(tombed), 1] = draw(st.lists(st.integers(0, k), min_size=K, max_size=K))[
        : len(tombed)
    ]
    stamp = np.where(status != 0, stamp, 0)
    # a sender buries what its tombstones name (`team.bury`), or its message is refused
    step = dict(zip(tombs[:, 0].tolist(), tombs[:, 1].tolist(), strict=True))
    buried = np.array([step.get(int(lb), -1) > st for lb, st in zip(label, stamp, strict=True)])
    status, label = np.where(buried, 0, status), np.where(buried, -1, label)
    return {
        "mean": mean, "cov": cov, "label": label, "status": status, "stamp": stamp,
        "tombs": tombs,
    }  # fmt: skip


def on_the_wire(content: dict, encoding: str, spec: Spec) -> dict:
    """A full consensus content as a run with `encoding` sends it: with an encoding, its
    confirmed slots listed (`agents.tracked.listed_slots`), packed where the encoding
    packs its rows (`radio.packs`); with the full encoding, as it is."""
    if encoding == "full":
        return content
    tracks = team.TrackSet(
        **{name: value[None, None] for name, value in content.items() if name != "tombs"},
        tombs=content["tombs"][None, None],
    )
    out = listed_slots(tracks, content["status"] == team.CONFIRMED, CODECS[encoding])
    if radio.packs("consensus", encoding):
        out = radio.pack_rows(out, spec.contents("consensus") or {})
    return out


@pytest.mark.parametrize("encoding", ["full", "compact", "quantized"])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_whatever_a_receiver_adopts_its_own_tracks_and_report_pass_its_own_checks(data, encoding):
    scenario = SCENARIO.with_overrides({"radio.encoding": encoding})
    spec = Spec.of(scenario, False)
    agent = tracked_receiver(scenario, ME)
    k = data.draw(st.integers(2, 30), label="k")
    serial = data.draw(st.integers(0, 4), label="serial")
    points = np.array([[200.0, 200.0, 1.0, 0.0], [260.0, 180.0, 0.0, 1.0], [150, 300, 0, 0]])
    # the receiver's own tracks: admitted, with labels it could hold (none unissued)
    own = data.draw(track_content(spec, k, serial, points), label="own")
    mine = manage.unissued(own["label"], serial, spec.m, (ME, spec.n))
    own["status"], own["label"] = np.where(mine, 0, own["status"]), np.where(mine, -1, own["label"])
    sent = on_the_wire(own, encoding, spec)
    assert not isinstance(spec.radio(consensus_message(sent, k, ME), k), str)
    agent.serial = serial
    state = (
        team.TrackSet(**{name: value[None, None] for name, value in own.items() if name != "tombs"},
                      tombs=own["tombs"][None, None]),
        np.zeros((1, 1, spec.slots), dtype=np.int8),
    )  # fmt: skip
    rounds = data.draw(st.integers(1, 3), label="rounds")
    for _ in range(rounds):
        contents = {}
        for q in SENDERS:
            offer = data.draw(track_content(spec, k, serial, points), label=f"from {q}")
            admitted = spec.radio(consensus_message(on_the_wire(offer, encoding, spec), k, q), k)
            if isinstance(admitted, str):
                continue  # only what the rule admits reaches a receiver, as it reads it
            contents[q] = admitted[0][3]
        state = agent._agree(state, contents)
    agreed, changed = state
    label = agreed.label[0, 0]
    assert len(set(label[label >= 0].tolist())) == int((label >= 0).sum())  # the round's

    # the next cycle: the book after fusion, its scan with births, what it then sends
    book = manage.Book(
        label=agreed.label, status=agreed.status, stamp=agreed.stamp,
        hits=np.ones_like(agreed.label), scans=np.ones_like(agreed.label),
        misses=np.zeros_like(agreed.label), serial=np.array([[serial]]),
    )  # fmt: skip
    book = manage.after_fusion(book, agreed.label, agreed.status, changed, scenario, agreed.stamp)
    believed = np.array([200.0, 200.0, 425.0, 15.0, 0.0])
    z = np.array(data.draw(st.lists(st.floats(150, 250), min_size=8, max_size=8))).reshape(4, 2)
    R = np.broadcast_to(4.0 * np.eye(2), (4, 2, 2))
    scanned = manage.scan(
        book, agreed.mean, agreed.cov, z[None, None], R[None, None],
        np.ones((1, 1, 4), dtype=bool), believed[None, None], np.ones((1, 1), dtype=bool),
        scenario, None, agent.ctx.const.tracker, k + 1, (ME, spec.n),
    )  # fmt: skip
    offered = scanned_tracks(scanned, agreed.tombs, k + 1)
    content = {
        "mean": offered.mean[0, 0], "cov": offered.cov[0, 0], "label": offered.label[0, 0],
        "status": offered.status[0, 0].astype(np.int64), "stamp": offered.stamp[0, 0],
        "tombs": offered.tombs[0, 0],
    }  # fmt: skip
    admitted = spec.radio(consensus_message(on_the_wire(content, encoding, spec), k + 1, ME), k + 1)
    assert not isinstance(admitted, str), admitted
    agent.believed = believed
    slot_bids, best, _ = agent._plan(scanned.book, scanned.mean)
    slot = int(np.argmax(np.where(scanned.book.confirmed[0, 0], slot_bids, -np.inf)))
    slot = slot if scanned.book.confirmed[0, 0].any() else -1
    report = agent._report(
        k + 1, slot, best, scanned.book, scanned.mean, scanned.cov, slot_bids, rounds,
        (0, 0), np.zeros(2),
    )  # fmt: skip
    checked = spec.report(report)
    assert not isinstance(checked, str), checked


def test_a_label_of_the_receivers_own_it_has_not_issued_is_left_out_and_counted():
    """The lie that took honest programs down: a member offers the label the receiver
    will give its next birth. Left out, the receiver's next birth holds it once."""
    scenario = SCENARIO
    spec = Spec.of(scenario, False)
    agent = tracked_receiver(scenario, ME)
    agent.serial = 1  # it issued m + 0 n + ME; its next birth takes m + n + ME
    K, m, n = spec.slots, spec.m, spec.n
    mine = m + n + ME
    status = np.zeros(K, dtype=np.int64)
    status[0] = 2
    label = np.full(K, -1)
    label[0] = mine
    offer = {
        "mean": np.tile([800.0, 800.0, 0.0, 0.0], (K, 1)),
        "cov": np.broadcast_to(9.0 * np.eye(4), (K, 4, 4)).copy(),
        "label": label, "status": status, "stamp": np.zeros(K, np.int64),
        "tombs": np.full((K, 2), -1),
    }  # fmt: skip
    assert not isinstance(spec.radio(consensus_message(offer, 3, 1), 3), str)  # admitted
    own = team.TrackSet(
        mean=np.zeros((1, 1, K, 4)), cov=np.broadcast_to(np.eye(4), (1, 1, K, 4, 4)).copy(),
        label=np.full((1, 1, K), -1), status=np.zeros((1, 1, K), np.int8),
        stamp=np.zeros((1, 1, K), np.int64), tombs=np.full((1, 1, K, 2), -1),
    )  # fmt: skip
    agreed, _ = agent._agree((own, np.zeros((1, 1, K), np.int8)), {1: offer})
    assert (agreed.status == 0).all()  # nothing adopted
    assert agent.mailbox.drops == {"label not issued": 1}
    # an issued label of its own, or another UAV's, is taken
    offer["label"][0] = m + ME
    agreed, _ = agent._agree((own, np.zeros((1, 1, K), np.int8)), {1: offer})
    assert agreed.label[0, 0, 0] == m + ME and agreed.status[0, 0, 0] == 2
    assert manage.unissued(np.array([m + ME, mine, m + n + 1, 3]), 1, m, (ME, n)).tolist() == [
        False, True, False, False,
    ]  # fmt: skip


def test_tombstones_of_a_track_the_sender_holds_refuse_its_message():
    """An honest sender buries the tracks its tombstones name (`team.bury`): a message
    holding one with an older stamp is a lie about the deletion, or about the track."""
    spec = Spec.of(SCENARIO, False)
    K, k = spec.slots, 6
    status, label, stamp = np.zeros(K, np.int64), np.full(K, -1), np.zeros(K, np.int64)
    status[:2], label[:2], stamp[:2] = 2, [0, 3], [4, 6]
    tombs = np.full((K, 2), -1)
    content = {
        "mean": np.tile([200.0, 200.0, 0.0, 0.0], (K, 1)),
        "cov": np.broadcast_to(9.0 * np.eye(4), (K, 4, 4)).copy(),
        "label": label, "status": status, "stamp": stamp, "tombs": tombs,
    }  # fmt: skip

    def reason(deleted):
        tombs[:] = -1
        if deleted:
            tombs[: len(deleted)] = deleted
        out = spec.radio(consensus_message(content, k, 1), k)
        return out if isinstance(out, str) else None

    assert reason([]) is None
    assert reason([(0, 5)]) == "tombstone of a track it holds"  # deleted after its stamp 4
    assert reason([(0, 4), (3, 6)]) is None  # met at the deletion's step: it knows better
    assert reason([(5, 6), (3, 6)]) is None  # a label it does not hold
    assert reason([(5, 6), (3, 7 - 1), (0, 6)]) == "tombstone of a track it holds"
