"""Only the swarm's members speak in it: authentication, replay windows, message checks,
and attacks on a running swarm (forged, malformed and replayed messages, forged tokens)."""

import threading
import time

import msgspec
import numpy as np
import pytest

import uavtrack
from uavtrack.agents import messages, run_swarm
from uavtrack.agents.messages import VERSION, Array, Part, Radio, Report, Sense, Spec, encode
from uavtrack.agents.security import (
    EVERYONE,
    WINDOW,
    WORLD,
    Credential,
    Envelope,
    Gate,
    Keyring,
    tag_of,
)
from uavtrack.agents.transport import Bus, Mailbox, MemoryTransport
from uavtrack.testing import assert_same_trace

pytest.importorskip("cryptography")

RUN = "0123456789ab"
SEQ = 2**32 + 5


def gates(programs=3):
    """The world's gate and each program's, of one run, all knowing the public keys."""
    ring = Keyring(RUN, programs)
    world = ring.gate()
    out = []
    for p in range(programs):
        gate = Gate(run=RUN, me=p, programs=programs, credential=ring.credential(p))
        gate.learn(ring.public())
        out.append(gate)
    return ring, world, out


def test_a_sealed_message_opens_only_at_its_receiver_and_only_once():
    _, world, (g0, g1, g2) = gates()
    payload = g0.seal(1, b"body")
    assert g1.open(payload) == (0, b"body")
    assert g1.open(payload) == "replayed"
    assert g2.open(payload) == "not for this program"
    assert world.open(g0.seal(WORLD, b"report")) == (0, b"report")
    assert g2.open(world.seal(2, b"sense")) == (WORLD, b"sense")


def test_one_member_cannot_speak_as_another():
    _, _, (g0, g1, g2) = gates()
    # program 2 holds its own key only: a message it makes in 0's name does not open at 1
    forged = msgspec.msgpack.decode(g2.seal(1, b"bids"), type=Envelope)
    as_zero = msgspec.msgpack.encode(
        Envelope(sender=0, receiver=1, seq=forged.seq, body=b"bids", tag=forged.tag)
    )
    assert g1.open(as_zero) == "not authentic"
    # nor does a tag moved onto another body, or onto another sequence number
    genuine = msgspec.msgpack.decode(g0.seal(1, b"bids"), type=Envelope)
    for envelope in (
        Envelope(sender=0, receiver=1, seq=genuine.seq, body=b"other bids", tag=genuine.tag),
        Envelope(sender=0, receiver=1, seq=genuine.seq + 1, body=genuine.body, tag=genuine.tag),
    ):
        assert g1.open(msgspec.msgpack.encode(envelope)) == "not authentic"
    assert g1.drops == {"not authentic": 3}


def test_a_stranger_with_keys_of_its_own_is_not_heard():
    _, _, (g0, g1, _) = gates()
    stranger = Keyring(RUN, 3)  # the same run id, other keys
    intruder = Gate(run=RUN, me=0, programs=3, credential=stranger.credential(0))
    intruder.learn(stranger.public())
    assert g1.open(intruder.seal(1, b"consensus")) == "not authentic"
    hello = stranger.gate().seal(EVERYONE, b"hello")
    assert g1.open(hello) == "not authentic"


def test_only_the_world_signs_a_broadcast():
    ring, world, (g0, g1, _) = gates()
    assert g1.open(world.seal(EVERYONE, b"hello")) == (WORLD, b"hello")
    # a program claiming to be the world, or broadcasting in its own name
    envelope = msgspec.msgpack.decode(g0.seal(1, b"hello"), type=Envelope)
    for sender in (WORLD, 0):
        forged = Envelope(
            sender=sender, receiver=EVERYONE, seq=envelope.seq, body=b"hello", tag=envelope.tag
        )
        assert g1.open(msgspec.msgpack.encode(forged)) in ("not authentic", "unknown sender")


def test_malformed_and_unknown_envelopes_are_dropped_by_reason():
    _, _, (g0, g1, _) = gates()
    good = g0.seal(1, b"x")
    for payload, reason in (
        (b"", "malformed"),
        (b"\x93garbage", "malformed"),
        (good[:-3], "malformed"),
        (
            msgspec.msgpack.encode(Envelope(sender=7, receiver=1, seq=1, body=b"x", tag=b"")),
            "unknown sender",
        ),
        (
            msgspec.msgpack.encode(Envelope(sender=1, receiver=1, seq=1, body=b"x", tag=b"")),
            "unknown sender",
        ),
        (
            msgspec.msgpack.encode(Envelope(sender=0, receiver=1, seq=-5, body=b"x", tag=b"")),
            "malformed",
        ),
    ):
        assert g1.open(payload) == reason


def test_a_frame_to_several_opens_at_each_receiver_named_and_nowhere_else():
    # radio.frames = "broadcast": one envelope, a tag per receiver under that pair's key
    _, world, gates_ = gates(4)
    g0, g1, g2, g3 = gates_
    payload = g0.seal_for([1, 3], b"bids")
    assert g1.open(payload) == (0, b"bids")
    assert g3.open(payload) == (0, b"bids")
    assert g1.open(payload) == "replayed"
    assert g2.open(payload) == "not for this program"
    assert world.open(payload) == "not for this program"


def test_a_member_who_hears_a_frame_to_several_cannot_change_it_for_the_others():
    """Program 1 receives 0's frame to 1 and 2, with 2's tag in it. Whatever it changes
    (the body, the sequence number, its own tag moved to 2's place, 2 dropped or
    itself named twice, the sender), 2 opens nothing; it can only pass the frame on
    unchanged, which delivers to 2 what 0 said to 2 (a relay, as any radio allows)."""
    _, _, (g0, g1, g2, _) = gates(4)
    payload = g0.seal_for([1, 2], b"bids")
    genuine = msgspec.msgpack.decode(payload, type=Envelope)
    assert isinstance(genuine.tag, list) and isinstance(genuine.receiver, list)
    mine, theirs = genuine.tag
    forged = [
        dict(body=b"other bids"),
        dict(seq=genuine.seq + 1),
        dict(tag=[mine, mine]),
        dict(sender=1, tag=[theirs, theirs]),
        dict(receiver=2, tag=mine),  # as a frame to 2 alone, with 1's tag
        dict(receiver=[2, 1]),  # the receivers swapped, the tags not
    ]
    fields = ("sender", "receiver", "seq", "body", "tag")
    reasons = []
    for change in forged:
        values = {f: change.get(f, getattr(genuine, f)) for f in fields}
        reasons.append(g2.open(msgspec.msgpack.encode(Envelope(**values))))
    assert reasons == ["not authentic"] * 6
    # the receivers are not in the tags: a list that keeps 2's own tag is a relay of the
    # frame, and delivers to 2 what 0 said to 2, once
    relayed = Envelope(
        sender=0, receiver=[1, 2, 3], seq=genuine.seq, body=genuine.body, tag=[mine, theirs, mine]
    )
    assert g2.open(msgspec.msgpack.encode(relayed)) == (0, b"bids")
    assert g2.open(payload) == "replayed"


def test_a_malformed_list_of_receivers_is_dropped_before_any_tag_is_checked():
    _, _, (g0, g1, _, _) = gates(4)
    tag = b"t" * 16
    for receiver, tags in (
        ([1], [tag]),  # a list of one: a plain envelope names its receiver
        ([1, 1], [tag, tag]),  # a receiver twice
        ([1, 2], [tag]),  # lists of different lengths
        (list(range(6)), [tag] * 6),  # more receivers than the run has programs
        ([1, 2], tag),  # a list of receivers with one tag
        (1, [tag, tag]),  # one receiver with a list of tags
    ):
        envelope = Envelope(sender=0, receiver=receiver, seq=SEQ, body=b"x", tag=tags)
        assert g1.open(msgspec.msgpack.encode(envelope)) == "malformed", receiver
    with pytest.raises(ValueError, match="two or more"):
        g0.seal_for([1, 1], b"x")


def test_the_replay_window_takes_late_numbers_once_and_refuses_old_ones():
    _, _, (g0, g1, _) = gates()
    sealed = [g0.seal(1, bytes([i])) for i in range(5)]
    for i in (4, 0, 2):  # out of order: each once
        assert g1.open(sealed[i]) == (0, bytes([i]))
    assert g1.open(sealed[2]) == "replayed"
    assert g1.open(sealed[1]) == (0, b"\x01")
    g0._seq += WINDOW + 10  # a sender far ahead: the oldest numbers fall out of the window
    assert g1.open(g0.seal(1, b"late")) == (0, b"late")
    assert g1.open(sealed[3]) == "replayed"


def test_a_key_file_is_private_never_overwritten_and_read_back(tmp_path):
    ring = Keyring(RUN, 2)
    path = tmp_path / "k.key"
    ring.credential(1).write(path)
    assert oct(path.stat().st_mode & 0o777) == "0o600"
    assert Credential.read(path) == ring.credential(1)
    with pytest.raises(FileExistsError):
        ring.credential(0).write(path)
    (tmp_path / "link").symlink_to(path)
    with pytest.raises(ValueError, match="cannot read"):
        Credential.read(tmp_path / "link")
    (tmp_path / "bad").write_text('{"uavtrack_credential": 1, "run": "x"}')
    (tmp_path / "bad").chmod(0o600)
    with pytest.raises(ValueError, match="missing or malformed"):
        Credential.read(tmp_path / "bad")


@pytest.mark.parametrize("mode", [0o644, 0o640, 0o604, 0o660, 0o606], ids=lambda m: f"{m:04o}")
def test_a_key_file_open_to_others_is_refused_with_the_fix(tmp_path, mode):
    # as ssh refuses a private key: a key file others may read may have been stolen
    path = tmp_path / "k.key"
    Keyring(RUN, 2).credential(1).write(path)
    path.chmod(mode)
    with pytest.raises(ValueError) as refused:
        Credential.read(path)
    said = str(refused.value)
    assert f"permissions {mode:04o} are too open" in said and f"chmod 600 {path}" in said
    path.chmod(0o600)  # the fix it names works
    assert Credential.read(path).program == 1


def test_a_key_file_is_written_private_whatever_the_umask(tmp_path):
    import os

    old = os.umask(0o277)  # would leave a file created 0600 at 0400
    try:
        Keyring(RUN, 2).credential(0).write(tmp_path / "k.key")
    finally:
        os.umask(old)
    assert (tmp_path / "k.key").stat().st_mode & 0o777 == 0o600
    assert Credential.read(tmp_path / "k.key").program == 0


def test_uavtrack_agent_refuses_a_key_file_others_can_read(tmp_path, capsys):
    from uavtrack import cli

    path = tmp_path / "k.key"
    Keyring(RUN, 2).credential(1).write(path)
    path.chmod(0o644)
    code = cli.main(["agent", "--key", str(path), "--connect", "tcp/127.0.0.1:1"])
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "--key:" in err and "0644 are too open" in err and f"chmod 600 {path}" in err


# ------------------------------------------------------------------ what a run admits


def spec(n=3, m=2):
    return Spec(n=n, m=m, programs=n, actions=3, rounds=n + 3, behind=1)


def radio(parts, k=0, sender=1):
    return Radio(version=VERSION, run=RUN, k=k, sender=sender, parts=parts)


def test_radio_parts_of_the_wrong_shape_type_value_round_or_cycle_are_refused():
    s = spec()
    good = {"known": Array.of(np.array([True, True, False]))}  # the sender knows itself
    assert isinstance(s.radio(radio([Part("flood", 1, -1, good)]), 0), list)
    cases = {
        "wrong shape or type": [
            Part("flood", 1, -1, {"known": Array.of(np.ones(4, dtype=bool))}),
            Part("flood", 1, -1, {"known": Array.of(np.ones(3))}),
            Part("beacon", 0, -1, {"position": Array("<f8", (3,), b"\x00" * 5)}),
        ],
        "not finite": [Part("beacon", 0, -1, {"position": Array.of(np.array([0, np.nan, 1.0]))})],
        "unexpected fields": [Part("flood", 1, -1, {"known": good["known"], "x": good["known"]})],
        "unknown protocol": [Part("gossip", 1, -1, good), Part("presence", 0, 0, good)],
        "round out of range": [Part("flood", 99, -1, good), Part("flood", 2, 3, good)],
    }
    for reason, parts in cases.items():
        for p in parts:
            assert s.radio(radio([p]), 0) == reason, (reason, p)
    assert s.radio(radio([Part("flood", 1, -1, good)], k=9), 0) == "outside the window of cycles"
    # a bid may be NaN (not scored), never infinite; a confidence may be -inf, never +inf
    bids = {"bids": Array.of(np.array([np.nan, 1.0])), "stamp": Array.of(np.array(0))}
    assert isinstance(s.radio(radio([Part("bids", 0, -1, bids)]), 0), list)
    bids["bids"] = Array.of(np.array([np.inf, 1.0]))
    assert s.radio(radio([Part("bids", 0, -1, bids)]), 0) == "not finite"


def report(**change):
    fields = dict(
        version=VERSION,
        run=RUN,
        k=0,
        uav=1,
        action=2,
        target=1,
        mean=Array.of(np.zeros((2, 4))),
        cov=Array.of(np.broadcast_to(np.eye(4), (2, 4, 4))),  # positive definite
        bids=Array.of(np.zeros(2)),
        rounds=1,
        sent=1,
        delivered=1,
        decision_ms=1.0,
        decision_wall_ms=1.5,
    )
    return Report(**{**fields, **change})


@pytest.mark.parametrize(
    "change,reason",
    [
        ({"action": 99}, "action or target out of range"),
        ({"action": -1}, "action or target out of range"),
        ({"target": 2}, "action or target out of range"),
        ({"target": -1}, "action or target out of range"),
        ({"mean": Array.of(np.zeros((3, 4)))}, "wrong shape or type"),
        ({"cov": Array.of(np.full((2, 4, 4), np.inf))}, "not finite"),
        ({"rounds": -3}, "count out of range"),
        ({"decision_ms": float("nan")}, "not finite"),
        ({"decision_wall_ms": -1.0}, "not finite"),
    ],
)
def test_a_report_the_run_cannot_fly_is_refused(change, reason):
    assert isinstance(spec().report(report()), dict)
    assert spec().report(report(**change)) == reason


def test_a_tracked_report_carries_existence_in_zero_to_one():
    s = Spec(n=3, m=2, programs=3, actions=3, rounds=6, behind=1, slots=3, labels=50)
    tracked = dict(
        mean=Array.of(np.zeros((3, 4))),
        cov=Array.of(np.broadcast_to(np.eye(4), (3, 4, 4))),
        bids=Array.of(np.array([0.5, np.nan, np.nan])),
        target=7,
        label=Array.of(np.array([7, 9, -1])),
        status=Array.of(np.array([2, 1, 0])),
        existence=Array.of(np.array([0.97, 0.4, 0.0])),
    )
    assert isinstance(s.report(report(**tracked)), dict)
    for bad, reason in [
        (np.array([1.5, 0.4, 0.0]), "probability out of range"),
        (np.array([0.9, -0.1, 0.0]), "probability out of range"),
        (np.array([np.nan, 0.4, 0.0]), "not finite"),
        (np.array([0.9, 0.4]), "wrong shape or type"),
    ]:
        assert s.report(report(**{**tracked, "existence": Array.of(bad)})) == reason
    assert s.report(report(**{**tracked, "existence": None})) == "unexpected fields"


def test_a_download_whose_existence_is_no_probability_is_refused():
    """The central node's tracks carry each slot's existence (tracker.confirmation
    existence): a UAV adopts them whole, so one outside [0, 1] is refused at the door."""
    s = Spec(n=3, m=2, programs=4, actions=3, rounds=6, behind=1, slots=3, labels=50,
             book=("existence",))  # fmt: skip
    counts = {name: np.array([3, 1, 0]) for name in ("hits", "scans", "misses")}
    content = dict(
        mean=np.zeros((3, 4)), cov=np.broadcast_to(np.eye(4), (3, 4, 4)),
        label=np.array([7, 9, -1]), status=np.array([2, 1, 0]), stamp=np.array([0, 0, 0]),
        **counts, serial=np.array(4), target=np.array(7), existence=np.array([0.97, 0.4, 0.0]),
    )  # fmt: skip

    def download(**change):
        wire = {k: Array.of(v) for k, v in {**content, **change}.items()}
        return s.radio(radio([Part("download", 0, -1, wire)], sender=3), 0)

    assert isinstance(download(), list)
    assert download(existence=np.array([2.0, 0.4, 0.0])) == "probability out of range"
    assert download(existence=np.array([0.9, -1.0, 0.0])) == "probability out of range"


def test_a_sense_of_another_uav_or_of_the_wrong_shape_is_refused():
    s = spec()

    def sense(**change):
        fields = dict(
            version=VERSION,
            run=RUN,
            k=0,
            uav=1,
            believed=Array.of(np.zeros(5)),
            observed=Array.of(np.array([True, False])),
            z=Array.of(np.zeros((1, 2))),
            links=Array.of(np.zeros(3, dtype=bool)),
            alive=Array.of(np.ones(3, dtype=bool)),
        )
        return Sense(**{**fields, **change})

    assert isinstance(s.sense(sense(), 1), dict)
    assert s.sense(sense(), 2) == "not for this program"
    assert s.sense(sense(z=Array.of(np.zeros((2, 2)))), 1) == "wrong shape or type"
    assert s.sense(sense(links=Array.of(np.zeros(30, dtype=bool))), 1) == "wrong shape or type"
    assert s.sense(sense(believed=Array.of(np.full(5, np.nan))), 1) == "not finite"


def test_a_mailbox_keeps_a_bounded_window_whatever_a_member_sends():
    ring, _, (g0, g1, _) = gates()
    box = Mailbox(g1, spec())
    box.begin(5, 4)
    known = {"known": Array.of(np.ones(3, dtype=bool))}
    for k in range(0, 200):  # a member floods every cycle, past and future, every round
        for r in range(0, 10):
            message = radio([Part("flood", r, -1, known)], k=k, sender=0)
            box.handler("k", g0.seal(1, encode(message)))
    cycles = {slot[0] for slot in box.radio}
    assert cycles <= set(range(4, 8)) and len(box.radio) == len(cycles)
    assert all(len(rounds) <= spec().rounds + 1 for rounds in box.radio.values())
    assert box.drops["outside the window of cycles"] > 1500
    assert box.drops["round out of range"] > 0


def test_what_comes_before_the_hello_is_bounded_in_bytes_and_its_drops_counted():
    # before the Hello nothing can be opened, so a program keeps what comes, unverified:
    # whatever a stranger sends, in whatever names, it keeps at most a few MB
    ring, _, (g0, g1, _) = gates()
    box = Mailbox(Gate(run=RUN, me=1, programs=0, credential=ring.credential(1)))

    def kept():
        return sum(len(p) for queue in box._early.values() for p in queue)

    junk = b"\x00" * (1 << 20)
    for sender in range(12):  # 12 MB of large messages, each in another's name
        box.handler(
            "k",
            msgspec.msgpack.encode(Envelope(sender=sender, receiver=1, seq=1, body=junk, tag=b"")),
        )
    assert kept() == 0 and box.drops == {"too large before the run's keys": 12}
    body = b"\x00" * 60_000  # under a sender's share: 200 senders' worth is 12 MB
    for sender in range(200):
        for seq in (1, 2):
            box.handler(
                "k",
                msgspec.msgpack.encode(
                    Envelope(sender=sender, receiver=1, seq=seq, body=body, tag=b"")
                ),
            )
    assert 3 << 20 < kept() <= 4 << 20  # 4 MB in all
    assert all(len(queue) == 1 for queue in box._early.values())  # one 60 kB each
    assert box.drops["over the buffer before the run's keys"] > 200  # of 400
    # a member's presence said before the Hello is refused while the buffer is full, and
    # opened once said again after it: nothing honest is lost for good
    presence = radio([Part("presence", 0, 0, {"heard": Array.of(np.ones(3, dtype=bool))})], -1, 0)
    box.handler("k", g0.seal(1, encode(presence)))
    box.gate.programs = 3  # the Hello's count, as serve() sets it
    box.learn(spec(), ring.public())
    assert box.early_bytes == 0 and not box._early
    box.handler("k", g0.seal(1, encode(presence)))
    assert box.content(-1, "presence", 0, 0) is not None


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_a_token_is_a_hint_about_programs_heard_and_an_authentic_word_takes_it_back():
    ring, _, (g0, g1, _) = gates()
    bus = Bus()
    box = Mailbox(g1, spec(), MemoryTransport(bus))
    box.transport.watch(f"uavtrack/{RUN}/alive/", box.lost)  # as the world watches
    stranger = MemoryTransport(bus)
    stranger.announce(f"uavtrack/{RUN}/alive/0")  # in 0's name, before 0 said a word
    stranger.announce(f"uavtrack/{RUN}/alive/2")
    stranger.close()  # both go: no one here heard from 0 or 2, nothing is believed
    assert not box.wait(lambda: False, time.monotonic() + 0.3)
    assert not box.gone and not box.suspects
    hello = radio([Part("presence", 0, 0, {"heard": Array.of(np.ones(3, dtype=bool))})], -1, 0)
    member = MemoryTransport(bus)
    member.announce(f"uavtrack/{RUN}/alive/0")  # program 0 makes its token, then speaks
    box.handler("k", g0.seal(1, encode(hello)))
    assert box.heard == {0}
    stranger = MemoryTransport(bus)
    stranger.announce(f"uavtrack/{RUN}/alive/0")
    stranger.close()  # a copy of 0's token goes: 0's own is still there
    assert not box.wait(lambda: False, time.monotonic() + 0.3)
    assert not box.gone
    member.close()  # 0's own token goes: confirmed, 0 is gone
    assert box.wait(lambda: box.is_gone(0), time.monotonic() + 30)
    box.handler("k", g0.seal(1, encode(hello)))  # and yet it speaks: it is back
    assert not box.is_gone(0)


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_tokens_that_come_and_go_without_end_never_hold_a_wait_past_its_deadline():
    _, _, (g0, g1, _) = gates()
    bus = Bus()
    box = Mailbox(g1, spec(), MemoryTransport(bus))
    box.transport.watch(f"uavtrack/{RUN}/alive/", box.lost)  # as the world watches
    member = MemoryTransport(bus)
    member.announce(f"uavtrack/{RUN}/alive/0")
    box.handler("k", g0.seal(1, encode(radio([], -1, 0))))
    stop = threading.Event()
    asked = []
    original = MemoryTransport.alive

    def counted(self, key):
        asked.append(key)
        return original(self, key)

    def flap():  # a copy of member 0's token, and one of 2, which no program holds
        while not stop.is_set():
            for program in (0, 2):
                copy = MemoryTransport(bus)
                copy.announce(f"uavtrack/{RUN}/alive/{program}")
                copy.close()

    box.transport.alive = counted.__get__(box.transport)
    flapper = threading.Thread(target=flap, daemon=True)
    flapper.start()
    done = {}

    def wait():
        start = time.monotonic()
        done["ok"] = box.wait(lambda: False, start + 2.0)
        done["took"] = time.monotonic() - start  # 2 s, or more on a machine that stalls

    waiter = threading.Thread(target=wait)
    try:
        waiter.start()
        waiter.join(60)  # a wait that kept confirming would never end
    finally:
        stop.set()
        flapper.join(10)
    assert done["ok"] is False and not box.gone
    # a check (one query, two when it finds nothing) per half second at most
    assert 1 <= len(asked) <= 2 * (done["took"] / 0.5 + 1)


# ------------------------------------------------------------------ attacks on a swarm


class Intruder:
    """A party on a swarm's bus: it hears every publication (as anyone reaching the
    endpoint of an unencrypted swarm can) and publishes what `act` returns for it."""

    def __init__(self, bus: Bus, act) -> None:
        self.link = MemoryTransport(bus)
        self.act, self.seen, self.busy = act, [], threading.local()
        self.link.subscribe("uavtrack/", self.hear)

    def hear(self, key: str, payload: bytes) -> None:
        if getattr(self.busy, "on", False):
            return
        self.seen.append((key, payload))
        self.busy.on = True
        try:
            for out_key, out in self.act(key, payload):
                self.link.publish(out_key, out)
        finally:
            self.busy.on = False


def attacked_swarm(act, scenario, method="distributed", sign=True, seed=1, patch=None):
    """A memory swarm with an intruder acting on its bus; returns (swarm, intruder)."""
    from uavtrack.agents import swarm as swarm_module

    made = {}
    original = swarm_module.Bus

    def bus():
        made["bus"] = original()
        made["intruder"] = Intruder(made["bus"], act)
        return made["bus"]

    swarm_module.Bus = bus
    try:
        out = run_swarm(scenario, method, seed=seed, transport="memory", sign=sign)
    finally:
        swarm_module.Bus = original
    return out, made["intruder"]


def decode_any(payload):
    """The envelope and message of a payload, whatever the run (None if not one)."""
    try:
        envelope = msgspec.msgpack.decode(payload, type=Envelope)
        message = msgspec.msgpack.Decoder(messages.Message).decode(envelope.body)
    except (msgspec.DecodeError, msgspec.ValidationError):
        return None, None
    return envelope, message


def forge(envelope, message, seq_offset=10**6, **change):
    """The message changed, in a new envelope that claims the same sender, with the
    checksum anyone can make (no valid MAC)."""
    body = encode(msgspec.structs.replace(message, **change))
    sender, receiver, seq = envelope.sender, envelope.receiver, envelope.seq + seq_offset
    forged = Envelope(
        sender=sender,
        receiver=receiver,
        seq=seq,
        body=body,
        tag=tag_of(b"", message.run, sender, receiver, seq, body),
    )
    return msgspec.msgpack.encode(forged)


def forgeries(key, payload):
    """What a stranger makes of each message it hears: the worst it can say in its name."""
    envelope, message = decode_any(payload)
    if message is None:
        return []
    out = []
    if isinstance(message, Radio) and message.k >= 0:
        parts = []
        for p in message.parts:
            content = p.content
            if p.protocol == "consensus" and content is not None:  # a tuple of certainty
                content = dict(content)
                content["gamma"] = Array.of(np.full(content["gamma"].shape[0], 1e12))
                content["mean"] = Array.of(np.full(content["mean"].shape, 5000.0))
            if p.protocol == "bids" and content is not None:  # everyone wants target 0
                content = dict(content)
                bids = np.zeros(content["bids"].shape[0])
                bids[0] = 1e9
                content["bids"] = Array.of(bids)
            parts.append(Part(p.protocol, p.round, p.final, content))
        out.append((key, forge(envelope, message, parts=parts)))
    if isinstance(message, Report):
        out.append((key, forge(envelope, message, action=0, target=0)))
    if isinstance(message, Sense):
        out.append((key, forge(envelope, message, alive=Array.of(np.zeros(5, dtype=bool)))))
    if isinstance(message, messages.Hello):
        prior = np.asarray(message.prior_mean.array()) + 60.0
        out.append((key, forge(envelope, message, prior_mean=Array.of(prior))))
    return out


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_a_strangers_forgeries_change_nothing_and_are_counted():
    scenario = uavtrack.Scenario(steps=12)
    swarm, intruder = attacked_swarm(forgeries, scenario)
    reference = uavtrack.simulate(scenario, "distributed", seed=1)
    assert_same_trace(swarm.result.trace, reference.trace)
    assert swarm.traffic.lost == {}
    forged = swarm.traffic.drops.get("not authentic", 0)
    assert forged >= 12 * 5  # at least a forged Sense and Report per UAV and cycle
    assert set(swarm.traffic.drops) <= {"not authentic", "outside the window of cycles"}


def test_without_signing_the_same_forgeries_take_the_swarm_over():
    # the attack above is real: unsigned, the forged Sense messages fail every UAV
    scenario = uavtrack.Scenario(steps=12)
    swarm, _ = attacked_swarm(forgeries, scenario, sign=False)
    reference = uavtrack.simulate(scenario, "distributed", seed=1)
    assert swarm.result.observation_rate < reference.observation_rate


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_replayed_messages_are_dropped_and_change_nothing():
    scenario = uavtrack.Scenario(steps=10)
    heard = []

    def replay(key, payload):
        heard.append((key, payload))
        return heard[-3:-1]  # the two messages before, again

    swarm, _ = attacked_swarm(replay, scenario)
    reference = uavtrack.simulate(scenario, "distributed", seed=1)
    assert_same_trace(swarm.result.trace, reference.trace)
    assert swarm.traffic.drops.get("replayed", 0) > 100
    assert set(swarm.traffic.drops) <= {"replayed", "outside the window of cycles"}


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_malformed_payloads_on_every_key_change_nothing():
    scenario = uavtrack.Scenario(steps=8)

    def garbage(key, payload):
        envelope, _ = decode_any(payload)
        junk = [b"\xc1not msgpack", payload[: len(payload) // 2]]
        if envelope is not None:
            seq = envelope.seq + 7
            bad = Envelope(
                sender=envelope.sender,
                receiver=envelope.receiver,
                seq=seq,
                body=b"\x93xyz",
                tag=b"",
            )
            junk.append(msgspec.msgpack.encode(bad))
        return [(key, j) for j in junk]

    swarm, _ = attacked_swarm(garbage, scenario)
    reference = uavtrack.simulate(scenario, "distributed", seed=1)
    assert_same_trace(swarm.result.trace, reference.trace)
    assert swarm.traffic.drops["malformed"] > 50


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_a_faulty_member_is_dropped_by_reason_and_never_crashes_the_others(monkeypatch):
    # UAV 2 reports a bank angle that does not exist at step 4, UAV 1 sends consensus
    # tuples of the wrong shape: the world and the neighbours drop them and go on
    from uavtrack.agents import agent

    cycle, send = agent.UavAgent.cycle, agent.AgentRadio.send

    def faulty_cycle(self, k, sense, central=True):
        report = cycle(self, k, sense, central)
        if self.me == 2 and k == 4:
            return msgspec.structs.replace(report, action=99)
        return report

    def faulty_send(self, k, parts, to=None):
        if self.me == 1:
            parts = [
                Part(p.protocol, p.round, p.final, {n: Array.of(np.zeros(7)) for n in p.content})
                if p.protocol == "consensus" and p.content is not None
                else p
                for p in parts
            ]
        send(self, k, parts, to)

    monkeypatch.setattr(agent.UavAgent, "cycle", faulty_cycle)
    monkeypatch.setattr(agent.AgentRadio, "send", faulty_send)
    scenario = uavtrack.Scenario(steps=6, comm_range=80.0)
    swarm = run_swarm(scenario, "distributed", seed=1, transport="memory", deadline=0.1)
    drops = swarm.traffic.drops
    assert drops["action or target out of range"] == 1
    assert drops["wrong shape or type"] > 0
    assert swarm.traffic.lost == {2: 4}  # its report was refused: it decided nothing
    trace = swarm.result.trace
    assert not trace.alive[4:, 2].any() and trace.alive[:, [0, 1, 3, 4]].all()
    assert np.isfinite(swarm.result.ospa) and np.isfinite(swarm.result.rmse)


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_a_forged_liveliness_token_loses_no_healthy_uav():
    scenario = uavtrack.Scenario(steps=10)
    done = {}

    from uavtrack.agents import swarm as swarm_module

    original = swarm_module.Bus

    class Watched(original):
        def __init__(self):
            super().__init__()
            Intruder(self, lambda key, payload: self.forge(key))

        def forge(self, key):
            if key.endswith("/to/world") and not done:
                done["key"] = f"uavtrack/{key.split('/')[1]}/alive/2"
                with self.lock:
                    self.alive.append(done["key"])
                self.drop(done["key"])  # its watchers hear that UAV 2 is gone
            return []

    swarm_module.Bus = Watched
    try:
        swarm = run_swarm(scenario, "distributed", seed=1, transport="memory")
    finally:
        swarm_module.Bus = original
    assert "key" in done
    assert swarm.traffic.lost == {}
    assert_same_trace(swarm.result.trace, uavtrack.simulate(scenario, "distributed", seed=1).trace)


def test_the_security_page_backs_every_line_with_a_test_that_exists():
    # docs/security.md: each row of its tables names tests as `file.py::test` (or
    # `::test`, of the file named before in the row); each must be a test of that file
    import re
    from pathlib import Path

    root = Path(__file__).parent.parent
    page = (root / "docs" / "security.md").read_text()
    lines = page.splitlines()
    rows = [
        row
        for row, after in zip(lines, lines[1:] + [""], strict=True)
        if row.startswith("| ") and not after.startswith("|---")  # not a table's header
    ]
    named = 0
    for row in rows:
        refs = re.findall(r"`(\w+\.py)?::(test_\w+)`", row)
        assert refs or "not defended" in row, row
        current = None
        for module, test in refs:
            current = module or current
            assert current is not None, row
            source = (root / "tests" / current).read_text()
            assert f"def {test}(" in source, (current, test)
            named += 1
    assert named >= 30
