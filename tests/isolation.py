"""The wall around the fast loop: a test not marked ``integration`` may not start a process,
open a network endpoint, a Zenoh session or Dask, or fly JSBSim.

``pytest -m "not integration"`` is the mathematics and the cycle in one process, quick on a
loaded machine; whatever starts processes or talks over a network belongs to
``pytest -m integration``. While a test without the marker sets up or runs (see
``tests/conftest.py``), each of these entry points fails it with a line naming the test and
what it started:

* processes: ``subprocess.Popen._execute_child`` (every ``subprocess`` call, asyncio's
  subprocesses, a browser), ``multiprocessing.process.BaseProcess.start`` (``Process``,
  ``Pool``, ``ProcessPoolExecutor``'s workers, Dask's nannies), ``os.fork``,
  ``os.forkpty``, ``os.system``, ``os.posix_spawn[p]``;
* endpoints: ``bind``, ``connect``, ``connect_ex`` and ``sendto`` of an IPv4 or IPv6
  ``socket.socket`` (a Unix socket or a socket pair stays allowed), ``zenoh.open``;
* ``jsbsim.FGFDMExec``, and Dask's ``Client`` and ``LocalCluster``.

Each is patched once and asks one global whether the running test may; zenoh (2 ms) and
jsbsim (80 ms) are imported here when installed, so a test that imports them first is
still watched, while Dask (0.6 s) is patched only once something imported it: its clusters
bind sockets and start processes, which are watched anyway.
"""

import functools
import importlib.util
import multiprocessing.process
import os
import socket
import subprocess
import sys
from contextlib import contextmanager

import pytest

_NETWORK = (socket.AF_INET, socket.AF_INET6)


class _State:
    test: str | None = None
    """Node id of the running test that may not start processes; None when it may."""
    caught: list[str] = []
    """What that test tried, kept even when its code swallowed the failure."""


def refuse(what: str) -> None:
    """Fail the running test if it is not marked integration; `what` names the call."""
    test = _State.test
    if test is not None:
        _State.caught.append(what)
        pytest.fail(message(test, what), pytrace=False)


def message(test: str, what: str) -> str:
    return (
        f"{test} {what}, which the fast loop (pytest -m 'not integration') may not do; "
        "mark it @pytest.mark.integration"
    )


def _watch(owner, name: str, what: str, network_only: bool = False) -> None:
    """Replace ``owner.name`` by a copy that first asks `refuse`; once only."""
    original = getattr(owner, name, None)
    if original is None or getattr(original, "_isolation", False):
        return

    def watched(*args, **kwargs):
        if _State.test is not None and (not network_only or args[0].family in _NETWORK):
            refuse(what)
        return original(*args, **kwargs)

    functools.update_wrapper(watched, original, updated=())
    watched._isolation = True
    setattr(owner, name, watched)


def install() -> None:
    """Patch the entry points; cheap and idempotent, so it runs before every guarded test
    (and picks up Dask once something has imported it)."""
    if not getattr(install, "done", False):
        _watch(subprocess.Popen, "_execute_child", "starts a process (subprocess)")
        start = "starts a process (multiprocessing)"
        _watch(multiprocessing.process.BaseProcess, "start", start)
        for name in ("fork", "forkpty", "system", "posix_spawn", "posix_spawnp"):
            _watch(os, name, f"starts a process (os.{name})")
        for name in ("bind", "connect", "connect_ex", "sendto"):
            _watch(socket.socket, name, f"opens a network endpoint (socket {name})", True)
        for module in ("zenoh", "jsbsim"):
            if importlib.util.find_spec(module) is not None:
                __import__(module)
        install.done = True
    if "zenoh" in sys.modules:
        _watch(sys.modules["zenoh"], "open", "opens a Zenoh session")
    if "jsbsim" in sys.modules:
        _watch(sys.modules["jsbsim"], "FGFDMExec", "runs JSBSim")
    if "distributed" in sys.modules:
        from distributed import Client, LocalCluster

        _watch(Client, "__init__", "starts a Dask client")
        _watch(LocalCluster, "__init__", "starts a Dask cluster")


@contextmanager
def guard(item: pytest.Item):
    """While inside, `item` may start processes and endpoints only if marked integration;
    on leaving, a refused call its code swallowed (or made in a thread) still fails it."""
    install()
    allowed = item.get_closest_marker("integration") is not None
    previous = _State.test, _State.caught
    _State.test, _State.caught = (None if allowed else item.nodeid), []
    try:
        yield
    finally:
        caught = _State.caught
        _State.test, _State.caught = previous
    if caught:
        pytest.fail(message(item.nodeid, caught[0]), pytrace=False)
