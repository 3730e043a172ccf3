"""The clocks of the decision time (Fig. 7): CPU time, with wall time beside it.

A UAV's decision time is the work its own processor would do: the CPU time of the
thread that plans and assigns (`time.thread_time`), which other programs on the same
machine do not inflate. Wall time (`time.perf_counter`) is kept beside it; on a loaded
2-core machine it moved 5 to 20 times while the CPU time did not. Timed stages return
their seconds with a last axis of two: [..., 0] CPU, [..., 1] wall.

The CPU clock of a thread is a system call (and on a contended machine one that costs
context switches), so it is read at the start and the end of a stage only, never per UAV
or per problem: the parts of a stage are timed on the wall clock (`tick`) and take their
share of the stage's CPU time by it.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable, Generator
from contextlib import contextmanager
from types import FrameType
from typing import Any

import numpy as np

# np.unique loads numpy.ma on first use: here, not inside a timed stage
import numpy.ma  # noqa: F401  # pyright: ignore[reportUnusedImport]

CPU, WALL = 0, 1
"""Indices of the two clocks along the last axis of a timed stage's seconds."""


_local = threading.local()


def _set_up() -> list[float]:
    """This thread's seconds of one-time set-up (`set_up`) so far, [CPU, wall]: left out
    of its timings. Per thread, as the CPU clock is: in the in-memory swarm every UAV is
    a thread of one process, and one UAV's set-up is no other's."""
    tally = getattr(_local, "set_up", None)
    if tally is None:
        tally = _local.set_up = [0.0, 0.0]
    return tally


def start() -> tuple[float, float, float, float]:
    """A mark on both clocks."""
    tally = _set_up()
    return time.thread_time(), time.perf_counter(), tally[0], tally[1]


def since(mark: tuple[float, float, float, float]) -> np.ndarray:
    """Seconds since `mark` on both clocks, (2,): [CPU, wall], without the set-up this
    thread did in between."""
    tally = _set_up()
    return np.array(
        [
            time.thread_time() - mark[0] - (tally[0] - mark[2]),
            time.perf_counter() - mark[1] - (tally[1] - mark[3]),
        ]
    )


def tick() -> float:
    """The wall clock alone, without this thread's set-up (seconds from any origin): the
    cheap reading (`time.perf_counter` is no system call) that times the parts of a
    stage, whose CPU time `since` reads once for the whole stage (`assignment.charged`)."""
    return time.perf_counter() - _set_up()[1]


@contextmanager
def set_up() -> Generator[None, None, None]:
    """One-time work inside a timed stage (loading a module on first use, or waiting for
    another thread to load it): it is not a decision's time, so `since` leaves it out.

    Nor is it interrupted half-way: a Ctrl-C (or SIGTERM) that lands while an extension
    module initialises can leave it failing with an ImportError instead of the
    interrupt. In the main thread the two signals are held until the work is done, then
    delivered to the handlers they were meant for."""
    cpu, wall = time.thread_time(), time.perf_counter()
    held = _hold(HELD)
    try:
        yield
    finally:
        tally = _set_up()
        tally[0] += time.thread_time() - cpu
        tally[1] += time.perf_counter() - wall
        _release(held)


HELD = (signal.SIGINT, signal.SIGTERM)
"""The signals `set_up` holds: those the command line turns into an orderly stop."""


_Handler = Callable[[int, FrameType | None], Any]
"""A Python signal handler."""


def _hold(signals: tuple[int, ...]) -> dict[int, tuple[_Handler, list[int]]] | None:
    """Replace the Python handlers of `signals` with ones that only note the signal;
    None outside the main thread (where handlers cannot be set, nor run)."""
    if threading.current_thread() is not threading.main_thread():
        return None
    held: dict[int, tuple[_Handler, list[int]]] = {}
    for signum in signals:
        handler = signal.getsignal(signum)
        if callable(handler):  # a Python handler (SIG_DFL and SIG_IGN are left alone)
            seen: list[int] = []
            signal.signal(signum, lambda number, frame, seen=seen: seen.append(number))
            held[signum] = (handler, seen)
    return held


def _release(held: dict[int, tuple[_Handler, list[int]]] | None) -> None:
    """Put the handlers back, and deliver to them the signals that came meanwhile."""
    for signum, (handler, _) in (held or {}).items():
        signal.signal(signum, handler)
    for signum, (_, seen) in (held or {}).items():
        if seen:
            signal.raise_signal(signum)


def both(seconds: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Seconds of a stage as (*shape, 2). A method's own stage may give one clock,
    `shape` alone: it stands for both."""
    seconds = np.asarray(seconds, dtype=float)
    if seconds.shape == shape:
        return np.stack([seconds, seconds], axis=-1)
    return np.broadcast_to(seconds, shape + (2,))
