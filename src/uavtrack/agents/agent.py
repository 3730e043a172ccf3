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

Every wait has a deadline: what has not arrived by then counts as lost, so a crashed
or frozen neighbour costs a round's deadline, never the run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .. import assignment, estimation, fusion, network, simulation
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
from .messages import VERSION, Radio, Report, Sense, Tick, arrays, encode, packed
from .transport import Mailbox, Transport


def keys(run: str) -> dict[str, str]:
    """The key layout of a run."""
    root = f"uavtrack/{run}/"
    return {
        "root": root,
        "hello": root + "hello",
        "sense": root + "sense/",
        "tick": root + "tick",
        "report": root + "report/",
        "radio": root + "radio/",
        "alive": root + "alive/",
    }


@dataclass
class Inbox:
    """One round's arrivals at one receiver: contents by sender (delivered, in sender
    order), and how many messages were sent to it and delivered (the simulator's count)."""

    contents: dict[int, dict[str, np.ndarray]]
    sent: int
    delivered: int


class AgentRadio:
    """A program's side of the radio: it broadcasts, and keeps of what arrives what the
    emulated radio delivers: round r of cycle k - delay, from a sender it could hear at
    that cycle, unless the fault realisation (`faults.Faults`, a pure function of the
    message) loses it. The same rule as `radio.Radio`, seen by one receiver."""

    def __init__(
        self,
        me: int,
        n: int,
        faults: Faults,
        transport: Transport,
        mailbox: Mailbox,
        run: str,
        deadline: float,
    ) -> None:
        self.me, self.n, self.faults = me, n, faults
        self.transport, self.mailbox, self.run = transport, mailbox, run
        self.deadline, self.delay = deadline, faults.model.delay
        self.links: dict[int, np.ndarray] = {}  # cycle -> (N,) senders heard
        self.alive: dict[int, np.ndarray] = {}  # cycle -> (N,) alive
        self.bad: dict[int, np.ndarray | None] = {}  # cycle -> (N+1, N+1) link states
        self.key = keys(run)["radio"]
        self.missing = 0  # expected messages that never came (a crashed sender)

    def begin(self, k: int, links: np.ndarray, alive: np.ndarray) -> None:
        self.links[k], self.alive[k] = links, alive
        previous = self.bad.get(k - 1)
        states = self.faults.link_states(k, None if previous is None else previous[None])
        self.bad[k] = None if states is None else states[0]
        for old in [c for c in self.links if c < k - self.delay - 1]:
            self.links.pop(old)
            self.alive.pop(old)
            self.bad.pop(old)
        self.mailbox.forget(k - self.delay - 1)

    def send(self, k: int, protocol: str, round_: int, content: dict, final: bool = False) -> None:
        message = Radio(VERSION, self.run, k, protocol, round_, self.me, final, packed(content))
        self.transport.publish(f"{self.key}{self.me}", encode(message))

    def lost(self, k: int, protocol: str, round_: int, sender: np.ndarray, receiver) -> np.ndarray:
        bad = self.bad.get(k)
        return self.faults.lost(
            k, protocol, round_, 0, sender, receiver, None if bad is None else bad[None]
        )

    def receive(self, k: int, protocol: str, round_: int) -> Inbox | None:
        """What arrives now of `protocol`'s round, or None when nothing was sent yet."""
        sent_at = k - self.delay
        if sent_at < 0 or sent_at not in self.links:
            return None
        senders = np.flatnonzero(self.links[sent_at])
        senders = senders[senders != self.me]
        lost = self.lost(sent_at, protocol, round_, senders, self.me)
        expected = [int(q) for q in senders[~lost]]
        deadline = time.monotonic() + self.deadline
        mailbox = self.mailbox
        mailbox.wait(
            lambda: all(
                mailbox.content(sent_at, protocol, q, round_) is not None for q in expected
            ),
            deadline,
        )
        contents = {}
        for q in expected:
            raw = mailbox.content(sent_at, protocol, q, round_)
            value = None if raw is None else arrays(raw)
            if value is None:
                self.missing += 1
                continue
            contents[q] = value
        return Inbox(contents, len(senders), len(contents))


class UavAgent:
    """One UAV's program (see the module docstring)."""

    def __init__(
        self,
        me: int,
        scenario: Scenario,
        method: str | Method,
        faults: Faults,
        transport: Transport,
        mailbox: Mailbox,
        run: str,
        deadline: float,
        prior: tuple[np.ndarray, np.ndarray],
    ) -> None:
        self.me, self.scenario, self.method = me, scenario, get(method)
        self.n, self.m = scenario.n_uavs, scenario.n_targets
        self.transport, self.mailbox, self.run = transport, mailbox, run
        self.radio = AgentRadio(me, self.n, faults, transport, mailbox, run, deadline)
        self.ctx = simulation.Context.of(scenario, self.method, [np.random.SeedSequence(0)])
        self.setting = self.ctx.setting
        self.mean, self.cov = prior  # (Nt, 4), (Nt, 4, 4): the belief predicted to k
        self.target = -1
        self.held = None
        if scenario.faults.loss > 0:
            self.held = Held(np.zeros((self.n, self.m)), np.full(self.n, -1, dtype=np.int64))
        if not isinstance(self.method, Distributed | Greedy | Centralized):
            raise ValueError(
                f"method {self.method.name!r}: the agent form runs methods built on "
                "Distributed, Greedy or Centralized"
            )
        self.central = isinstance(self.method, Centralized)
        self.keys = keys(run)

    # ------------------------------------------------------------ the cycle

    def cycle(self, sense: Sense) -> Report:
        """One decision cycle from the world's message; returns the report to send."""
        k, s = sense.k, self.scenario
        believed = self.believed = sense.believed.array()
        alive = sense.alive.array().astype(bool)
        self.radio.begin(k, sense.links.array().astype(bool), alive)
        observed = sense.observed.array().astype(bool)
        z = sense.z.array().reshape(-1, 2)
        zc, R = simulation.convert(np.repeat(believed[None], len(z), axis=0), z, s)
        mean, cov = estimation.filter_step(
            self.mean[None], self.cov[None], observed[None], zc, R, None, None
        )
        mean, cov = mean[0], cov[0]
        if self.central:
            fused_mean, fused_cov, rounds, sent, delivered, target = self.upload(
                k, mean, cov, believed
            )
        else:
            fused_mean, fused_cov, rounds, sent, delivered = self.consensus(k, mean, cov, alive)
        top = None if self.central else self.method.top(self.setting, np.array([[self.largest]]))
        plan_start = time.perf_counter()
        bids, best = self.setting.plan(believed[None, None], fused_mean[None, None], top)
        bids, best = bids[0, 0], best[0, 0]
        plan_seconds = time.perf_counter() - plan_start
        if self.central:
            target = target if target >= 0 else self.target
            target = target if target >= 0 else int(assignment.greedy(bids))
            solve_seconds, more = 0.0, (0, 0)
        elif isinstance(self.method, Greedy):
            target, solve_seconds, more = int(assignment.greedy(bids)), 0.0, (0, 0)
        else:
            target, solve_seconds, more = self.auction(k, bids, alive)
        action = int(best[target])
        self.target = target
        report = Report(
            VERSION,
            self.run,
            k,
            self.me,
            action,
            target,
            packed({"x": fused_mean})["x"],
            packed({"x": fused_cov})["x"],
            packed({"x": bids})["x"],
            int(rounds),
            int(sent + more[0]),
            int(delivered + more[1]),
            1e3 * (plan_seconds + solve_seconds),
        )
        self.mean, self.cov = estimation.predict(
            fused_mean, fused_cov, self.ctx.const.A, self.ctx.const.Q
        )
        return report

    # ------------------------------------------------------------ fusion

    def consensus(self, k: int, mean, cov, alive):
        """The D_i protocol and the max-consensus rounds (Algorithm 2 lines 15-25)."""
        s = self.setting
        depth, sent, delivered = self.learn_depth(k)
        rounds = depth + s.extra_rounds
        if s.budget is not None:
            rounds = min(rounds, s.budget)
        state = {  # per target: confidence, estimate, its time stamp and whose it is
            "gamma": estimation.confidence(cov),
            "mean": mean,
            "cov": cov,
            "stamp": np.full(self.m, k, dtype=np.int64),
            "origin": np.full(self.m, self.me, dtype=np.int64),
        }
        for r in range(1, rounds + 1):
            self.radio.send(k, "consensus", r, state)
            inbox = self.radio.receive(k, "consensus", r)
            if inbox is None:
                continue
            sent += inbox.sent
            delivered += inbox.delivered
            offered = inbox.contents
            if s.stale:
                offered = {q: s.forward(t, k) for q, t in offered.items()}
            if any(set(t) != set(state) for t in offered.values()):
                offered = {q: t for q, t in offered.items() if set(t) == set(state)}
            state = self._adopt(state, offered)
        self.radio.send(k, "consensus", rounds + 1, state, final=True)
        return state["mean"], state["cov"], rounds, sent, delivered

    def _adopt(self, state: dict, offered: dict[int, dict]) -> dict:
        """eq. (27) for this UAV: `fusion.adopt` over its closed neighbourhood in index
        order (itself with its current tuple), then `fusion.pick`."""
        ids = sorted({self.me, *offered})
        where = ids.index(self.me)
        candidates = {
            name: np.stack([state[name] if q == self.me else offered[q][name] for q in ids])[None]
            for name in state
        }
        dense = np.eye(len(ids), dtype=bool)[None]
        dense[0, where, :] = True
        links = network.Links(1, len(ids), dense)
        gamma = candidates["gamma"]
        best = fusion.adopt(gamma, gamma, links)
        picked = fusion.pick(candidates, candidates, best)
        return {name: value[0, where] for name, value in picked.items()}

    def learn_depth(self, k: int) -> tuple[int, int, int]:
        """The D_i protocol (`fusion.learn_depth`) from this UAV's side; sets
        `self.largest`, the most members of a closed neighbourhood it belongs to."""
        known = np.zeros(self.n, dtype=bool)
        known[self.me] = True
        depth, sent, delivered, r = 0, 0, 0, 0
        self.largest = 1
        budget = self.setting.budget
        while True:
            r += 1
            self.radio.send(k, "flood", r, {"known": known})
            inbox = self.radio.receive(k, "flood", r)
            if inbox is None:
                depth = r - 1
                break
            sent += inbox.sent
            delivered += inbox.delivered
            if r == 2:  # the sets sent now are the senders' closed neighbourhoods
                sizes = [int(c["known"].sum()) for c in inbox.contents.values()]
                self.largest = max([int(known.sum()), *sizes])
            ids = sorted({self.me, *inbox.contents})
            offered = np.stack(
                [known if q == self.me else inbox.contents[q]["known"] for q in ids]
            )[None]
            dense = np.eye(len(ids), dtype=bool)[None]
            dense[0, ids.index(self.me), :] = True
            grown = fusion.flood(offered, offered, network.Links(1, len(ids), dense))
            grown = grown[0, ids.index(self.me)]
            if not (grown != known).any():
                depth = r - 1
                break
            known = grown
            if budget is not None and r >= budget:
                depth = budget
                break
        self.radio.send(k, "flood", r + 1, {"known": known}, final=True)
        return depth, sent, delivered

    # ------------------------------------------------------------ assignment

    def auction(self, k: int, bids: np.ndarray, alive: np.ndarray):
        """Beacons and bids to the neighbours, then this UAV's auction (`assignment.local`)."""
        s, me, n = self.setting, self.me, self.n
        self.radio.send(k, "beacon", 0, {"position": self.believed[:3]})  # who, where, when
        self.radio.send(k, "bids", 0, {"bids": bids, "stamp": np.array(k)})
        beacon, inbox = self.radio.receive(k, "beacon", 0), self.radio.receive(k, "bids", 0)
        sent = sum(a.sent for a in (beacon, inbox) if a is not None)
        delivered = sum(a.delivered for a in (beacon, inbox) if a is not None)
        if inbox is None:  # nothing has arrived yet: alone
            members, view = np.zeros(n, dtype=bool), np.broadcast_to(bids, (n, self.m)).copy()
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
        view[me] = bids
        members = members & alive
        members[me] = True
        rows = np.flatnonzero(members)
        start = time.perf_counter()
        if rows.size == 1:
            target = int(assignment.greedy(bids))
        else:
            target = assignment.local(view[rows], int(np.searchsorted(rows, me)), self.method.solve)
        return target, time.perf_counter() - start, (sent, delivered)

    # ------------------------------------------------------------ centralized

    def upload(self, k: int, mean, cov, believed):
        """The centralized baseline from a UAV's side: upload its tables, take the
        download of `delay` cycles ago (`methods.take_download`). Returns the fused
        estimates, rounds, messages sent and delivered, and the target sent (-1: none)."""
        s, m = self.setting, self.m
        tuples = {
            "gamma": estimation.confidence(cov),
            "mean": mean,
            "cov": cov,
            "stamp": np.full(m, k, dtype=np.int64),
            "uav": believed,
        }
        self.radio.send(k, "upload", 0, tuples)
        down, arrived, target = self._download(k)
        if down is None:  # nothing sent yet
            return mean, cov, 1, 0, 0, -1
        mean, cov = (
            x[0, 0] for x in take_download(mean[None, None], cov[None, None], down, arrived, s, k)
        )
        if not s.faulty:
            one = int(self.n > 1)
            return mean, cov, one, one, one, target
        sent = int(self.radio.alive[k - self.radio.delay][self.me])
        return mean, cov, 1, sent, int(arrived[0, 0]), target if arrived[0, 0] else -1

    def _download(self, k: int):
        """The central node's download sent `delay` cycles ago: this UAV's tuples (1, 1,
        M, ...), whether it arrived (1, 1), and the target it names; (None, None, -1)
        before any was sent."""
        sent_at = k - self.radio.delay
        if sent_at < 0:
            return None, None, -1
        mailbox, central = self.mailbox, self.n
        lost = bool(self.radio.lost(sent_at, "download", 0, np.array(central), self.me))
        expect = bool(self.radio.alive[sent_at][self.me]) and not lost
        if expect:
            mailbox.wait(
                lambda: mailbox.content(sent_at, "download", central, 0) is not None,
                time.monotonic() + self.radio.deadline,
            )
        raw = mailbox.content(sent_at, "download", central, 0) if expect else None
        content = None if raw is None else arrays(raw)
        if content is None:
            return nothing_heard(1, 1, self.m), np.zeros((1, 1), dtype=bool), -1
        down = {name: content[name][None, None] for name in ("gamma", "mean", "cov", "stamp")}
        return down, np.ones((1, 1), dtype=bool), int(content["target"][self.me])


class CentralAgent:
    """The central node of the centralized baseline: uploads in, downloads out."""

    def __init__(
        self,
        scenario: Scenario,
        faults: Faults,
        transport: Transport,
        mailbox: Mailbox,
        run: str,
        deadline: float,
    ) -> None:
        self.scenario, self.n, self.m = scenario, scenario.n_uavs, scenario.n_targets
        self.transport, self.mailbox, self.run = transport, mailbox, run
        self.radio = AgentRadio(self.n, self.n, faults, transport, mailbox, run, deadline)
        self.ctx = simulation.Context.of(scenario, get("centralized"), [np.random.SeedSequence(0)])
        self.setting = self.ctx.setting

    def cycle(self, tick: Tick) -> Report:
        """One cycle: fuse and assign the uploads of `delay` cycles ago, send downloads."""
        k, s, n, m = tick.k, self.setting, self.n, self.m
        alive = tick.alive.array().astype(bool)
        self.radio.begin(k, np.zeros(n, dtype=bool), alive)
        sent = delivered = 0
        start = time.perf_counter()
        sent_at = k - self.radio.delay
        down, targets = nothing_heard(1, n, m), np.full((1, n), -1, dtype=np.int64)
        if sent_at >= 0:
            alive_then = self.radio.alive[sent_at]
            uavs = np.flatnonzero(alive_then)
            lost = self.radio.lost(sent_at, "upload", 0, uavs, np.array(n))
            expected = [int(q) for q in uavs[~lost]]
            mailbox = self.mailbox
            mailbox.wait(
                lambda: all(mailbox.content(sent_at, "upload", q, 0) is not None for q in expected),
                time.monotonic() + self.radio.deadline,
            )
            heard = np.zeros((1, n), dtype=bool)
            got = {
                "gamma": np.zeros((1, n, m)),
                "mean": np.zeros((1, n, m, 4)),
                "cov": np.zeros((1, n, m, 4, 4)),
                "stamp": np.zeros((1, n, m), dtype=np.int64),
            }
            reported = np.zeros((1, n, 5))
            for q in expected:
                raw = mailbox.content(sent_at, "upload", q, 0)
                content = None if raw is None else arrays(raw)
                if content is None:
                    continue
                heard[0, q] = True
                for name in got:
                    got[name][0, q] = content[name]
                reported[0, q] = content["uav"]
            if s.faulty:
                sent, delivered = int(alive_then.sum()), int(heard.sum())
            else:
                sent = delivered = n if n > 1 else 0
            down, targets = central_node(got, heard, reported, s, k)
        content = {name: down[name][0, 0] for name in ("gamma", "mean", "cov", "stamp")}
        content["target"] = targets[0]
        self.radio.send(k, "download", 0, content)
        seconds = time.perf_counter() - start
        empty = packed({"x": np.zeros(0)})["x"]
        return Report(
            VERSION, self.run, k, n, -1, -1, empty, empty, empty, 0, sent, delivered, 1e3 * seconds
        )
