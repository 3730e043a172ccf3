"""The main loop of one program of a swarm: a UAV (0 .. N-1) or the central node (N).

It subscribes to what is its own (the run, its sense messages, the radio), waits for
the world's `Hello`, says it is ready, then runs one cycle per `Sense` (or `Tick`) until
the last step, until the world tells it that it has failed, or until the world is gone.
Started as ``python -m uavtrack.agents RUN UAV ENDPOINT`` by `uavtrack swarm`, or by
hand on another machine (`uavtrack agent`).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass

import numpy as np
from msgspec import structs

from ..config import Scenario
from ..faults import Faults
from ..methods import get
from .agent import CentralAgent, UavAgent, keys
from .messages import VERSION, Radio, Report, encode, packed
from .transport import Mailbox, Transport

STARTUP = 120.0
"""Seconds a program waits for the world's first message."""
LINGER = 10.0
"""Seconds a program that ran its last cycle waits for the world to finish."""


@dataclass(frozen=True)
class Served:
    """How a program ended: the cycles it ran of the run's `steps`, and why it stopped:
    "done" (every step), "failed" (the world said this UAV failed, at step `at`),
    "world gone" (the world ended or went silent at step `at`), "no world" (no world of
    the run answered), "not in run" (this program's number is not one of the run's),
    "taken" (another program with this number is running)."""

    ran: int
    steps: int
    end: str
    at: int = -1
    programs: int = 0
    central: bool = False

    def name(self, me: int) -> str:
        """How to call program `me` of this run."""
        return "central node program" if self.central and me == self.programs - 1 else "UAV program"


def serve(
    transport: Transport, run: str, me: int, wait: float = STARTUP, first: float | None = None
) -> Served:
    """Run program `me` of swarm `run` to its end. wait: seconds to wait for the other
    programs and for each message of the run; first: for the world's first message
    (default `wait`)."""
    k_ = keys(run)
    mailbox = Mailbox(run)
    # the world's hello last: once it arrives, the declarations before it have too
    transport.subscribe(f"{k_['sense']}{me}", mailbox.handler)
    transport.subscribe(k_["radio"], mailbox.handler)
    transport.subscribe(k_["tick"], mailbox.handler)
    transport.watch(f"{k_['alive']}world", mailbox.lost)
    transport.subscribe(k_["hello"], mailbox.handler)
    limit = time.monotonic() + (wait if first is None else first)
    mailbox.wait(lambda: ("hello",) in mailbox.inbox or mailbox.gone, limit)
    hello = mailbox.inbox.get(("hello",))
    if hello is None:
        return Served(0, 0, "no world")
    scenario = Scenario.from_dict(json.loads(hello.scenario), origin="the world's scenario")
    n = scenario.n_uavs
    central = get(hello.method).central
    programs = n + int(central)
    if me >= programs:
        return Served(0, scenario.steps, "not in run", programs=programs, central=central)
    if transport.alive(f"{k_['alive']}{me}"):  # another program with this number runs
        return Served(0, scenario.steps, "taken", programs=programs, central=central)
    faults = Faults(scenario.faults, hello.key.array()[None].astype(np.uint32), n)
    if me == n:
        program = CentralAgent(scenario, faults, transport, mailbox, run, hello.deadline)
    else:
        prior = (hello.prior_mean.array().copy(), hello.prior_cov.array().copy())
        prior = (prior[0], np.broadcast_to(prior[1], (scenario.n_targets, 4, 4)).copy())
        program = UavAgent(
            me, scenario, hello.method, faults, transport, mailbox, run, hello.deadline, prior
        )
    transport.announce(f"{k_['alive']}{me}")
    if not meet(transport, mailbox, run, me, programs, wait):
        return Served(0, scenario.steps, "world gone", 0, programs, central)
    empty = packed({"x": np.zeros(0)})["x"]
    ready = Report(VERSION, run, -1, me, -1, -1, empty, empty, empty, 0, 0, 0, 0.0)
    transport.publish(f"{k_['report']}{me}", encode(ready))
    first = ("tick", 0) if me == n else ("sense", 0, me)
    limit = time.monotonic() + wait
    while first not in mailbox.inbox and not mailbox.gone and time.monotonic() < limit:
        _presence(transport, run, me)  # until the run starts: others may still need it
        mailbox.wait(lambda: first in mailbox.inbox or bool(mailbox.gone), time.monotonic() + 0.1)
    published = (getattr(transport, "published", 0), getattr(transport, "bytes", 0))
    ran, end, at = 0, "done", -1
    for k in range(scenario.steps):
        want = ("tick", k) if me == n else ("sense", k, me)
        patience = time.monotonic() + wait
        mailbox.wait(lambda want=want: want in mailbox.inbox or bool(mailbox.gone), patience)
        message = mailbox.take(want)
        if message is None:  # the world is gone or silent: stop
            end, at = "world gone", k
            break
        if me < n and not bool(message.alive.array()[me]):
            end, at = "failed", k  # the world says this UAV has failed
            break
        report = program.cycle(message)
        now = (getattr(transport, "published", 0), getattr(transport, "bytes", 0))
        report = structs.replace(
            report,
            published=now[0] - published[0],
            bytes=now[1] - published[1],
            dropped=mailbox.dropped,
        )
        published = now
        transport.publish(f"{k_['report']}{me}", encode(report))
        ran += 1
    # stay until the world is done: closing at once could lose the last report in flight
    mailbox.wait(lambda: bool(mailbox.gone), time.monotonic() + LINGER)
    return Served(ran, scenario.steps, end, at, programs, central)


def _presence(transport: Transport, run: str, me: int) -> None:
    message = Radio(VERSION, run, -1, "presence", 0, me, True, {})
    transport.publish(f"{keys(run)['radio']}{me}", encode(message))


def meet(transport: Transport, mailbox: Mailbox, run: str, me: int, programs: int, wait: float):
    """Announce this program to the others until it has heard every one of them (UAVs
    0 .. N-1 and the central node N if any): then the routes between all programs
    exist, and no message of the first cycle is lost to a subscription still in transit."""
    others = [p for p in range(programs) if p != me]
    heard = lambda: all(mailbox.content(-1, "presence", p, 0) is not None for p in others)  # noqa: E731
    limit = time.monotonic() + wait
    while time.monotonic() < limit and not mailbox.gone:
        _presence(transport, run, me)
        if mailbox.wait(heard, time.monotonic() + 0.1):
            return True
    return False
