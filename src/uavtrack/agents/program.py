"""The main loop of one program of a swarm: a UAV (0 .. N-1) or the central node (N).

It subscribes to what is its own (its inbox key, the world's Hello), asks for the run
until the world's Hello comes, says it is ready once it has heard every other program,
then runs one cycle per `Sense` (or `Tick`) until the last step, until the world tells
it that it has failed, or until the world is gone. Started by `uavtrack swarm` (``python
-m uavtrack.agents``), or by hand on another machine (`uavtrack agent`).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass

import numpy as np
from msgspec import structs

from ..config import G, Scenario
from ..faults import Faults
from ..methods import get
from .agent import CentralAgent, UavAgent, part
from .messages import VERSION, Radio, Ready, Spec, encode
from .security import WORLD, Credential, Gate
from .tracked import TrackedCentral, TrackedUav
from .transport import ANY_HELLO, Link, Mailbox, Transport, ZenohTransport, inbox_key, keys

STARTUP = 120.0
"""Seconds a program waits for the world's first message."""
LINGER = 30.0
"""Seconds a program that ran its last cycle waits for the world to finish (answering it,
should it ask again for the last report): longer than a world stopped past the Zenoh
lease takes to hear its programs again once it runs."""


@dataclass(frozen=True, kw_only=True)
class Served:
    """How a program ended: the cycles it ran of the run's `steps`, and why it stopped:
    "done" (every step), "failed" (the world said this UAV failed, at step `at`),
    "lost" (the world no longer counts this program from step `at`, for the reason
    `why`: it missed a cycle's deadline, or its session ended; not a failure of the fault
    model), "world gone" (the world ended or went silent at step `at`), "no world" (no world of
    the run answered), "not in run" (this program's number is not one of the run's),
    "taken" (the world's Hello names this number a member: another program holding its
    key runs it), "under way" (the run had started, at step `at`), "needs key" (the run
    authenticates its members and this program has no key), "wrong key" (the key this
    program holds is not the one the world's Hello names for its number: a damaged or
    forged key file), "not authentic" (the only world that answered could not prove it
    is the run's: another key file's, or a forgery), "other run" (only worlds of other
    runs, `others`, answered)."""

    ran: int
    steps: int
    end: str
    at: int = -1
    programs: int = 0
    central: bool = False
    others: tuple[str, ...] = ()
    why: str = ""

    def name(self, me: int) -> str:
        """How to call program `me` of this run."""
        return "central node program" if self.central and me == self.programs - 1 else "UAV program"


def serve(
    transport: Transport,
    run: str,
    me: int,
    wait: float = STARTUP,
    first: float | None = None,
    credential: Credential | None = None,
    ros2: int | None = None,
) -> Served:
    """Run program `me` of swarm `run` to its end. wait: seconds to wait for the other
    programs and for each message of the run; first: for the world's first message
    (default `wait`); credential: this program's key (`security.Credential`), needed
    when the run authenticates its members; ros2: a ROS 2 domain id, to publish a UAV's
    pose, transform and estimates as ROS 2 topics in rmw_zenoh's conventions
    (`io.ros2.UavNode`; Zenoh transport only)."""
    k_ = keys(run)
    gate = Gate(run=run, me=me, programs=0, credential=credential)
    mailbox = Mailbox(gate, None, transport)
    transport.subscribe(inbox_key(run, me), mailbox.handler)
    transport.watch(f"{k_['alive']}world", mailbox.lost)
    transport.subscribe(k_["hello"], mailbox.handler)
    hello, others = _hello(transport, mailbox, run, wait if first is None else first)
    if hello is None:
        if others:
            return Served(ran=0, steps=0, end="other run", others=tuple(sorted(others)))
        end = "not authentic" if gate.drops.get("not authentic") else "no world"
        return Served(ran=0, steps=0, end=end)
    scenario = Scenario.from_dict(json.loads(hello.scenario), origin="the world's scenario")
    n = scenario.n_uavs
    method = get(hello.method)
    central = method.central
    programs = n + int(central)
    if hello.authenticated and credential is None:
        return Served(
            ran=0, steps=scenario.steps, end="needs key", programs=programs, central=central
        )
    if me >= programs:
        return Served(
            ran=0, steps=scenario.steps, end="not in run", programs=programs, central=central
        )
    if hello.authenticated and credential is not None and not _holds(credential, hello.publics, me):
        return Served(
            ran=0, steps=scenario.steps, end="wrong key", programs=programs, central=central
        )
    if me in hello.members:  # the world's word, signed: not a token anyone can make
        return Served(ran=0, steps=scenario.steps, end="taken", programs=programs, central=central)
    if hello.step >= 0:
        return Served(
            ran=0,
            steps=scenario.steps,
            end="under way",
            at=hello.step,
            programs=programs,
            central=central,
        )
    gate.programs = programs
    if central and me < n:  # without its central node a UAV waits for no download
        transport.watch(f"{k_['alive']}{n}", mailbox.lost)
    spec = Spec.of(scenario, central, method.plans)
    mailbox.learn(spec, hello.publics)
    link = Link(transport, gate)
    faults = Faults(scenario.faults, hello.key.array()[None].astype(np.uint32), n)
    prior = (hello.prior_mean.array().copy(), hello.prior_cov.array().copy())
    prior = (prior[0], np.broadcast_to(prior[1], (scenario.n_targets, 4, 4)).copy())
    tracked = scenario.tracker.unlabelled
    if me == n and tracked:
        program = TrackedCentral(scenario, faults, link, mailbox, hello.deadline, prior)
    elif me == n:
        program = CentralAgent(scenario, faults, link, mailbox, hello.deadline)
    else:
        kind = TrackedUav if tracked else UavAgent
        program = kind(me, scenario, hello.method, faults, link, mailbox, hello.deadline, prior)
    node = None
    if ros2 is not None and me < n:
        from ..io.ros2 import UavNode

        if not isinstance(transport, ZenohTransport):
            raise ValueError("ROS 2 topics need the Zenoh transport")
        tracks = scenario.tracker.unlabelled
        variance = scenario.faults.position_std**2
        node = UavNode(
            transport.session, ros2, me, scenario.n_targets, scenario.dt, tracks, variance, G
        )
    try:
        return _cycles(transport, link, mailbox, program, node, run, me, n, programs,
                       central, scenario, wait)  # fmt: skip
    finally:
        if node is not None:
            node.close()


def _holds(credential: Credential, publics: list[bytes], me: int) -> bool:
    """Whether `credential` holds the private key of the public key the Hello names for
    program `me`."""
    return me < len(publics) and credential.public() == bytes(publics[me])


def _cycles(transport, link, mailbox, program, node, run, me, n, programs, central, scenario,
            wait) -> Served:  # fmt: skip
    """The program's cycles, from meeting the others to the world's end."""
    k_ = keys(run)
    transport.announce(f"{k_['alive']}{me}")
    if not meet(link, mailbox, me, programs, wait):
        return Served(
            ran=0, steps=scenario.steps, end="world gone", at=0, programs=programs, central=central
        )
    link.send(WORLD, Ready(VERSION, run, me))
    first_ = ("tick", 0) if me == n else ("sense", 0)
    limit = time.monotonic() + wait
    while first_ not in mailbox.inbox and not mailbox.world_gone and time.monotonic() < limit:
        _presence(link, mailbox, me, programs)  # until the run starts: others may need it
        mailbox.wait(lambda: first_ in mailbox.inbox or mailbox.world_gone, time.monotonic() + 0.1)
    counted = (transport.published, transport.bytes, mailbox.received)
    ran, end, at, why = 0, "done", -1, ""
    kind = "tick" if me == n else "sense"
    last = None  # the last report sent
    for k in range(scenario.steps):
        want = (kind, k)
        asked = None if last is None else (kind, last.k)
        answering(link, mailbox, last, asked, lambda want=want: want in mailbox.inbox, wait)
        lost = mailbox.inbox.get(("lost",))
        if lost is not None:  # the world no longer counts this program, and says why
            end, at, why = "lost", lost.k, lost.reason
            break
        got = mailbox.take(want)
        if got is None:  # the world is gone or silent: stop
            end, at = "world gone", k
            break
        message, arrays = got
        if me < n and not bool(arrays["alive"][me]):
            end, at = "failed", k  # the world says this UAV has failed
            break
        report = program.cycle(k, arrays, getattr(message, "central", True))
        now = (transport.published, transport.bytes, mailbox.received)
        report = structs.replace(
            report,
            published=now[0] - counted[0],
            bytes=now[1] - counted[1],
            received=now[2] - counted[2],
            drops=mailbox.reasons(),
        )
        counted = now
        link.send(WORLD, report)
        last = report
        mailbox.take(want)  # asked again while this cycle ran: this report answers it
        if node is not None:
            bank = program.ctx.const.actions[report.action % 3]  # (uav.min_speed: 3 to 5 slow)
            slots = [None if a is None else a.array() for a in (report.label, report.status)]
            scan = getattr(program, "scan", None)  # with tracks: this cycle's, on the ground
            existence = None if report.existence is None else report.existence.array()
            node.publish(
                k, program.believed, bank, report.mean.array(), report.cov.array(), *slots, scan,
                existence,
            )  # fmt: skip
        ran += 1
    if node is not None:  # no more topics (failed, world gone, done): leave the ROS 2 graph
        if end != "done":  # its tracks go from the view before its run's end
            node.clear()
        node.close()  # now, not when the lingering ends
    if end == "done" and last is not None:  # stay until the world is done: closing at
        # once could lose the last report in flight, or leave the world asking for it
        answering(link, mailbox, last, (kind, last.k), lambda: False, LINGER)
    return Served(
        ran=ran, steps=scenario.steps, end=end, at=at, programs=programs, central=central, why=why
    )


def answering(link: Link, mailbox: Mailbox, last, asked, ready, seconds: float) -> None:
    """Wait up to `seconds` until ready() holds, the world says this program is lost, or
    the world is gone; meanwhile, should the world's message `asked` (the Sense or Tick
    that report `last` answered) come again, send `last` again: a world that was stopped
    asks again for the reports that its programs' closed sessions lost."""
    until = time.monotonic() + seconds
    while True:
        mailbox.wait(
            lambda: (
                ready()
                or asked in mailbox.inbox
                or ("lost",) in mailbox.inbox
                or mailbox.world_gone
            ),
            until,
        )
        if last is None or mailbox.take(asked) is None:
            return
        link.send(WORLD, last)


def _hello(transport: Transport, mailbox: Mailbox, run: str, wait: float):
    """The world's Hello, asked for every half second until it comes (a world already
    running answers at its next cycle), or None when none came within `wait` seconds;
    and the runs of the other worlds heard meanwhile. When only worlds of other runs
    answer for `OTHERS` seconds, the wait ends early: this program is at the wrong world,
    or holds another run's key."""
    others: set[str] = set()

    def other(key: str, payload: bytes) -> None:
        found = key.split("/")[1] if key.count("/") >= 2 else ""
        if found and found != run:
            others.add(found)

    transport.subscribe(ANY_HELLO, other)
    start = time.monotonic()
    limit = start + wait
    join = keys(run)["join"]
    while time.monotonic() < limit and not mailbox.world_gone:
        transport.publish(join, b"")
        if mailbox.wait(lambda: ("hello",) in mailbox.inbox, min(limit, time.monotonic() + 0.5)):
            break
        if others and time.monotonic() - start > OTHERS:
            break
    return mailbox.inbox.get(("hello",)), others


OTHERS = 3.0
"""Seconds a program waits for its own world once worlds of other runs have answered."""


def _presence(link: Link, mailbox: Mailbox, me: int, programs: int, world: bool = False) -> None:
    """Say who this program has heard, to every program that has not yet heard it, and
    with `world` to the world too until its Hello names this program a member."""
    heard = np.zeros(programs, dtype=bool)
    acknowledged = np.zeros(programs, dtype=bool)
    with mailbox.cond:
        for q in range(programs):
            content = mailbox.content(-1, "presence", q, 0)
            if content is not None:
                heard[q] = True
                acknowledged[q] = bool(content["heard"][me])
    heard[me] = acknowledged[me] = True
    body = encode(
        Radio(
            version=VERSION,
            run=link.run,
            k=-1,
            sender=me,
            parts=[part("presence", 0, {"heard": heard})],
        )
    )
    for q in np.flatnonzero(~acknowledged):
        link.send_body(int(q), body)
    hello = mailbox.inbox.get(("hello",))
    if world and hello is not None and me not in hello.members:
        link.send_body(WORLD, body)


def meet(link: Link, mailbox: Mailbox, me: int, programs: int, wait: float) -> bool:
    """Announce this program to the others until it has heard every one of them (UAVs
    0 .. N-1 and the central node N if any): then the routes between all programs
    exist, and no message of the first cycle is lost to a subscription still in transit.
    The world hears it too: its authentic presence makes this program a member, which
    the world's Hello then names, so a second program with the same key is refused."""
    others = [p for p in range(programs) if p != me]
    heard = lambda: all(mailbox.content(-1, "presence", p, 0) is not None for p in others)  # noqa: E731
    limit = time.monotonic() + wait
    while time.monotonic() < limit and not mailbox.world_gone:
        _presence(link, mailbox, me, programs, world=True)
        if mailbox.wait(heard, time.monotonic() + 0.1):
            return True
    return False
