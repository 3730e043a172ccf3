"""The radio of a batch of trials: what each UAV sends in a cycle, and what arrives.

Messages are broadcast in numbered rounds of a protocol (the D_i flooding and the
consensus run rounds 1, 2, ...; beacons, bids, uploads and downloads are one-round
protocols, round 0). A message of round r of cycle k travels over the links of cycle k
(the UAVs' 3-D distance at k within r_C, both alive), unless the fault realisation
loses it, and is received in round r of cycle k + delay. A UAV keeps transmitting its
final state in rounds beyond the last one it ran (the drivers send it once more when
a protocol ends), so a receiver that needs more rounds than a sender ran gets the
sender's final state.

With no faults this is the paper's synchronous exchange: everything sent in round r
of cycle k arrives in round r of cycle k over the links of k.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from .faults import Faults
from .network import Links
from .numerics.codec import CODECS, Codec, mirrored, upper


@dataclass(kw_only=True)
class Sent:
    """What the UAVs sent in one cycle: its links, link states, and each protocol's rounds."""

    k: int
    links: Links
    bad: np.ndarray | None
    alive: np.ndarray
    rounds: dict[str, list[Any]] = field(default_factory=dict)
    budget: Budget | None = None  # with radio.bandwidth_bps: what each UAV's share affords


class Inbox(NamedTuple):
    """One round's arrivals: the senders' content (as sent: arrays (B, N, ...) by name, in
    a dict or a record such as `fusion.Estimates`), the links
    the messages travelled (`network.Links`, before losses: what was sent) and those
    that delivered them (after losses). Self-links are always present: a UAV's own
    current state is always at hand."""

    content: Any
    links: Links
    delivered: Links


@dataclass(frozen=True)
class RadioState:
    """What the radio carries over between cycles: messages still in flight (the last
    `delay` cycles) and the Gilbert-Elliott link states of the last step."""

    history: tuple[Sent, ...] = ()
    bad: np.ndarray | None = None


Count = tuple[Any, Any]
"""Messages (sent, delivered): per trial (B,) arrays in the batch, ints in an agent."""


def counted(
    delay: int, when_sent: Callable[[], Iterable[Count]], arrived: Iterable[Count]
) -> Count:
    """The messages a cycle counts of its protocols, (sent, delivered): the one rule of
    every method, in the batch and in the agents.

    Without delay (d = 0) the messages sent in a round are read in that round, and are
    counted where they arrive: sent, one per link into a receiver taking part in the
    round (what was offered to it); delivered, those the fault realisation does not lose
    (what arrived). `arrived` gives these per round or protocol (`fusion.count` of a
    batch inbox, an agent's `Inbox.sent` and `Inbox.delivered`, an upload's or a
    download's senders alive and those whose message came).

    With delay d > 0 what is read now was sent d cycles ago, and whether a message sent
    now will be read is not known yet (the run may end first): the messages are counted
    when sent, each transmission of this cycle over its links, delivered those the fault
    realisation does not lose. `when_sent()` gives these (`Radio.transmitted`,
    `Radio.transmitted_central`, `AgentRadio.transmitted`); it is called only with delay.

    Returns the sums of the pairs that apply ((0, 0) for none).
    """
    pairs = list(when_sent()) if delay > 0 else list(arrived)
    if not pairs:
        return 0, 0
    sent, delivered = pairs[0]
    for more in pairs[1:]:
        sent, delivered = sent + more[0], delivered + more[1]
    return sent, delivered


UNLIMITED = 2**31 - 1
"""The rounds a UAV's share affords when the radio has no limit (or it has no receiver)."""


@dataclass(frozen=True, kw_only=True)
class Limit:
    """A radio of limited capacity (``radio.bandwidth_bps``) and the frames it schedules:
    the bytes per cycle a channel carries (capacity x dT / 8), the first-priority frame
    per copy (the beacon with the bids; the greedy method's beacon; the centralized
    upload, with tracks each UAV's own (B, N); 0: none), the largest
    frame a round of D_i flooding and consensus can be (every target's tuple in it), the
    central node's download, and whether every UAV talks to the central node (then all
    share one channel)."""

    bytes_per_cycle: float
    first: int | np.ndarray
    round: int
    download: int = 0
    central: bool = False
    beacon: int = 0
    """A centralized method's avoidance beacon per copy (one to each UAV in range), sent
    with its upload as one first priority (0: none)."""
    broadcast: int = 0
    """With ``radio.frames = "broadcast"``: the bytes of a receiver's number at its largest
    (a frame to R >= 2 receivers goes once, `copies`); 0: one frame per receiver."""


@dataclass(frozen=True, kw_only=True)
class Budget:
    """What each program's share of a limited radio affords in one cycle (`Limit`).

    share (B, N): the bytes of each UAV, the channel's bytes over its closed
    neighbourhood (itself and the UAVs in range), or with a central node over every
    living UAV and the node; first (B, N): whether its first-priority frame fits (to
    every receiver); rounds (B, N): the rounds of flooding and consensus it can send
    after it, each reserved at `Limit.round` per receiver (`UNLIMITED` with no receiver);
    served (B, N): whether the central node's share reaches the UAV's download (the
    living UAVs in index order)."""

    share: np.ndarray
    first: np.ndarray
    rounds: np.ndarray
    served: np.ndarray

    @classmethod
    def of(cls, limit: Limit, receivers: np.ndarray, alive: np.ndarray) -> Budget:
        """The budget of a cycle whose UAVs have `receivers` (B, N) in range."""
        B, n = alive.shape
        if limit.central:
            contenders = np.broadcast_to(alive.sum(axis=1, keepdims=True) + 1, (B, n))
            copies = np.ones((B, n), dtype=np.int64)  # the upload, to the node
        else:
            contenders, copies = receivers + 1, receivers
        share = np.floor(limit.bytes_per_cycle / contenders).astype(np.int64)
        if limit.broadcast and not limit.central:

            def sent(frame: Any) -> Any:
                return copies_largest(frame, receivers, limit.broadcast)
        else:

            def sent(frame: Any) -> Any:
                return frame * copies

        cost = sent(limit.first) + copies_largest(limit.beacon, receivers, limit.broadcast)
        first = cost <= share
        left = share - np.where(first, cost, 0)
        per_round = np.maximum(copies_largest(limit.round, receivers, limit.broadcast), 1)
        rounds = np.where(receivers > 0, left // per_round, UNLIMITED)
        served = np.ones((B, n), dtype=bool)
        if limit.central and limit.download:
            node = np.floor(limit.bytes_per_cycle / (alive.sum(axis=1) + 1)).astype(np.int64)
            order = np.cumsum(alive, axis=1)  # the living UAVs in index order
            served = alive & (order * limit.download <= node[:, None])
        return cls(share=share, first=first, rounds=rounds, served=served)


class Radio:
    """One cycle of the radio for a batch of trials."""

    def __init__(
        self,
        k: int,
        links: Links,
        alive: np.ndarray,
        faults: Faults,
        state: RadioState,
        limit: Limit | None = None,
        broadcast: bool = False,
    ) -> None:
        self.k, self.faults, self.delay = k, faults, faults.model.delay
        self.broadcast = broadcast  # ``radio.frames``: one frame to all receivers (`copies`)
        self.now = Sent(k=k, links=links, bad=faults.link_states(k, state.bad), alive=alive)
        self.history = state.history
        B, n = alive.shape
        self.bytes = np.zeros((B, n + 1), dtype=np.int64)  # sent, by UAV; the node's last
        self._reach: tuple[np.ndarray, np.ndarray] | None = None
        if limit is not None:  # what each UAV's share affords this cycle
            self.now.budget = Budget.of(limit, self.reach()[0], alive)

    def send(self, protocol: str, content: Any) -> None:
        """Every UAV transmits `content` (arrays (B, N, ...) by name, in a dict or a record)
        in the next round of `protocol`."""
        self.now.rounds.setdefault(protocol, []).append(content)

    def sending(self, protocol: str) -> bool:
        """Whether a round of `protocol` was sent this cycle."""
        return protocol in self.now.rounds

    def _sent(self) -> Sent | None:
        """The cycle whose messages arrive now."""
        if self.delay == 0:
            return self.now
        for sent in self.history:
            if sent.k == self.k - self.delay:
                return sent
        return None

    def receive(self, protocol: str, round_: int = 0) -> Inbox | None:
        """What arrives now of `protocol`'s round, or None when nothing was sent (the
        first `delay` cycles)."""
        sent = self._sent()
        if sent is None or protocol not in sent.rounds:
            return None
        contents = sent.rounds[protocol]
        content = contents[min(max(round_, 1), len(contents)) - 1]
        faults, links = self.faults, self._sent_on(sent, protocol, round_)
        if faults.model.loss <= 0:
            return Inbox(content, links, links)
        trial, receiver, sender = links.pairs()
        lost = faults.lost(sent.k, protocol, round_, trial, sender, receiver, sent.bad)
        return Inbox(content, links, links.keep(~lost))

    @staticmethod
    def _sent_on(sent: Sent, protocol: str, round_: int) -> Links:
        """The links a round of `protocol` was sent on: those of its cycle, less the
        senders whose share did not afford it (`Budget`)."""
        budget = sent.budget
        if budget is None or protocol not in ("flood", "consensus", "beacon", "bids"):
            return sent.links
        trial, _, sender = sent.links.pairs()
        if protocol in ("beacon", "bids"):
            afforded = budget.first[trial, sender]
        else:
            afforded = budget.rounds[trial, sender] >= round_
        return sent.links.keep(afforded)

    def receive_central(self, protocol: str):
        """(content, delivered (B, N) bool) of an upload (UAV i -> central, delivered[i])
        or a download (central -> UAV i) arriving now; (None, None) when nothing was sent."""
        sent = self._sent()
        if sent is None or protocol not in sent.rounds:
            return None, None
        content = sent.rounds[protocol][0]
        B, n = sent.alive.shape
        trial, uav = np.ogrid[:B, :n]
        central = np.full_like(uav, n)
        sender, receiver = (uav, central) if protocol == "upload" else (central, uav)
        lost = self.faults.lost(sent.k, protocol, 0, trial, sender, receiver, sent.bad)
        return content, self._central_sent(sent, protocol) & ~lost

    @staticmethod
    def _central_sent(sent: Sent, protocol: str) -> np.ndarray:
        """(B, N) the uploads (of each UAV) or downloads (to each) sent: the living
        UAVs', less what the shares did not afford (`Budget`)."""
        budget = sent.budget
        if budget is None:
            return sent.alive
        return sent.alive & (budget.first if protocol == "upload" else budget.served)

    def afforded(self, senders: np.ndarray, what: str = "first") -> np.ndarray:
        """`senders` (B, N) less those whose share does not afford `what` this cycle:
        "first", their first-priority frame; "served", the node's download to them."""
        budget = self.now.budget
        if budget is None:
            return senders
        return senders & getattr(budget, what)

    def transmitted(
        self, protocol: str, rounds: np.ndarray, first: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        """Messages sent now, counted when sent (with delay, whether a receiver will read
        one d cycles later is not known yet): UAV i sends rounds[b, i] rounds of
        `protocol`, numbered first, first + 1, ..., one message per link of this cycle and
        round. Returns (sent, delivered) per trial (B,): delivered are those the fault
        realisation does not lose."""
        links = self.now.links
        if links.edges:
            other = ~links.own
            trial, receiver, sender = (x[other] for x in links.edge_list)
        else:
            trial, receiver, sender = np.nonzero(links.adjacency())
        count = rounds[trial, sender]
        budget = self.now.budget
        if budget is not None:  # what the senders' shares afford
            if protocol in ("beacon", "bids"):
                count = count * budget.first[trial, sender]
            else:
                count = np.minimum(count, budget.rounds[trial, sender])
        B = links.batch
        sent = np.bincount(trial, weights=count, minlength=B).astype(np.int64)
        if self.faults.model.loss <= 0:
            return sent, sent.copy()
        delivered = np.zeros(B, dtype=np.int64)
        for r in range(int(count.max(initial=0))):
            on = count > r
            lost = self.faults.lost(
                self.k, protocol, first + r, trial[on], sender[on], receiver[on], self.now.bad
            )
            delivered += np.bincount(trial[on][~lost], minlength=B)
        return sent, delivered

    def transmitted_central(self, protocol: str) -> tuple[np.ndarray, np.ndarray]:
        """An upload (each living UAV to the central node) or a download (the node to each
        living UAV) sent now, counted when sent: (sent, delivered) per trial (B,)."""
        alive = self.now.alive
        B, n = alive.shape
        trial, uav = np.ogrid[:B, :n]
        central = np.full_like(uav, n)
        sender, receiver = (uav, central) if protocol == "upload" else (central, uav)
        lost = self.faults.lost(self.k, protocol, 0, trial, sender, receiver, self.now.bad)
        alive = self._central_sent(self.now, protocol)
        return alive.sum(axis=1), (alive & ~lost).sum(axis=1)

    def reach(self) -> tuple[np.ndarray, np.ndarray]:
        """Each UAV's receivers in range now (B, N) and the bytes their numbers take in
        the frames' envelopes (B, N)."""
        if self._reach is None:
            links, (B, n) = self.now.links, self.now.alive.shape
            if links.edges:
                other = ~links.own
                trial, receiver, sender = (x[other] for x in links.edge_list)
                where = trial * n + sender
                count = np.bincount(where, minlength=B * n).reshape(B, n)
                named = np.bincount(where, int_bytes(receiver), B * n).reshape(B, n)
            else:
                into = links.adjacency() & _others(n)  # [trial, receiver, sender]
                count = into.sum(axis=1)
                named = count if n <= 128 else np.einsum("brs,r->bs", into, int_bytes(_senders(n)))
            self._reach = count.astype(np.int64), named.astype(np.int64)
        return self._reach

    def on_air(
        self, parts: Any, count: int, senders: np.ndarray, node: bool = False, frames: Any = 1
    ) -> None:
        """Count frames: each UAV where `senders` (B, N) sends `frames` (B, N, or 1)
        frames of `count` parts of `parts` bytes in all (`part_bytes`; an array (B, N)
        or a number) to each UAV in range now, or with `node` to the central node."""
        n = senders.shape[1]
        frame = frame_bytes(self.k, _senders(n), parts, count)
        if node:
            sent = frame + int_bytes(n)
        else:
            sent = self.copies(frame, 1)
        self.bytes[:, :n] += np.where(senders, frames * sent, 0)

    def copies(self, frames: Any, count: Any) -> Any:
        """The bytes (B, N) each UAV puts on the air for `count` frames (B, N, or a number)
        of `frames` bytes in all, each one copy less its receiver's number, to every UAV
        in range now: one copy per receiver; with ``radio.frames = "broadcast"``, to R >= 2
        receivers one copy naming them all, a tag for each (`broadcast_bytes`)."""
        receivers, named = self.reach()
        unicast = receivers * frames + named * count
        if not self.broadcast:
            return unicast
        once = frames + count * (broadcast_bytes(receivers) + named)
        return np.where(receivers >= 2, once, unicast)

    def from_node(self, parts: Any, count: int, receivers: np.ndarray) -> None:
        """Count the central node's frames: one of `count` parts of `parts` bytes (B, N)
        to each UAV where `receivers` (B, N)."""
        n = receivers.shape[1]
        frame = frame_bytes(self.k, n, parts, count) + int_bytes(_senders(n))
        self.bytes[:, n] += np.where(receivers, frame, 0).sum(axis=1)

    def rounds_on_air(
        self, ran: np.ndarray, rounds: np.ndarray, flood: int, tuples: Any, alive: np.ndarray
    ) -> None:
        """Count the frames of the D_i flooding with the consensus, as an agent bundles
        them (`agents.agent.UavAgent.rounds`): a UAV that stopped the flooding in round R
        (`ran`) and runs C consensus rounds (`rounds`) sends rounds 1 .. max(R, C) + 1;
        round r carries the flooding's set (`flood` bytes of content) while r <= R + 1
        (final in R + 1) and the consensus tuples (`tuples`) in every round, final in the
        last, which carries no tuples when R > C (those of round C + 1 were final).

        So a UAV sends R + 1 frames of both parts and C - R of the tuples alone when
        R <= C, and R frames of both and one of the set and an empty final part when
        R > C. Each part's size depends on its round only through MessagePack's size of
        the round numbers, one byte below 128 rounds; beyond, frame by frame. `tuples`
        is the bytes of every round's tuples, or a list of them by round (B, N) each
        (``fusion.trigger``, compact encoding): then frame by frame too."""
        last = np.maximum(ran, rounds) + 1
        budget = self.now.budget
        if budget is not None:  # the rounds each share affords: the frames beyond are not sent
            last = np.minimum(last, budget.rounds)
        if (
            isinstance(tuples, list)
            or budget is not None
            or int(np.where(alive, last, 0).max(initial=0)) >= 128
        ):
            return self._rounds_one_by_one(ran, rounds, flood, tuples, alive)
        set_part = part_bytes("flood", 1, -1, flood)
        tuple_part = part_bytes("consensus", 1, -1, tuples)
        empty_part = part_bytes("consensus", 1, -1, None)
        late = ran > rounds  # the last frame: the set and an empty final part
        both = np.where(late, ran, ran + 1)
        alone = np.where(late, 0, rounds - ran)
        k, who = self.k, _senders(alive.shape[1])
        per_receiver = (
            both * frame_bytes(k, who, set_part + tuple_part, 2)
            + alone * frame_bytes(k, who, tuple_part, 1)
            + late * frame_bytes(k, who, set_part + empty_part, 2)
        )
        sent = self.copies(per_receiver, both + alone + late)
        self.bytes[:, : alive.shape[1]] += np.where(alive, sent, 0)

    def _rounds_one_by_one(
        self, ran: np.ndarray, rounds: np.ndarray, flood: int, tuples: Any, alive: np.ndarray
    ) -> None:
        """`rounds_on_air` frame by frame (round numbers of any size, tuples by round)."""
        last = np.maximum(ran, rounds) + 1
        every = tuples
        for r in range(1, int(np.where(alive, last, 0).max(initial=0)) + 1):
            if isinstance(every, list):  # a UAV's tuples of round r (r <= C + 1)
                tuples = every[min(r, len(every)) - 1]
            on = alive & (r <= last)
            if self.now.budget is not None:
                on &= r <= self.now.budget.rounds
            flood_final = np.where(r == ran + 1, r, -1)
            flooding = np.where(r <= ran + 1, part_bytes("flood", r, flood_final, flood), 0)
            closing = (r == last) & (ran > rounds)
            final = np.where(r == last, np.where(closing, rounds + 1, r), -1)
            consensus = np.where(
                closing,
                part_bytes("consensus", r, final, None),
                part_bytes("consensus", r, final, tuples),
            )
            for count in (1, 2):  # frames of the tuples alone, and of both parts
                both = r <= ran + 1
                self.on_air(flooding + consensus, count, on & (both == (count == 2)))

    def close(self) -> RadioState:
        """The state to carry into the next cycle."""
        history = (*self.history, self.now)[-self.delay :] if self.delay else ()
        return RadioState(history, self.now.bad)


# ---------------------------------------------------------------- bytes on the air
#
# The agent form (`agents`) sends one frame per receiver and round: an envelope
# (`agents.security.Envelope`: sender, receiver, sequence number, body, tag) around a
# `agents.messages.Radio` (version, run, cycle k, sender, its parts), each part one
# protocol's (`agents.messages.Part`: protocol, round, final, content), the content a map
# of arrays (`agents.messages.Array`: dtype, shape, data), all MessagePack. The batch
# counts the same bytes from the same layout with MessagePack's size rules below, so a
# run's bytes equal what the agents put on the wire (a test checks the rules against
# the encoder, another a swarm's bytes against `uavtrack run`'s). The transport's own
# framing (Zenoh's headers and key) is not counted.

WIRE_VERSION = 9
"""Schema version of the agent form's messages (`agents.messages.VERSION`)."""
RUN_CHARS = 12
"""Characters of a run's identifier (a random hex token, `agents.swarm`)."""
TAG_BYTES = 16
"""Bytes of every envelope's tag: the keyed BLAKE2b MAC of an authenticated swarm, an
unkeyed BLAKE2b checksum of the same bytes otherwise (`agents.security.Gate.seal`), so a
frame's size does not depend on the setting."""
SEQ_START = 2**32
"""A program's first sequence number is SEQ_START + 1: every envelope's sequence number is
then a MessagePack uint64 (9 bytes), and a frame's size does not depend on how many
messages its sender sent before."""


@functools.cache
def _others(n: int) -> np.ndarray:
    """(n, n) True off the diagonal (read only)."""
    out = ~np.eye(n, dtype=bool)
    out.flags.writeable = False
    return out


@functools.cache
def _senders(n: int) -> Any:
    """The programs 0 .. n - 1 (read only) as far as their size goes: 0 when every
    number takes one byte."""
    if n <= 128:
        return 0
    out = np.arange(n)
    out.flags.writeable = False
    return out


Layout = dict[str, tuple[str, tuple[int, ...]]]
"""A content's arrays: name -> (dtype as numpy writes it, shape)."""

F8, I8, B1 = "<f8", "<i8", "|b1"


Field = tuple[str, tuple[int, ...], str]
"""An array of a message's content: (dtype, shape, domain); the domain names what its
values may be, which the agents' receivers check (`agents.messages.DOMAINS`)."""


def described(
    protocol: str,
    n: int,
    m: int,
    slots: int = 0,
    avoid: bool = False,
    tuples: str = "full",
    book: tuple[str, ...] = (),
    recent: bool = False,
) -> dict[str, Field]:
    """The arrays of a protocol's content in the agent form, with their domains: `n`
    UAVs, `m` targets, K = `slots` track slots per UAV with unknown association (0:
    known), and with ``planner.avoidance`` (`avoid`) a beacon that carries the sender's
    whole state. The one declaration of the wire's content: the batch counts its bytes
    (`layout`), the agents admit exactly it (`agents.messages.Spec.contents`). (-1, ...)
    is a scan's Z measurements, or the targets a consensus message carries.

    tuples: how the consensus carries its tuples: "full", every target's in float64;
    "listed" (``fusion.trigger``), the same for the targets it lists; "compact" or
    "quantized" (``radio.encoding``), the targets it lists, each estimate as that codec
    packs it (`numerics.codec.CODECS`), without the confidence (its receiver computes it).

    book: the track book's fields beyond M-of-N's that the download carries
    (`tracks.manage.sent_fields`)."""
    codec = CODECS.get(tuples)
    if protocol == "consensus" and tuples != "full" and slots:
        return _listed_tracks(slots, codec)
    if protocol == "consensus" and tuples != "full":
        if codec is not None:
            return {
                "targets": ("<u2", (-1,), "targets"),
                **codec.fields("estimate"),
                "stamp": ("<i4", (-1,), "stamp"),
                "origin": ("<u2", (-1,), "uav index"),
            }
        return {
            "targets": (I8, (-1,), "targets"),
            "gamma": (F8, (-1,), "confidence or none"),
            "mean": (F8, (-1, 4), "estimate"),
            "cov": (F8, (-1, 4, 4), "covariance"),
            "stamp": (I8, (-1,), "stamp"),
            "origin": (I8, (-1,), "uav index"),
        }
    beacon: dict[str, Field] = (
        {"uav": (F8, (5,), "uav state")} if avoid else {"position": (F8, (3,), "position")}
    )
    if recent:  # ``planner.avoidance_model = "measured"``: the sender's last two actions
        beacon["recent"] = ("|u1", (), "recent commands")
    if slots:
        K = slots
        tracks: dict[str, Field] = {
            "mean": (F8, (K, 4), "track estimate"),
            "cov": (F8, (K, 4, 4), "track covariance"),
            "label": (I8, (K,), "label or none"),
            "status": (I8, (K,), "track status"),
            "stamp": (I8, (K,), "track stamp"),
        }
        counts: dict[str, Field] = {
            name: (I8, (K,), "counts") for name in ("hits", "scans", "misses")
        }
        counts |= {
            name: (F8, (K,), "existence") if name == "existence" else (I8, (K,), "counts")
            for name in book
        }
        contents: dict[str, dict[str, Field]] = {
            "flood": {"known": (B1, (n,), "known")},
            "consensus": {**tracks, "tombs": (I8, (K, 2), "tombstones")},
            "beacon": beacon,
            "bids": {
                "bids": (F8, (K,), "slot bids"),
                "label": (I8, (K,), "bid labels"),
                "stamp": (I8, (), "cycle"),
            },
            "upload": {
                "z": (F8, (-1, 2), "ground positions"),
                "R": (F8, (-1, 2, 2), "measurement covariance"),
                "uav": (F8, (5,), "uav state"),
            },
            "download": {
                **tracks, **counts, "serial": (I8, (), "counts"),
                "target": (I8, (), "label or none"),
            },
        }  # fmt: skip
        return contents[protocol]
    known: dict[str, Field] = {
        "gamma": (F8, (m,), "confidence"),
        "mean": (F8, (m, 4), "estimate"),
        "cov": (F8, (m, 4, 4), "covariance"),
        "stamp": (I8, (m,), "stamp"),
    }
    contents = {
        "flood": {"known": (B1, (n,), "known")},
        "consensus": {**known, "origin": (I8, (m,), "uav index")},
        "beacon": beacon,
        "bids": {"bids": (F8, (m,), "bids"), "stamp": (I8, (), "cycle")},
        "upload": {**known, "uav": (F8, (5,), "uav state")},
        "download": {
            **known,
            "gamma": (F8, (m,), "confidence or none"),
            "target": (I8, (), "target or none"),
        },
    }
    return contents[protocol]


def _listed_tracks(slots: int, codec: Codec | None) -> dict[str, Field]:
    """A track consensus that lists its slots (``fusion.trigger``, ``radio.encoding``):
    the confirmed slots it carries, each under its team label (the others are not
    offered: a receiver reads only confirmed tracks), and the sender's tombstones. With
    an encoding (`codec`): its estimates, 32-bit integers."""
    if codec is not None:
        return {
            "slots": ("<u2", (-1,), "slots"),
            **codec.fields("track estimate"),
            "label": ("<u4", (-1,), "team label"),
            "stamp": ("<i4", (-1,), "track stamp"),
            "tombs": ("<i4", (slots, 2), "tombstones"),
        }
    return {
        "slots": (I8, (-1,), "slots"),
        "mean": (F8, (-1, 4), "track estimate"),
        "cov": (F8, (-1, 4, 4), "track covariance"),
        "label": (I8, (-1,), "team label"),
        "stamp": (I8, (-1,), "track stamp"),
        "tombs": (I8, (slots, 2), "tombstones"),
    }


@dataclass(frozen=True, kw_only=True)
class Wire:
    """What shapes a run's messages, the arguments of `described`: n UAVs, m targets,
    K track slots (0: known association), the beacon's whole state (``planner.avoidance``),
    how the consensus carries its tuples and the book fields a download carries
    (`methods.base.wire_of` reads them from a scenario)."""

    n: int
    m: int
    slots: int = 0
    avoid: bool = False
    tuples: str = "full"
    book: tuple[str, ...] = ()
    recent: bool = False

    def described(self, protocol: str, tuples: str | None = None) -> dict[str, Field]:
        """`described` of a protocol in this run (tuples: another listing than the run's)."""
        listing = self.tuples if tuples is None else tuples
        return described(
            protocol, self.n, self.m, self.slots, self.avoid, listing, self.book, self.recent
        )

    def layout(self, protocol: str, tuples: str | None = None) -> Layout:
        """`layout` of a protocol in this run (tuples: another listing than the run's)."""
        listing = self.tuples if tuples is None else tuples
        return layout(
            protocol, self.n, self.m, self.slots, self.avoid, listing, self.book, self.recent
        )

    def bytes(self, protocol: str, rows: Any = None, tuples: str | None = None) -> Any:
        """`content_bytes` of a protocol's content in this run (`rows`: of its variable
        arrays, (B, N) or a number; a fixed layout's are cached)."""
        listing = self.tuples if tuples is None else tuples
        if rows is None and (protocol != "consensus" or listing == "full"):
            return layout_bytes(
                protocol, self.n, self.m, self.slots, self.avoid, self.book, self.recent
            )
        return content_bytes(self.layout(protocol, tuples), rows)


def layout(
    protocol: str,
    n: int,
    m: int,
    slots: int = 0,
    avoid: bool = False,
    tuples: str = "full",
    book: tuple[str, ...] = (),
    recent: bool = False,
) -> Layout:
    """The arrays of a protocol's content, (dtype, shape) by name: `described` without
    the domains, what the batch counts the bytes of; its rows packed in one byte array
    where they travel so (`packs`)."""
    fields = described(protocol, n, m, slots, avoid, tuples, book, recent)
    if packs(protocol, tuples):
        return packed_layout(fields)
    return {name: (dtype, shape) for name, (dtype, shape, _) in fields.items()}


ROWS = "rows"
"""The byte array that carries a packed content's rows (`packs`)."""


def packs(protocol: str, tuples: str) -> bool:
    """Whether a content's row fields (first axis -1) travel packed, one record per row
    in one byte array `ROWS` (`rows_dtype`): the quantized consensus, whose rows are a
    few bytes each, where every array of its own would cost a dozen bytes of header."""
    return protocol == "consensus" and tuples == "quantized"


def rows_dtype(fields: dict[str, Field]) -> np.dtype:
    """The record of one row: a content's row fields (first axis -1), in their order,
    without padding."""
    rows = [
        (name, dtype, shape[1:]) for name, (dtype, shape, _) in fields.items() if shape[:1] == (-1,)
    ]
    return np.dtype(rows)


def packed_layout(fields: dict[str, Field]) -> Layout:
    """The layout of a content whose row fields travel packed (`packs`): `ROWS`, then
    its other fields as they are."""
    out: Layout = {ROWS: ("|u1", (-1, rows_dtype(fields).itemsize))}
    out |= {n: (d, s) for n, (d, s, _) in fields.items() if s[:1] != (-1,)}
    return out


def pack_rows(content: dict[str, np.ndarray], fields: dict[str, Field]) -> dict[str, np.ndarray]:
    """A content (`fields`) with its row fields packed into `ROWS` (`packs`)."""
    record = rows_dtype(fields)
    names = record.names or ()
    count = len(content[names[0]]) if names else 0
    rows = np.zeros(count, dtype=record)
    for name in names:
        rows[name] = content[name]
    out = {ROWS: rows.view(np.uint8).reshape(count, record.itemsize)}
    return out | {n: v for n, v in content.items() if n not in names}


def unpack_rows(rows: np.ndarray, fields: dict[str, Field]) -> dict[str, np.ndarray]:
    """The row fields of a packed `ROWS` array (count, itemsize) uint8 (`pack_rows`
    undone), each a contiguous array of its own dtype."""
    record = rows_dtype(fields)
    values = np.frombuffer(np.ascontiguousarray(rows).tobytes(), dtype=record)
    return {name: np.ascontiguousarray(values[name]) for name in record.names or ()}


_POSITIVE = (np.array([128, 256, 65536, 2**32]), np.array([1, 2, 3, 5, 9]))
_NEGATIVE = (np.array([-(2**31), -32768, -128, -32]), np.array([9, 5, 3, 2, 1]))


def int_bytes(value: Any) -> Any:
    """MessagePack bytes of integers: fixint, then 1, 2, 4 or 8 bytes more (an int for
    an int, else an int64 array)."""
    if isinstance(value, int | np.integer):
        v = int(value)
        if v >= 0:
            return 1 if v < 128 else 2 if v < 256 else 3 if v < 65536 else 5 if v < 2**32 else 9
        return (
            1 if v >= -32 else 2 if v >= -128 else 3 if v >= -32768 else 5 if v >= -(2**31) else 9
        )
    v = np.asarray(value, dtype=np.int64)
    limits, sizes = _POSITIVE
    positive = sizes[np.searchsorted(limits, v, side="right")]
    if v.size == 0 or v.min() >= 0:
        return positive
    limits, sizes = _NEGATIVE
    return np.where(v >= 0, positive, sizes[np.searchsorted(limits, v, side="right")])


def _sized(n: Any, limits: tuple[int, ...], heads: tuple[int, ...]) -> Any:
    """The header bytes of a length `n` (heads[i] below limits[i], the last beyond)."""
    if isinstance(n, int | np.integer):
        return next((h for limit, h in zip(limits, heads, strict=False) if n < limit), heads[-1])
    return np.asarray(heads)[np.searchsorted(limits, np.asarray(n, dtype=np.int64), "right")]


def str_bytes(chars: Any) -> Any:
    """MessagePack bytes of strings of `chars` (ASCII) characters."""
    return _sized(chars, (32, 256, 65536), (1, 2, 3, 5)) + chars


def bin_bytes(size: Any) -> Any:
    """MessagePack bytes of binaries of `size` bytes."""
    return _sized(size, (256, 65536), (2, 3, 5)) + size


def head_bytes(count: Any) -> Any:
    """MessagePack bytes of the header of an array or a map of `count` entries."""
    return _sized(count, (16, 65536), (1, 3, 5))


@functools.cache
def _key(name: str) -> int:
    return int(str_bytes(len(name)))


def array_bytes(dtype: str, shape: Any, rows: Any = None) -> np.ndarray:
    """An array on the wire, `agents.messages.Array` (dtype, shape, data): of `shape`, or
    of `rows` (vectorised) by shape[1:] where shape[0] is -1."""
    dims = np.asarray(shape[1:] if shape[:1] == (-1,) else shape, dtype=np.int64)
    size = np.dtype(dtype).itemsize * int(np.prod(dims))
    fixed = 1 + _key(dtype) + int(head_bytes(len(shape))) + int(int_bytes(dims).sum())
    if shape[:1] == (-1,):
        rows = np.asarray(rows, dtype=np.int64)
        return fixed + int_bytes(rows) + bin_bytes(size * rows)
    return fixed + bin_bytes(size)


def content_bytes(layout: Layout, rows: Any = None) -> np.ndarray:
    """A part's content: the map of `layout`'s arrays (`rows`: of the variable ones)."""
    total = head_bytes(len(layout))
    for name, (dtype, shape) in layout.items():
        total = total + _key(name) + array_bytes(dtype, shape, rows)
    return np.asarray(total, dtype=np.int64)


def part_bytes(protocol: str, round_: Any, final: Any, content: Any) -> Any:
    """One protocol's part of a frame (`agents.messages.Part`), vectorised over the
    round, the final round (-1: not final) and the content's bytes (None: no content)."""
    content = 1 if content is None else content  # nil
    return 1 + _key(protocol) + int_bytes(round_) + int_bytes(final) + content


_BODY = (
    1  # a tagged map of 6 entries: the tag, then the 5 fields
    + _key("type") + _key("radio")
    + _key("version") + int_bytes(WIRE_VERSION)
    + _key("run") + str_bytes(RUN_CHARS)
    + _key("k") + _key("sender") + _key("parts")
)  # fmt: skip
"""The bytes of a `agents.messages.Radio` body besides the values of k, the sender and
the parts."""


@functools.cache
def layout_bytes(
    protocol: str,
    n: int,
    m: int,
    slots: int = 0,
    avoid: bool = False,
    book: tuple[str, ...] = (),
    recent: bool = False,
) -> int:
    """`content_bytes` of a fixed `layout` (no scan in it)."""
    return int(content_bytes(layout(protocol, n, m, slots, avoid, book=book, recent=recent)))


def wire_mean(mean: np.ndarray) -> np.ndarray:
    """Estimates as the compact encoding delivers them: rounded to float32."""
    return mean.astype(np.float32).astype(np.float64)


def wire_cov(cov: np.ndarray) -> np.ndarray:
    """Covariances (..., 4, 4) as the compact encoding delivers them: the upper triangle
    rounded to float32, mirrored below the diagonal."""
    return mirrored(upper(cov).astype(np.float32))


FRAMES = ("unicast", "broadcast")
"""The values of ``radio.frames``: one frame per receiver, or one to all receivers."""


def broadcast_bytes(receivers: Any) -> Any:
    """What a frame to R >= 2 receivers (vectorised) takes beyond one copy less its
    receiver's number and the receivers' numbers: the envelope names a list of
    receivers and holds a list of tags, one per receiver (`agents.security.Gate.seal`),
    so two list headers and R - 1 more tags."""
    return 2 * head_bytes(receivers) + (receivers - 1) * bin_bytes(TAG_BYTES)


def copies_largest(frame: Any, receivers: np.ndarray, number: int) -> Any:
    """The bytes of a frame of `frame` bytes a copy (its receiver's number included, at
    `number` bytes) to `receivers` (B, N) receivers each: one copy per receiver, or with
    `number` > 0 (``radio.frames = "broadcast"``) one to R >= 2 receivers naming all.
    A capacity's budget (`Budget`), at each number's largest."""
    unicast = frame * receivers
    if not number:
        return unicast
    once = frame + broadcast_bytes(receivers) + (receivers - 1) * number
    return np.where((receivers >= 2) & (np.asarray(frame) > 0), once, unicast)


def frame_bytes(k: int, sender: Any, parts: Any, count: Any) -> Any:
    """One frame from `sender` (vectorised) of `count` parts of `parts` bytes in all, to
    one receiver, less the receiver's number (`int_bytes` of it, added by the caller)."""
    k_bytes, sender_bytes = int_bytes(k), int_bytes(sender)
    if isinstance(sender_bytes, int) and isinstance(parts, int | np.integer):
        return _frame(k_bytes, sender_bytes, int(parts), count)  # a number: cached
    return _frame.__wrapped__(k_bytes, sender_bytes, parts, count)


@functools.lru_cache(maxsize=4096)
def _frame(k: Any, sender: Any, parts: Any, count: Any) -> Any:
    """`frame_bytes` from the bytes that k and the sender's number take."""
    body = _BODY + k + sender + head_bytes(count) + parts
    # the envelope: an array of 5, sender, (receiver), sequence number, body, tag
    seq = int_bytes(SEQ_START + 1)
    return head_bytes(5) + sender + seq + bin_bytes(body) + bin_bytes(TAG_BYTES)
