"""Running a swarm: the world program and one program per UAV, on a transport.

* ``memory``: every program in a thread of this process, on an in-process bus
  (deterministic; for tests and quick runs).
* ``zenoh``: one OS process per program (``python -m uavtrack.agents``), peer mode on
  loopback endpoints; the world listens, the programs connect to it. Every process
  started here is stopped here, by pid: at the end, on an error, on Ctrl-C. A program
  whose parent dies, or whose world is gone, stops by itself.
"""

from __future__ import annotations

import os
import re
import secrets
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from ..config import Scenario
from ..errors import RunError, UsageError
from ..methods import get
from ..simulation import Result, result_of
from .program import serve
from .transport import Bus, MemoryTransport, ZenohTransport, zenoh_reason
from .world import Traffic, WorldProgram

TRANSPORTS = ("memory", "zenoh")


@dataclass(frozen=True)
class SwarmResult:
    """The trial's result (as `simulate` returns it) and what the run cost."""

    result: Result
    traffic: Traffic
    run: str
    transport: str


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on `host` now."""
    with socket.socket() as probe:
        probe.bind((host, 0))
        return probe.getsockname()[1]


def world_endpoint(listen: str | None) -> str:
    """The endpoint the world listens on, as the programs will reach it: a free loopback
    port when none is given, and a free port of the host for ``tcp/HOST:0`` (the
    programs must be told a real port)."""
    if listen is None:
        return f"tcp/127.0.0.1:{free_port()}"
    if not listen.strip():
        raise UsageError("--listen is empty; give an endpoint such as tcp/127.0.0.1:7447")
    found = re.fullmatch(r"tcp/(\[[^\]]+\]|[^:/]+):0", listen.strip())
    if found is None:
        return listen
    host = found.group(1)
    try:
        return f"tcp/{host}:{free_port(host.strip('[]'))}"
    except OSError as exc:
        raise UsageError(f"cannot listen on {listen}: {exc.strerror or exc}") from None


@dataclass(frozen=True)
class Options:
    """How a swarm runs (see `run_swarm`)."""

    deadline: float = 2.0
    listen: str | None = None
    connect: tuple[str, ...] = ()
    spawn: bool = True
    realtime: bool = False
    trace: bool = True
    progress: Callable[[int], None] | None = None
    startup: float = 60.0
    announce: Callable[[str, str], None] | None = None


def run_swarm(
    scenario: Scenario,
    method: str = "distributed",
    seed: int = 0,
    transport: str = "memory",
    deadline: float = 2.0,
    listen: str | None = None,
    connect: tuple[str, ...] = (),
    spawn: bool = True,
    realtime: bool = False,
    trace: bool = True,
    progress: Callable[[int], None] | None = None,
    startup: float | None = None,
    announce: Callable[[str, str], None] | None = None,
) -> SwarmResult:
    """Run one trial as a swarm of programs; its result equals `simulate`'s for the same
    scenario, method and seed (the same faults included).

    deadline: seconds a round waits for messages; listen: the world's endpoint (zenoh;
    default a free loopback port); connect: more endpoints for the world to join
    (programs on other machines); spawn: start the programs here (else wait for them,
    started with `uavtrack agent`; `announce` is told the run id and the endpoint);
    realtime: pace cycles at dt; startup: seconds to wait for the programs.
    """
    if transport not in TRANSPORTS:
        raise UsageError(f"unknown transport {transport!r}; choose memory or zenoh")
    get(method)  # refuses an unknown method now
    run = secrets.token_hex(6)
    n = scenario.n_uavs
    programs = list(range(n)) + ([n] if get(method).central else [])
    options = Options(
        deadline,
        listen,
        tuple(connect),
        spawn,
        realtime,
        trace,
        progress,
        startup if startup is not None else 30.0 + 4.0 * len(programs),
        announce,
    )
    go = _in_memory if transport == "memory" else _over_zenoh
    return go(scenario, method, seed, run, programs, options)


def _in_memory(scenario, method, seed, run, programs, o: Options) -> SwarmResult:
    bus = Bus()
    world_link = MemoryTransport(bus)
    world_link.announce(f"uavtrack/{run}/alive/world")
    world = WorldProgram(scenario, method, seed, world_link, run, o.deadline, o.startup)
    errors: list[BaseException] = []

    def program(me: int) -> None:
        link = MemoryTransport(bus)
        try:
            serve(link, run, me, wait=o.startup)
        except BaseException as exc:  # reported by the world's thread
            errors.append(exc)
        finally:
            link.close()

    threads = [threading.Thread(target=program, args=(p,), daemon=True) for p in programs]
    for thread in threads:
        thread.start()
    try:
        batch = world.run_trial(trace=o.trace, realtime=o.realtime, progress=o.progress)
    finally:
        world_link.close()  # the programs see the world gone and stop
        for thread in threads:
            thread.join(timeout=o.deadline + 5.0)
    if errors:
        raise RunError(f"a program failed: {type(errors[0]).__name__}: {errors[0]}") from errors[0]
    return SwarmResult(result_of(batch, seed), world.traffic, run, "memory")


def _over_zenoh(scenario, method, seed, run, programs, o: Options) -> SwarmResult:
    try:
        import zenoh  # noqa: F401
    except ImportError:
        raise UsageError(
            '--transport zenoh needs eclipse-zenoh: pip install "uavtrack[agents]"'
        ) from None
    endpoint = world_endpoint(o.listen)
    try:
        link = ZenohTransport([endpoint], list(o.connect))
    except Exception as exc:  # zenoh reports a busy port, a bad endpoint, no answer so
        where = " and ".join([f"listen on {endpoint}", *(f"connect to {c}" for c in o.connect)])
        raise UsageError(f"cannot {where}: {zenoh_reason(exc)}") from None
    children: list[subprocess.Popen] = []
    try:
        link.announce(f"uavtrack/{run}/alive/world")
        world = WorldProgram(scenario, method, seed, link, run, o.deadline, o.startup)
        if o.announce is not None:
            o.announce(run, endpoint)
        if o.spawn:
            for me in programs:
                children.append(
                    subprocess.Popen(
                        [sys.executable, "-m", "uavtrack.agents", run, str(me), endpoint],
                        stdin=subprocess.DEVNULL,
                        start_new_session=True,  # Ctrl-C is the swarm's to handle
                    )
                )

        def check() -> None:
            ended = [c for c in children if c.poll() is not None]
            if ended:
                codes = ", ".join(str(c.returncode) for c in ended)
                raise RunError(
                    f"{len(ended)} of {len(children)} agent processes exited before the run "
                    f"started (exit codes {codes}); see their messages above"
                )

        world.check = check if o.spawn else None
        try:
            batch = world.run_trial(trace=o.trace, realtime=o.realtime, progress=o.progress)
        except TimeoutError as exc:
            raise RunError(str(exc)) from None
    finally:
        link.close()  # the programs see the world gone and end
        stop(children, grace=o.deadline + 3.0)
    return SwarmResult(result_of(batch, seed), world.traffic, run, "zenoh")


def stop(children: list[subprocess.Popen], grace: float = 5.0) -> None:
    """Stop the processes started here, by pid: let them finish, then terminate, then kill."""
    limit = time.monotonic() + grace
    for child in children:
        try:
            child.wait(timeout=max(0.0, limit - time.monotonic()))
        except subprocess.TimeoutExpired:
            pass
    for child in children:
        if child.poll() is None:
            child.send_signal(signal.SIGTERM)
    for child in children:
        try:
            child.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()


def watch_parent(parent: int) -> None:
    """End this process within a second once `parent` is gone (even by SIGKILL)."""

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="uavtrack-parent-watch").start()
