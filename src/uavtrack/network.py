"""Communication graph: UAVs i and q are neighbours when their 3-D distance is <= r_C.

The graph follows the UAVs, so it changes every step and may split into several
connected components (paper Sec. 3).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np


def adjacency(uavs: np.ndarray, comm_range: float) -> np.ndarray:
    """Symmetric neighbour relation from the UAVs' 3-D positions (paper Sec. 3).

    uavs: (..., N, 5) states (x, y, h used). Returns (..., N, N) bool, without self-loops.
    """
    pos = uavs[..., :3]
    diff = pos[..., :, None, :] - pos[..., None, :, :]
    dist2 = np.einsum("...ijk,...ijk->...ij", diff, diff)
    adj = dist2 <= comm_range**2
    n = adj.shape[-1]
    adj[..., np.arange(n), np.arange(n)] = False
    return adj


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


@dataclass(frozen=True)
class Links:
    """Who hears whom: directed links of B graphs of N nodes, self-links included.

    Two forms of one relation, chosen once per graph by `links`: ``dense`` (B, N, N)
    bool indexed [trial, receiver, sender] for small teams, or edge lists (``trial``,
    ``receiver``, ``sender``, each (E,), sorted by trial and receiver, every node's
    self-link included, so the segments starting at ``starts`` are the B x N receivers
    in order) for large ones. The per-round rules of `fusion` accept either.
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

    @cached_property
    def starts(self) -> np.ndarray:
        """First edge of each (trial, receiver) segment (edge form)."""
        row = self.segment
        return np.flatnonzero(np.r_[True, row[1:] != row[:-1]])

    @cached_property
    def segment(self) -> np.ndarray:
        """The (trial, receiver) segment of each edge, trial * N + receiver (edge form)."""
        return self.trial * self.n + self.receiver

    @cached_property
    def own(self) -> np.ndarray:
        """Whether each edge is a self-link (edge form)."""
        return self.receiver == self.sender

    @cached_property
    def others(self) -> np.ndarray:
        """The dense relation as floats without self-links (dense form)."""
        out = self.dense.astype(np.float64)
        idx = np.arange(self.n)
        out[:, idx, idx] = 0.0
        return out

    @cached_property
    def penalty(self) -> np.ndarray:
        """0 where a link exists, -inf elsewhere, (B, N, N, 1) (dense form)."""
        return np.where(self.dense, 0.0, -np.inf)[..., None]

    def pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(trial, receiver, sender) index arrays in the layout of this form's masks."""
        if self.edges:
            return self.trial, self.receiver, self.sender
        b, i, q = np.ogrid[: self.batch, : self.n, : self.n]
        return b, i, q

    def keep(self, mask: np.ndarray) -> Links:
        """The links where `mask` (in this form's layout) holds; self-links always stay."""
        if self.edges:
            keep = mask | self.own
            return Links(
                self.batch, self.n, None, self.trial[keep], self.receiver[keep], self.sender[keep]
            )
        eye = np.eye(self.n, dtype=bool)
        return Links(self.batch, self.n, self.dense & (mask | eye))

    def incoming(self) -> np.ndarray:
        """Links into each receiver from others, (B, N) int."""
        return self._incoming

    @cached_property
    def _incoming(self) -> np.ndarray:
        if self.edges:
            out = np.zeros(self.batch * self.n, dtype=np.int64)
            np.add.at(out, self.segment[~self.own], 1)
            return out.reshape(self.batch, self.n)
        return self.dense.sum(axis=-1) - np.diagonal(self.dense, axis1=-2, axis2=-1)

    def adjacency(self) -> np.ndarray:
        """The dense relation without self-links, (B, N, N) bool."""
        if self.edges:
            adj = np.zeros((self.batch, self.n, self.n), dtype=bool)
            adj[self.trial, self.receiver, self.sender] = True
        else:
            adj = self.dense.copy()
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
        return Links(B, n, full)
    b, i, q = np.nonzero(full)  # sorted by (trial, receiver), self-links included
    return Links(B, n, None, b, i, q)
