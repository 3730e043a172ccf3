"""The paper's method and its two baselines, one signature, chosen by name.

A method decides two things in the cycle: how the UAVs' local estimates are fused
(`fuse`) and how bids become an assignment of UAVs to targets (`assign`). Everything
else (sensing, filtering, planning, control) is shared.

* ``distributed`` (the paper's): max-consensus over the radio graph with per-UAV
  stopping, then each UAV's Hungarian auction over its one-hop neighbourhood.
* ``centralized``: a central node receives every UAV's tables whatever the radio
  range, takes the most confident estimate of each target over the whole team (the
  max-consensus fusion on the complete graph), and solves one global assignment.
* ``greedy``: the same fusion as distributed; each UAV takes the target of its own
  highest bid, with no interaction.
"""

from __future__ import annotations

import time
from typing import ClassVar

import numpy as np

from . import assignment, fusion


class Method:
    """Interface of a decision method; subclasses override `fuse` and `assign`."""

    name: ClassVar[str]
    central: ClassVar[bool] = False
    """Whether one node plans for everyone (its decision time is the whole team's)."""

    def fuse(self, confidence: np.ndarray, adjacency: np.ndarray) -> fusion.Consensus:
        """Which UAV's local estimate each UAV adopts, per target.

        confidence: (B, N, M); adjacency: (B, N, N) radio graph.
        """
        return fusion.fuse(confidence, adjacency)

    def assign(self, bids: np.ndarray, adjacency: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Targets from bids. bids: (B, N, M). Returns (target (B, N), seconds (B, N))."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class Distributed(Method):
    """The paper's method: Algorithm 2 with Algorithm 1's neighbourhood auction."""

    name = "distributed"

    def assign(self, bids, adjacency):
        return assignment.neighbourhood_timed(bids, adjacency)


class Centralized(Method):
    """A central node with everyone's data: global fusion, one global assignment."""

    name = "centralized"
    central = True

    def fuse(self, confidence, adjacency):
        b, n, _ = confidence.shape
        source = np.broadcast_to(np.argmax(confidence, axis=-2)[:, None, :], confidence.shape)
        rounds = np.full((b, n), 1 if n > 1 else 0, dtype=np.int64)
        # every UAV uploads its table and downloads the fused one
        messages = np.full(b, 2 * n if n > 1 else 0, dtype=np.int64)
        return fusion.Consensus(source.copy(), rounds, messages, np.zeros(b, dtype=np.int64))

    def assign(self, bids, adjacency):
        target, seconds = assignment.centralized_timed(bids)
        return target, np.repeat(seconds[:, None], bids.shape[-2], axis=-1)


class Greedy(Method):
    """Same fusion as distributed; each UAV takes its own best bid."""

    name = "greedy"

    def assign(self, bids, adjacency):
        start = time.perf_counter()
        out = assignment.greedy(bids)
        return out, np.full(out.shape, (time.perf_counter() - start) / out.size)


METHODS: dict[str, Method] = {m.name: m for m in (Distributed(), Centralized(), Greedy())}


def get(method: str | Method) -> Method:
    """A method by name (``distributed``, ``centralized``, ``greedy``) or instance."""
    if isinstance(method, Method):
        return method
    try:
        return METHODS[method]
    except (KeyError, TypeError):
        names = ", ".join(METHODS)
        raise ValueError(f"unknown method {method!r}; choose one of: {names}") from None
