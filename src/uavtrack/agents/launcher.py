"""Starting a swarm's programs by forking one process that has already loaded them.

A UAV program started as a fresh interpreter spends about 0.4 s of CPU importing numpy,
pydantic, msgspec, Zenoh and the model before it does anything, and a swarm starts N+1 of
them. `uavtrack swarm` instead starts one *launcher* (``python -m uavtrack.agents
--launcher FD``), which imports all of that once and then forks one child per program:
the children share the loaded modules and start in milliseconds. A child then runs
exactly what a program started by hand runs (`run_program`): it opens its own
Zenoh session after the fork (nothing of Zenoh runs in the launcher, which never opens
one), joins the world and serves.

The launcher and ``uavtrack swarm`` talk over a Unix socket pair (``SOCK_SEQPACKET``, one
JSON message per request and per report; no network):

* ``{"start": spec}`` with one file descriptor attached, the file the program's standard
  error goes to: the launcher forks, the child runs the program, and the launcher answers
  ``{"started": me, "pid": pid}`` (or ``{"refused": me, "why": ...}``);
* ``{"signal": pid, "number": n}``: the launcher signals its child `pid` only while that
  child has not been reaped, so a signal never reaches a later process that reuses the
  pid;
* the launcher reports each child's end, ``{"ended": pid, "code": c}`` (c as
  `subprocess.Popen.returncode`: negative for a signal).

Every process ends with the one that started it: the launcher with ``uavtrack swarm``
(`_process.die_with`), each child with the launcher; when the socket closes, the launcher
terminates the children still running, reaps them and exits. It reaps every child it
forked, so their CPU time is counted in the swarm's (``RUSAGE_CHILDREN``).
"""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from typing import IO, Any

from ..errors import RunError

MESSAGE = 1 << 20
"""The largest request or report, in bytes (a spec with its key is a few kilobytes)."""

NAME = b"uavtrack-%d"
"""A forked program's process name (``/proc/PID/comm``, what ``top`` and ``ps -e`` show):
its command line is the launcher's."""
LAUNCHER = b"uavtrack-launch"
"""The launcher's own process name."""

STARTING = 60.0
"""Seconds the launcher may take to load the model and answer the first start."""


class Launcher:
    """The parent's side: the launcher process and its socket (see the module doc)."""

    def __init__(self) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.log: IO[bytes] = tempfile.TemporaryFile(prefix="uavtrack-launcher-")
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "uavtrack.agents", "--launcher"]
                + [str(theirs.fileno()), str(os.getpid())],
                pass_fds=[theirs.fileno()],
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=self.log,
                start_new_session=True,  # Ctrl-C is the swarm's to handle
            )
        except BaseException:
            ours.close()
            self.log.close()
            raise
        finally:
            theirs.close()
        self.socket = ours
        self.lock = threading.Lock()
        self.started: dict[int, tuple[int, str]] = {}  # program -> (pid, or -1; why)
        self.forked: dict[int, Forked] = {}  # pid -> its handle
        self.answered = threading.Condition(self.lock)
        self.gone = False
        self.fault = ""  # why the launcher was ended here, if it was
        self.reader = threading.Thread(target=self._read, daemon=True, name="uavtrack-launcher")
        self.reader.start()

    def start(self, me: int, spec: dict, log: IO[bytes]) -> Forked:
        """Fork program `me` with `spec`, its standard error into `log`; its handle."""
        request = json.dumps({"start": spec}).encode()
        try:
            socket.send_fds(self.socket, [request], [log.fileno()])
        except OSError:
            raise RunError(f"the program launcher {self.ended()}{self._quoted()}") from None
        limit = time.monotonic() + STARTING
        with self.answered:
            while me not in self.started and not self.gone:
                left = limit - time.monotonic()
                if left <= 0:
                    break
                self.answered.wait(left)
            if me not in self.started:
                if self.gone:
                    raise RunError(
                        f"the program launcher {self.ended()} before starting program {me}"
                        + self._quoted()
                    )
                raise RunError(
                    f"the program launcher did not start program {me} within {STARTING:g} s"
                    + self._quoted()
                )
            pid, why = self.started.pop(me)
            if pid < 0:
                raise RunError(f"the program launcher could not start program {me}: {why}")
            handle = self.forked.setdefault(pid, Forked(pid, self))
            if self.gone:  # the launcher went before this handle was made: so did its child
                handle.ended(-signal.SIGKILL)
        return handle

    def signal(self, pid: int, number: int) -> None:
        """Ask the launcher to send signal `number` to its child `pid` (if still running)."""
        try:
            self.socket.send(json.dumps({"signal": pid, "number": int(number)}).encode())
        except OSError:  # the launcher is gone, and its children with it
            pass

    def said(self) -> str:
        """The last lines the launcher printed ("" if nothing)."""
        try:
            size = os.fstat(self.log.fileno()).st_size
            data = os.pread(self.log.fileno(), min(size, 4096), max(0, size - 4096))
        except (OSError, ValueError):
            return ""
        return " | ".join(data.decode(errors="replace").strip().splitlines()[-3:])

    def _quoted(self) -> str:
        said = self.said()
        return f"; it said: {said}" if said else ""

    def ended(self, wait: float = 2.0) -> str:
        """How the launcher process ended, as words ("ended (killed by SIGKILL)"); waits
        up to `wait` seconds for it, as its socket closes a moment before it exits."""
        if self.fault:
            return self.fault
        try:
            code = self.process.wait(timeout=wait)
        except subprocess.TimeoutExpired:
            return "stopped answering"
        if code < 0:
            try:
                return f"ended (killed by {signal.Signals(-code).name})"
            except ValueError:
                return f"ended (killed by signal {-code})"
        return f"ended (exit code {code})"

    def _receive(self) -> bytes:
        """The launcher's next report (b"": its socket closed)."""
        try:
            return self.socket.recv(MESSAGE)
        except OSError:
            return b""

    def _read(self) -> None:
        """Take the launcher's reports until its socket closes. A report that is not one
        (garbage on the socket) ends the launcher, which no longer can be believed: it
        is killed, by its pid, and its programs with it, and `ended` says why."""
        while data := self._receive():
            try:
                self._take(json.loads(data))
            except (ValueError, TypeError, KeyError, AttributeError):
                self.fault = f"sent a report that is not one ({data[:40]!r})"
                self.process.kill()
                break
        with self.answered:  # its children died with it (their parent-death signal)
            self.gone = True
            for handle in self.forked.values():
                handle.ended(-signal.SIGKILL)
            self.answered.notify_all()

    def _take(self, report: dict) -> None:
        """One report: a program started or refused, a program ended."""
        with self.answered:
            if "started" in report:
                self.started[int(report["started"])] = (int(report["pid"]), "")
            elif "refused" in report:
                self.started[int(report["refused"])] = (-1, str(report["why"]))
            elif "ended" in report:
                pid = int(report["ended"])
                self.forked.setdefault(pid, Forked(pid, self)).ended(int(report["code"]))
            else:
                raise KeyError("no report")
            self.answered.notify_all()

    def close(self, grace: float = 5.0) -> None:
        """Close the socket (the launcher then stops what still runs and exits) and wait
        for the launcher, killing it after `grace` seconds."""
        try:
            self.socket.shutdown(socket.SHUT_WR)
        except OSError:
            pass
        try:
            self.process.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.reader.join(timeout=grace)
        self.socket.close()
        self.log.close()


class Forked:
    """A forked program, with the part of `subprocess.Popen` that `swarm` uses: pid,
    returncode, poll, wait, send_signal, kill."""

    def __init__(self, pid: int, launcher: Launcher) -> None:
        self.pid = pid
        self.launcher = launcher
        self.returncode: int | None = None
        self._ended = threading.Event()

    def ended(self, code: int) -> None:
        if self.returncode is None:
            self.returncode = code
        self._ended.set()

    def poll(self) -> int | None:
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if not self._ended.wait(timeout):
            raise subprocess.TimeoutExpired(f"program {self.pid}", timeout or 0.0)
        assert self.returncode is not None  # set before the event
        return self.returncode

    def send_signal(self, number: int) -> None:
        if self.returncode is None:
            self.launcher.signal(self.pid, number)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


# ------------------------------------------------------------------ the launcher process


def run_program(spec: dict, parent: int) -> int:
    """Run one program with `spec` until its run ends (what ``python -m uavtrack.agents``
    runs, and each forked child): the run, the program's number, the endpoints, Zenoh's
    options, its key; it ends with process `parent`. Its exit code."""
    from .._process import die_with

    die_with(parent)
    from .program import STARTUP, serve
    from .security import Credential
    from .transport import ZenohOptions, ZenohTransport, zenoh_reason

    credential = Credential.from_json(spec["credential"]) if spec["credential"] else None
    options = ZenohOptions(**spec["zenoh"])
    try:  # this program's own TLS files, named if its peers would refuse them
        options.check(spec["connect"])
    except ValueError as exc:
        print(f"program {spec['program']}: {exc}", file=sys.stderr)
        return 2
    try:
        transport = ZenohTransport([], spec["connect"], options)
    except Exception as exc:  # the world is already gone, or its endpoint refuses
        print(f"program {spec['program']}: cannot join: {zenoh_reason(exc)}", file=sys.stderr)
        return 1
    try:
        served = serve(
            transport,
            spec["run"],
            int(spec["program"]),
            wait=spec.get("wait") or STARTUP,
            credential=credential,
            ros2=spec.get("ros2"),
        )
    except KeyboardInterrupt:
        return 130
    finally:
        transport.close()
    if served.end in ("done", "failed"):
        return 0
    at = f" at step {served.at}" if served.at >= 0 else ""
    why = f": {served.why}" if served.why else ""
    wait = spec.get("wait") or STARTUP
    end = {"world gone": f"the world ended or went silent for {wait:g} s"}.get(served.end)
    print(f"program {spec['program']}: {end or served.end}{at}{why}", file=sys.stderr)
    return 1


def main(fd: int, parent: int) -> int:
    """The launcher: load the programs' modules, then fork one per start request until the
    socket `fd` closes. `parent`: the pid of ``uavtrack swarm``, whose end is its own."""
    from .._process import die_with

    die_with(parent)
    _name(LAUNCHER)
    from . import program, security, tracked, transport  # noqa: F401  loaded once, for all

    try:
        import zenoh  # noqa: F401  imported, never opened here
    except ImportError:
        pass
    link = socket.socket(fileno=fd)
    wake_read, wake_write = os.pipe()
    os.set_blocking(wake_write, False)
    signal.set_wakeup_fd(wake_write)
    signal.signal(signal.SIGCHLD, lambda *_: None)  # wakes the select below
    children: set[int] = set()
    open_ = True
    try:
        while open_ or children:
            _reap(children, link)
            if not open_:  # the swarm is done with us: what still runs is stopped
                for pid in children:
                    os.kill(pid, signal.SIGTERM)
                _reap_all(children, link, grace=2.0)
                break
            ready, _, _ = select.select([link, wake_read], [], [], 1.0)
            if wake_read in ready:
                os.read(wake_read, 4096)
            if link not in ready:
                continue
            try:
                data, fds, _, _ = socket.recv_fds(link, MESSAGE, 1)
            except OSError:
                data, fds = b"", []
            if not data:
                open_ = False
                continue
            request = json.loads(data)
            if "start" in request:
                spec = request["start"]
                log = fds[0] if fds else os.open(os.devnull, os.O_WRONLY)
                pid = _fork(spec, log, link, (wake_read, wake_write))
                os.close(log)
                if pid > 0:
                    children.add(pid)
                    _report(link, {"started": spec["program"], "pid": pid})
                else:
                    _report(link, {"refused": spec["program"], "why": "fork failed"})
            elif "signal" in request and int(request["signal"]) in children:
                try:
                    os.kill(int(request["signal"]), int(request["number"]))
                except ProcessLookupError:
                    pass
    except KeyboardInterrupt:
        pass
    finally:
        for pid in children:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        _reap_all(children, link, grace=2.0)
    return 0


def _fork(spec: dict, log: int, link: socket.socket, wake: tuple[int, int]) -> int:
    """Fork one program; the child never returns. The child's pid, or -1. Returns once
    the child holds its own streams and name (it closes `named` then)."""
    waiting, named = os.pipe()
    parent = os.getpid()  # read before the fork: once the child has named itself the
    # launcher may be gone, and os.getppid() would name whoever adopted the child
    try:
        pid = os.fork()
    except OSError:
        os.close(waiting)
        os.close(named)
        return -1
    if pid:
        os.close(named)
        os.read(waiting, 1)  # end of file: the child has named itself (or died)
        os.close(waiting)
        return pid
    code = 1
    try:  # the child: none of the launcher's plumbing, its own standard streams
        os.close(waiting)
        signal.set_wakeup_fd(-1)
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        link.close()
        for fd in wake:
            os.close(fd)
        os.dup2(log, 2)
        os.close(log)
        null = os.open(os.devnull, os.O_RDWR)
        os.dup2(null, 0)
        os.dup2(null, 1)
        os.close(null)
        _name(NAME % int(spec["program"]))
        os.close(named)
        code = run_program(spec, parent)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:
        import traceback

        traceback.print_exc()
    finally:
        try:
            sys.stderr.flush()
        finally:
            os._exit(code)


def _name(name: bytes) -> None:
    """Set this process's name (Linux; elsewhere nothing)."""
    try:
        import ctypes

        ctypes.CDLL(None).prctl(15, name[:15], 0, 0, 0)  # PR_SET_NAME
    except (OSError, AttributeError):
        pass


def _report(link: socket.socket, report: dict[str, Any]) -> None:
    try:
        link.send(json.dumps(report).encode())
    except OSError:  # the swarm is gone; its children go with us
        pass


def _reap(children: set[int], link: socket.socket) -> None:
    """Reap the children that ended, reporting each."""
    for pid in list(children):
        try:
            done, status = os.waitpid(pid, os.WNOHANG)
        except ChildProcessError:
            done, status = pid, 0
        if done:
            children.discard(pid)
            _report(link, {"ended": pid, "code": _code(status)})


def _reap_all(children: set[int], link: socket.socket, grace: float) -> None:
    """Reap every child, killing those still running after `grace` seconds."""
    limit = time.monotonic() + grace
    while children and time.monotonic() < limit:
        _reap(children, link)
        if children:
            time.sleep(0.02)
    for pid in list(children):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        _, status = os.waitpid(pid, 0)
        children.discard(pid)
        _report(link, {"ended": pid, "code": _code(status)})


def _code(status: int) -> int:
    """A wait status as `subprocess.Popen.returncode`."""
    return os.waitstatus_to_exitcode(status)
