"""Bids and the auction over team labels: the columns of the assignment problems.

The auction of the paper assigns UAVs to targets; with tracks it assigns them to team
labels (`tracks.team`): two UAVs bidding for one label bid for the same target, and a
label no neighbour holds is one's own. Each UAV scores its confirmed tracks
(`planning.plan` over its slots); the bids are laid out by label, one column per label
any UAV of the trial holds confirmed, in increasing label order, so that the methods'
assignment rules (`assignment.auction`, `.centralized`, `.greedy`) run unchanged. A UAV
bids 0 for a label it does not hold (it has no estimate of it: the value of following
it is nothing it can plan). Columns are an arrangement of the batch, not knowledge: a
UAV's auction is over the labels it knows alone (its own and those its neighbours' bids
carry, `methods.distributed.known_labels`), and a central assignment over its trial's
labels, so a trial decides the same in any batch (`assignment.auction`'s ``known``).
"""

# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, kw_only=True)
class Columns:
    """The labels of one step as columns: labels (B, L) int64, each trial's confirmed
    labels in increasing order (-1 pads the trials with fewer); column (B, N, K) the
    column of each slot (-1: a slot not confirmed)."""

    labels: np.ndarray
    column: np.ndarray

    @property
    def width(self) -> int:
        return self.labels.shape[1]

    def per_label(self, values: np.ndarray, fill: float = np.nan) -> np.ndarray:
        """Per-slot values (B, N, K, ...) laid out by column (B, N, L, ...): each UAV's
        value for the slot holding each label, `fill` where it holds none confirmed.
        With a track's mean (B, N, K, 4): each UAV's estimate of each label's target."""
        B, N, _ = self.column.shape
        out = np.full((B, N, self.width, *values.shape[3:]), fill, dtype=float)
        b, i, s = np.nonzero(self.column >= 0)
        out[b, i, self.column[b, i, s]] = values[b, i, s]
        return out


def of(label: np.ndarray, confirmed: np.ndarray, more: np.ndarray | None = None) -> Columns:
    """The columns of the confirmed slots: label (B, N, K) int64, confirmed (B, N, K);
    more (B, X): labels to lay out beside them (-1: none), as those of bids sent cycles
    ago that arrive now (``faults.delay``)."""
    B, N, K = label.shape
    key = np.where(confirmed, label, -1).reshape(B, N * K)
    if more is not None:
        key = np.concatenate([key, more.reshape(B, -1)], axis=1)
    ordered = np.sort(key, axis=1)
    fresh = ordered >= 0
    fresh[:, 1:] &= ordered[:, 1:] != ordered[:, :-1]
    L = max(int(fresh.sum(axis=1).max(initial=0)), 1)
    b, at = np.nonzero(fresh)
    rank = np.cumsum(fresh, axis=1) - 1
    labels = np.full((B, L), -1, dtype=np.int64)
    labels[b, rank[b, at]] = ordered[b, at]
    return Columns(labels=labels, column=label_column(np.where(confirmed, label, -1), labels))


def bids(slot_bids: np.ndarray, cols: Columns) -> np.ndarray:
    """Each UAV's bids by column, (B, N, L): its bid for the slot holding that label, 0
    for a label it does not hold confirmed. slot_bids (B, N, K)."""
    B, N, _ = slot_bids.shape
    out = np.zeros((B, N, cols.width))
    b, i, s = np.nonzero(cols.column >= 0)
    out[b, i, cols.column[b, i, s]] = slot_bids[b, i, s]
    return out


def holds(cols: Columns) -> np.ndarray:
    """Which labels each UAV holds confirmed, (B, N, L) bool by column."""
    B, N, _ = cols.column.shape
    out = np.zeros((B, N, cols.width), dtype=bool)
    b, i, s = np.nonzero(cols.column >= 0)
    out[b, i, cols.column[b, i, s]] = True
    return out


def slot_of(target: np.ndarray, cols: Columns, slot_bids: np.ndarray) -> np.ndarray:
    """The slot each UAV follows: the one holding its assigned column, target (B, N)
    (-1: none). A UAV assigned a label it does not hold confirmed (possible when a
    neighbourhood has more UAVs than labels) follows its own best confirmed track
    instead; one without any returns -1 (it flies straight, searching)."""
    match = (cols.column == target[..., None]) & (target[..., None] >= 0)
    has = match.any(axis=-1)
    own = np.where(cols.column >= 0, slot_bids, -np.inf)
    best = np.argmax(own, axis=-1)
    any_own = (cols.column >= 0).any(axis=-1)
    return np.where(has, np.argmax(match, axis=-1), np.where(any_own, best, -1))


def label_column(label: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """The column of each label (B, ...) among a trial's column labels (B, L), each row
    increasing then -1 (`of`); -1 for a label absent (or -1). A sorted search on
    (trial, label) keys: no (B, ..., L) comparison."""
    B = labels.shape[0]
    valid = labels >= 0
    span = int(max(labels.max(initial=0), label.max(initial=0))) + 1
    trial = np.arange(B).reshape((B,) + (1,) * (label.ndim - 1))
    keys = (np.arange(B)[:, None] * span + labels)[valid]  # increasing: rows in order
    place = np.nonzero(valid)[1]
    wanted = trial * span + label
    if not keys.size:
        return np.full(label.shape, -1, dtype=np.int64)
    at = np.minimum(np.searchsorted(keys, wanted), keys.size - 1)
    found = (keys[at] == wanted) & (label >= 0)
    return np.where(found, place[at], -1)


def relabel(value: np.ndarray, before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """Bids held by column (B, ..., L) under the labels `before` (B, L), laid out under
    the labels `after` (B, L'): a label no longer present is dropped, a new one holds 0
    (nothing heard of it yet)."""
    B = value.shape[0]
    where = label_column(after, before)  # (B, L') the old column of each new label
    lead = (B,) + (1,) * (value.ndim - 2) + (after.shape[1],)
    picked = np.take_along_axis(value, np.maximum(where, 0).reshape(lead), axis=-1)
    return np.where((where >= 0).reshape(lead), picked, 0.0)
