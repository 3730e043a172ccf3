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

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from .faults import Faults
from .network import Links


@dataclass(kw_only=True)
class Sent:
    """What the UAVs sent in one cycle: its links, link states, and each protocol's rounds."""

    k: int
    links: Links
    bad: np.ndarray | None
    alive: np.ndarray
    rounds: dict[str, list[Any]] = field(default_factory=dict)


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


class Radio:
    """One cycle of the radio for a batch of trials."""

    def __init__(
        self, k: int, links: Links, alive: np.ndarray, faults: Faults, state: RadioState
    ) -> None:
        self.k, self.faults, self.delay = k, faults, faults.model.delay
        self.now = Sent(k=k, links=links, bad=faults.link_states(k, state.bad), alive=alive)
        self.history = state.history

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
        faults = self.faults
        if faults.model.loss <= 0:
            return Inbox(content, sent.links, sent.links)
        trial, receiver, sender = sent.links.pairs()
        lost = faults.lost(sent.k, protocol, round_, trial, sender, receiver, sent.bad)
        return Inbox(content, sent.links, sent.links.keep(~lost))

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
        return content, sent.alive & ~lost

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
        return alive.sum(axis=1), (alive & ~lost).sum(axis=1)

    def close(self) -> RadioState:
        """The state to carry into the next cycle."""
        history = (*self.history, self.now)[-self.delay :] if self.delay else ()
        return RadioState(history, self.now.bad)
