"""Communication graph: UAVs i and q are neighbours when their 3-D distance is <= r_C.

The graph follows the UAVs, so it changes every step and may split into several
connected components (paper Sec. 3).
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np


def adjacency(uavs: np.ndarray, comm_range: float) -> np.ndarray:
    """Symmetric neighbour relation from the UAVs' 3-D positions (paper Sec. 3).

    uavs: (..., N, 5) states (x, y, h used). Returns (..., N, N) bool, without self-loops.
    """
    pos = uavs[..., :3]
    adj = in_range(pos[..., :, None, :] - pos[..., None, :, :], comm_range)
    n = adj.shape[-1]
    adj[..., np.arange(n), np.arange(n)] = False
    return adj


def in_range(diff: np.ndarray, comm_range: float) -> np.ndarray:
    """Whether offsets (..., 3) between two UAVs are within r_C: the one predicate of
    the radio graph, whichever way the candidate pairs were found."""
    x, y, z = diff[..., 0], diff[..., 1], diff[..., 2]
    return x * x + y * y + z * z <= comm_range * comm_range


def radio_links(
    uavs: np.ndarray, alive: np.ndarray, comm_range: float, form: str = "auto"
) -> Links:
    """The radio graph of a step as `Links`: UAVs within r_C in 3-D, both alive.

    uavs: (B, N, 5); alive: (B, N). Small teams get the dense form from the N x N
    distances; large ones (`SPARSE_FROM` UAVs and more) the edge form, their candidate
    pairs from a grid of cells (`grid_pairs`), so the work grows with the
    pairs in range, not with N^2. Both keep exactly the pairs `in_range` accepts.
    """
    B, n = alive.shape
    if form not in ("auto", "dense", "edges"):
        raise ValueError(f"form must be 'auto', 'dense' or 'edges', not {form!r}")
    if form == "dense" or (form == "auto" and n < SPARSE_FROM):
        adj = adjacency(uavs, comm_range)
        if not alive.all():
            adj &= alive[:, :, None] & alive[:, None, :]
        return links(adj, "dense")
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for b in range(B):
        living = np.flatnonzero(alive[b])
        pos = uavs[b, living, :3]
        i, q = grid_pairs(pos, comm_range)
        i, q = living[i], living[q]
        keep = in_range(uavs[b, i, :3] - uavs[b, q, :3], comm_range)
        i, q = i[keep], q[keep]
        everyone = np.arange(n)
        receiver = np.concatenate([i, q, everyone])
        sender = np.concatenate([q, i, everyone])
        parts.append((np.full(receiver.size, b), receiver, sender))
    trial, receiver, sender = (np.concatenate(x) for x in zip(*parts, strict=True))
    order = np.lexsort((sender, receiver, trial))
    return Links(
        batch=B, n=n, dense=None, trial=trial[order], receiver=receiver[order], sender=sender[order]
    )


_HALF_STENCIL = ((0, 0), (1, 0), (-1, 1), (0, 1), (1, 1))
"""A cell and the neighbouring cells after it: every pair of touching cells once."""


def grid_pairs(pos: np.ndarray, comm_range: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, q), i != q, each unordered pair once, among which are all those of
    positions (n, 3) within `comm_range` (and some farther: `in_range` decides), from
    square cells of side `comm_range` in the horizontal plane: two
    positions within it in 3-D are within it horizontally, so in the same or touching
    cells. Sorted by cell, each position meets the positions of its cell after it and
    of the touching cells of `_HALF_STENCIL` as index ranges of the sorted order.
    It needs no scipy, and costs about what scipy's k-d tree does: 0.2 ms against 0.12
    ms at 300 positions of a spread team, 1.2x less from 1,000 to 10,000."""
    n = len(pos)
    if n < 2:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty.copy()
    # cells at least the range wide (and at most a million across, for a tiny range)
    span = float(np.ptp(pos[:, :2]))
    side = max(comm_range, span * 1e-6, 1e-300)
    cell = np.floor(pos[:, :2] / side).astype(np.int64)
    cell -= cell.min(axis=0) - 1  # every cell and its neighbours >= 0
    width = int(cell[:, 1].max()) + 2
    key = cell[:, 0] * width + cell[:, 1]
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    everyone = np.arange(n)
    firsts: list[np.ndarray] = [np.zeros(0, dtype=np.intp)]
    seconds: list[np.ndarray] = [np.zeros(0, dtype=np.intp)]
    for dx, dy in _HALF_STENCIL:
        target = sorted_key + (dx * width + dy)
        if dx == dy == 0:  # the same cell: the positions after this one in the order
            start = everyone + 1
        else:
            start = np.searchsorted(sorted_key, target, side="left")
        end = np.searchsorted(sorted_key, target, side="right")
        count = np.maximum(end - start, 0)
        total = int(count.sum())
        if not total:
            continue
        offset = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
        firsts.append(np.repeat(order, count))
        seconds.append(order[np.repeat(start, count) + offset])
    return np.concatenate(firsts), np.concatenate(seconds)


def complete(n: int, batch: tuple[int, ...] = ()) -> np.ndarray:
    """The complete graph on n UAVs, shape batch + (n, n), no self-loops."""
    adj = np.ones(batch + (n, n), dtype=bool)
    adj[..., np.arange(n), np.arange(n)] = False
    return adj


def closed(adj: np.ndarray) -> np.ndarray:
    """Closed neighbourhoods: each UAV is its own neighbour, (..., N, N) bool."""
    n = adj.shape[-1]
    return adj | np.eye(n, dtype=bool)


def without_self_loops(adj: np.ndarray) -> np.ndarray:
    """The relation with its diagonal cleared: a UAV is not its own radio neighbour."""
    n = adj.shape[-1]
    if not adj[..., np.arange(n), np.arange(n)].any():
        return adj
    out = adj.copy()
    out[..., np.arange(n), np.arange(n)] = False
    return out


SPARSE_FROM = 24
"""Team size from which `links` chooses edge lists over N x N arrays."""


@dataclass(frozen=True, kw_only=True)
class Links:
    """Who hears whom: directed links of B graphs of N nodes, self-links included.

    Two forms of one relation, chosen once per graph by `links`: ``dense`` (B, N, N)
    bool indexed [trial, receiver, sender] for small teams, or edge lists (``trial``,
    ``receiver``, ``sender``, each (E,), sorted by trial and receiver, every node's
    self-link included, so the segments starting at ``starts`` are the B x N receivers
    in order) for large ones. The per-round rules of `fusion` accept either.

    `into` keeps the links into some receivers only (those still running a protocol);
    in the edge form the segments are then those receivers', in the same order.
    """

    batch: int
    n: int
    dense: np.ndarray | None = None
    trial: np.ndarray | None = None
    receiver: np.ndarray | None = None
    sender: np.ndarray | None = None

    @property
    def edges(self) -> bool:
        return self.dense is None

    @property
    def edge_list(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(trial, receiver, sender), each (E,) (edge form)."""
        if self.trial is None or self.receiver is None or self.sender is None:
            raise ValueError("links in the dense form have no edge list")
        return self.trial, self.receiver, self.sender

    @property
    def matrix(self) -> np.ndarray:
        """The (B, N, N) bool relation [trial, receiver, sender] (dense form)."""
        if self.dense is None:
            raise ValueError("links in the edge form have no dense relation")
        return self.dense

    @cached_property
    def starts(self) -> np.ndarray:
        """First edge of each (trial, receiver) segment (edge form)."""
        row = self.segment
        if not row.size:
            return np.zeros(0, dtype=np.int64)
        return np.flatnonzero(np.r_[True, row[1:] != row[:-1]])

    @cached_property
    def segment(self) -> np.ndarray:
        """The (trial, receiver) segment of each edge, trial * N + receiver (edge form)."""
        trial, receiver, _ = self.edge_list
        return trial * self.n + receiver

    @cached_property
    def ordinal(self) -> np.ndarray:
        """The number of each edge's segment, 0, 1, ... in order (edge form)."""
        row = np.zeros(self.segment.size, dtype=np.int64)
        row[self.starts[1:]] = 1
        return np.cumsum(row)

    @property
    def heads(self) -> tuple[np.ndarray, np.ndarray]:
        """(trial, receiver) of each segment (edge form)."""
        trial, receiver, _ = self.edge_list
        return trial[self.starts], receiver[self.starts]

    def into(self, receivers: np.ndarray) -> Links:
        """The links into the receivers where `receivers` (B, N) holds; the dense form,
        whose rules run on every receiver at once, is returned as it is."""
        if not self.edges or receivers.all():
            return self
        trial, receiver, sender = self.edge_list
        keep = receivers[trial, receiver]
        return Links(
            batch=self.batch,
            n=self.n,
            dense=None,
            trial=trial[keep],
            receiver=receiver[keep],
            sender=sender[keep],
        )

    @cached_property
    def own(self) -> np.ndarray:
        """Whether each edge is a self-link (edge form)."""
        _, receiver, sender = self.edge_list
        return receiver == sender

    @cached_property
    def others(self) -> np.ndarray:
        """The dense relation as floats without self-links (dense form)."""
        out = self.matrix.astype(np.float64)
        idx = np.arange(self.n)
        out[:, idx, idx] = 0.0
        return out

    @cached_property
    def penalty(self) -> np.ndarray:
        """0 where a link exists, -inf elsewhere, (B, N, N, 1) (dense form)."""
        return np.where(self.matrix, 0.0, -np.inf)[..., None]

    def pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(trial, receiver, sender) index arrays in the layout of this form's masks."""
        if self.edges:
            return self.edge_list
        b, i, q = np.ogrid[: self.batch, : self.n, : self.n]
        return b, i, q

    def keep(self, mask: np.ndarray) -> Links:
        """The links where `mask` (in this form's layout) holds; self-links always stay."""
        if self.edges:
            trial, receiver, sender = self.edge_list
            keep = mask | self.own
            return Links(
                batch=self.batch,
                n=self.n,
                dense=None,
                trial=trial[keep],
                receiver=receiver[keep],
                sender=sender[keep],
            )
        eye = np.eye(self.n, dtype=bool)
        return Links(batch=self.batch, n=self.n, dense=self.matrix & (mask | eye))

    def incoming(self) -> np.ndarray:
        """Links into each receiver from others, (B, N) int."""
        return self._incoming

    @cached_property
    def _incoming(self) -> np.ndarray:
        if self.edges:
            out = np.zeros(self.batch * self.n, dtype=np.int64)
            np.add.at(out, self.segment[~self.own], 1)
            return out.reshape(self.batch, self.n)
        dense = self.matrix
        return dense.sum(axis=-1) - np.diagonal(dense, axis1=-2, axis2=-1)

    def adjacency(self) -> np.ndarray:
        """The dense relation without self-links, (B, N, N) bool."""
        if self.edges:
            adj = np.zeros((self.batch, self.n, self.n), dtype=bool)
            adj[self.edge_list] = True
        else:
            adj = self.matrix.copy()
        idx = np.arange(self.n)
        adj[:, idx, idx] = False
        return adj


def links(adjacency: np.ndarray, form: str = "auto") -> Links:
    """Links of a batch of graphs from their (B, N, N) adjacency (diagonal ignored).

    form: "dense", "edges", or "auto" (edges from `SPARSE_FROM` nodes).
    """
    if form not in ("auto", "dense", "edges"):
        raise ValueError(f"form must be 'auto', 'dense' or 'edges', not {form!r}")
    B, n = adjacency.shape[0], adjacency.shape[-1]
    full = closed(adjacency)
    if form == "dense" or (form == "auto" and n < SPARSE_FROM):
        return Links(batch=B, n=n, dense=full)
    b, i, q = np.nonzero(full)  # sorted by (trial, receiver), self-links included
    return Links(batch=B, n=n, dense=None, trial=b, receiver=i, sender=q)
