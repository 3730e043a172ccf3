"""A member with valid keys that sends what no honest program would: every message kind
with every field at every bad value (the fuzz set). Honest programs finish every cycle,
and what they refuse is counted by reason."""

from __future__ import annotations

import math
import threading

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import uavtrack
from uavtrack import estimation, fusion
from uavtrack.agents import messages, run_swarm
from uavtrack.agents.messages import (
    VERSION,
    Array,
    Hello,
    Lost,
    Radio,
    Ready,
    Report,
    Sense,
    Tick,
    encode,
)
from uavtrack.agents.security import WORLD
from uavtrack.agents.transport import Link
from uavtrack.robust import gate

pytest.importorskip("cryptography")

BAD = ("nan", "+inf", "-inf", "zero", "negative", "1e300", "wrong shape", "wrong dtype")
"""The bad values every field takes in turn."""

FLOATS = {"nan": math.nan, "+inf": math.inf, "-inf": -math.inf, "1e300": 1e300}
OTHER_DTYPE = {"f": "<i8", "i": "<f8", "u": "<f8", "b": "<i8"}
WORLDS = ("sense", "tick", "hello", "ready", "lost")
"""Kinds only the world sends (and Ready, only about oneself): a member forges them."""


def bad_array(wire: Array, how: str) -> Array:
    """`wire`'s array at a bad value: its shape filled with the value (a float array
    whatever the field's type), zero, negated (an unsigned one: its largest value), one
    element too many, another dtype."""
    value = wire.array()
    if how in FLOATS:
        return Array.of(np.full(value.shape, FLOATS[how]))
    if how == "zero":
        return Array.of(np.zeros_like(value))
    if how == "negative" and value.dtype.kind == "u":  # no sign: the largest it holds
        return Array.of(np.full_like(value, np.iinfo(value.dtype).max))
    if how == "negative":
        return Array.of(~value if value.dtype.kind == "b" else -np.abs(value) - 1)
    if how == "wrong shape":
        return Array.of(np.resize(value, value.size + 1))
    return Array.of(value.astype(OTHER_DTYPE[value.dtype.kind]))


def bad_value(value, how: str):
    """Any field at a bad value; where the field's type cannot hold it (an int field
    at NaN), a value of another type, which decoding refuses."""
    if isinstance(value, Array):
        return bad_array(value, how)
    if how == "wrong shape":
        return [value, value]
    if how == "wrong dtype":
        return b"x" if isinstance(value, str) else "x"
    if isinstance(value, dict):  # a report's drops by reason
        many = {f"reason {i}": 1 for i in range(100)}
        chosen = {"zero": {}, "negative": {"lost": -1}, "1e300": many}
        return chosen[how] if how in chosen else {"x": FLOATS[how]}
    if isinstance(value, list):  # parts, keys
        return {"zero": [], "negative": value[:-1], "1e300": value * 8}.get(how, FLOATS.get(how))
    if isinstance(value, bool | str | bytes) or value is None:
        return FLOATS.get(how, {"zero": 0, "negative": -1}.get(how))
    if how in FLOATS:  # an int field holds no NaN: the largest int for 1e300
        return 2**62 if how == "1e300" and isinstance(value, int) else FLOATS[how]
    return 0 if how == "zero" else -abs(value) - 1


def _replace(struct, **change):
    return msgspec.structs.replace(struct, **change)


def variants(message):
    """(field, bad value, message changed) for every field of `message` at every bad
    value; for a radio message also each part's header and each array of its content
    (named protocol.field), and bids scored once and NaN elsewhere."""
    for name in message.__struct_fields__:
        for how in BAD:
            yield name, how, _replace(message, **{name: bad_value(getattr(message, name), how)})
    if not isinstance(message, Radio):
        return
    for i, part in enumerate(message.parts):

        def with_part(changed, i=i):
            return _replace(message, parts=message.parts[:i] + [changed] + message.parts[i + 1 :])

        for name in ("protocol", "round", "final"):
            for how in BAD:
                changed = _replace(part, **{name: bad_value(getattr(part, name), how)})
                yield f"{part.protocol}.{name}", how, with_part(changed)
        for name, wire in (part.content or {}).items():
            for how in BAD:
                content = dict(part.content, **{name: bad_array(wire, how)})
                yield f"{part.protocol}.{name}", how, with_part(_replace(part, content=content))
        if part.protocol == "bids" and part.content is not None:
            bids = part.content["bids"].array().copy()
            bids[1:] = np.nan
            content = dict(part.content, bids=Array.of(bids))
            yield "bids.bids", "nan but one", with_part(_replace(part, content=content))


def forged(run: str, k: int, me: int, n: int, m: int) -> list:
    """The world's messages and a Ready as a member could make them: well formed,
    refused for who sent them."""
    believed = Array.of(np.array([100.0, 100.0, 425.0, 15.0, 0.0]))
    flags = Array.of(np.ones(n, dtype=bool))
    nothing = Array.of(np.zeros((0, 2)))
    return [
        Sense(
            version=VERSION,
            run=run,
            k=k,
            uav=0,
            believed=believed,
            observed=Array.of(np.zeros(m, bool)),
            z=nothing,
            links=flags,
            alive=flags,
        ),
        Tick(version=VERSION, run=run, k=k, alive=flags),
        Hello(
            version=VERSION,
            run=run,
            scenario="{}",
            method="distributed",
            key=Array.of(np.zeros(2, np.uint32)),
            prior_mean=Array.of(np.zeros((m, 4))),
            prior_cov=Array.of(np.eye(4)),
            deadline=1.0,
            authenticated=True,
            publics=[b"k" * 32] * (n + 1),
        ),  # fmt: skip
        Ready(VERSION, run, me),
        Lost(version=VERSION, run=run, k=k, program=(me + 1) % n, reason="forged"),
    ]


class Member:
    """Program `me`, a member with valid keys, that sends before each of its messages
    variants of it, one (kind, field, bad value) at a time, and with its first report the
    world's messages forged, to every other program and the world.

    A variant that cannot be decoded is refused whatever it holds: each is sent once,
    with the first message of its kind; so is each variant of a presence message (a
    presence is kept until the next one replaces it). One that decodes is sent alone
    before a message of its kind, so that each is checked, and used if admitted, in a
    slot (cycle, round, receiver) of its own; the message follows (and is refused as a
    duplicate when the variant was admitted). `sent` holds (kind, field, bad value) of
    what went out."""

    def __init__(self, me: int, programs: int, scenario) -> None:
        self.me, self.programs = me, programs
        self.n, self.m = scenario.n_uavs, scenario.n_targets
        self.sent: set[tuple[str, str, str]] = set()
        self.all: set[tuple[str, str, str]] = set()
        self.forged = False
        self.lock = threading.Lock()

    def wrap(self, original):
        def send_body(link: Link, receiver: int, body: bytes) -> int:
            if link.gate.me == self.me:
                self.attack(original, link, receiver, body)
            return original(link, receiver, body)

        return send_body

    def attack(self, send, link: Link, receiver: int, body: bytes) -> None:
        message = msgspec.msgpack.Decoder(messages.Message).decode(body)
        kind = self.kind(message)
        out, slot = [], None
        with self.lock:
            for name, how, variant in variants(message):
                key = (kind, name, how)
                self.all.add(key)
                if key in self.sent:
                    continue
                encoded = encode(variant)
                if messages.decode(encoded, link.run) is None or kind == "radio:presence":
                    out.append((receiver, encoded))
                    self.sent.add(key)
                elif slot is None:
                    slot = (receiver, encoded)
                    self.sent.add(key)
            if isinstance(message, Report) and not self.forged:
                self.forged = True
                others = [WORLD] + [q for q in range(self.programs) if q != self.me]
                for one in forged(link.run, message.k, self.me, self.n, self.m):
                    for name, how, variant in variants(one):
                        key = (type(one).__name__.lower(), name, how)
                        self.sent.add(key)
                        self.all.add(key)
                        out += [(q, encode(variant)) for q in others]
        for to, encoded in out + ([slot] if slot else []):
            send(link, to, encoded)

    @staticmethod
    def kind(message) -> str:
        if isinstance(message, Radio):
            return "radio:" + "+".join(p.protocol for p in message.parts)
        return type(message).__name__.lower()


def attacked(monkeypatch, scenario, method: str, me: int):
    """A memory swarm in which program `me` is a `Member`; returns (swarm, member)."""
    programs = scenario.n_uavs + int(method == "centralized")
    member = Member(me, programs, scenario)
    monkeypatch.setattr(Link, "send_body", member.wrap(Link.send_body))
    swarm = run_swarm(scenario, method, seed=1, transport="memory", deadline=1.0)
    return swarm, member


def fields_of(keys) -> dict[tuple[str, str], set[str]]:
    out: dict[tuple[str, str], set[str]] = {}
    for kind, name, how in keys:
        out.setdefault((kind, name), set()).add(how)
    return out


def assert_honest_programs_finished(swarm, member: Member, steps: int) -> None:
    trace = swarm.result.trace
    honest = [q for q in range(trace.alive.shape[1]) if q != member.me]
    assert set(swarm.traffic.lost) <= {member.me}, swarm.traffic.lost
    assert trace.alive[:, honest].all() and trace.alive.shape[0] == steps
    assert np.isfinite(trace.mean[:, honest]).all() and np.isfinite(trace.cov[:, honest]).all()


STEPS = 80
"""Cycles of each run: enough for every decodable variant of a report (one a cycle)."""
RUNS = {
    # (method, the member, association): the kinds it sends
    ("distributed", 1, "known"): {
        "radio:presence", "radio:flood+consensus", "radio:beacon+bids", "report"
    },
    ("centralized", 1, "known"): {"radio:presence", "radio:upload", "report"},
    ("centralized", 5, "known"): {"radio:presence", "radio:download", "report"},
    # tracks with labels, status, stamps and tombstones; bids by label
    ("distributed", 1, "jpda"): {
        "radio:presence", "radio:flood+consensus", "radio:beacon+bids", "report"
    },
    ("centralized", 1, "jpda"): {"radio:presence", "radio:upload", "report"},  # a scan
    ("centralized", 5, "jpda"): {"radio:presence", "radio:download", "report"},  # a book
    # a learned policy: beacons of whole states, reports with no target and no bids
    ("policy:bc", 1, "known"): {
        "radio:presence", "radio:flood+consensus", "radio:beacon", "report"
    },
}  # fmt: skip
TRACKED = {"sensor.detection_probability": 0.9, "sensor.clutter_rate": 2.0}


@pytest.mark.integration  # a swarm: the agent form against real deadlines
@pytest.mark.parametrize("method,me,association", list(RUNS), ids=lambda x: str(x))
def test_every_kind_field_and_bad_value_from_a_member_stops_no_honest_program(
    monkeypatch, method, me, association
):
    scenario = uavtrack.Scenario(steps=STEPS)
    if association != "known":  # a report has two more fields: label and status
        tracked = {"tracker.association": association, "steps": STEPS + 20, **TRACKED}
        scenario = scenario.with_overrides(tracked)
    swarm, member = attacked(monkeypatch, scenario, method, me)
    assert_honest_programs_finished(swarm, member, scenario.steps)
    sent = fields_of(member.sent)
    kinds = {kind for kind, _ in sent}
    assert RUNS[(method, me, association)] | set(WORLDS) <= kinds
    assert member.sent == member.all, sorted(member.all - member.sent)[:5]  # every variant
    for (kind, name), values in sent.items():  # every field at every bad value
        assert set(BAD) <= values, (kind, name, set(BAD) - values)
    assert swarm.traffic.drops.get("malformed", 0) > 0
    assert swarm.traffic.drops.get("not from its sender", 0) > 0


# ------------------------------------------------------------------ the attacks of the issue


def altered(content: dict, how: str) -> dict:
    """A member's consensus tuple (or bids) altered as in the attacks that took swarms
    down before the rule: each still finite, so the old check admitted it."""
    if how == "nan bids":
        return dict(content, bids=Array.of(np.full(content["bids"].shape, np.nan)))
    gamma, mean, cov = (content[n].array().copy() for n in ("gamma", "mean", "cov"))
    if how == "covariance x 1e300":
        cov = cov * 1e300
    elif how == "confidence 1e300, means moved 500 m":
        gamma, mean = np.full(gamma.shape, 1e300), mean + [500.0, 500.0, 0.0, 0.0]
    elif how == "means 1e300":
        gamma, mean = np.full(gamma.shape, 1e300), np.full(mean.shape, 1e300)
    elif how == "zero covariance":
        cov = np.zeros(cov.shape)
    elif how == "negative covariance":
        cov = -cov
    elif how == "covariance 1e-9":  # consistent, but beyond any sensor
        cov = np.broadcast_to(1e-9 * np.eye(4), cov.shape).copy()
        gamma = 1.0 / np.trace(cov, axis1=-2, axis2=-1)
    elif how == "means moved 1 km":  # beyond where anything gets in a 2 s run
        mean = mean + [1000.0, 1000.0, 0.0, 0.0]
    return dict(content, gamma=Array.of(gamma), mean=Array.of(mean), cov=Array.of(cov))


def member_alters(monkeypatch, protocol: str, alter) -> None:
    """Program 1, a member with valid keys, sends every part of `protocol` it has
    content for altered by `alter(content)`; the rest as an honest program would."""
    from uavtrack.agents import agent

    send = agent.AgentRadio.send

    def faulty(self, k, parts, to=None):
        if self.me == 1:
            parts = [
                msgspec.structs.replace(p, content=alter(p.content))
                if p.protocol == protocol and p.content is not None
                else p
                for p in parts
            ]
        send(self, k, parts, to)

    monkeypatch.setattr(agent.AgentRadio, "send", faulty)


ATTACKS = {
    "nan bids": "bids not scored",
    "covariance x 1e300": "covariance beyond the run's largest",
    "confidence 1e300, means moved 500 m": "confidence disagrees with covariance",
    "means 1e300": "confidence disagrees with covariance",
    "zero covariance": "covariance not positive definite",
    "negative covariance": "covariance not positive definite",
    "covariance 1e-9": "covariance below the sensor's accuracy",
    "means moved 1 km": "position out of bounds",
}


@pytest.mark.integration  # a swarm: the agent form against real deadlines
@pytest.mark.parametrize("how", list(ATTACKS))
def test_the_attacks_that_took_swarms_down_are_dropped_by_reason(monkeypatch, how):
    protocol = "bids" if how == "nan bids" else "consensus"
    member_alters(monkeypatch, protocol, lambda content: altered(content, how))
    scenario = uavtrack.Scenario(steps=2)  # a refused message costs its receivers a deadline
    swarm = run_swarm(scenario, "distributed", seed=1, transport="memory", deadline=0.2)
    assert swarm.traffic.lost == {}
    assert swarm.traffic.drops.get(ATTACKS[how], 0) > 0, swarm.traffic.drops
    result = swarm.result
    assert np.isfinite([result.observation_rate, result.rmse, result.nees, result.ospa]).all()
    assert result.rmse < 100  # the honest UAVs kept their estimates


BEACON_LIES = {
    "a beacon 1 km away": "position out of bounds",
    "a beacon at 3 times the speed": "speed out of bounds",
}


@pytest.mark.integration  # a swarm: the agent form against real deadlines
@pytest.mark.parametrize("how", list(BEACON_LIES))
def test_a_members_lying_beacon_never_enters_a_policys_observation(monkeypatch, how):
    """A learned policy reads its neighbours from their beacons: a member whose every
    beacon no honest UAV could send (teleported, or beyond the aircraft's speed) is
    never heard (dropped by reason), and every honest program flies on to the end."""
    from uavtrack.agents import agent

    def lie(content):
        uav = content["uav"].array().copy()
        if how == "a beacon 1 km away":
            uav[:2] += 1000.0
        else:
            uav[3] *= 3.0
        return dict(content, uav=Array.of(uav))

    member_alters(monkeypatch, "beacon", lie)
    chosen = agent.UavAgent.chosen
    kept: list[int] = []

    def spy(self, k, mean, cov, observed):
        out = chosen(self, k, mean, cov, observed)
        if self.me != 1:  # whether an honest UAV kept a beacon of the member
            kept.append(int(self.beacons.stamp[0, self.me, 1]))
        return out

    monkeypatch.setattr(agent.UavAgent, "chosen", spy)
    scenario = uavtrack.Scenario(steps=6)
    swarm = run_swarm(scenario, "policy:bc", seed=1, transport="memory", deadline=0.5)
    assert swarm.traffic.lost == {}
    reasons = {r: c for r, c in swarm.traffic.drops.items() if BEACON_LIES[how] in r}
    assert sum(reasons.values()) > 0, swarm.traffic.drops
    assert len(kept) == 4 * scenario.steps and set(kept) == {-1}
    assert np.isfinite(swarm.result.observation_rate)
    assert swarm.result.trace.alive.all()


def lied_tracks(content: dict, how: str) -> dict:
    """A member's consensus tracks altered, each still finite and well formed."""
    mean, cov, label, status = (
        content[n].array().copy() for n in ("mean", "cov", "label", "status")
    )
    if how == "tracks moved 1 km":
        mean = mean + [1000.0, 1000.0, 0.0, 0.0]
    elif how == "covariance 1e-9":
        cov = np.broadcast_to(1e-9 * np.eye(4), cov.shape).copy()
    elif how == "one label twice":
        label[status != 0] = label[status != 0].min()
    elif how == "a label beyond the run":
        label[status != 0] = 2**40 + np.arange((status != 0).sum())
    elif how == "status 7":
        status[status != 0] = 7
    changed = {"mean": mean, "cov": cov, "label": label, "status": status}
    return dict(content, **{name: Array.of(value) for name, value in changed.items()})


TRACK_ATTACKS = {
    "tracks moved 1 km": "position out of bounds",
    "covariance 1e-9": "covariance below the sensor's accuracy",
    "one label twice": "labels not distinct",
    "a label beyond the run": "index out of range",
    "status 7": "track status out of range",
}


@pytest.mark.integration  # a swarm: the agent form against real deadlines
@pytest.mark.parametrize("how", list(TRACK_ATTACKS))
def test_a_members_lies_about_its_tracks_are_dropped_by_reason(monkeypatch, how):
    member_alters(monkeypatch, "consensus", lambda content: lied_tracks(content, how))
    scenario = uavtrack.Scenario(steps=3).with_overrides({"tracker.association": "jpda", **TRACKED})
    swarm = run_swarm(scenario, "distributed", seed=1, transport="memory", deadline=0.2)
    assert swarm.traffic.lost == {}
    assert swarm.traffic.drops.get(TRACK_ATTACKS[how], 0) > 0, swarm.traffic.drops
    trace = swarm.result.trace
    honest = [0, 2, 3, 4]
    held = trace.status[:, honest] != 0
    assert np.isfinite(trace.mean[:, honest][held]).all()
    assert (trace.label[:, honest][held] < 2**40).all()  # no lie was adopted
    reference = uavtrack.simulate(scenario, "distributed", seed=1)
    assert reference.gospa_false == 0 and np.isfinite(reference.gospa)
    assert swarm.result.gospa_false == 0  # a track moved 1 km would be a false one
    assert swarm.result.gospa < 2 * reference.gospa


def every_label_at_one_point(content: dict) -> dict:
    """Every slot confirmed under the labels 0 .. K-1, every track at one point with a
    covariance of the sender's own: well formed, within the bounds, each label once."""
    mean, cov, status = (content[n].array() for n in ("mean", "cov", "status"))
    K = status.size
    live = np.flatnonzero(status != 0)
    point = mean[live[0]] if live.size else np.array([200.0, 200.0, 0.0, 0.0])
    P = cov[live[0]] if live.size else 25.0 * np.eye(4)
    changed = {
        "mean": np.tile(point, (K, 1)), "cov": np.broadcast_to(P, (K, 4, 4)).copy(),
        "label": np.arange(K), "status": np.full(K, 2),
    }  # fmt: skip
    return dict(content, **{name: Array.of(value) for name, value in changed.items()})


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_a_member_offering_every_label_at_one_point_stops_no_honest_program(monkeypatch):
    """Labels 0 .. K-1 include labels the honest UAVs give their next births: taken,
    an honest UAV held one twice and its own messages were refused (2 of 4 honest
    programs lost at step 5 of seed 2). They are left out and counted."""
    member_alters(monkeypatch, "consensus", every_label_at_one_point)
    scenario = uavtrack.Scenario(steps=15).with_overrides(
        {"tracker.association": "jpda", **TRACKED}
    )
    swarm = run_swarm(scenario, "distributed", seed=2, transport="memory", deadline=0.5)
    assert swarm.traffic.lost == {}
    assert swarm.traffic.drops.get("label not issued", 0) > 0, swarm.traffic.drops
    assert "labels not distinct" not in swarm.traffic.drops
    trace = swarm.result.trace
    for step, row in np.ndindex(trace.label.shape[:2]):
        held = trace.label[step, row][trace.status[step, row] != 0]
        assert np.unique(held).size == held.size, (step, row, held)


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_a_member_tombstoning_every_track_it_holds_is_refused_and_counted():
    """`examples/quiet_lies.py --lie tombstones`: every label it holds, deleted at each
    cycle, with its tracks. An honest sender buries what it deletes before it sends,
    so the message is refused whole, counted, and the honest programs finish."""
    import runpy
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / "quiet_lies.py"
    example = runpy.run_path(str(path), run_name="quiet_lies")
    scenario = example["scenario_of"]("tombstones", 5)
    rates, drops = example["lying_runs"]("tombstones", scenario, 1)
    assert drops.get("tombstone of a track it holds", 0) >= 5, drops
    assert np.isfinite(rates).all()


# ------------------------------------------------------------------ a member that lies well


def lying_member():
    import runpy
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / "lying_member.py"
    return runpy.run_path(str(path), run_name="lying_member")


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_a_member_lying_within_the_bounds_takes_the_team_over_unless_the_gate_is_on():
    example = lying_member()
    base = uavtrack.Scenario(steps=60)
    gated = base.with_overrides({"robust.gate": 0.9999})
    honest = example["honest_rates"](base, 2)
    liar = example["swarm_rates"](base, 2, example["LIAR"])
    guarded = example["swarm_rates"](gated, 2, example["LIAR"])
    assert liar.mean() < honest.mean() - 0.3  # the lie is plausible and it works
    assert guarded.mean() >= example["honest_rates"](gated, 2).mean() - 0.05


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_with_tracks_a_lying_member_takes_the_team_over_unless_the_gate_is_on():
    """The liar moves every track it offers 100 m at the most confidence the run admits;
    with the gate a receiver refuses what contradicts the slots its own scans met and
    its scan, and catches the liar."""
    example = lying_member()
    base = uavtrack.Scenario(steps=60).with_overrides({"tracker.association": "jpda"})
    gated = base.with_overrides({"robust.gate": 0.9999})
    honest = example["honest_rates"](base, 1)
    liar = example["swarm_rates"](base, 1, example["LIAR"])
    guarded = example["swarm_rates"](gated, 1, example["LIAR"])
    assert liar.mean() < honest.mean() - 0.3  # one trial: 0.04 against 0.73
    assert guarded.mean() >= example["honest_rates"](gated, 1).mean() - 0.05


@pytest.mark.integration  # a swarm: the agent form against real deadlines
@pytest.mark.parametrize("method", ["distributed", "centralized", "greedy"])
@pytest.mark.parametrize(
    "overrides",
    [
        {"robust.gate": 0.9},
        {"robust.gate": 0.9, "fusion.rule": "covariance_intersection"},
        {
            "robust.gate": 0.9,
            "robust.gate_memory": 2,
            "faults.loss": 0.3,
            "faults.delay": 2,
            "robust.stale": True,
        },  # fmt: skip
    ],
    ids=["gate", "gate-ci", "gate-faults"],
)
def test_memory_swarm_with_the_gate_equals_the_simulator(method, overrides):
    from uavtrack.testing import assert_same_trace

    scenario = uavtrack.Scenario(steps=40).with_overrides(overrides)
    swarm = run_swarm(scenario, method, seed=3, transport="memory")
    reference = uavtrack.simulate(scenario, method, seed=3)
    assert_same_trace(swarm.result.trace, reference.trace)
    assert swarm.traffic.dropped == 0


@pytest.mark.integration  # a swarm: the agent form against real deadlines
@pytest.mark.parametrize("method", ["distributed", "greedy", "centralized"])
def test_memory_swarm_with_the_gate_and_tracks_equals_the_simulator(method):
    from uavtrack.testing import assert_same_trace

    scenario = uavtrack.Scenario(steps=30).with_overrides(
        {
            "tracker.association": "jpda",
            "sensor.detection_probability": 0.9,
            "sensor.clutter_rate": 2.0,
            "robust.gate": 0.9,
            "robust.gate_memory": 2,
            "faults.loss": 0.2,
        }
    )
    swarm = run_swarm(scenario, method, seed=3, transport="memory")
    reference = uavtrack.simulate(scenario, method, seed=3)
    assert_same_trace(swarm.result.trace, reference.trace)
    assert swarm.traffic.dropped == 0


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_a_centralized_swarm_with_the_gate_and_tracks_and_no_faults_equals_the_simulator():
    # without faults the batch's assignment is the node's over its own tracks, as the
    # agent form's: the UAVs' tracks, which the gate may keep from the download, differ
    from uavtrack.testing import assert_same_trace

    scenario = uavtrack.Scenario(steps=40).with_overrides(
        {
            "tracker.association": "jpda",
            "sensor.clutter_rate": 1.0,
            "n_uavs": 7,
            "n_targets": 2,
            "robust.gate": 0.99,
        }
    )
    swarm = run_swarm(scenario, "centralized", seed=3, transport="memory")
    assert_same_trace(swarm.result.trace, uavtrack.simulate(scenario, "centralized", seed=3).trace)


# ------------------------------------------------------------------ what passes is usable


def receiver(scenario, me=0, method="distributed"):
    """A UAV program's agent on a bus of its own (nothing is sent anywhere)."""
    from uavtrack.agents.agent import UavAgent
    from uavtrack.agents.messages import Spec
    from uavtrack.agents.security import Gate
    from uavtrack.agents.transport import Bus, Mailbox, MemoryTransport
    from uavtrack.faults import Faults

    n, m = scenario.n_uavs, scenario.n_targets
    gate_ = Gate(run="r", me=me, programs=n, credential=None)
    link = Link(MemoryTransport(Bus()), gate_)
    mailbox = Mailbox(gate_, Spec.of(scenario, False))
    faults = Faults(scenario.faults, np.zeros((1, 2), dtype=np.uint32), n)
    prior = (np.full((m, 4), 100.0), np.broadcast_to(np.eye(4), (m, 4, 4)).copy())
    return UavAgent(me, scenario, method, faults, link, mailbox, 1.0, prior)


@st.composite
def admitted_tuples(draw, bounds, m=3, k=4):
    """Consensus tuples at the edges of what a run admits: covariances of any
    orientation with eigenvalues from below the floor to the cap, positions anywhere
    within (and some beyond) the field plus its margin, speeds up to (and beyond) the
    largest, stamps anywhere in the window."""
    floats = lambda lo, hi: st.floats(lo, hi, allow_nan=False, allow_infinity=False)  # noqa: E731
    eig = np.exp(
        draw(
            st.lists(
                floats(np.log(bounds.floor / 2), np.log(bounds.cap)), min_size=4 * m, max_size=4 * m
            )
        )
    )
    angles = draw(st.lists(floats(0, np.pi), min_size=6 * m, max_size=6 * m))
    cov = []
    for j in range(m):
        Q = np.eye(4)
        for a, (p, q) in zip(
            angles[6 * j : 6 * j + 6], [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)], strict=True
        ):
            G = np.eye(4)
            G[p, p] = G[q, q] = np.cos(a)
            G[p, q], G[q, p] = -np.sin(a), np.sin(a)
            Q = Q @ G
        P = Q @ np.diag(eig[4 * j : 4 * j + 4]) @ Q.T
        cov.append(0.5 * (P + P.T))
    cov = np.array(cov)
    where = draw(
        st.lists(floats(bounds.low * 1.1, bounds.high * 1.1), min_size=2 * m, max_size=2 * m)
    )
    speed = draw(
        st.lists(floats(-1.2 * bounds.speed, 1.2 * bounds.speed), min_size=2 * m, max_size=2 * m)
    )
    mean = np.concatenate(
        [np.reshape(where, (m, 2)), np.reshape(speed, (m, 2)) / np.sqrt(2)], axis=1
    )
    stamp = np.array(draw(st.lists(st.integers(0, k), min_size=m, max_size=m)))
    gamma = estimation.confidence(cov)
    return {
        "gamma": gamma,
        "mean": mean,
        "cov": cov,
        "stamp": stamp,
        "origin": np.zeros(m, np.int64),
    }


SCENARIO = uavtrack.Scenario(n_targets=3, steps=40)


@pytest.mark.integration  # a swarm: the agent form against real deadlines
@pytest.mark.parametrize(
    "overrides",
    [
        {},
        {"robust.gate": 0.9},
        {"fusion.rule": "covariance_intersection", "robust.gate": 0.9},
        {"faults.delay": 1, "robust.stale": True, "robust.gate": 0.9},
    ],  # fmt: skip
    ids=["paper", "gate", "ci-gate", "stale-gate"],
)
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_whatever_the_rule_admits_the_receivers_use_without_error(overrides, data):
    import warnings

    from uavtrack.agents.messages import Spec

    scenario = SCENARIO.with_overrides(overrides)
    spec = Spec.of(scenario, False)
    agent = receiver(scenario)
    m, k = scenario.n_targets, 4
    offered = {q: data.draw(admitted_tuples(spec.bounds, m, k)) for q in (1, 2)}
    own = data.draw(admitted_tuples(spec.bounds, m, k))
    own["stamp"] = np.full(m, k)
    agent.measured = gate.Measured(
        np.array(data.draw(st.lists(st.booleans(), min_size=m, max_size=m)))[None, None],
        data.draw(admitted_tuples(spec.bounds, m, k))["mean"][None, None, :, :2],
        np.broadcast_to(np.eye(2), (1, 1, m, 2, 2)),
        np.array(data.draw(st.lists(st.booleans(), min_size=m, max_size=m)))[None, None],
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow, no invalid value, nothing
        checked = {}
        for q, content in offered.items():
            parts = spec.radio(consensus_message(content, k, q), k)
            if isinstance(parts, str):  # only what the rule admits reaches a receiver
                continue
            checked[q] = fusion.Estimates.of(agent._plausible(parts[0][3]))
            if agent.setting.stale:
                checked[q] = agent.setting.forward(checked[q], k)
        state = agent._adopt(fusion.Estimates.of(own), checked)
        assert np.isfinite(state.mean).all() and np.isfinite(state.cov).all()
        bids, _ = agent.setting.plan(
            np.array([[[100.0, 100.0, 425.0, 15.0, 0.0]]]), state.mean[None, None]
        )
        assert np.isfinite(bids).all() and (bids >= 0).all()


def consensus_message(content: dict, k: int, sender: int) -> Radio:
    wire = {name: Array.of(value) for name, value in content.items()}
    return Radio(
        version=VERSION,
        run="r",
        k=k,
        sender=sender,
        parts=[messages.Part("consensus", 1, -1, wire)],
    )


@pytest.mark.integration  # a swarm: the agent form against real deadlines
def test_what_a_member_sends_beyond_the_rule_is_counted_in_the_swarm_json(monkeypatch, capsys):
    import json

    from uavtrack import cli
    from uavtrack.agents import agent

    send = agent.AgentRadio.send

    def zero_covariance(self, k, parts, to=None):
        if self.me == 2:
            parts = [
                msgspec.structs.replace(p, content=altered(p.content, "zero covariance"))
                if p.protocol == "consensus" and p.content is not None
                else p
                for p in parts
            ]
        send(self, k, parts, to)

    monkeypatch.setattr(agent.AgentRadio, "send", zero_covariance)
    args = ["swarm", "--transport", "memory", "--steps", "2", "--deadline", "0.3", "--json"]
    assert cli.main(args) == 0
    swarm = json.loads(capsys.readouterr().out)["swarm"]
    assert swarm["dropped_by_reason"]["covariance not positive definite"] > 0
    assert swarm["lost"] == {}
