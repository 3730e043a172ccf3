"""``distributed``, the paper's method: the D_i flooding protocol and max-consensus over
the radio with per-UAV stopping, then beacons and bids to one-hop neighbours and each
UAV's Hungarian auction over its neighbourhood (`assignment.local`). A new auction rule
plugs in by subclassing `Distributed` and replacing `solve` (examples/custom_method.py).
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

import numpy as np

from .. import assignment, fusion, timing
from ..radio import counted, part_bytes
from ..tracks import columns
from .base import Assigned, Fused, Held, Inputs, Method, Setting, beacon_of, wire


class Distributed(Method):
    """The paper's method: Algorithm 2 with Algorithm 1's neighbourhood auction."""

    name = "distributed"

    @staticmethod
    def solve(bids: np.ndarray) -> np.ndarray:
        """The neighbourhood problem: targets (n,) of the n members, Remark 2."""
        return assignment.hungarian(bids)

    @property
    def built_in_solve(self) -> bool:
        """Whether `solve` is this class's own, which reads only each member's k best
        bids in a problem of k members (a subclass's may read any bid)."""
        return type(self).solve is Distributed.solve

    def top(self, setting: Setting, largest: np.ndarray | None) -> np.ndarray | None:
        """A UAV's bids serve the auction of every neighbourhood it belongs to, and in
        an auction of k members only each member's k best bids matter
        (`assignment.hungarian`): it needs as many as the largest of them has members.
        A replaced `solve` may read any bid: then all."""
        if not setting.prune or not self.built_in_solve:
            return None
        return largest

    def assign(self, inputs: Inputs, fused: Fused, bids: np.ndarray) -> Assigned:
        s, radio, k = inputs.setting, inputs.radio, inputs.k
        B, n, m = bids.shape
        radio.send("beacon", beacon_of(inputs.believed, k, inputs.recent))
        sent_bids = {"bids": bids, "stamp": np.full((B, n), k)}
        if inputs.columns is not None and inputs.holds is not None:  # the labels they are for
            sent_bids |= {"labels": inputs.columns.labels, "holds": inputs.holds}
        radio.send("bids", sent_bids)
        beacon, inbox = radio.receive("beacon"), radio.receive("bids")
        parts = sum(part_bytes(p, 0, -1, wire(inputs, p)) for p in ("beacon", "bids"))
        radio.on_air(parts, 2, radio.afforded(inputs.alive))  # one frame: beacon, bids
        zero, everyone = np.zeros(B, dtype=np.int64), np.ones((B, n), dtype=bool)
        once = inputs.alive.astype(np.int64)
        sent, delivered = counted(
            s.delay,
            lambda: (radio.transmitted(p, once, first=0) for p in ("beacon", "bids")),
            (fusion.count(a, everyone, zero, zero) for a in (beacon, inbox) if a is not None),
        )
        alive = inputs.alive
        idx = np.arange(n)
        held, known = inputs.held, inputs.holds  # with tracks: the labels each UAV knows
        if inbox is None:  # nothing has arrived yet: every UAV alone
            members = np.zeros((B, n, n), dtype=bool)
            view = bids
        elif s.delay == 0 and held is None:  # all bids current, none lost: one shared view
            members = inbox.delivered.adjacency()
            view = bids
            if inputs.holds is not None:
                known = known_labels(members, inputs.holds)
        else:
            got = inbox.delivered.adjacency()  # bids that arrived this cycle
            heard = beacon.delivered.adjacency() if beacon is not None else got
            arrived, holds = inbox.content["bids"], inputs.holds
            if s.delay > 0 and inputs.columns is not None:  # sent under that cycle's labels
                arrived, holds = relabelled(inbox.content, inputs.columns.labels)
            members, view, stamp = bid_view(
                got, arrived[:, None], inbox.content["stamp"][:, None], heard, held, s.stale
            )
            if holds is not None and inputs.holds is not None:  # only the labels it knows
                known = known_labels(got, inputs.holds, holds)
                view = np.where(known[:, :, None, :], view, 0.0)
            held = held if held is None else Held(view, stamp)
            view = np.array(np.broadcast_to(view, (B, n, n, m)))
            view[:, idx, idx] = bids  # a UAV's own bids are current
        if not alive.all():
            members = members & alive[:, :, None] & alive[:, None, :]
        solve = None if self.built_in_solve else self.solve  # None: the auction's own fast path
        target, seconds = assignment.auction(view, members, solve, timing, known)
        return Assigned(
            target=np.where(alive, target, -1),
            seconds=seconds,
            sent=sent,
            delivered=delivered,
            held=held,
        )


def relabelled(content: dict[str, np.ndarray], labels: np.ndarray) -> tuple[np.ndarray, ...]:
    """Bids sent cycles ago by columns of that cycle's labels (content's "bids" (B, N, L')
    and "holds" (B, N, L') under "labels" (B, L')) laid out by this cycle's `labels`
    (B, L) (`tracks.columns.relabel`). The columns hold every label such bids carry
    (`tracks.columns.of`), so nothing a sender held is lost."""
    before = content["labels"]
    bids = columns.relabel(content["bids"], before, labels)
    holds = columns.relabel(content["holds"].astype(np.float64), before, labels) > 0
    return bids, holds


def known_labels(got: np.ndarray, holds: np.ndarray, sent: np.ndarray | None = None) -> np.ndarray:
    """The labels each receiver knows this cycle (B, N, L), by columns of team labels:
    those it holds confirmed, holds (B, N, L), and those the senders whose bids arrived
    (got (B, N, N)) held when they sent them, `sent` (B, N, L; None: `holds`, bids of
    this cycle). Its auction is over these columns alone (`assignment.auction`): a label
    of the trial that nobody it heard from holds is nothing it could bid on or know of.
    The bids it holds of a label it does not know are 0, as for one a sender does not
    hold."""
    sent = holds if sent is None else sent
    heard = np.einsum("bis,bsl->bil", got.astype(np.int64), sent.astype(np.int64)) > 0
    return holds | heard


def bid_view(
    got: np.ndarray,
    bids: np.ndarray,
    stamp: np.ndarray,
    heard: np.ndarray,
    held: Held | None,
    stale: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A receiver's auction after this cycle's arrivals: who takes part, and the bids it
    holds of each sender. Broadcasts over leading receiver axes.

    got (..., N) bool: the senders whose bid arrived this cycle; bids (..., N, M) and
    stamp (..., N): those bids and the step they were sent; heard (..., N): the senders
    whose beacon arrived; held: the bids held before (None when messages are never
    lost: nothing to remember). Without `stale`, a sender heard by its beacon takes part
    with the last bid held of it, however old; with `stale`, only senders whose bid
    arrived take part. Returns (members (..., N), bids held (..., N, M), their stamps).
    """
    if held is None:
        return got, bids, stamp
    value = np.where(got[..., None], bids, held.value)
    stamp = np.where(got, stamp, held.stamp)
    members = got if stale else heard & (stamp >= 0)
    return members, value, stamp
