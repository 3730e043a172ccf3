"""The clocks of the decision time (Fig. 7): CPU time, with wall time beside it.

A UAV's decision time is the work its own processor would do: the CPU time of the
thread that plans and assigns (`time.thread_time`), which other programs on the same
machine do not inflate. Wall time (`time.perf_counter`) is kept beside it; on a loaded
2-core machine it moved 5 to 20 times while the CPU time did not. Timed stages return
their seconds with a last axis of two: [..., 0] CPU, [..., 1] wall.
"""

from __future__ import annotations

import time

import numpy as np

CPU, WALL = 0, 1
"""Indices of the two clocks along the last axis of a timed stage's seconds."""


def start() -> tuple[float, float]:
    """A mark on both clocks."""
    return time.thread_time(), time.perf_counter()


def since(mark: tuple[float, float]) -> np.ndarray:
    """Seconds since `mark` on both clocks, (2,): [CPU, wall]."""
    return np.array([time.thread_time() - mark[0], time.perf_counter() - mark[1]])


def both(seconds: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Seconds of a stage as (*shape, 2). A method's own stage may give one clock,
    `shape` alone: it stands for both."""
    seconds = np.asarray(seconds, dtype=float)
    if seconds.shape == shape:
        return np.stack([seconds, seconds], axis=-1)
    return np.broadcast_to(seconds, shape + (2,))
