"""One UAV as a program, and the central node of the centralized baseline.

A `UavAgent` owns only its own state: its belief of every target (mean, covariance),
its last target, the bids it holds of its neighbours, and what it has heard. Every
cycle the world sends it its own measurements, where its GPS says it is and whom it can
hear (`messages.Sense`); it then runs the paper's cycle by exchanging messages with
the others (`messages.Radio`): the D_i flooding, the consensus rounds, beacons and
bids (or, for the centralized baseline, an upload to the central node and its
download), and reports its action to the world (`messages.Report`).

It calls the simulator's stage functions on its own slice (leading axes of size 1):
`simulation.convert`, `estimation.filter_step`, `fusion.flood` and `fusion.adopt`,
`planning.plan`, `methods.bid_view`, `assignment.local`, `methods.central_node` and
`methods.take_download`. What differs from the batch simulator is only who holds which
rows, so a swarm's trace equals `uavtrack run`'s for the same seed and faults.

A radio message goes to each UAV in range, one per receiver and round, and carries
every protocol that runs in that round: round r of the D_i flooding with round r of
the consensus (a UAV learns in round r whether its D_i reaches r, from the same
message), the beacon with the bids. The fault model's losses are drawn per protocol at
the receiver, as in the simulator, so bundling changes no number.

Every wait has a deadline: what has not arrived by then counts as lost, so a crashed
or frozen neighbour costs a round's deadline, never the run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .. import assignment, estimation, fusion, network, simulation, timing
from ..airspace import avoidance, beacons, response
from ..config import Scenario
from ..faults import Faults
from ..methods import (
    Centralized,
    Distributed,
    Greedy,
    Held,
    Method,
    bid_view,
    central_node,
    get,
    nothing_heard,
    take_download,
)
from ..numerics.codec import Codec
from ..radio import counted, pack_rows, packs
from ..robust import gate
from .messages import VERSION, Part, Radio, Report, Spec, encode, packed
from .transport import Link, Mailbox


@dataclass
class Inbox:
    """One round's arrivals at one receiver: contents by sender (delivered, in sender
    order), and how many messages were sent to it and delivered (the simulator's count)."""

    contents: dict[int, dict[str, np.ndarray]]
    sent: int
    delivered: int


class AgentRadio:
    """A program's side of the radio: it sends to the UAVs in range, and keeps of what
    arrives what the emulated radio delivers: round r of cycle k - delay, from a sender
    it could hear at that cycle, unless the fault realisation (`faults.Faults`, a pure
    function of the message) loses it. The same rule as `radio.Radio`, seen by one
    receiver."""

    def __init__(
        self,
        me: int,
        n: int,
        faults: Faults,
        link: Link,
        mailbox: Mailbox,
        deadline: float,
        broadcast: bool = False,
    ) -> None:
        self.me, self.n, self.faults = me, n, faults
        self.broadcast = broadcast  # ``radio.frames``: one frame to several receivers
        self.link, self.mailbox, self.run = link, mailbox, link.run
        self.deadline, self.delay = deadline, faults.model.delay
        self.links: dict[int, np.ndarray] = {}  # cycle -> (N,) senders heard
        self.alive: dict[int, np.ndarray] = {}  # cycle -> (N,) alive
        self.central: dict[int, bool] = {}  # cycle -> the central node is alive
        self.bad: dict[int, np.ndarray | None] = {}  # cycle -> (N+1, N+1) link states
        self.afford: dict[int, np.ndarray | None] = {}  # cycle -> (N, 3) `radio.Budget`
        self.late: dict[str, int] = {}  # this cycle's messages that missed it, by protocol
        self.bytes = 0  # this cycle's frames on the wire (`radio.frame_bytes`)

    def begin(
        self,
        k: int,
        links: np.ndarray,
        alive: np.ndarray,
        central: bool = True,
        afford: np.ndarray | None = None,
    ) -> None:
        self.links[k], self.alive[k], self.central[k] = links, alive, central
        self.afford[k] = afford
        self.late, self.bytes = {}, 0
        previous = self.bad.get(k - 1)
        states = self.faults.link_states(k, None if previous is None else previous[None])
        self.bad[k] = None if states is None else states[0]
        for old in [c for c in self.links if c < k - self.delay - 1]:
            for table in (self.links, self.alive, self.central, self.bad, self.afford):
                table.pop(old)
        self.mailbox.begin(k, k - self.delay - 1)

    def affords(self, k: int, q: int, protocol: str, round_: int = 0) -> bool:
        """Whether the share of program q affords a message of `protocol`'s round at
        cycle k (`radio.Budget`, as the world says; always, on an unlimited radio): the
        first-priority frame (beacon, bids, upload), the rounds of flooding and
        consensus, the central node's download to UAV q."""
        afford = self.afford.get(k)
        if afford is None:
            return True
        if protocol in ("beacon", "bids", "upload"):
            return bool(afford[q, 0])
        if protocol == "download":
            return bool(afford[q, 2])
        return bool(afford[q, 1] >= round_)

    def send(self, k: int, parts: list[Part], to=None) -> None:
        """One message of these parts to each UAV in range at cycle k (or to `to`), if
        this program's share affords it."""
        first = parts[0]
        to_check = self.me if to is None or first.protocol != "download" else int(to)
        if not self.affords(k, to_check, first.protocol, first.round):
            return
        receivers = np.flatnonzero(self.links[k]) if to is None else np.atleast_1d(to)
        receivers = [int(q) for q in receivers if q != self.me]
        body = encode(Radio(version=VERSION, run=self.run, k=k, sender=self.me, parts=parts))
        if self.broadcast and len(receivers) >= 2:
            self.bytes += self.link.broadcast(receivers, body)
            return
        for q in receivers:
            self.bytes += self.link.send_body(q, body)

    def lost(self, k: int, protocol: str, round_: int, sender: np.ndarray, receiver) -> np.ndarray:
        bad = self.bad.get(k)
        return self.faults.lost(
            k, protocol, round_, 0, sender, receiver, None if bad is None else bad[None]
        )

    def transmitted(self, k: int, protocol: str, rounds: int, first: int = 1, to=None):
        """Messages this program sends at cycle k, counted when sent (`radio.Radio.
        transmitted`, seen by one sender): `rounds` rounds of `protocol` from round
        `first` to each UAV in range (or to `to`). Returns (sent, delivered)."""
        receivers = np.flatnonzero(self.links[k]) if to is None else np.atleast_1d(to)
        receivers = receivers[receivers != self.me]
        if protocol == "download":  # the node's share: to the UAVs it reaches
            receivers = np.array([q for q in receivers if self.affords(k, int(q), protocol)])
            receivers = receivers.astype(np.int64)
        elif self.afford.get(k) is not None:
            rounds = sum(self.affords(k, self.me, protocol, first + r) for r in range(rounds))
        delivered = sum(
            int((~self.lost(k, protocol, first + r, np.array(self.me), receivers)).sum())
            for r in range(rounds)
        )
        return len(receivers) * rounds, delivered

    def receive(self, k: int, protocol: str, round_: int) -> Inbox | None:
        """What arrives now of `protocol`'s round, or None when nothing was sent yet."""
        sent_at = k - self.delay
        if sent_at < 0 or sent_at not in self.links:
            return None
        senders = np.flatnonzero(self.links[sent_at])
        senders = np.array(
            [
                q
                for q in senders
                if q != self.me and self.affords(sent_at, int(q), protocol, round_)
            ],
            dtype=np.int64,
        )
        lost = self.lost(sent_at, protocol, round_, senders, self.me)
        expected = [int(q) for q in senders[~lost]]
        mailbox = self.mailbox
        mailbox.wait(
            lambda: all(
                mailbox.content(sent_at, protocol, q, round_) is not None for q in expected
            ),
            time.monotonic() + self.deadline,
        )
        contents = {}
        with mailbox.cond:
            for q in expected:
                value = mailbox.content(sent_at, protocol, q, round_)
                if value is not None:
                    contents[q] = value
        self.missed(protocol, len(expected) - len(contents))
        return Inbox(contents, len(senders), len(contents))

    def missed(self, protocol: str, count: int) -> None:
        """`count` messages of `protocol` that the fault model delivers had not come when
        this program stopped waiting for them: late (or never sent: their sender stopped
        or gone). The simulator's radio is never late, so a cycle with such a message
        may decide otherwise than the simulator's: it is counted, never silent."""
        if count > 0:
            self.late[protocol] = self.late.get(protocol, 0) + count


def dropped(mailbox: Mailbox, reasons: dict[str, int]) -> None:
    """Count what a program could not use, by reason, with the drops of its mailbox."""
    with mailbox.cond:
        for reason, count in reasons.items():
            mailbox.drops[reason] = mailbox.drops.get(reason, 0) + count


def plausible(spec: Spec, mailbox: Mailbox, content: dict) -> dict:
    """A sender's tuples with those beyond the run's plausibility bounds replaced by no
    estimate (`messages.Spec.estimates`), counted with the drops."""
    content, reasons = spec.estimates(content)
    dropped(mailbox, reasons)
    return content


def check_method(method: Method, scenario: Scenario | None = None) -> None:
    """Refuse (ValueError) a method the agent form cannot run as it is: one not built on
    Distributed, Greedy or Centralized, one that replaces their `assign` (each UAV
    program runs the method's neighbourhood rule, `solve`, not a batch `assign`), one
    that reads the whole team (`Method.local` False: a graph policy), or a learned
    policy with tracks of unknown association in `scenario`."""
    bases = [c for c in type(method).__mro__ if c in (Distributed, Greedy, Centralized)]
    if not bases:
        raise ValueError(
            f"method {method.name!r}: the agent form runs methods built on "
            "Distributed, Greedy or Centralized"
        )
    if not method.local:
        raise ValueError(
            f"method {method.name!r} reads the whole team's observations (a graph policy), "
            "which no UAV program holds: run it with uavtrack run, compare or sweep"
        )
    if not method.plans and scenario is not None and scenario.tracker.unlabelled:
        raise ValueError(
            f"method {method.name!r} chooses without planning (a learned policy); the UAV "
            "programs run it with known association only: run tracks with uavtrack run"
        )
    if type(method).assign is not bases[0].assign:
        raise ValueError(
            f"method {method.name!r} replaces assign, which the agent form does not run "
            "(each UAV program runs a method's neighbourhood rule, solve): run it with "
            "uavtrack run or compare"
        )


def closed(ids: list[int], me: int) -> tuple[int, network.Links]:
    """A receiver's closed neighbourhood as one batch of the stage functions: the row of
    `me` among `ids` (itself and the senders heard, in index order) and links on which
    that row hears every other row and the others hear nothing."""
    where = ids.index(me)
    dense = np.eye(len(ids), dtype=bool)[None]
    dense[0, where, :] = True
    return where, network.Links(batch=1, n=len(ids), dense=dense)


def listing(t: fusion.Estimates, mask: np.ndarray, codec: Codec | None) -> dict[str, np.ndarray]:
    """A consensus round's content with only the tuples of `mask` (M,), listed by target
    (`radio.layout`, "listed"; with a `codec`, that encoding's: its estimates, no
    confidence)."""
    targets = np.flatnonzero(mask)
    mean, cov = fusion.required(t.mean, "mean")[targets], fusion.required(t.cov, "cov")[targets]
    stamp, origin = fusion.required(t.stamp, "stamp"), fusion.required(t.origin, "origin")
    if codec is not None:
        return {
            "targets": targets.astype("<u2"), **codec.pack(mean, cov),
            "stamp": stamp[targets].astype("<i4"), "origin": origin[targets].astype("<u2"),
        }  # fmt: skip
    gamma = fusion.required(t.gamma, "gamma")[targets]
    return {
        "targets": targets.astype(np.int64), "gamma": gamma, "mean": mean, "cov": cov,
        "stamp": stamp[targets], "origin": origin[targets],
    }  # fmt: skip


def listed(
    content: dict[str, np.ndarray], m: int, k: int, sender: int, codec: Codec | None
) -> dict[str, np.ndarray]:
    """A consensus content as every target's tuples (`listing` undone): a target not
    listed has no estimate (confidence -inf, mean 0, covariance I, stamp k); an encoded
    content's estimates are unpacked by the run's `codec` and their confidences computed
    from them, as the batch does. A full content is as it is."""
    if "targets" not in content:
        return content
    targets = content["targets"].astype(np.int64)
    gamma = np.full(m, -np.inf)
    mean, cov = np.zeros((m, 4)), np.broadcast_to(np.eye(4), (m, 4, 4)).copy()
    stamp, origin = np.full(m, k, dtype=np.int64), np.full(m, sender, dtype=np.int64)
    if codec is None:
        mean[targets] = content["mean"]
        cov[targets], gamma[targets] = content["cov"], content["gamma"]
    else:
        mean[targets], cov[targets] = codec.unpack(content)
        gamma[targets] = estimation.confidence(cov[targets])
    stamp[targets], origin[targets] = content["stamp"], content["origin"]
    return {"gamma": gamma, "mean": mean, "cov": cov, "stamp": stamp, "origin": origin}


def part(protocol: str, round_: int, content: dict | None, final: int = -1) -> Part:
    return Part(protocol, round_, final, None if content is None else packed(content))


class UavAgent:
    """One UAV's program (see the module docstring)."""

    def __init__(
        self,
        me: int,
        scenario: Scenario,
        method: str | Method,
        faults: Faults,
        link: Link,
        mailbox: Mailbox,
        deadline: float,
        prior: tuple[np.ndarray, np.ndarray],
    ) -> None:
        self.me, self.scenario, self.method = me, scenario, get(method)
        self.n, self.m = scenario.n_uavs, scenario.n_targets
        self.link, self.mailbox, self.run = link, mailbox, link.run
        broadcast = scenario.radio.frames == "broadcast"
        self.radio = AgentRadio(me, self.n, faults, link, mailbox, deadline, broadcast)
        self.ctx = simulation.Context.of(scenario, self.method, [np.random.SeedSequence(0)])
        self.setting = self.ctx.setting
        self.spec = Spec.of(scenario, isinstance(self.method, Centralized), self.method.plans)
        self.measured: gate.Measured | None = None
        self.seen: np.ndarray | None = None  # (1, 1, Nt) the step it last measured each
        tracker = self.ctx.const.tracker
        # (Nt, 4), (Nt, 4, 4) and the IMM's modes: the belief predicted to k
        self.mean, self.cov, self.modes = tracker.start(*prior)
        self.target = -1
        self.held = None
        if scenario.faults.loss > 0:
            self.held = Held(np.zeros((self.n, self.m)), np.full(self.n, -1, dtype=np.int64))
        check_method(self.method, scenario)
        self.central = isinstance(self.method, Centralized)
        self.beacons = avoidance.Heard.nothing(1, self.n)  # with planner.avoidance
        self.recent = response.START  # and the measured model: its last two actions
        if self.spec.recent:  # measured now, before the run's deadlines start
            response.measure(scenario)
        self.limits = beacons.Limits.of(scenario)  # what an honest beacon can do
        self.told: np.ndarray | None = None  # with fusion.trigger: the confidences last sent
        self.beacon: tuple[int, Inbox | None] | None = None  # (k, this cycle's beacons)
        self.kept_at = -1  # the last cycle whose beacons `beacons` holds

    # ------------------------------------------------------------ the cycle

    def cycle(self, k: int, sense: dict[str, np.ndarray], central: bool = True) -> Report:
        """One decision cycle from the world's message (its checked arrays); returns the
        report to send."""
        s = self.scenario
        believed = self.believed = sense["believed"]
        alive = sense["alive"]
        self.radio.begin(k, sense["links"], alive, central, sense.get("afford"))
        observed = sense["observed"]
        z = sense["z"]
        zc, R = simulation.convert(np.repeat(believed[None], len(z), axis=0), z, s)
        if self.setting.gate is not None:  # what the gate checks estimates against
            recent = gate.recent(self.seen, k, s.robust.gate_memory, (1, 1, self.m))
            self.measured = gate.Measured.of(observed[None, None], zc, R, recent)
            self.seen = gate.seen(self.seen, observed[None, None], k)
        tracker = self.ctx.const.tracker
        belief = tracker.update(self.mean, self.cov, self.modes, observed, zc, R)
        mean, cov = belief[:2]
        target = -1  # the central node's choice (centralized only)
        if self.central:
            fused_mean, fused_cov, rounds, sent, delivered, target = self.upload(
                k, mean, cov, believed
            )
        else:
            fused_mean, fused_cov, rounds, sent, delivered = self.consensus(k, mean, cov)
        if not self.method.plans:  # a learned policy: no bids, no auction, its target kept
            bids, target, solve_seconds = np.full(self.m, np.nan), self.target, np.zeros(2)
            action, more, plan_seconds = self.chosen(k, fused_mean, fused_cov, observed)
        else:
            top = None
            if not self.central:
                top = self.method.top(self.setting, np.array([[self.largest]]))
            plan_start = timing.start()
            bids, best = self.setting.plan(believed[None, None], fused_mean[None, None], top)
            bids, best = bids[0, 0], best[0, 0]
            plan_seconds = timing.since(plan_start)
            if self.central:
                target = target if target >= 0 else self.target
                target = target if target >= 0 else int(assignment.greedy(bids))
                solve_seconds, more = np.zeros(2), (0, 0)
            elif isinstance(self.method, Greedy):
                target, solve_seconds, more = int(assignment.greedy(bids)), np.zeros(2), (0, 0)
            else:
                target, solve_seconds, more = self.auction(k, bids, alive)
            action = int(best[target])
        if self.scenario.planner.avoidance != "none":  # its best scores break the ties
            scored = max(target, 0)  # a policy's UAV has none: the batch's first target
            values = simulation.first_values(believed[None], fused_mean[None, None, scored], s)
            values = values[0, 0]
            action, beaconed = self.avoided(k, action, values)
            more = (more[0] + beaconed[0], more[1] + beaconed[1])
        self.target = target
        cpu, wall = (1e3 * (plan_seconds + solve_seconds)).tolist()
        report = Report(
            version=VERSION,
            run=self.run,
            k=k,
            uav=self.me,
            action=action,
            target=target,
            mean=packed({"x": fused_mean})["x"],
            cov=packed({"x": fused_cov})["x"],
            bids=packed({"x": bids})["x"],
            rounds=int(rounds),
            sent=int(sent + more[0]),
            delivered=int(delivered + more[1]),
            decision_ms=cpu,
            decision_wall_ms=wall,
            late=dict(self.radio.late),
            radio_bytes=self.radio.bytes,
        )
        self.mean, self.cov, self.modes = tracker.close(*belief, fused_mean, fused_cov)
        return report

    # ------------------------------------------------------------ fusion

    def consensus(self, k: int, mean, cov):
        """The D_i protocol and the max-consensus rounds (Algorithm 2 lines 15-25), run
        together: round r carries this UAV's flooding set and consensus tuple after
        r - 1 rounds. Its consensus runs rounds = D_i (+ extra, up to the budget) rounds;
        round r of it is adopted only once round r of the flooding shows D_i >= r.

        Sends, as the two protocols apart would: flooding rounds 1 .. R (R the round it
        stopped in) and its final set from R + 1; consensus rounds 1 .. rounds and its
        final tuple from rounds + 1. When rounds = R - 1, the tuple of round R was already
        the final one: round R + 1 only marks it final."""
        s = self.setting
        state = fusion.Estimates(  # per target: confidence, estimate, stamp and whose it is
            gamma=estimation.confidence(cov),
            mean=mean,
            cov=cov,
            stamp=np.full(self.m, k, dtype=np.int64),
            origin=np.full(self.m, self.me, dtype=np.int64),
        )

        def adopt(state: fusion.Estimates, contents: dict[int, dict]) -> fusion.Estimates:
            offered = {
                q: fusion.Estimates.of(self._plausible(listed(t, self.m, k, q, s.codec)))
                for q, t in contents.items()
            }
            if s.stale:
                offered = {q: s.forward(t, k) for q, t in offered.items()}
            return self._adopt(state, offered)

        content = self._content(k, state)
        state, rounds, sent, delivered = self.rounds(k, state, content, adopt)
        mean, cov = fusion.required(state.mean, "mean"), fusion.required(state.cov, "cov")
        return mean, cov, rounds, sent, delivered

    def _content(self, k: int, state: fusion.Estimates):
        """content(state): what each consensus round sends of the tuples, all of them or,
        with ``fusion.trigger`` or the compact encoding, those `fusion.Sending` picks
        (as the batch's `methods.base.sending`), listed (`listing`); keeps `told`."""
        s = self.setting
        if s.trigger is None and not s.compact:
            return lambda t: dict(t.items())
        first = None
        if s.trigger is not None:
            gamma = fusion.required(state.gamma, "gamma")
            first = fusion.triggered(gamma, self.told, k, s.trigger, s.refresh)
        how = fusion.Sending(first=first, changes=True)
        told = np.full(self.m, np.nan) if self.told is None else self.told.copy()
        sent: list[fusion.Estimates] = []  # the tuples of each round so far

        if s.trigger is not None:
            self.told = told

        def content(t: fusion.Estimates) -> dict[str, np.ndarray]:
            r = len(sent) + 1
            mask = how.mask(r, t, sent[-1] if sent else None)
            sent.append(t)
            if self.radio.affords(k, self.me, "consensus", r):  # what the share sends
                told[mask] = fusion.required(t.gamma, "gamma")[mask]
            out = listing(t, mask, s.codec)
            if packs("consensus", s.tuples):  # its rows in one byte array
                out = pack_rows(out, self.spec.contents("consensus") or {})
            return out

        return content

    def rounds(self, k: int, state, content, adopt):
        """The D_i protocol with the consensus rounds of `consensus` over any state:
        content(state) is what a round sends, adopt(state, contents by sender) what a
        round's arrivals make of it. Returns (state, rounds, sent, delivered)."""
        s = self.setting
        known = np.zeros(self.n, dtype=bool)
        known[self.me] = True
        self.largest = 1
        stopped = rounds = None  # R, and the consensus rounds once D_i is known
        depth = r = 0
        arrived = []  # (sent, delivered) of each round's inbox
        flood_final = consensus_final = False
        while True:
            r += 1
            parts = []
            if stopped is None:
                parts.append(part("flood", r, {"known": known}))
            elif not flood_final:  # r = R + 1
                parts.append(part("flood", r, {"known": known}, final=r))
                flood_final = True
            if rounds is None or r <= rounds:
                parts.append(part("consensus", r, content(state)))
            elif not consensus_final:
                if rounds + 1 < r:  # rounds = R - 1: the tuple of round R was the final one
                    parts.append(part("consensus", r, None, final=rounds + 1))
                else:
                    parts.append(part("consensus", r, content(state), final=r))
                consensus_final = True
            if parts:
                self.radio.send(k, parts)
            if flood_final and consensus_final:
                break
            if stopped is None:
                inbox = self.radio.receive(k, "flood", r)
                known, depth, stopped = self._flood(inbox, known, r)
                if inbox is not None:
                    arrived.append((inbox.sent, inbox.delivered))
                if stopped is not None:
                    rounds = depth + s.extra_rounds
                    rounds = rounds if s.budget is None else min(rounds, s.budget)
            if rounds is None or r <= rounds:
                inbox = self.radio.receive(k, "consensus", r)
                if inbox is not None:
                    arrived.append((inbox.sent, inbox.delivered))
                    state = adopt(state, inbox.contents)
        # the loop ends once D_i is known (it stopped) and the consensus rounds are done
        assert stopped is not None and rounds is not None
        sent, delivered = counted(
            s.delay,
            lambda: (
                self.radio.transmitted(k, "flood", stopped),
                self.radio.transmitted(k, "consensus", rounds),
            ),
            arrived,
        )
        return state, rounds, sent, delivered

    def _flood(self, inbox: Inbox | None, known: np.ndarray, r: int):
        """Round r of the D_i protocol (`fusion.learn_depth`) from this UAV's side: its
        set after the round, D_i, and r if it stopped in this round (else None). Sets
        `self.largest`, the most members of a closed neighbourhood it belongs to."""
        if inbox is None:  # nothing in flight yet: nothing to learn
            return known, r - 1, r
        if r == 2:  # the sets sent now are the senders' closed neighbourhoods
            sizes = [int(c["known"].sum()) for c in inbox.contents.values()]
            self.largest = max([int(known.sum()), *sizes])
        ids = sorted({self.me, *inbox.contents})
        offered = np.stack([known if q == self.me else inbox.contents[q]["known"] for q in ids])
        where, links = closed(ids, self.me)
        grown = fusion.flood(offered[None], offered[None], links)[0, where]
        if not (grown != known).any():
            return known, r - 1, r
        budget = self.setting.budget
        if budget is not None and r >= budget:
            return grown, budget, r
        return grown, r, None

    def _adopt(
        self, state: fusion.Estimates, offered: dict[int, fusion.Estimates]
    ) -> fusion.Estimates:
        """eq. (27) for this UAV: `fusion.adopt` over its closed neighbourhood in index
        order (itself with its current tuple), then `fusion.pick`; or, with
        ``fusion.rule`` = covariance_intersection, `fusion.intersect_round` over it.
        With ``robust.gate`` only what agrees with its measurements (`gate.admitted`)."""
        ids = sorted({self.me, *offered})
        where = ids.index(self.me)

        def stacked(name: str, mine: np.ndarray) -> np.ndarray:  # (1, members, M, ...)
            rows = [mine if q == self.me else getattr(offered[q], name) for q in ids]
            return np.stack(rows)[None]

        candidates = fusion.Estimates(**{name: stacked(name, v) for name, v in state.items()})
        where, links = closed(ids, self.me)
        admitted = None
        if self.setting.gate is not None:  # every row measured as this UAV (its row is kept)
            mine, rows = self.measured, (1, len(ids))
            assert mine is not None  # the sensing step measured, as the gate is on
            measured = gate.Measured(
                *(
                    np.broadcast_to(x, rows + x.shape[2:])
                    for x in (mine.observed, mine.z, mine.R, mine.recent)
                )
            )
            estimates = (
                fusion.required(candidates.mean, "mean"),
                fusion.required(candidates.cov, "cov"),
            )
            claimed = None
            if self.setting.trigger is not None or self.setting.compact:  # listed targets
                claimed = np.isfinite(fusion.required(candidates.gamma, "gamma"))
            admitted = gate.admitted(
                links, estimates, estimates, measured, self.setting.gate, claimed
            )
        picked = fusion.combine(self.setting.rule, candidates, candidates, links, admitted)
        return picked.map(lambda value: value[0, where])

    def _plausible(self, content: dict) -> dict:
        return plausible(self.spec, self.mailbox, content)

    # ------------------------------------------------------------ assignment

    def auction(self, k: int, bids: np.ndarray, alive: np.ndarray):
        """Beacon and bids to the neighbours (one message), then this UAV's auction
        (`assignment.local`)."""
        s, n = self.setting, self.n
        stamp = np.array(k, dtype=np.int64)
        beacon, inbox, (sent, delivered) = self.heard(k, {"bids": bids, "stamp": stamp})
        if inbox is None:  # nothing has arrived yet: alone
            members, view = np.zeros(n, dtype=bool), np.broadcast_to(bids, (n, self.m)).copy()
            target, seconds = self.solve(view, members, alive, bids)
            return target, seconds, (sent, delivered)
        else:
            got = np.zeros(n, dtype=bool)
            offered = np.zeros((n, self.m))
            stamps = np.zeros(n, dtype=np.int64)
            for q, content in inbox.contents.items():
                got[q], offered[q], stamps[q] = True, content["bids"], content["stamp"]
            heard = got
            if beacon is not None:
                heard = np.zeros(n, dtype=bool)
                heard[list(beacon.contents)] = True
            members, view, stamp = bid_view(got, offered, stamps, heard, self.held, s.stale)
            if self.held is not None:
                self.held = Held(view, stamp)
            view = view.copy()
        target, seconds = self.solve(view, members, alive, bids)
        return target, seconds, (sent, delivered)

    def heard(self, k: int, bids_part: dict):
        """Beacon and bids (the parts given) to the neighbours in one message; returns
        what arrived of both and the messages (sent, delivered)."""
        s = self.setting
        self.radio.send(k, [part("beacon", 0, self.beacon_content()), part("bids", 0, bids_part)])
        beacon, inbox = self.radio.receive(k, "beacon", 0), self.radio.receive(k, "bids", 0)
        self.beacon = (k, beacon)
        sent, delivered = counted(
            s.delay,
            lambda: (self.radio.transmitted(k, p, 1, first=0) for p in ("beacon", "bids")),
            ((a.sent, a.delivered) for a in (beacon, inbox) if a is not None),
        )
        return beacon, inbox, (sent, delivered)

    def chosen(self, k: int, mean: np.ndarray, cov: np.ndarray, observed: np.ndarray):
        """A learned policy's action (`env.policy`, as `simulation.chosen` for the
        batch): this UAV's beacon of its whole state to the UAVs in range, then the
        policy's reading of its own state, its fused estimates (mean (M, 4), cov
        (M, 4, 4)), the targets it measured and the beacons it heard (those no honest
        UAV sends are dropped, counted). Returns (action, messages (sent, delivered),
        seconds of inference (2,))."""
        from ..env.spaces import View  # the env extra, which a policy needs

        n, m, me = self.n, self.m, self.me
        self.radio.send(k, [part("beacon", 0, self.beacon_content())])
        beacon = self.radio.receive(k, "beacon", 0)
        self.beacon = (k, beacon)
        counts = counted(
            self.setting.delay,
            lambda: [self.radio.transmitted(k, "beacon", 1, first=0)],
            [(beacon.sent, beacon.delivered)] if beacon is not None else [],
        )
        links, heard = self.keep(k, beacon)
        believed, alive = np.zeros((1, n, 5)), np.zeros((1, n), dtype=bool)
        believed[0, me], alive[0, me] = self.believed, True
        means, covs = np.zeros((1, n, m, 4)), np.broadcast_to(np.eye(4), (1, n, m, 4, 4)).copy()
        means[0, me], covs[0, me] = mean, cov
        seen = np.zeros((1, n, m), dtype=bool)
        seen[0, me] = observed
        view = View(
            k=k, believed=believed, uavs=believed, mean=means, cov=covs, links=links,
            alive=alive, observed=seen, heard=heard, detected=seen,
        )  # fmt: skip
        start = timing.start()
        action = int(self.method.choose(view, self.scenario)[0, me])
        return action, (int(counts[0]), int(counts[1])), timing.since(start)

    def beacon_content(self) -> dict[str, np.ndarray]:
        """Who, where, when (`messages.Spec`): the position, or the whole state (with
        avoidance, or for a policy's observation)."""
        if self.spec.recent:
            return {"uav": self.believed, "recent": np.array(self.recent, dtype=np.uint8)}
        if self.spec.avoid:
            return {"uav": self.believed}
        return {"position": self.believed[:3]}

    def avoided(
        self, k: int, action: int, values: np.ndarray | None
    ) -> tuple[int, tuple[int, int]]:
        """``planner.avoidance``: the action `avoidance.choose` lets this UAV fly, from
        the beacons it heard, as `simulation.avoid` filters the batch's (values (3,):
        each first action's best score for its target, or None). A cycle that sent no
        beacon (centralized, greedy) sends one now, counted as there. Returns (action,
        messages (sent, delivered))."""
        s, n, me = self.scenario, self.n, self.me
        counts = (0, 0)
        if self.beacon is not None and self.beacon[0] == k:
            beacon = self.beacon[1]
        else:
            self.radio.send(k, [part("beacon", 0, self.beacon_content())])
            beacon = self.radio.receive(k, "beacon", 0)
            counts = counted(
                self.setting.delay,
                lambda: [self.radio.transmitted(k, "beacon", 1, first=0)],
                [(beacon.sent, beacon.delivered)] if beacon is not None else [],
            )
        if self.kept_at != k:  # a policy's cycle kept them already
            self.keep(k, beacon)
        desired = np.full((1, n), simulation.STRAIGHT)
        believed, alive = np.zeros((1, n, 5)), np.zeros((1, n), dtype=bool)
        desired[0, me], believed[0, me], alive[0, me] = action, self.believed, True
        scores = None
        if values is not None:
            scores = np.zeros((1, n, 3))
            scores[0, me] = values
        own = np.full((1, n), self.recent) if self.spec.recent else None
        chosen = avoidance.choose_in(s, desired, believed, alive, self.beacons, k, scores, own)
        action = int(chosen[0, me])
        if self.spec.recent:
            self.recent = int(response.recent(np.asarray(self.recent), np.asarray(action)))
        return action, (int(counts[0]), int(counts[1]))

    def keep(self, k: int, beacon: Inbox | None) -> tuple[np.ndarray, np.ndarray]:
        """Keep this cycle's beacons in `beacons` (`avoidance.Heard`), but those no
        honest UAV sends (dropped, counted). Returns who was heard now, got (1, N, N)
        [receiver, sender], and their states (1, N, 5) as sent."""
        n, me = self.n, self.me
        got = np.zeros((1, n, n), dtype=bool)
        states, stamps = np.zeros((1, n, 5)), np.full((1, n), -1)
        recent = np.full((1, n), response.START) if self.spec.recent else None
        sent = k - self.setting.delay
        for q, content in ({} if beacon is None else beacon.contents).items():
            reason = self._believable(q, content["uav"], sent)
            if reason is not None:  # not heard: no honest UAV sends it
                dropped(self.mailbox, {reason: 1})
                continue
            got[0, me, q], states[0, q], stamps[0, q] = True, content["uav"], sent
            if recent is not None:
                recent[0, q] = content["recent"]
        memory = avoidance.memory_of(self.setting.delay, self.scenario.faults.loss)
        self.beacons = self.beacons.update(got, states, stamps, k, memory, recent)
        self.kept_at = k
        return got, states

    def _believable(self, q: int, state: np.ndarray, sent: int) -> str | None:
        """Why q's beacon sent at step `sent` is one no honest UAV sends, against the last
        this UAV kept of q (`airspace.beacons.believable`), or None."""
        when = int(self.beacons.stamp[0, self.me, q])
        before = (self.beacons.state[0, self.me, q], when) if when >= 0 else None
        return beacons.believable(self.limits, q, state, sent, before, self.believed)

    def solve(self, view: np.ndarray, members: np.ndarray, alive: np.ndarray, bids: np.ndarray):
        """This UAV's auction (`assignment.local`) over the bids it holds, view (N, M)
        (its own row replaced by `bids`), among the living members that can serve it.
        Returns (target, seconds (2,))."""
        me = self.me
        view[me] = bids
        members = members & alive
        members[me] = True
        able = assignment.able(view, members, me)
        if (members & ~able).any():  # a neighbour's bids cannot serve this auction
            dropped(self.mailbox, {"bids not scored": int((members & ~able).sum())})
            members = able
        rows = np.flatnonzero(members)
        start = timing.start()
        if rows.size == 1:
            target = int(assignment.greedy(bids))
        else:
            method = self.method  # neither central nor greedy (`cycle`): a Distributed
            assert isinstance(method, Distributed), "the auction is Distributed's"
            solve = None if method.built_in_solve else method.solve
            target = assignment.local(view[rows], int(np.searchsorted(rows, me)), solve, timing)
        return target, timing.since(start)

    # ------------------------------------------------------------ centralized

    def upload(self, k: int, mean, cov, believed):
        """The centralized baseline from a UAV's side: upload its tables, take the
        download of `delay` cycles ago (`methods.take_download`). Returns the fused
        estimates, rounds, messages sent and delivered, and the target sent (-1: none).
        Without the central node (lost), the UAV keeps its own estimates and its last
        target."""
        s, m, one = self.setting, self.m, int(self.n > 1)
        tuples = {
            "gamma": estimation.confidence(cov),
            "mean": mean,
            "cov": cov,
            "stamp": np.full(m, k, dtype=np.int64),
            "uav": believed,
        }
        if self.radio.central[k]:
            self.radio.send(k, [part("upload", 0, tuples)], to=self.n)
        download = self._download(k)
        # as `radio.counted`: this UAV counts the download offered to it and whether it
        # came, or with delay its upload when sent (the central node the uploads, or its
        # downloads); fault-free a UAV alone exchanges nothing, as in `methods.Centralized`
        offered = []
        if download is not None:
            then = k - self.radio.delay
            mine = int(self.radio.alive[then][self.me]) if s.faulty else one
            mine *= int(self.radio.affords(then, self.me, "download"))  # sent to it at all
            offered.append((mine, mine * int(download[1][0, 0])))
        sent, delivered = counted(
            s.delay, lambda: [self.radio.transmitted(k, "upload", 1, 0, to=self.n)], offered
        )
        if download is None:  # nothing sent yet
            return mean, cov, 1, sent, delivered, -1
        down, arrived, target = download
        mean, cov = (
            x[0, 0]
            for x in take_download(
                mean[None, None], cov[None, None], down, arrived, s, k, self.measured
            )
        )
        if not s.faulty:  # the download arrived, or was late (counted in `_download`)
            return mean, cov, one, sent, delivered, target
        return mean, cov, 1, sent, delivered, target if arrived[0, 0] else -1

    def _download(self, k: int) -> tuple[fusion.Estimates, np.ndarray, int] | None:
        """The central node's download sent `delay` cycles ago: this UAV's tuples (1, 1,
        M, ...), whether it arrived (1, 1), and the target it names; None before any was
        sent."""
        sent_at = k - self.radio.delay
        if sent_at < 0:
            return None
        mailbox, central = self.mailbox, self.n
        lost = bool(self.radio.lost(sent_at, "download", 0, np.array(central), self.me))
        expect = bool(self.radio.alive[sent_at][self.me]) and not lost
        expect = expect and self.radio.central[sent_at]
        expect = expect and self.radio.affords(sent_at, self.me, "download")
        if expect:  # two rounds: the node waits up to a round's deadline for the uploads
            mailbox.wait(  # before it sends the downloads
                lambda: (
                    mailbox.content(sent_at, "download", central, 0) is not None
                    or mailbox.is_gone(central)
                ),
                time.monotonic() + 2 * self.radio.deadline,
            )
        content = mailbox.content(sent_at, "download", central, 0) if expect else None
        if expect and content is None:  # late, or the node's token went: it never came
            self.radio.missed("download", 1)
        if content is None:
            return nothing_heard(1, 1, self.m), np.zeros((1, 1), dtype=bool), -1
        content = self._plausible(content)
        down = fusion.Estimates.of(content).map(lambda value: value[None, None])
        return down, np.ones((1, 1), dtype=bool), int(content["target"])


class CentralAgent:
    """The central node of the centralized baseline: uploads in, downloads out."""

    def __init__(
        self, scenario: Scenario, faults: Faults, link: Link, mailbox: Mailbox, deadline: float
    ) -> None:
        self.scenario, self.n, self.m = scenario, scenario.n_uavs, scenario.n_targets
        self.link, self.mailbox, self.run = link, mailbox, link.run
        broadcast = scenario.radio.frames == "broadcast"
        self.radio = AgentRadio(self.n, self.n, faults, link, mailbox, deadline, broadcast)
        self.ctx = simulation.Context.of(scenario, get("centralized"), [np.random.SeedSequence(0)])
        self.setting = self.ctx.setting
        self.spec = Spec.of(scenario, True)

    def cycle(self, k: int, tick: dict[str, np.ndarray], central: bool = True) -> Report:
        """One cycle: fuse and assign the uploads of `delay` cycles ago, send downloads."""
        s, n, m = self.setting, self.n, self.m
        alive = tick["alive"]
        self.radio.begin(k, np.zeros(n, dtype=bool), alive, afford=tick.get("afford"))
        start = timing.start()
        down, targets = nothing_heard(1, n, m), np.full((1, n), -1, dtype=np.int64)
        uploads, offered = self.uploads(k)
        if uploads is not None:
            heard = np.zeros((1, n), dtype=bool)
            got = {
                "gamma": np.zeros((1, n, m)),
                "mean": np.zeros((1, n, m, 4)),
                "cov": np.zeros((1, n, m, 4, 4)),
                "stamp": np.zeros((1, n, m), dtype=np.int64),
            }
            reported = np.zeros((1, n, 5))
            for q, content in uploads.items():
                content = plausible(self.spec, self.mailbox, content)
                heard[0, q] = True
                for name in got:
                    got[name][0, q] = content[name]
                reported[0, q] = content["uav"]
            down, targets = central_node(fusion.Estimates(**got), heard, reported, s, k, timing)
        contents = {}
        for i in np.flatnonzero(alive):  # each living UAV its download
            contents[int(i)] = dict(down.map(lambda value, i=i: value[0, i]).items())
            contents[int(i)]["target"] = np.array(targets[0, i], dtype=np.int64)
        return self.downloads(k, alive, contents, offered, start)

    def uploads(self, k: int) -> tuple[dict[int, dict] | None, list]:
        """The uploads of `delay` cycles ago that came, by sender (None before any was
        sent), and the uploads offered to the node and those that came (`radio.counted`)."""
        s, n = self.setting, self.n
        sent_at = k - self.radio.delay
        if sent_at < 0:
            return None, []
        alive_then = self.radio.alive[sent_at]
        uavs = np.flatnonzero(alive_then)
        lost = self.radio.lost(sent_at, "upload", 0, uavs, np.array(n))
        expected = [int(q) for q in uavs[~lost] if self.radio.affords(sent_at, int(q), "upload")]
        mailbox = self.mailbox
        mailbox.wait(
            lambda: all(mailbox.content(sent_at, "upload", q, 0) is not None for q in expected),
            time.monotonic() + self.radio.deadline,
        )
        uploads = {}
        for q in expected:
            content = mailbox.content(sent_at, "upload", q, 0)
            if content is None:
                self.radio.missed("upload", 1)
                continue
            uploads[q] = content
        if s.faulty:
            sent = [q for q in uavs if self.radio.affords(sent_at, int(q), "upload")]
            offered = [(len(sent), len(uploads))]
        else:  # every upload arrives, but one that was late; a UAV alone sends none
            one = int(n > 1)
            offered = [(n * one, len(uploads) * one)]
        return uploads, offered

    def downloads(self, k: int, alive, contents: dict[int, dict], offered, start) -> Report:
        """Each living UAV its download (contents by UAV); the node's report of the cycle
        (its CPU time since `start`: its work, not its waits)."""
        s, n = self.setting, self.n
        sent, delivered = counted(  # with delay: the downloads, when sent
            s.delay,
            lambda: [
                self.radio.transmitted(k, "download", 1, 0, to=int(i))
                for i in np.flatnonzero(alive)
            ],
            offered,
        )
        for i, content in contents.items():
            self.radio.send(k, [part("download", 0, content)], to=i)
        cpu, wall = (1e3 * timing.since(start)).tolist()
        empty = packed({"x": np.zeros(0)})["x"]
        return Report(
            version=VERSION, run=self.run, k=k, uav=n, action=-1, target=-1,
            mean=empty, cov=empty, bids=empty, rounds=0, sent=sent, delivered=delivered,
            decision_ms=cpu, decision_wall_ms=wall, late=dict(self.radio.late),
            radio_bytes=self.radio.bytes,
        )  # fmt: skip
