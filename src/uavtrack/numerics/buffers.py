"""Full-size arrays that a run reuses from cycle to cycle.

A large team's state is big (1000 UAVs x 1000 targets: 128 MB of covariances), and a
cycle that allocates its estimates anew every step pays for it twice: the kernel maps
and zeroes fresh pages for every new array (and may compact memory for huge pages),
and the first write to each page faults. `Buffers` hands a role (say, "the predicted
covariances") two arrays in turn, so that in steady state a cycle writes into memory it
already has.

Only a caller that owns what it computes may use one: the batch driver
(`simulation.run`), which keeps a cycle's arrays until the next cycle has used them and
no longer (the metrics and the trace copy what they keep). An array handed out for a
role is reused two requests later for that role, so a value must be dead by then.
"""

from __future__ import annotations

import numpy as np

SMALLEST = 4 * 2**20
"""Bytes from which a request is served from the pool; smaller arrays are allocated
fresh (the allocator reuses their memory itself)."""


class Buffers:
    """Two arrays per role and shape, handed out in turn (`take`)."""

    def __init__(self) -> None:
        self._pairs: dict[tuple[str, tuple[int, ...], str], list[np.ndarray]] = {}
        self._turn: dict[tuple[str, tuple[int, ...], str], int] = {}

    def take(self, role: str, shape: tuple[int, ...], dtype: type | np.dtype = float) -> np.ndarray:
        """An uninitialised C-contiguous array for `role`: the one handed out two requests
        ago for this role and shape when there is one, else a new one."""
        kind = np.dtype(dtype)
        if int(np.prod(shape)) * kind.itemsize < SMALLEST:
            return np.empty(shape, kind)
        key = (role, tuple(shape), kind.str)
        pair = self._pairs.setdefault(key, [])
        turn = self._turn.get(key, 0)
        self._turn[key] = 1 - turn
        if len(pair) <= turn:
            pair.append(np.empty(shape, kind))
        return pair[turn]


def take(
    buffers: Buffers | None, role: str, shape: tuple[int, ...], dtype: type | np.dtype = float
) -> np.ndarray:
    """`Buffers.take`, or a new array without a pool."""
    if buffers is None:
        return np.empty(shape, dtype)
    return buffers.take(role, shape, dtype)
