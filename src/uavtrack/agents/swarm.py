"""Running a swarm: the world program and one program per UAV, on a transport.

* ``memory``: every program in a thread of this process, on an in-process bus
  (deterministic; for tests and quick runs).
* ``zenoh``: one OS process per program, peer mode on loopback endpoints; the world
  listens, the programs connect to it. The programs are forked by one launcher process
  that loaded their modules once (`launcher`), so each starts in milliseconds. Every process
  started here is stopped here, by pid: at the end, on an error, on Ctrl-C. A program
  whose parent dies, or whose world is gone, stops by itself.

By default the world makes the run's keys (`security.Keyring`) and hands each spawned
program its own through its standard input (with `--no-spawn`, in key files the user
copies to the machines of the programs), so only the run's members can speak in it.
"""

from __future__ import annotations

import os
import re
import secrets
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..config import Scenario, ScenarioError
from ..errors import RunError, UsageError, install_hint
from ..io.replay import Recording, scenario_for
from ..io.replay import briefing as replay_briefing
from ..io.replay import result_of as replay_result
from ..methods import get
from ..radio import RUN_CHARS
from ..records import Result
from ..simulation import result_of
from .agent import check_method
from .launcher import Forked, Launcher
from .program import serve
from .security import Keyring
from .transport import Bus, MemoryTransport, ZenohOptions, ZenohTransport, zenoh_reason
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
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
        probe.bind((host, 0))
        return probe.getsockname()[1]


def world_endpoint(listen: str | None, tls: bool = False) -> str:
    """The endpoint the world listens on, as the programs will reach it: a free loopback
    port when none is given (tls/ with TLS), and a free port of the host for
    ``tcp/HOST:0`` or ``tls/HOST:0`` (the programs must be told a real port)."""
    if listen is None:
        return f"{'tls' if tls else 'tcp'}/127.0.0.1:{free_port()}"
    if not listen.strip():
        raise UsageError("--listen is empty; give an endpoint such as tcp/127.0.0.1:7447")
    found = re.fullmatch(r"(tcp|tls)/(\[[^\]]+\]|[^:/]+):0", listen.strip())
    if found is None:
        return listen.strip()
    scheme, host = found.group(1), found.group(2)
    try:
        return f"{scheme}/{host}:{free_port(host.strip('[]'))}"
    except OSError as exc:
        raise UsageError(f"cannot listen on {listen}: {exc.strerror or exc}") from None


@dataclass(frozen=True, kw_only=True)
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
    patience: float | None = None
    announce: Callable[[str, str, list[Path]], None] | None = None
    sign: bool = True
    keys: Path | None = None
    zenoh: ZenohOptions = field(default_factory=ZenohOptions)
    ros2: int | None = None
    recording: Recording | None = None
    pilot: Any = None

    def result(self, batch, seed: int) -> Result:
        """The run's `Result`: a replay's (`replay.result_of`) with a recording."""
        if self.recording is not None:
            return replay_result(batch, self.recording)
        return result_of(batch, seed)

    def world(self, scenario, method, seed, link, run, keyring) -> WorldProgram:
        """The run's world program on `link`."""
        return WorldProgram(
            scenario, method, seed, link, run, self.deadline, self.startup, keyring,
            recording=self.recording, pilot=self.pilot,
        )  # fmt: skip


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
    announce: Callable[[str, str, list[Path]], None] | None = None,
    sign: bool = True,
    keys: Path | None = None,
    zenoh: ZenohOptions | None = None,
    ros2: int | None = None,
    patience: float | None = None,
    recording: Recording | None = None,
    pilot: Any = None,
) -> SwarmResult:
    """Run one trial as a swarm of programs; its result equals `simulate`'s for the same
    scenario, method and seed (the same faults included).

    deadline: seconds a round waits for messages; listen: the world's endpoint (zenoh;
    default a free loopback port); connect: more endpoints for the world to join
    (programs on other machines); spawn: start the programs here (else wait for them,
    started with `uavtrack agent`; `announce` is told the run id, the endpoint and the
    key files written in `keys`); realtime: pace cycles at dt; startup: seconds to wait
    for the programs; patience: seconds a spawned program waits for each message of the
    world before it ends, saying the world went silent (default: `startup` in memory,
    `program.STARTUP` over Zenoh); sign: authenticate every message (`security`); zenoh: a Zenoh
    configuration file and TLS files; ros2: a ROS 2 domain id (0-232): every UAV program
    also publishes its pose, transform and estimates as ROS 2 topics, the world the
    simulated clock on /clock (`io.ros2`, zenoh only); recording: recorded scans and
    poses the world tells the programs in place of its truth (`replay.Recording`; the
    result then equals `replay.replay`'s); pilot: what flies the decisions (a
    `io.mavlink.MavlinkPilot`; None: the scenario's aircraft, or with a recording nothing).
    """
    if transport not in TRANSPORTS:
        raise UsageError(f"unknown transport {transport!r}; choose memory or zenoh")
    try:  # refuses an unknown method, or one the programs cannot run, now
        check_method(get(method), scenario)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if sign and not spawn and keys is None:
        raise UsageError(
            "--no-spawn with signed messages needs --keys DIR, a folder for the programs' "
            "key files (or --no-sign)"
        )
    if ros2 is not None:
        if transport != "zenoh":
            raise UsageError("--ros2 publishes over Zenoh: it needs --transport zenoh")
        if isinstance(ros2, bool) or not isinstance(ros2, int) or not 0 <= ros2 <= 232:
            raise UsageError(f"--ros2: a ROS 2 domain id is 0 to 232, got {ros2!r}")
        try:
            from ..io import ros2 as _  # noqa: F401
        except ImportError as exc:
            raise UsageError(f"--ros2: {exc}") from None
    if recording is not None:
        try:
            scenario = scenario_for(recording, scenario)
        except ScenarioError as exc:
            raise UsageError(str(exc)) from None
        try:  # the programs' Hello carries one briefing covariance
            replay_briefing(recording, scenario)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        if not np.isfinite(recording.polar[recording.valid]).all():
            raise UsageError(
                "the UAV programs are told range and bearing: this recording has "
                "measurements given only on the ground (x, y, R)"
            )
    run = secrets.token_hex(RUN_CHARS // 2)
    n = scenario.n_uavs
    programs = list(range(n)) + ([n] if get(method).central else [])
    options = Options(
        deadline=deadline,
        listen=listen,
        connect=tuple(connect),
        spawn=spawn,
        realtime=realtime,
        trace=trace,
        progress=progress,
        startup=startup if startup is not None else 30.0 + 4.0 * len(programs),
        patience=patience,
        announce=announce,
        sign=sign,
        keys=keys,
        zenoh=zenoh or ZenohOptions(),
        ros2=ros2,
        recording=recording,
        pilot=pilot,
    )
    keyring = Keyring(run, len(programs)) if sign else None
    go = _in_memory if transport == "memory" else _over_zenoh
    return go(scenario, method, seed, run, programs, options, keyring)


def _in_memory(scenario, method, seed, run, programs, o: Options, keyring) -> SwarmResult:
    bus = Bus()
    world_link = MemoryTransport(bus)
    world_link.announce(f"uavtrack/{run}/alive/world")
    world = o.world(scenario, method, seed, world_link, run, keyring)
    errors: list[BaseException] = []

    def program(me: int) -> None:
        link = MemoryTransport(bus)
        credential = keyring.credential(me) if keyring is not None else None
        try:
            serve(link, run, me, wait=o.patience or o.startup, credential=credential)
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
    return SwarmResult(o.result(batch, seed), world.traffic, run, "memory")


def _over_zenoh(scenario, method, seed, run, programs, o: Options, keyring) -> SwarmResult:
    try:
        import zenoh  # noqa: F401
    except ImportError:
        raise UsageError(
            f"--transport zenoh needs eclipse-zenoh: {install_hint('agents')}"
        ) from None
    endpoint = world_endpoint(o.listen, o.zenoh.tls)
    try:  # before Zenoh: a certificate its peers refuse would show only as timeouts
        o.zenoh.check([endpoint, *o.connect])
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    try:
        link = ZenohTransport([endpoint], list(o.connect), o.zenoh, mode="router")
    except Exception as exc:  # zenoh reports a busy port, a bad endpoint, no answer so
        reason = zenoh_reason(exc)
        if o.connect and "Unable to connect" in reason:  # listening worked
            where = " or ".join(o.connect)
            raise UsageError(f"cannot connect to {where}: {reason}") from None
        raise UsageError(f"cannot listen on {endpoint}: {reason}") from None
    children: list[Child] = []
    launcher: Launcher | None = None
    written: list[Path] = []
    quoted: set[int] = set()  # programs whose words the error already quotes
    finished = False
    clock = None
    try:
        if o.spawn:  # loads the programs' modules while the world sets up
            launcher = Launcher()
        link.announce(f"uavtrack/{run}/alive/world")
        world = o.world(scenario, method, seed, link, run, keyring)
        if o.ros2 is not None:
            from ..io.ros2 import ClockNode

            clock = ClockNode(link.session, o.ros2, scenario.dt)
            world.clock = clock.publish
        if not o.spawn and keyring is not None and o.keys is not None:  # `swarm` checked keys
            written = write_keys(keyring, programs, o.keys)
        if o.announce is not None:
            o.announce(run, endpoint, written)
        if launcher is not None:
            for me in programs:
                spec = {
                    "run": run,
                    "program": me,
                    "connect": [endpoint],
                    "zenoh": asdict(o.zenoh),
                    "credential": keyring.credential(me).to_json() if keyring else None,
                    "parent": os.getpid(),
                    "ros2": o.ros2,
                    "wait": o.patience,
                }
                children.append(Child.start(me, spec, launcher))

        def check() -> None:
            ended = [c for c in children if c.process.poll() is not None]
            if ended:  # the others may be failing the same way: a moment for them to say so
                wait_for([c.process for c in children], 2.0)
                ended = [c for c in children if c.process.poll() is not None]
                quoted.update(c.me for c in ended)
                raise RunError(
                    f"{len(ended)} of {len(children)} agent processes exited before the run "
                    f"started: {said_by(ended)}"
                )

        def supervise(k: int) -> None:
            if launcher is not None and launcher.gone:
                raise RunError(
                    f"the program launcher {launcher.ended()} at step {k}, and every UAV "
                    "program with it"
                )

        world.check = check if o.spawn else None
        world.supervise = supervise
        try:
            batch = world.run_trial(trace=o.trace, realtime=o.realtime, progress=o.progress)
        except TimeoutError as exc:
            raise RunError(str(exc)) from None
        finished = True
        for child in children:  # a lost program that ended says why, better than a token
            if child.me in world.traffic.lost and child.process.poll() is not None:
                world.traffic.why[child.me] = ended_why(child)
    finally:
        if clock is not None:
            clock.close()
        link.close()  # the programs see the world gone and end
        # after the last cycle they finish by themselves; on an error or Ctrl-C, at once
        stop([c.process for c in children], grace=o.deadline + 3.0 if finished else 0.0)
        if launcher is not None:
            launcher.close()
        for path in written:
            path.unlink(missing_ok=True)
        _forward([c for c in children if c.me not in quoted])
        for child in children:
            child.close()
    return SwarmResult(o.result(batch, seed), world.traffic, run, "zenoh")


def write_keys(keyring: Keyring, programs: list[int], folder: Path) -> list[Path]:
    """Each program's key file in `folder`, ``<run>-<program>.key``, readable by the
    owner only; removed when the run ends."""
    written = []
    try:
        for me in programs:
            path = Path(folder) / f"{keyring.run}-{me}.key"
            keyring.credential(me).write(path)
            written.append(path)
    except OSError as exc:
        for path in written:
            path.unlink(missing_ok=True)
        raise UsageError(f"--keys: cannot write {exc.filename}: {exc.strerror}") from None
    return written


@dataclass
class Child:
    """A spawned program: its process (forked by the `launcher.Launcher`) and the file its
    standard error goes to (already unlinked: it goes with the last process that holds
    it, whatever ends this one)."""

    me: int
    process: Forked
    log: Any

    @classmethod
    def start(cls, me: int, spec: dict, launcher: Launcher) -> Child:
        log = tempfile.TemporaryFile(prefix="uavtrack-program-")
        try:
            return cls(me, launcher.start(me, spec, log), log)
        except BaseException:
            log.close()
            raise

    def printed(self) -> list[str]:
        """The lines the program printed on its standard error."""
        try:
            size = os.fstat(self.log.fileno()).st_size
            data = os.pread(self.log.fileno(), min(size, 1 << 20), max(0, size - (1 << 20)))
        except (OSError, ValueError):
            return []
        return data.decode(errors="replace").strip().splitlines()

    def close(self) -> None:
        self.log.close()


def said_by(children: list[Child]) -> str:
    """What programs said last: each different saying once, with the programs that said
    it and their exit codes."""
    sayings: dict[str, list[Child]] = {}
    for child in children:
        lines = child.printed()
        sayings.setdefault(" | ".join(lines[-3:]), []).append(child)
    parts = []
    for text, group in sayings.items():
        who = ", ".join(str(c.me) for c in group)
        ended = {code for c in group if (code := c.process.returncode) is not None}
        codes = ", ".join(str(code) for code in sorted(ended)) or "none yet"
        name = "program" if len(group) == 1 else "programs"
        parts.append(
            f"{name} {who} (exit code {codes}) " + (f"said: {text}" if text else "printed nothing")
        )
    return "; ".join(parts)


def ended_why(child: Child) -> str:
    """Why a lost program ended, in its own words: its exit code and last line."""
    code = child.process.returncode
    said = child.printed()
    words = f": {said[-1][:300]}" if said else ", printing nothing"
    how = f"exit code {code}"
    if code is not None and code < 0:
        try:
            how = f"killed by {signal.Signals(-code).name}"
        except ValueError:
            how = f"killed by signal {-code}"
    return f"its process ended ({how}){words}"


def wait_for(processes: list[Forked], seconds: float) -> None:
    """Wait until every process has ended, or `seconds` have passed."""
    limit = time.monotonic() + seconds
    for process in processes:
        try:
            process.wait(timeout=max(0.0, limit - time.monotonic()))
        except subprocess.TimeoutExpired:
            return


def _forward(children: list[Child], lines: int = 20) -> None:
    """Show on this process's standard error what the programs printed, if anything."""
    for child in children:
        text = child.printed()
        if text:
            shown = text[-lines:]
            skipped = f" (last {lines} of {len(text)} lines)" if len(text) > lines else ""
            print(f"program {child.me} printed{skipped}:", file=sys.stderr)
            for line in shown:
                print(f"  {line}", file=sys.stderr)


def stop(children: list[Forked], grace: float = 5.0) -> None:
    """Stop the processes started here, by pid: let them finish, then terminate, then kill."""
    wait_for(children, grace)
    for child in children:
        if child.poll() is None:
            child.send_signal(signal.SIGTERM)
    for child in children:
        try:
            child.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()
