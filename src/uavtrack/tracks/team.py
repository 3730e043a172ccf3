"""The team agrees on tracks: track-to-track association, fusion and team labels.

With unknown association every UAV holds K track slots, each under a label of its own
making. Before fusing, a UAV must find which of its neighbours' tracks are its own
targets: the same label says so outright; otherwise the statistical distance of the two
estimates, gated and solved as an assignment, does. Matched tracks are fused by the
consensus rule (the most confident estimate, eq. (27) per track, or fast covariance
intersection), take the smaller of their labels, and foreign confirmed tracks nobody
holds yet are adopted. Labels only ever decrease to another label of the same target, so
on a connected graph they converge, like max-consensus, within D_i rounds to the smallest
label any UAV had for it (`agree`, with D_i from `fusion.learn_depth`).

`team_round` is one round for every receiver at once; `agree` runs the rounds over a
`radio.Radio` as `fusion.consensus` runs its tuples (protocol "consensus", the same
message count).
"""

# Strict typing, less the unknown-type rules (numpy resolves an overloaded call with an
# argument of type Any, as any array's shape, to Unknown).
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .. import fusion, network
from ..estimation import confidence
from ..numerics import lsap
from ..numerics.codec import Codec
from ..radio import Radio
from .association import components

EMPTY, TENTATIVE, CONFIRMED = 0, 1, 2
"""Track statuses (int8)."""

KEPT, FUSED, ADOPTED, EMPTIED = 0, 1, 2, 3
"""The `changed` codes of a slot after a round (see `team_round`)."""

RULES = ("max_consensus", "covariance_intersection")


@dataclass(frozen=True, kw_only=True)
class TrackSet:
    """Each UAV's track slots: mean (B, N, K, 4), cov (B, N, K, 4, 4), label (B, N, K)
    int64 (-1 empty), status (B, N, K) int8 (0 empty, 1 tentative, 2 confirmed); and
    optionally stamp (B, N, K) int64, the last step a measurement met the track anywhere
    in the team as far as the UAV knows, and tombs (B, N, T, 2) int64, the labels the UAV
    knows were deleted where a UAV looked and did not see them, with the step of each
    (label -1: none), which travel with the tracks (`agree`).

    The estimates of empty slots are never read."""

    mean: np.ndarray
    cov: np.ndarray
    label: np.ndarray
    status: np.ndarray
    stamp: np.ndarray | None = None
    tombs: np.ndarray | None = None

    def __post_init__(self) -> None:
        lead = self.status.shape
        if len(lead) != 3:
            raise ValueError(f"track status must be (B, N, K), got shape {lead}")
        wanted = {"mean": lead + (4,), "cov": lead + (4, 4), "label": lead}
        if self.stamp is not None:
            wanted["stamp"] = lead
        for name, shape in wanted.items():
            if getattr(self, name).shape != shape:
                raise ValueError(
                    f"track {name} must have shape {shape} for status {lead}, "
                    f"got {getattr(self, name).shape}"
                )
        if self.tombs is not None and (
            self.tombs.ndim != 4 or self.tombs.shape[:2] != lead[:2] or self.tombs.shape[3] != 2
        ):
            raise ValueError(f"tombs must be (B, N, T, 2) for status {lead}")


class Admit(Protocol):
    """Which confirmed offers their receivers may take: row (O,) each offer's receiver
    (b * N + i), sender (O,), mean (O, 4), cov (O, 4, 4), slot (O,) the receiver's slot
    holding the offer's label (flat, row * K + k; -1: none), own the receivers' slots
    (mean (S, 4), cov (S, 4, 4), flat). Returns (O,) bool."""

    def __call__(
        self,
        row: np.ndarray,
        sender: np.ndarray,
        mean: np.ndarray,
        cov: np.ndarray,
        slot: np.ndarray,
        own: tuple[np.ndarray, np.ndarray],
    ) -> np.ndarray: ...


def team_round(
    own: TrackSet,
    offered: TrackSet,
    links: network.Links,
    threshold: float,
    rule: str = "max_consensus",
    admit: Admit | None = None,
) -> tuple[TrackSet, np.ndarray]:
    """One round of track agreement for every receiver at once.

    `links` says which senders' `offered` tracks were delivered to which receiver (in
    either form of `network.Links`; self-links are ignored: a UAV's own tracks are `own`).
    For one receiving UAV:

    1. Only *confirmed* tracks of neighbours are considered (tentative tracks are a UAV's
       own hypotheses).
    2. Same label: an offered track whose label the receiver holds belongs to that slot.
       rule "max_consensus": the slot takes the most confident estimate (confidence
       1/trace(P), `estimation.confidence`) among its own and those offers (ties: own
       first, then the lowest sender index), the paper's eq. (27) per track;
       "covariance_intersection": the fast-CI fusion of its own and those offers
       (`fusion.fast_weights`, `fusion.intersect`: the formula of
       `fusion.intersect_round`). The fused slot is confirmed.
    3. Offers with labels the receiver does not hold: per label keep the most confident
       offer (ties: lowest sender). Then associate these with the receiver's present
       tracks (tentative or confirmed) by the statistical distance of the two estimates,
       d2 = (x_a - x_b)^T (P_a + P_b)^-1 (x_a - x_b) on the 4-D state, gated by
       d2 <= threshold (the caller gives chi2.ppf(P_G, 4)); solved as an assignment
       minimising the total d2 (`lsap.solve`, scipy's `linear_sum_assignment`, on the gated
       pairs, the most pairs first; components of the gate graph without ambiguity
       are resolved without calling it; the receiver's estimates are those it held at
       the start of the round). A matched pair: estimate fused by the rule (one fusion
       per slot, with its same-label offers of step 2), label = min(own label, offered
       label), status confirmed. An own track already
       matched by label in step 2 takes part too (it may also be the same target as an
       unheld label: duplicates across the team then merge to one label).
       Several neighbours may offer one target under different labels, and a UAV holds
       one track per target: a track that took an offer from sender q takes no other
       offer of q (q holds them as different targets), so the assignment is repeated
       with the offers left until no gated pair is left, each slot collecting at most
       one offer per sender, and the group takes the smallest of its labels.
    4. Unmatched offered labels are adopted, the most confident first; the offers left
       that gate with an adopted one (from other senders) join it as in step 3, so that
       one target offered under several labels becomes one track. The new tracks go
       into empty slots, the most confident first; when there is no empty slot, an own
       *tentative* track of lower confidence (untouched in this round) is replaced,
       the least confident first; otherwise the offer is dropped.
    5. Labels are unique within a UAV after the round: every label that enters a slot
       is one the receiver did not hold, each taken once.

    admit: which confirmed offers a receiver may take at all (`Admit`, ``robust.gate``:
    `robust.gate.tracks_admitted`); None: all.

    own, offered: (B, N, K) `TrackSet`s. threshold: the gate on d2. Returns the new
    `TrackSet` and `changed` (B, N, K) int8: 0 the slot is as it was, 1 the slot's track
    stayed but its estimate, label or status changed (fused, relabelled, confirmed), 2 a
    foreign track was adopted into the slot (a new track for this UAV), 3 the slot was
    emptied (these rules never empty a slot: deleting a track is track management's).
    """
    if rule not in RULES:
        raise ValueError(f"unknown fusion rule {rule!r}: expected one of {', '.join(RULES)}")
    if not np.isfinite(threshold) or threshold <= 0:
        raise ValueError(f"the track gate must be a positive number, got {threshold}")
    if offered.status.shape != own.status.shape:
        raise ValueError(
            f"offered tracks {offered.status.shape} do not match own tracks {own.status.shape}"
        )
    B, n, K = own.status.shape
    if (links.batch, links.n) != (B, n):
        raise ValueError(f"links of {links.batch} x {links.n} UAVs for tracks of {B} x {n}")
    S = B * n * K  # own slots, flat; candidate s < S is own slot s, S + o is offer o
    mean0, cov0 = own.mean.reshape(S, 4), own.cov.reshape(S, 4, 4)
    label0, status0 = own.label.reshape(S), own.status.reshape(S)

    # 1. the confirmed offers delivered, flat: receiver row b * N + i, sender q
    t, i, q = _deliveries(links)
    e, k = np.nonzero(offered.status[t, q] == CONFIRMED)
    src = (t[e] * n + q[e]) * K + k
    row, sender = t[e] * n + i[e], q[e]
    o_mean, o_cov = offered.mean.reshape(S, 4)[src], offered.cov.reshape(S, 4, 4)[src]
    o_label, o_gamma = offered.label.reshape(S)[src], confidence(offered.cov.reshape(S, 4, 4)[src])
    stamp0 = _stamp(own).reshape(S)
    o_stamp = _stamp(offered).reshape(S)[src]

    # 2. same label: the slot of the receiver holding it (labels are distinct within a
    # UAV: one slot at most), found by a sorted join on (receiver, label)
    held, held_slot = _holding(own, row, o_label)
    if admit is not None:  # the offers a receiver refuses are as if never delivered
        slot = np.full(held.shape, -1)
        slot[held] = held_slot
        keep = np.flatnonzero(admit(row, sender, o_mean, o_cov, slot, (mean0, cov0)))
        row, sender, o_mean, o_cov = row[keep], sender[keep], o_mean[keep], o_cov[keep]
        o_label, o_gamma, o_stamp = o_label[keep], o_gamma[keep], o_stamp[keep]
        held, held_slot = held[keep], slot[keep][held[keep]]

    # 3. the other labels, the most confident offer of each per receiver
    free = np.flatnonzero(~held)
    order = free[np.lexsort((sender[free], -o_gamma[free], o_label[free], row[free]))]
    U = order[_starts(row[order], o_label[order])]
    edges = _gate_edges(U, row, sender, o_mean, o_cov, mean0, cov0, status0, K, threshold)
    # a sender that offered a slot's own label holds this other label as another target
    taken = np.sort(held_slot * n + sender[held])  # membership by a sorted search
    asked = edges.own * n + sender[edges.offer]
    at = np.minimum(np.searchsorted(taken, asked), max(taken.size - 1, 0))
    block = (taken[at] == asked) if taken.size else np.zeros(asked.shape, dtype=bool)
    edges = edges.without(block)
    anchors, members = _associate(U, sender, o_gamma, o_label, edges, S)

    # every group: its anchor (own slot, or the adopted offer S + u) and its members;
    # under max-consensus an offer of a confirmed slot's own label that is no more
    # confident and no newer than the slot changes nothing (the slot wins ties): left out
    same = np.flatnonzero(held)
    if rule == "max_consensus" and same.size:
        useful = (
            (o_gamma[same] > confidence(cov0[held_slot]))
            | (o_stamp[same] > stamp0[held_slot])
            | (status0[held_slot] != CONFIRMED)
        )
        same, held_slot = same[useful], held_slot[useful]
    key = np.concatenate([held_slot, anchors])
    cand = np.concatenate([S + same, members])
    owned = np.unique(key[key < S])
    key, cand = np.concatenate([key, owned]), np.concatenate([cand, owned])
    prio = np.where(cand < S, -1, sender[np.maximum(cand - S, 0)])  # own first, then sender

    c_mean = np.concatenate([mean0, o_mean])
    c_cov = np.concatenate([cov0, o_cov])
    c_label = np.concatenate([label0, o_label])
    g_key, g_mean, g_cov, g_label = _fuse(key, cand, prio, c_mean, c_cov, c_label, rule)
    g_stamp = _newest(key, cand, np.concatenate([stamp0, o_stamp]))

    mean, cov = mean0.copy(), cov0.copy()
    label, status = label0.copy(), status0.copy()
    changed = np.zeros(S, dtype=np.int8)
    mine_g = g_key < S
    s = g_key[mine_g]
    mean[s], cov[s], label[s], status[s] = g_mean[mine_g], g_cov[mine_g], g_label[mine_g], CONFIRMED
    stamp = stamp0.copy()
    stamp[s] = g_stamp[mine_g]
    moved = (
        np.any(mean[s] != mean0[s], axis=-1)
        | np.any(cov[s] != cov0[s], axis=(-2, -1))
        | (label[s] != label0[s])
        | (status[s] != status0[s])
    )
    changed[s] = np.where(moved, FUSED, KEPT)

    # 4. the new tracks into free slots
    new = ~mine_g
    slot = _place(row[g_key[new] - S], confidence(g_cov[new]), status0, cov0, owned, K)
    ok = slot >= 0
    d = slot[ok]
    mean[d], cov[d], label[d] = g_mean[new][ok], g_cov[new][ok], g_label[new][ok]
    stamp[d] = g_stamp[new][ok]
    status[d], changed[d] = CONFIRMED, ADOPTED
    out = TrackSet(
        mean=mean.reshape(own.mean.shape),
        cov=cov.reshape(own.cov.shape),
        label=label.reshape(own.label.shape),
        status=status.reshape(own.status.shape),
        stamp=None if own.stamp is None else stamp.reshape(own.label.shape),
        tombs=own.tombs,
    )
    return out, changed.reshape(B, n, K)


def _holding(own: TrackSet, row: np.ndarray, label: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which of the offers (receiver row (O,), label (O,)) name a label their receiver
    holds in a present slot, and that slot (flat, row * K + slot) for each of those."""
    B, n, K = own.label.shape
    present = own.status.reshape(B * n, K) != EMPTY
    r, k = np.nonzero(present)
    if not r.size or not row.size:
        return np.zeros(row.shape, dtype=bool), np.zeros(0, dtype=np.int64)
    mine = own.label.reshape(B * n, K)[r, k]
    span = int(max(mine.max(), label.max())) + 1
    keys = r * span + mine
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    wanted = row * span + label
    at = np.minimum(np.searchsorted(keys, wanted), keys.size - 1)
    held = (keys[at] == wanted) & (label >= 0)
    slot = (r * K + k)[order][at]
    return held, slot[held]


def _stamp(tracks: TrackSet) -> np.ndarray:
    return np.zeros(tracks.label.shape, np.int64) if tracks.stamp is None else tracks.stamp


def _newest(key: np.ndarray, cand: np.ndarray, stamp: np.ndarray) -> np.ndarray:
    """Each group's newest stamp (groups as `_fuse` orders them: keys ascending)."""
    if not key.size:
        return stamp[:0]
    order = np.argsort(key, kind="stable")
    key, cand = key[order], cand[order]
    return np.maximum.reduceat(stamp[cand], np.flatnonzero(_starts(key)))


@dataclass(frozen=True, kw_only=True)
class Listing:
    """Which track slots a UAV's consensus messages carry (``fusion.trigger``,
    ``radio.encoding`` compact), as `fusion.Sending` does for tuples.

    Round 1 carries the confirmed slots of `first` (B, N, K) (None: every confirmed
    slot); a later round the confirmed slots that changed since the UAV's previous round
    (estimate, label, stamp or status); past its rounds a UAV repeats its last round's
    message. A slot not listed is not offered: receivers read confirmed tracks only
    (`team_round`), so listing every confirmed slot loses nothing. codec: how estimates
    travel (``radio.encoding``, `numerics.codec.Codec`; None: float64 as they are). until: the
    rounds (B, N) each UAV's share affords (None: all)."""

    first: np.ndarray | None = None
    codec: Codec | None = None
    until: np.ndarray | None = None

    def mask(self, r: int, tracks: TrackSet, previous: TrackSet | None) -> np.ndarray:
        """The slots (B, N, K) round r carries, from this round's and the previous
        round's tracks."""
        has = tracks.status == CONFIRMED
        if r == 1 or previous is None:
            return has if self.first is None else self.first & has
        changed = (
            (tracks.label != previous.label)
            | (tracks.status != previous.status)
            | (_stamp(tracks) != _stamp(previous))
            | (tracks.mean != previous.mean).any(axis=-1)
            | (tracks.cov != previous.cov).any(axis=(-2, -1))
        )
        return changed & has

    def carrying(self, tracks: TrackSet, mask: np.ndarray) -> TrackSet:
        """The tracks as a message carries them: the slots not in `mask` empty, the
        others as they arrive."""
        mean, cov = tracks.mean, tracks.cov
        if self.codec is not None:
            mean, cov = self.codec.delivered(mean, cov)
        return TrackSet(
            mean=mean,
            cov=cov,
            label=np.where(mask, tracks.label, -1),
            status=np.where(mask, tracks.status, EMPTY).astype(tracks.status.dtype),
            stamp=tracks.stamp,
            tombs=tracks.tombs,
        )


def triggered(
    tracks: TrackSet,
    told: np.ndarray | None,
    told_labels: np.ndarray | None,
    k: int,
    trigger: float,
    refresh: int,
) -> np.ndarray | None:
    """``fusion.trigger`` on tracks: the slots (B, N, K) a UAV lists in a cycle's first
    round, those whose confidence moved by more than `trigger` of the confidence it last
    sent of the slot (`told`, NaN: never), or whose label is not the one it sent then
    (`told_labels`); None (all) in a refresh cycle or before anything was sent
    (`fusion.triggered`)."""
    gamma = confidence(tracks.cov)
    first = fusion.triggered(gamma, told, k, trigger, refresh)
    if first is None or told_labels is None:
        return first
    return first | (tracks.label != told_labels)


@dataclass(frozen=True, kw_only=True)
class Agreement:
    """What `agree` returns: each UAV's tracks and `changed` (B, N, K) int8, messages
    sent and delivered (B,), and with a `Listing` the slots each UAV's message of round
    r carried, carried[r - 1] (B, N), and the confidence and label of the last track
    each UAV sent of each slot this cycle, told and told_labels (B, N, K) (NaN, -1:
    none)."""

    tracks: TrackSet
    changed: np.ndarray
    sent: np.ndarray
    delivered: np.ndarray
    carried: list[np.ndarray] | None = None
    told: np.ndarray | None = None
    told_labels: np.ndarray | None = None


def agree(
    radio: Radio,
    tracks: TrackSet,
    rounds: np.ndarray,
    threshold: float,
    rule: str = "max_consensus",
    listing: Listing | None = None,
    receive: Callable[[TrackSet], TrackSet] | None = None,
    admit: Admit | None = None,
) -> Agreement:
    """The team's track agreement over the radio: UAV i runs rounds[b, i] rounds of
    `team_round` (protocol "consensus", as `fusion.consensus`): every UAV transmits its
    current tracks each round, receivers still within their rounds associate and fuse
    what was delivered, the others keep their tracks (and keep transmitting them).

    Since a label only ever gives way to a smaller label of the same target, labels run
    a min-consensus: on a connected graph, after D_i rounds (`fusion.learn_depth`) UAV i
    holds every confirmed target of its component under the smallest label any UAV had
    for it.

    rounds: (B, N) int. listing: which slots the messages carry (`Listing`; None: all,
    the full encoding). receive(offered): what a receiver makes of the tracks that arrive
    (with ``faults.delay``: predicted to now; None: as they are). admit: the offers a
    receiver may take (`team_round`; None: all). Returns an `Agreement`
    (tracks, changed (B, N, K) int8, sent (B,), delivered (B,), and with a listing what
    it carried): changed says per final slot
    whether it holds the UAV's own track as its filter left it (0), its own track with
    a fused estimate, label or status (1), a track new to
    this UAV (2: adopted in some round, whatever befell it later but a tombstone), or
    nothing where it held a track (3: buried by a tombstone, `bury`; `team_round` itself
    never empties a slot); sent and delivered count the messages as `fusion.count` does.

    With tombstones (``tracks.tombs``) each round first merges the senders' tombstones
    into the receiver's (`merge_tombs`) and buries what they name (`bury`), then
    associates and fuses, then buries again what it adopted from a sender that knew less:
    a deletion travels as far as the tracks do, and a copy of a deleted track does not
    bring it back unless a measurement met it after the deletion.
    """
    if rule not in RULES:
        raise ValueError(f"unknown fusion rule {rule!r}: expected one of {', '.join(RULES)}")
    B, n = rounds.shape
    if tracks.status.shape[:2] != (B, n):
        raise ValueError(f"rounds {rounds.shape} do not match tracks {tracks.status.shape}")
    sent, delivered = np.zeros(B, dtype=np.int64), np.zeros(B, dtype=np.int64)
    changed = np.zeros(tracks.status.shape, dtype=np.int8)
    carried: list[np.ndarray] = []
    previous = frozen = None
    told = np.full(tracks.status.shape, np.nan)
    told_labels = np.full(tracks.status.shape, -1, dtype=np.int64)
    top = int(rounds.max(initial=0))
    for r in range(1, top + 2):
        content = tracks
        if listing is not None:
            mask = listing.mask(r, tracks, previous)
            if frozen is not None:  # past its rounds: its last round's message again
                mask = np.where(np.greater(r, rounds + 1)[..., None], frozen, mask)
            final = np.equal(r, rounds + 1)[..., None]
            frozen = mask if frozen is None else np.where(final, mask, frozen)
            on_air = mask & np.less_equal(r, rounds + 1)[..., None]
            if listing.until is not None:
                on_air &= np.less_equal(r, listing.until)[..., None]
            told = np.where(on_air, confidence(tracks.cov), told)
            told_labels = np.where(on_air, tracks.label, told_labels)
            carried.append(mask.sum(axis=-1))
            previous, content = tracks, listing.carrying(tracks, mask)
        radio.send("consensus", content)  # after the last round: the final tracks
        if r > top:  # (for later rounds, with delay)
            break
        inbox = radio.receive("consensus", r)
        if inbox is None:  # nothing in flight yet (delay)
            continue
        active = rounds >= r
        sent, delivered = fusion.count(inbox, active, sent, delivered)
        links = inbox.delivered.into(active)
        if not links.edges:  # the dense form keeps every receiver: mute the finished
            links = network.Links(batch=B, n=n, dense=links.matrix & active[:, :, None])
        offered = inbox.content if receive is None else receive(inbox.content)
        tracks, changed = agree_round(tracks, changed, offered, links, threshold, rule, admit)
    changed = changed.astype(np.int8)
    if listing is None:
        return Agreement(tracks=tracks, changed=changed, sent=sent, delivered=delivered)
    return Agreement(
        tracks=tracks, changed=changed, sent=sent, delivered=delivered, carried=carried,
        told=told, told_labels=told_labels,
    )  # fmt: skip


def agree_round(
    tracks: TrackSet,
    changed: np.ndarray,
    offered: TrackSet,
    links: network.Links,
    threshold: float,
    rule: str = "max_consensus",
    admit: Admit | None = None,
) -> tuple[TrackSet, np.ndarray]:
    """One round of `agree` for the receivers of `links`: the senders' tombstones merged
    and applied (`merge_tombs`, `bury`), then `team_round`, then the tombstones applied
    again to what was adopted; `changed` (B, N, K) int8 accumulated as `agree` says.
    The agent form runs it on one receiver's closed neighbourhood."""
    if tracks.tombs is not None:  # deletions first: what is known gone is not fused
        before = tracks.status
        tracks = bury(tracks, merge_tombs(tracks.tombs, offered.tombs, links))
        changed = np.where((before != EMPTY) & (tracks.status == EMPTY), EMPTIED, changed)
    tracks, now = team_round(tracks, offered, links, threshold, rule, admit)
    # a new track stays new; an emptied slot that takes a new track holds a new track
    changed = np.where(now == ADOPTED, ADOPTED, np.maximum(changed, now))
    if tracks.tombs is not None:  # and not kept, if adopted from a UAV that knew less
        before = tracks.status
        tracks = bury(tracks, tracks.tombs)
        changed = np.where((before != EMPTY) & (tracks.status == EMPTY), EMPTIED, changed)
    return tracks, changed.astype(np.int8)


def merge_tombs(own: np.ndarray, offered: np.ndarray | None, links: network.Links) -> np.ndarray:
    """Each receiver's tombstones (B, N, T, 2) with those of the senders delivered to it:
    per label the latest step, the T latest labels kept."""
    if offered is None:
        return own
    B, n, T, _ = own.shape
    t, i, q = _deliveries(links)
    sent = offered.reshape(B * n, T, 2)[t * n + q]  # (E, T, 2): each delivery's tombstones
    rows = np.repeat(t * n + i, T)
    return _latest(own, rows, sent.reshape(-1, 2))


def entomb(tombs: np.ndarray, label: np.ndarray, step: int) -> np.ndarray:
    """Tombstones (B, N, T, 2) with the labels (B, N, K) (-1: none) entered at `step`."""
    B, n, K = label.shape
    rows = np.repeat(np.arange(B * n), K)
    more = np.stack([label.reshape(-1), np.full(label.size, step)], axis=-1)
    return _latest(tombs, rows, more)


def _latest(own: np.ndarray, rows: np.ndarray, more: np.ndarray) -> np.ndarray:
    """Tombstones own (B, N, T, 2) and more (M, 2) for the UAVs rows (M,) (trial * N +
    UAV) as T per UAV: per label the latest step, the T latest labels kept (ties to the
    smaller label). Only tombstones with a label (>= 0) are sorted: most are none."""
    B, n, T, _ = own.shape
    flat = own.reshape(B * n * T, 2)
    row = np.concatenate([np.repeat(np.arange(B * n), T), rows])
    every = np.concatenate([flat, more])
    real = every[:, 0] >= 0
    row, label, step = row[real], every[real, 0], every[real, 1]
    order = np.lexsort((-step, label, row))  # per UAV and label, the latest step first
    row, label, step = row[order], label[order], step[order]
    first = np.ones(row.size, dtype=bool)
    first[1:] = (row[1:] != row[:-1]) | (label[1:] != label[:-1])
    row, label, step = row[first], label[first], step[first]
    order = np.lexsort((label, -step, row))  # per UAV, the latest first
    row, label, step = row[order], label[order], step[order]
    rank = np.arange(row.size) - np.searchsorted(row, row, side="left")
    keep = rank < T
    out = np.full((B * n, T, 2), -1, dtype=np.int64)
    out[row[keep], rank[keep], 0] = label[keep]
    out[row[keep], rank[keep], 1] = step[keep]
    return out.reshape(B, n, T, 2)


def bury(tracks: TrackSet, tombs: np.ndarray) -> TrackSet:
    """The tracks with the tombstones `tombs` (B, N, T, 2) kept, and every slot whose
    label they name emptied unless a measurement met it at or after its tombstone's step
    (its stamp): a UAV that saw the target after the deletion knows better."""
    B, n, K = tracks.label.shape
    T = tombs.shape[2]
    flat = tombs.reshape(B * n * T, 2)
    real = flat[:, 0] >= 0
    step = np.full((B, n, K), -1, dtype=np.int64)  # the tombstone of each slot's label
    if real.any():
        span = int(max(flat[real, 0].max(), tracks.label.max(initial=0))) + 1
        keys = np.repeat(np.arange(B * n), T)[real] * span + flat[real, 0]
        order = np.argsort(keys, kind="stable")  # one tombstone per label and UAV
        keys, steps = keys[order], flat[real, 1][order]
        held = tracks.label >= 0
        slot_keys = np.arange(B * n).reshape(B, n, 1) * span + tracks.label
        at = np.minimum(np.searchsorted(keys, slot_keys), keys.size - 1)
        step = np.where(held & (keys[at] == slot_keys), steps[at], -1)
    dead = (step >= 0) & (_stamp(tracks) < step) & (tracks.status != EMPTY)
    return TrackSet(
        mean=tracks.mean,
        cov=tracks.cov,
        label=np.where(dead, -1, tracks.label),
        status=np.where(dead, EMPTY, tracks.status).astype(tracks.status.dtype),
        stamp=tracks.stamp,
        tombs=tombs,
    )


# ------------------------------------------------------------------ the parts


def _deliveries(links: network.Links) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(trial, receiver, sender) of every delivered link between two UAVs, sorted by
    trial and receiver, in either form."""
    if links.edges:
        t, i, q = links.edge_list
        other = ~links.own
        return t[other], i[other], q[other]
    t, i, q = np.nonzero(links.matrix)
    other = i != q
    return t[other], i[other], q[other]


def _starts(*keys: np.ndarray) -> np.ndarray:
    """Where a run of equal keys begins in sorted arrays of one length, (L,) bool."""
    out = np.ones(keys[0].size, dtype=bool)
    for x in keys:
        out[1:] &= x[1:] == x[:-1]
    if out.size:
        out[1:] = ~out[1:]
    return out


def _distance(ma: np.ndarray, Pa: np.ndarray, mb: np.ndarray, Pb: np.ndarray) -> np.ndarray:
    """d2 = (x_a - x_b)^T (P_a + P_b)^-1 (x_a - x_b), (...,)."""
    d = ma - mb
    return np.einsum("...i,...i->...", d, np.linalg.solve(Pa + Pb, d[..., None])[..., 0])


def _gated(
    ma: np.ndarray, Pa: np.ndarray, mb: np.ndarray, Pb: np.ndarray, threshold: float
) -> tuple[np.ndarray, np.ndarray]:
    """Which pairs pass the gate, and their d2. d2 >= |x_a - x_b|^2 / trace(P_a + P_b)
    (the largest eigenvalue is at most the trace), so pairs farther apart than that bound
    allows are out without solving (a margin keeps rounding from dropping one)."""
    near = np.sum((ma - mb) ** 2, axis=-1) <= threshold * (
        np.trace(Pa, axis1=-2, axis2=-1) + np.trace(Pb, axis1=-2, axis2=-1)
    ) * (1 + 1e-9)
    where = np.flatnonzero(near)
    d2 = _distance(ma[where], Pa[where], mb[where], Pb[where])
    inside = d2 <= threshold
    return where[inside], d2[inside]


@dataclass(frozen=True, kw_only=True)
class _Edges:
    """Gated pairs: own slot - offer (own, offer, d2) and offer - offer of different
    senders at one receiver (a, b, d2_ab, a < b); offers index the flat offers."""

    own: np.ndarray
    offer: np.ndarray
    d2: np.ndarray
    a: np.ndarray
    b: np.ndarray
    d2_ab: np.ndarray

    def without(self, drop: np.ndarray) -> _Edges:
        keep = ~drop
        return _Edges(
            own=self.own[keep],
            offer=self.offer[keep],
            d2=self.d2[keep],
            a=self.a,
            b=self.b,
            d2_ab=self.d2_ab,
        )


def _gate_edges(
    U: np.ndarray,
    row: np.ndarray,
    sender: np.ndarray,
    o_mean: np.ndarray,
    o_cov: np.ndarray,
    mean0: np.ndarray,
    cov0: np.ndarray,
    status0: np.ndarray,
    K: int,
    threshold: float,
) -> _Edges:
    """The gated pairs among the offers U (one per unheld label) and the present own
    slots of their receiver, and among the offers U of one receiver."""
    u = np.repeat(U, K)
    s = row[u] * K + np.tile(np.arange(K), U.size)
    present = status0[s] > EMPTY
    u, s = u[present], s[present]
    hit, d2 = _gated(mean0[s], cov0[s], o_mean[u], o_cov[u], threshold)
    # offer pairs of one receiver: U is sorted by receiver
    r = row[U]
    start = np.searchsorted(r, r, side="left")
    size = np.searchsorted(r, r, side="right") - start
    a = np.repeat(np.arange(U.size), size)
    b = start[a] + (np.arange(a.size) - np.repeat(np.cumsum(size) - size, size))
    keep = (a < b) & (sender[U[a]] != sender[U[b]])
    a, b = U[a[keep]], U[b[keep]]
    pair, d2_ab = _gated(o_mean[a], o_cov[a], o_mean[b], o_cov[b], threshold)
    return _Edges(own=s[hit], offer=u[hit], d2=d2, a=a[pair], b=b[pair], d2_ab=d2_ab)


def _associate(
    U: np.ndarray,
    sender: np.ndarray,
    gamma: np.ndarray,
    label: np.ndarray,
    edges: _Edges,
    S: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Steps 3 and 4 up to placement: each offer of U joins a group, (anchor, member)
    pairs, the anchor an own slot s or S + u for an adopted offer u (its own anchor).

    The components of the gate graph (own slots and offers, joined by gated pairs) are
    resolved apart. One own slot whose every offer gates with it, all from different
    senders: they all join it. No own slot, different senders, and the most confident
    offer gating with every other: it is adopted and the others join it. Any other
    component goes to `_resolve` (the assignments)."""
    if not U.size:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    nodes = S + sender.size
    count, comp = components(
        np.r_[edges.own, S + edges.a], np.r_[S + edges.offer, S + edges.b], nodes
    )
    cu = comp[S + U]
    n_off = np.bincount(cu, minlength=count)
    n_own = np.bincount(comp[np.unique(edges.own)], minlength=count)
    own_edges = np.bincount(comp[edges.own], minlength=count)
    n = int(sender.max(initial=0)) + 1
    senders = np.bincount(np.unique(cu * n + sender[U]) // n, minlength=count)
    distinct = senders == n_off
    degree = np.bincount(np.r_[edges.a, edges.b], minlength=sender.size)
    by = np.lexsort((label[U], sender[U], -gamma[U], cu))  # most confident first
    rank = U[by]
    top = np.full(count, -1)
    head = _starts(cu[by])
    top[cu[by][head]] = rank[head]
    one, lone = _easy(n_own, n_off, own_edges, distinct, degree[np.maximum(top, 0)])

    fast_a = one[comp[edges.own]]
    anchors = [edges.own[fast_a], S + top[cu[lone[cu]]]]
    members = [S + edges.offer[fast_a], S + U[lone[cu]]]
    hard = (n_off > 0) & ~one & ~lone
    if hard.any():
        a, m = _resolve_all(rank[hard[comp[S + rank]]], comp, sender, edges, hard, S)
        anchors.append(a)
        members.append(m)
    return np.concatenate(anchors), np.concatenate(members)


def _easy(
    n_own: np.ndarray,
    n_off: np.ndarray,
    own_edges: np.ndarray,
    distinct: np.ndarray,
    top_degree: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The components whose assignment is foregone, (one own slot taking every offer,
    no own slot and the most confident offer taking every other), per component: its
    own slots and offers, own-offer pairs, whether its offers' senders are distinct, and
    the gated pairs of its most confident offer. Both give what `_resolve` gives."""
    one = (n_own == 1) & (own_edges == n_off) & distinct
    lone = (n_own == 0) & distinct & (top_degree == n_off - 1)
    return one, lone


def _resolve_all(
    ranked: np.ndarray,
    comp: np.ndarray,
    sender: np.ndarray,
    edges: _Edges,
    hard: np.ndarray,
    S: int,
) -> tuple[np.ndarray, np.ndarray]:
    """`_resolve` on each hard component; ranked: its offers, most confident first."""
    own_in = hard[comp[edges.own]]
    ab_in = hard[comp[S + edges.a]]
    pairs: dict[tuple[int, int], float] = {}
    for s, u, d in zip(edges.own[own_in], S + edges.offer[own_in], edges.d2[own_in], strict=True):
        pairs[int(s), int(u)] = float(d)
    for a, b, d in zip(S + edges.a[ab_in], S + edges.b[ab_in], edges.d2_ab[ab_in], strict=True):
        pairs[int(a), int(b)] = pairs[int(b), int(a)] = float(d)
    owns: dict[int, list[int]] = {}
    for s in np.unique(edges.own[own_in]).tolist():
        owns.setdefault(int(comp[s]), []).append(s)
    offers: dict[int, list[int]] = {}
    for u in ranked.tolist():
        offers.setdefault(int(comp[S + u]), []).append(S + u)
    out: list[tuple[int, int]] = []
    for c, pending in offers.items():
        out += _resolve(owns.get(c, []), pending, sender, pairs, S)
    a, m = np.array(out, dtype=np.int64).reshape(-1, 2).T
    return a, m


def _resolve(
    owns: list[int],
    pending: list[int],
    sender: np.ndarray,
    pairs: dict[tuple[int, int], float],
    S: int,
) -> list[tuple[int, int]]:
    """One ambiguous component: repeat the assignment (fewest total d2 among the most
    gated pairs) of the pending offers to the groups, each taking at most one offer per
    sender; when none gates, adopt the most confident pending offer as a new group."""
    groups = list(owns)
    taken: dict[int, set[int]] = {g: set() for g in owns}
    out: list[tuple[int, int]] = []
    while pending:
        cost = np.full((len(pending), len(groups)), np.inf)
        for x, p in enumerate(pending):
            for y, g in enumerate(groups):
                d2 = pairs.get((g, p))
                if d2 is not None and int(sender[p - S]) not in taken[g]:
                    cost[x, y] = d2
        finite = np.isfinite(cost)
        if finite.any():
            big = cost[finite].sum() + 1.0  # one more pair always beats a lower total
            rows, cols = lsap.solve(np.where(finite, cost, big))
            hit = finite[rows, cols]
            for x, y in zip(rows[hit].tolist(), cols[hit].tolist(), strict=True):
                out.append((groups[y], pending[x]))
                taken[groups[y]].add(int(sender[pending[x] - S]))
            done = set(rows[hit].tolist())  # never empty: a gated pair beats none
            pending = [p for x, p in enumerate(pending) if x not in done]
            if done:
                continue
        first = pending.pop(0)
        groups.append(first)
        taken[first] = {int(sender[first - S])}
        out.append((first, first))
    return out


def _fuse(
    key: np.ndarray,
    cand: np.ndarray,
    prio: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    label: np.ndarray,
    rule: str,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each group's estimate by the rule and its smallest label. key, cand, prio: per
    member its group, its candidate index, its tie order (own -1, then sender).
    Returns (keys, mean, cov, label) per group, keys ascending."""
    if not key.size:
        return key, mean[:0], cov[:0], label[:0]
    gamma = confidence(cov[cand])
    if rule == "max_consensus":  # eq. (27): the most confident, ties own then lowest sender
        order = np.lexsort((prio, -gamma, key))
    else:
        order = np.lexsort((prio, key))
    key, cand = key[order], cand[order]
    starts = np.flatnonzero(_starts(key))
    g_label = np.minimum.reduceat(label[cand], starts)
    if rule == "max_consensus":
        best = cand[starts]
        return key[starts], mean[best], cov[best], g_label
    size = np.diff(np.r_[starts, key.size])
    column = np.arange(key.size) - np.repeat(starts, size)
    width = int(size.max(initial=1))
    m = np.zeros((starts.size, width, 4))
    P = np.broadcast_to(np.eye(4), (starts.size, width, 4, 4)).copy()
    present = np.zeros((starts.size, width), dtype=bool)
    g = np.repeat(np.arange(starts.size), size)
    m[g, column], P[g, column], present[g, column] = mean[cand], cov[cand], True
    fused_mean, fused_cov = fusion.intersect(m, P, fusion.fast_weights(P, present))
    return key[starts], fused_mean, fused_cov, g_label


def _place(
    row: np.ndarray,
    gamma: np.ndarray,
    status0: np.ndarray,
    cov0: np.ndarray,
    owned: np.ndarray,
    K: int,
) -> np.ndarray:
    """Step 4's slots for the new tracks (receiver row, confidence): per row, the most
    confident new track takes the first empty slot, and so on; past the empty slots the
    least confident own tentative track untouched this round, if less confident than
    the new one. Returns the flat slot per new track, -1: dropped."""
    R = status0.size // K
    touched = np.zeros(R * K, dtype=bool)
    touched[owned] = True
    tentative = (status0 == TENTATIVE) & ~touched
    kind = np.where(status0 == EMPTY, 0, np.where(tentative, 1, 2))
    own_gamma = np.zeros(R * K)
    own_gamma[tentative] = confidence(cov0[tentative])
    # the slots a row offers, in order: empty ones, then tentatives least confident first
    slots = np.arange(R * K)
    order = np.lexsort((slots, own_gamma, kind, slots // K))
    target = np.where(kind[order] < 2, order, -1).reshape(R, K)
    beat = np.where(kind[order] == 0, -np.inf, own_gamma[order]).reshape(R, K)
    # the new tracks of each row, most confident first
    by = np.lexsort((-gamma, row))
    first = np.searchsorted(row[by], row[by], side="left")
    rank = np.empty(row.size, dtype=np.int64)
    rank[by] = np.arange(row.size) - first
    out = np.full(row.size, -1)
    fits = rank < K
    r, j = row[fits], rank[fits]
    out[fits] = np.where((target[r, j] >= 0) & (gamma[fits] > beat[r, j]), target[r, j], -1)
    return out
