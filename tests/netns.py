"""Hosts on separate network stacks: a swarm's world and UAV programs in Linux network
namespaces joined through a router namespace, and radio drop-outs made in the router.

Each host is a namespace with one interface (``eth0``), the end of a veth pair whose
other end sits in the router's namespace; the router forwards between them:

    world host  10.231.0.2/24 -- 10.231.0.1 -+
    UAV host 1  10.231.1.2/24 -- 10.231.1.1 -+- router (IPv4 forwarding on)
    UAV host 2  10.231.2.2/24 -- 10.231.2.1 -+
    ...

The addresses are private (10/8) and live only inside the namespaces; nothing here
touches the machine's own network namespace. A cut is a pair of ``blackhole`` policy
rules in the router: what a cut host sends or is sent is dropped without a word (no
ICMP, no loss of carrier the host could notice), as a radio out of range drops it;
restoring deletes the rules. A cut between two hosts only drops what passes between
them. `Network.carrier` takes a host's link down instead (the host sees its carrier go),
as `Network.flapping` does over and over.

Names are unique per harness (``uvt-<pid>-<hex>-<host>``), every namespace is deleted
and every process started here stopped, by pid, when the harness closes (also on an
error or Ctrl-C); namespaces left by a harness whose process no longer exists (killed
by SIGKILL) are deleted by the next one.

``python -m tests.netns world ARGS`` runs ``uavtrack ARGS`` (a ``swarm`` command) and
prints ``step K`` on its standard error after each cycle, so a test can place a cut by
the world's progress rather than by the clock.
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PREFIX = "uvt-"
NETNS_DIR = Path("/run/netns")


def unavailable() -> str | None:
    """Why this machine cannot make network namespaces for a test, or None if it can."""
    if not sys.platform.startswith("linux"):
        return f"network namespaces are Linux's; this is {sys.platform}"
    if os.geteuid() != 0:
        return f"creating network namespaces needs root (running as uid {os.geteuid()})"
    if shutil.which("ip") is None:
        return "the ip command (iproute2) is not installed"
    probe = f"{PREFIX}{os.getpid()}-probe"
    made = _ip("netns", "add", probe, check=False)
    if made.returncode != 0:
        return f"ip netns add failed: {made.stderr.strip() or made.returncode}"
    try:
        link = _ip("-n", probe, "link", "set", "lo", "up", check=False)
        if link.returncode != 0:
            return f"cannot configure a network namespace: {link.stderr.strip()}"
    finally:
        _ip("netns", "delete", probe, check=False)
    return None


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    done = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if check and done.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {done.stderr.strip()}")
    return done


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def sweep_stale() -> list[str]:
    """Delete the namespaces of harnesses whose processes are gone; returns their names."""
    swept = []
    if not NETNS_DIR.is_dir():
        return swept
    for entry in NETNS_DIR.iterdir():
        found = re.fullmatch(rf"{PREFIX}(\d+)-[0-9a-f]+-\w+", entry.name)
        if found and not _pid_alive(int(found.group(1))):
            _ip("netns", "delete", entry.name, check=False)
            swept.append(entry.name)
    return swept


class Network:
    """`hosts` hosts (0 .. hosts-1) in their own namespaces, joined through a router.

    Use it as a context manager: leaving it stops the processes started with `start`
    and deletes every namespace."""

    def __init__(self, hosts: int) -> None:
        self.tag = f"{PREFIX}{os.getpid()}-{secrets.token_hex(3)}"
        self.hosts = hosts
        self.router = f"{self.tag}-r"
        self.names = [f"{self.tag}-h{i}" for i in range(hosts)]
        self.processes: list[subprocess.Popen] = []
        self.cuts: set[tuple[str, str | None]] = set()
        self.made: list[str] = []

    def __enter__(self) -> Network:
        sweep_stale()
        try:
            self._make()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _make(self) -> None:
        _ip("netns", "add", self.router)
        self.made.append(self.router)
        _ip("-n", self.router, "link", "set", "lo", "up")
        self.sh(self.router, "echo 1 > /proc/sys/net/ipv4/ip_forward")
        for i, name in enumerate(self.names):
            _ip("netns", "add", name)
            self.made.append(name)
            _ip("-n", self.router, "link", "add", f"h{i}", "type", "veth", "peer", "name",
                "eth0", "netns", name)  # fmt: skip
            _ip("-n", self.router, "addr", "add", f"10.231.{i}.1/24", "dev", f"h{i}")
            _ip("-n", self.router, "link", "set", f"h{i}", "up")
            _ip("-n", name, "addr", "add", f"{self.address(i)}/24", "dev", "eth0")
            _ip("-n", name, "link", "set", "lo", "up")
            _ip("-n", name, "link", "set", "eth0", "up")
            _ip("-n", name, "route", "add", "default", "via", f"10.231.{i}.1")

    @staticmethod
    def address(host: int) -> str:
        """Host `host`'s address."""
        return f"10.231.{host}.2"

    def sh(self, namespace: str, command: str) -> None:
        done = subprocess.run(
            ["ip", "netns", "exec", namespace, "sh", "-c", command],
            capture_output=True,
            text=True,
            timeout=30,
        )
        if done.returncode != 0:
            raise RuntimeError(f"{command} in {namespace}: {done.stderr.strip()}")

    def start(self, host: int, argv: list[str], **popen) -> subprocess.Popen:
        """Start `argv` on host `host` (``ip netns exec`` execs it: the pid is its own)."""
        process = subprocess.Popen(["ip", "netns", "exec", self.names[host], *argv], **popen)
        self.processes.append(process)
        return process

    def _rules(self, action: str, host: int, other: int | None) -> None:
        me = self.address(host)
        pairs = [("from", me), ("to", me)]
        if other is not None:
            you = self.address(other)
            pairs = [("from", me, "to", you), ("from", you, "to", me)]
        for selector in pairs:
            _ip("-n", self.router, "rule", action, *selector, "blackhole", "priority", "100",
                check=action == "add")  # fmt: skip

    def cut(self, host: int, other: int | None = None) -> None:
        """Drop, silently, everything host `host` sends or is sent (only what passes
        between it and host `other`, if given)."""
        self._rules("add", host, other)

    def restore(self, host: int, other: int | None = None) -> None:
        """Undo `cut(host, other)`."""
        self._rules("del", host, other)

    def carrier(self, host: int, up: bool) -> None:
        """Host `host`'s link down (the router's end: the host sees its carrier go) or
        up again (the router's route to it comes back with it)."""
        _ip("-n", self.router, "link", "set", f"h{host}", "up" if up else "down")

    @contextmanager
    def flapping(self, host: int, down: float = 0.5, up: float = 0.5):
        """Host `host`'s link down for `down` s and up for `up` s, over and over, while
        the block runs (up when it ends); yields a list that counts the flaps."""
        stop, flaps = threading.Event(), []

        def flap() -> None:
            while not stop.is_set():
                self.carrier(host, False)
                flaps.append(time.monotonic())
                stop.wait(down)
                self.carrier(host, True)
                stop.wait(up)

        thread = threading.Thread(target=flap, daemon=True)
        thread.start()
        try:
            yield flaps
        finally:
            stop.set()
            thread.join(30)
            self.carrier(host, True)

    def close(self) -> None:
        """Stop every process started here (by pid) and delete the namespaces."""
        for process in self.processes:
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
        limit = time.monotonic() + 5.0
        for process in self.processes:
            try:
                process.wait(timeout=max(0.1, limit - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        for name in reversed(self.made):
            _ip("netns", "delete", name, check=False)
        self.made = []


class Swarm:
    """A swarm over `network`: the world (``uavtrack swarm --no-spawn``) on host 0,
    listening on its address, and UAV program I (``uavtrack agent``) on host I + 1,
    with its key file. `args`: more options of ``uavtrack swarm``; the world writes its
    trace to `folder`/trace.npz and prints its JSON."""

    PORT = 7447

    def __init__(self, network: Network, uavs: int, folder: Path, args: list[str]) -> None:
        self.network, self.uavs, self.folder = network, uavs, Path(folder)
        self.trace = self.folder / "trace.npz"
        self.endpoint = f"tcp/{network.address(0)}:{self.PORT}"
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(
            [str(ROOT)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else [])
        )
        self.env = env
        self.cond = threading.Condition()
        self.step = 0
        self.run: str | None = None
        self.lines: list[str] = []
        self.times: list[float] = []  # when each cycle ended (monotonic clock) [s]
        argv = [sys.executable, "-m", "tests.netns", "world", "swarm", "--transport", "zenoh",
                "--no-spawn", "--listen", self.endpoint, "--keys", str(self.folder),
                "--json", "--trace", str(self.trace), *args]  # fmt: skip
        with open(self.folder / "world.out", "w") as out:
            self.world = network.start(
                0, argv, cwd=ROOT, env=env, stdout=out, stderr=subprocess.PIPE, text=True
            )
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()
        self.agents: list[subprocess.Popen] = []

    def _read(self) -> None:
        for line in self.world.stderr:
            with self.cond:
                self.lines.append(line.rstrip("\n"))
                found = re.fullmatch(r"step (\d+)\n?", line)
                if found:
                    self.step = int(found.group(1))
                    self.times.append(time.monotonic())
                self.cond.notify_all()
        with self.cond:
            self.cond.notify_all()

    def _until(self, condition, limit: float) -> bool:
        end = time.monotonic() + limit
        with self.cond:
            while not condition():
                left = end - time.monotonic()
                if left <= 0 or self.world.poll() is not None and not self.reader.is_alive():
                    return condition()
                self.cond.wait(min(left, 0.5))
            return True

    def join(self, limit: float = 120.0) -> None:
        """Start every UAV program once the world has written their key files."""
        end = time.monotonic() + limit
        while len(keys := sorted(self.folder.glob("*.key"))) < self.uavs:
            if time.monotonic() > end or self.world.poll() is not None:
                raise RuntimeError(f"the world did not start: {self.said[-500:]}")
            time.sleep(0.1)
        self.run = keys[0].name.rsplit("-", 1)[0]
        for i in range(self.uavs):
            key = self.folder / f"{self.run}-{i}.key"
            argv = [sys.executable, "-m", "uavtrack.cli", "agent", "--key", str(key),
                    "--connect", self.endpoint]  # fmt: skip
            with open(self.folder / f"agent{i}.out", "w") as out:
                self.agents.append(
                    self.network.start(i + 1, argv, env=self.env, stdout=out, stderr=out)
                )

    def reached(self, k: int, limit: float = 300.0) -> bool:
        """Wait until the world has run `k` cycles (False if it ended first)."""
        return self._until(lambda: self.step >= k, limit)

    def finished(self, limit: float = 600.0) -> bool:
        """Wait until the world has ended (False if it outlives `limit`)."""
        return self._until(lambda: self.world.poll() is not None, limit)

    def finish(
        self, limit: float = 300.0, programs: float = 60.0
    ) -> tuple[int, str, list[tuple[int, str]]]:
        """Wait for the world and the programs to end (killing, by pid, one that outlives
        `limit`, or a program that outlives the world by `programs` seconds): the world's
        exit code and standard output, and each program's exit code
        and what it printed."""
        ended = []
        for process, wait in [(self.world, limit)] + [(a, programs) for a in self.agents]:
            try:
                process.wait(timeout=wait)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
            ended.append(process.returncode)
        self.reader.join(10)
        said = [(self.folder / f"agent{i}.out").read_text() for i in range(len(self.agents))]
        out = (self.folder / "world.out").read_text()
        return ended[0], out, list(zip(ended[1:], said, strict=True))

    @property
    def said(self) -> str:
        """What the world printed on its standard error (its step lines aside)."""
        with self.cond:
            return "\n".join(x for x in self.lines if not re.fullmatch(r"step \d+", x))


def _world(argv: list[str]) -> int:
    """`uavtrack argv` with a line ``step K`` on standard error after each cycle (and
    every thread's stack there on SIGUSR1, to see where a world hangs)."""
    import faulthandler

    faulthandler.register(signal.SIGUSR1, all_threads=True)
    from uavtrack import cli
    from uavtrack.cli import swarm as swarm_cli

    @contextmanager
    def steps(scenario, **_):
        done = 0

        def advance(n: int) -> None:
            nonlocal done
            done += n
            print(f"step {done}", file=sys.stderr, flush=True)

        yield advance

    swarm_cli.steps_bar = steps
    return cli.main(argv)


if __name__ == "__main__":
    if sys.argv[1:2] != ["world"]:
        sys.exit("usage: python -m tests.netns world SWARM-ARGS")
    sys.exit(_world(sys.argv[2:]))
