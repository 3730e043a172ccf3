"""Bytes on the air: the batch's count of the agent form's frames (`radio.frame_bytes`)
against the encoder itself, and a swarm's frames against `uavtrack run`'s count."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import uavtrack
from uavtrack import radio
from uavtrack.agents.messages import DOMAINS, VERSION, Part, Radio, Spec, encode, packed
from uavtrack.agents.security import Gate
from uavtrack.faults import PROTOCOLS
from uavtrack.tracks import manage

PARTS = ("flood", "consensus", "beacon", "bids", "upload", "download")


def content_of(layout: radio.Layout, rows: int, rng: np.random.Generator) -> dict:
    out = {}
    for name, (dtype, shape) in layout.items():
        shape = (rows, *shape[1:]) if shape[:1] == (-1,) else shape
        out[name] = rng.normal(size=shape).astype(np.dtype(dtype))
    return out


@st.composite
def frames(draw):
    n = draw(st.integers(1, 300))
    m = draw(st.integers(1, 40))
    slots = draw(st.sampled_from([0, draw(st.integers(1, 20))]))
    avoid = draw(st.booleans())
    book = draw(st.sampled_from([(), ("existence",), ("close",), ("existence", "close")]))
    count = draw(st.integers(1, 3))
    parts = []
    for _ in range(count):
        protocol = draw(st.sampled_from(PARTS))
        round_ = draw(st.integers(0, 300))
        final = draw(st.sampled_from([-1, round_]))
        rows = draw(st.integers(0, 300))
        empty = draw(st.booleans()) and protocol == "consensus"
        parts.append((protocol, round_, final, None if empty else rows))
    k = draw(st.sampled_from([0, 1, 127, 128, 255, 256, 65535, 65536, 2**32]))
    sender = draw(st.integers(0, n - 1))
    receiver = draw(st.integers(0, n))
    return n, m, slots, avoid, book, parts, k, sender, receiver


@settings(max_examples=150, deadline=None)
@given(frames())
def test_the_counted_bytes_of_a_frame_are_those_the_agents_put_on_the_wire(frame):
    # every MessagePack size class is crossed: ints of 1-9 bytes, strings, binaries of
    # 8- and 16-bit lengths, variable rows (a scan), parts without content
    n, m, slots, avoid, book, parts, k, sender, receiver = frame
    rng = np.random.default_rng(0)
    wire, counted, count = [], 0, len(parts)
    for protocol, round_, final, rows in parts:
        layout = radio.layout(protocol, n, m, slots, avoid, book=book)
        if rows is None:
            wire.append(Part(protocol, round_, final, None))
            counted += int(radio.part_bytes(protocol, round_, final, None))
            continue
        content = content_of(layout, rows, rng)
        wire.append(Part(protocol, round_, final, packed(content)))
        size = radio.content_bytes(layout, rows)
        counted += int(radio.part_bytes(protocol, round_, final, size))
    run = "0123456789ab"
    assert len(run) == radio.RUN_CHARS
    body = encode(Radio(version=VERSION, run=run, k=k, sender=sender, parts=wire))
    on_wire = len(Gate(run=run, me=sender, programs=n + 1, credential=None).seal(receiver, body))
    assert on_wire == int(radio.frame_bytes(k, sender, counted, count) + radio.int_bytes(receiver))


@settings(max_examples=100, deadline=None)
@given(
    st.integers(2, 300).flatmap(
        lambda n: st.tuples(
            st.just(n),
            st.lists(st.integers(0, n), min_size=2, max_size=min(n + 1, 40), unique=True),
        )
    ),
    st.integers(0, 70000),
    st.booleans(),
)
def test_a_frame_to_several_receivers_is_counted_as_the_agents_put_it_on_the_wire(
    team, body_bytes, sign
):
    # radio.frames = "broadcast": one copy, less its receiver's number, plus
    # `broadcast_bytes` and every receiver's number; keyed or not, the same size
    n, receivers = team
    run = "0123456789ab"
    credential = None
    if sign:
        from uavtrack.agents.security import Keyring

        ring = Keyring(run, n + 1)
        credential = ring.credential(0)
    gate = Gate(run=run, me=0, programs=n + 1, credential=credential)
    if sign:
        gate.learn(ring.public())
    body = b"x" * body_bytes
    copy = len(gate.seal(receivers[0], body)) - radio.int_bytes(receivers[0])
    named = sum(radio.int_bytes(r) for r in receivers)
    counted = copy + radio.broadcast_bytes(len(receivers)) + named
    assert len(gate.seal_for(receivers, body)) == counted


def test_the_int_sizes_are_messagepacks_at_every_boundary():
    import msgspec

    values = [0, 127, 128, 255, 256, 65535, 65536, 2**32 - 1, 2**32, 2**62]
    values += [-1, -32, -33, -128, -129, -32768, -32769, -(2**31), -(2**31) - 1]
    for v in values:
        assert int(radio.int_bytes(v)) == len(msgspec.msgpack.encode(v)), v
    for size in [0, 255, 256, 65535, 65536]:
        assert int(radio.bin_bytes(size)) == len(msgspec.msgpack.encode(b"x" * size))
    for chars in [0, 31, 32, 255, 256]:
        assert int(radio.str_bytes(chars)) == len(msgspec.msgpack.encode("x" * chars))


@pytest.mark.parametrize("tracked", [False, True])
@pytest.mark.parametrize("avoid", [False, True])
def test_the_batch_layouts_are_what_the_agents_admit(tracked, avoid):
    overrides = {"planner.avoidance": "loiter" if avoid else "none"}
    if tracked:  # existence (the default) and merging: the download carries both
        overrides |= {"tracker.association": "gnn", "tracker.merge": 2}
    scenario = uavtrack.Scenario().with_overrides(overrides)
    spec = Spec.of(scenario, central=True)
    K = scenario.track_slots if tracked else 0
    book = manage.sent_fields(scenario.tracker) if tracked else ()
    assert book == (("existence", "close") if tracked else ())
    for protocol in PARTS:
        layout = radio.layout(protocol, scenario.n_uavs, scenario.n_targets, K, avoid, book=book)
        admitted = spec.contents(protocol)
        assert admitted is not None
        assert {name: kind[:2] for name, kind in admitted.items()} == layout, protocol
        assert {kind[2] for kind in admitted.values()} <= set(DOMAINS), protocol
    assert set(PARTS) <= set(PROTOCOLS)


def test_the_frame_size_depends_on_no_sequence_number_and_no_setting():
    # sequence numbers start above 2**32 (always 9 bytes); unauthenticated frames carry a
    # checksum as long as an authenticated frame's MAC
    gate = Gate(run="0123456789ab", me=0, programs=3, credential=None)
    sizes = {len(gate.seal(1, b"x" * 10)) for _ in range(300)}
    assert len(sizes) == 1


def test_bytes_follow_the_team_and_its_links():
    # a UAV with nobody in range sends no frame; the centralized UAVs one upload each
    alone = uavtrack.Scenario(steps=5, comm_range=1e-3)
    lonely = uavtrack.simulate(alone, "distributed", seed=0)
    assert lonely.trace is not None
    assert lonely.trace.bytes.sum() == 0 and lonely.bytes == 0
    scenario = uavtrack.Scenario(steps=5)
    central = uavtrack.simulate(scenario, "centralized", seed=0)
    assert central.trace is not None
    up = central.trace.bytes
    n, m = scenario.n_uavs, scenario.n_targets
    content = radio.content_bytes(radio.layout("upload", n, m))
    frame = radio.frame_bytes(0, 0, radio.part_bytes("upload", 0, -1, content), 1)
    assert (up == frame + radio.int_bytes(n)).all()  # cycle 0 and 1-byte ints throughout
    content = radio.content_bytes(radio.layout("download", n, m))
    frame = radio.frame_bytes(0, n, radio.part_bytes("download", 0, -1, content), 1)
    assert (central.trace.node_bytes == n * (frame + 1)).all()  # one to each UAV
    every = central.trace.bytes.sum(axis=1) + central.trace.node_bytes
    assert central.bytes == pytest.approx(every.mean() / n)


@pytest.mark.integration  # a swarm of programs
@pytest.mark.parametrize(
    ("method", "frames"),
    [
        ("distributed", "unicast"),
        ("greedy", "unicast"),
        ("centralized", "unicast"),
        ("distributed", "broadcast"),
        ("centralized", "broadcast"),
    ],
)
def test_a_swarms_frames_on_the_wire_are_the_bytes_the_batch_counts(method, frames):
    from uavtrack.agents import run_swarm

    scenario = uavtrack.Scenario(steps=8).with_overrides(
        {
            "faults.loss": 0.2,
            "radio.frames": frames,
            "planner.avoidance": "loiter",
            # a budget that binds: rounds (downloads) are left unsent
            "radio.bandwidth_bps": 6e4 if method == "distributed" else 1.5e5,
        }
        if frames == "broadcast"
        else {"faults.loss": 0.2}
    )
    batch = uavtrack.simulate(scenario, method, seed=4)
    swarm = run_swarm(scenario, method, seed=4, transport="memory")
    assert batch.trace is not None and swarm.result.trace is not None
    assert batch.trace.bytes.sum() > 0
    assert np.array_equal(swarm.result.trace.bytes, batch.trace.bytes)
    # the radio is most of what the programs publish (the rest: reports to the world)
    assert np.array_equal(swarm.result.trace.node_bytes, batch.trace.node_bytes)
    on_air = batch.trace.bytes.sum() + batch.trace.node_bytes.sum()
    assert on_air <= swarm.traffic.bytes
    if frames == "unicast":  # a frame to several is published to each receiver's key
        assert 0.5 * swarm.traffic.bytes < on_air


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(st.integers(0, 9), st.integers(0, 9), st.booleans()), min_size=6, max_size=6)
)
def test_the_rounds_counted_at_once_are_those_counted_frame_by_frame(uavs):
    # the closed form (rounds below 128) against the frame-by-frame rule it sums
    from uavtrack.config import FaultModel
    from uavtrack.faults import Faults
    from uavtrack.network import links

    ran = np.array([[u[0] for u in uavs]])
    rounds = np.array([[u[1] for u in uavs]])
    alive = np.array([[u[2] for u in uavs]])
    adjacency = np.random.default_rng(len(uavs)).random((1, 6, 6)) < 0.5
    adjacency = (adjacency | adjacency.transpose(0, 2, 1)) & alive[:, None] & alive[:, :, None]
    realised = Faults(FaultModel(), np.array([[1, 2]], dtype=np.uint32), 6)
    for broadcast in (False, True):
        counts = []
        for method in ("rounds_on_air", "_rounds_one_by_one"):
            wireless = radio.Radio(
                300, links(adjacency), alive, realised, radio.RadioState(), broadcast=broadcast
            )
            getattr(wireless, method)(ran, rounds, 70, 900, alive)
            counts.append(wireless.bytes)
        assert np.array_equal(*counts)
        assert (counts[0][0, :6][~alive[0]] == 0).all()
