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

import numpy as np

from ..config import Scenario
from ..faults import Faults
from .agent import CentralAgent, UavAgent, keys
from .messages import VERSION, Report, encode, packed
from .transport import Mailbox, Transport

STARTUP = 120.0
"""Seconds a program waits for the world's first message."""


def serve(transport: Transport, run: str, me: int, wait: float = STARTUP) -> int:
    """Run program `me` of swarm `run` to its end; returns the cycles it ran."""
    k_ = keys(run)
    mailbox = Mailbox(run)
    transport.subscribe(k_["hello"], mailbox.handler)
    transport.subscribe(f"{k_['sense']}{me}", mailbox.handler)
    transport.subscribe(k_["radio"], mailbox.handler)
    transport.subscribe(k_["tick"], mailbox.handler)
    transport.watch(f"{k_['alive']}world", mailbox.lost)
    if not mailbox.wait(
        lambda: ("hello",) in mailbox.inbox or mailbox.gone, time.monotonic() + wait
    ):
        return 0
    hello = mailbox.inbox.get(("hello",))
    if hello is None:
        return 0
    scenario = Scenario.from_dict(json.loads(hello.scenario), origin="the world's scenario")
    n = scenario.n_uavs
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
    empty = packed({"x": np.zeros(0)})["x"]
    ready = Report(VERSION, run, -1, me, -1, -1, empty, empty, empty, 0, 0, 0, 0.0)
    transport.publish(f"{k_['report']}{me}", encode(ready))
    published = (getattr(transport, "published", 0), getattr(transport, "bytes", 0))
    ran = 0
    for k in range(scenario.steps):
        want = ("tick", k) if me == n else ("sense", k, me)
        patience = time.monotonic() + wait
        mailbox.wait(lambda want=want: want in mailbox.inbox or bool(mailbox.gone), patience)
        message = mailbox.take(want)
        if message is None:  # the world is gone or silent: stop
            break
        if me < n and not bool(message.alive.array()[me]):
            break  # the world says this UAV has failed
        report = program.cycle(message)
        now = (getattr(transport, "published", 0), getattr(transport, "bytes", 0))
        report = _with_traffic(report, now[0] - published[0], now[1] - published[1])
        published = now
        transport.publish(f"{k_['report']}{me}", encode(report))
        ran += 1
    return ran


def _with_traffic(report: Report, published: int, size: int) -> Report:
    from msgspec import structs

    return structs.replace(report, published=published, bytes=size)
