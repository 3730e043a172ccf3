"""One UAV as a program with unknown association: its track slots, the team's
agreement on them over the radio, and the auction over team labels.

The world sends the UAV its scan unlabelled (`messages.Sense`: the detections and the
clutter in the order the sensor gave them, no target named). The program runs the
batch simulator's stages on its own row (leading axes of size 1): `manage.scan` on its
slots, the D_i protocol with rounds of `team.agree_round` on the tracks its neighbours
send (labels, status, stamps and tombstones travel with them), `manage.after_fusion`,
`planning.plan` over its slots, and the auction (`assignment.local`) over the labels it
knows: its own confirmed tracks' and those of the bids that reached it, in increasing
order, as the batch lays them out in columns (`tracks.columns`); the bids it holds of a
neighbour whose message was lost count for those labels only, as in the batch
(`methods.distributed.known_labels`). So a swarm's trace equals `uavtrack run`'s for
the same seed and faults.
"""

from __future__ import annotations

import time

import numpy as np

from .. import assignment, estimation, simulation, timing
from ..methods import Greedy, bid_view
from ..methods.base import NEVER, Held, forwarded, gated_tracks, scanned_tracks
from ..methods.centralized import download_admitted, node_targets
from ..numerics.codec import Codec
from ..radio import counted, pack_rows, packs
from ..tracks import association, manage, team
from .agent import CentralAgent, UavAgent, closed, dropped, part
from .messages import VERSION, Report, packed


class TrackedUav(UavAgent):
    """A UAV's program with ``tracker.association`` gnn or jpda (see the module
    docstring); with the centralized baseline it uploads its scan and takes the central
    node's tracks (`TrackedCentral`)."""

    def __init__(self, me, scenario, method, faults, link, mailbox, deadline, prior) -> None:
        super().__init__(me, scenario, method, faults, link, mailbox, deadline, prior)
        K = scenario.track_slots
        mean, cov = prior  # (M, 4), (M, 4, 4): the briefed targets
        book, mean, cov = manage.briefed(
            mean[None, None], cov[None, None], K, scenario.tracker.briefing
        )
        self.book = book
        self.mean, self.cov, self.modes = self.ctx.const.tracker.start(mean, cov)
        self.tombs = np.full((1, 1, K, 2), -1, dtype=np.int64)
        self.threshold = association.threshold(scenario.tracker.gate_probability, 4)
        self.told_labels: np.ndarray | None = None  # with fusion.trigger: the labels sent
        self.seen: np.ndarray | None = None  # with robust.gate: the step a scan met a slot
        self.target = -1  # the team label followed
        self.serial = 0  # its births so far: its labels n_targets + s n + me, s < serial
        self.kept: dict[int, tuple[np.ndarray, np.ndarray, int]] = {}
        """The bids held of each neighbour (labels, bids, step sent), when messages get
        lost: `Held` by label."""

    def cycle(self, k: int, sense: dict[str, np.ndarray], central: bool = True) -> Report:
        s, tracker = self.scenario, self.ctx.const.tracker
        believed = self.believed = sense["believed"]
        alive = sense["alive"]
        self.radio.begin(k, sense["links"], alive, central, sense.get("afford"))
        raw = sense["z"]
        z, R = simulation.convert(np.repeat(believed[None], len(raw), axis=0), raw, s)
        self.scan = z  # its scan on the ground, for the ROS 2 topics
        if self.central:
            return self._central_cycle(k, z, R)
        one = np.ones((1, 1), dtype=bool)
        scanned = manage.scan(
            self.book, self.mean, self.cov, z[None, None], R[None, None],
            np.ones((1, 1, len(raw)), dtype=bool), believed[None, None], one, s,
            self.modes, tracker, k, (self.me, self.n),
        )  # fmt: skip
        self.serial = int(scanned.book.serial[0, 0])  # the labels it has issued
        own = scanned_tracks(scanned, self.tombs, k)
        state = (own, np.zeros(own.status.shape, dtype=np.int8))
        scan = (z[None, None], R[None, None], np.ones((1, 1, len(raw)), dtype=bool))
        seen, admit = gated_tracks(self.setting, k, self.seen, scanned.met, scan, believed)
        (agreed, changed), rounds, sent, delivered = self.rounds(
            k, state, self._track_content(k, own),
            lambda state, got: self._agree(state, got, k, admit),
        )  # fmt: skip
        if seen is not None:
            self.seen = np.where(changed >= team.ADOPTED, NEVER, seen)
        book = manage.after_fusion(
            scanned.book, agreed.label, agreed.status, changed, s, agreed.stamp
        )
        slot_bids, best, plan_seconds = self._plan(book, agreed.mean)
        labels, confirmed = book.label[0, 0], book.confirmed[0, 0]
        if isinstance(self.method, Greedy):
            column, solve_seconds, more = self._greedy(slot_bids, labels, confirmed)
            held = np.unique(labels[confirmed])
        else:
            column, held, solve_seconds, more = self._auction(k, slot_bids, labels, alive)
        slot = _slot_of(column, held, labels, confirmed, slot_bids)
        report = self._report(
            k, slot, best, book, agreed.mean, agreed.cov, slot_bids, int(rounds),
            (sent + more[0], delivered + more[1]), plan_seconds + solve_seconds,
        )  # fmt: skip
        self._close(scanned, agreed, changed, book)
        return report

    def _plan(self, book: manage.Book, mean: np.ndarray):
        """Bids of the confirmed slots (K,) (NaN elsewhere), the best first action of
        each slot, and the seconds (CPU, wall) it took."""
        start = timing.start()
        slot_bids, best = self.setting.plan(self.believed[None, None], mean)
        slot_bids = manage.weighed(slot_bids, book, self.scenario)
        slot_bids = np.where(book.confirmed[0, 0], slot_bids[0, 0], np.nan)
        return slot_bids, best[0, 0], timing.since(start)

    def _report(self, k, slot, best, book, mean, cov, slot_bids, rounds, counts, seconds):
        """The cycle's report, following the track in `slot` (-1: none, straight)."""
        labels = book.label[0, 0]
        action = int(best[slot]) if slot >= 0 else simulation.STRAIGHT
        if self.scenario.planner.avoidance != "none":  # as the batch's: no scores, fixed fall-backs
            action, beaconed = self.avoided(k, action, None)
            counts = (counts[0] + beaconed[0], counts[1] + beaconed[1])
        followed = int(labels[slot]) if slot >= 0 else -1
        self.target = followed if followed >= 0 else self.target
        cpu, wall = (1e3 * seconds).tolist()
        return Report(
            version=VERSION, run=self.run, k=k, uav=self.me, action=action, target=followed,
            mean=packed({"x": mean[0, 0]})["x"], cov=packed({"x": cov[0, 0]})["x"],
            bids=packed({"x": slot_bids})["x"], rounds=rounds,
            sent=int(counts[0]), delivered=int(counts[1]),
            decision_ms=cpu, decision_wall_ms=wall, late=dict(self.radio.late),
            radio_bytes=self.radio.bytes,
            label=packed({"x": labels})["x"],
            status=packed({"x": book.status[0, 0].astype(np.int64)})["x"],
            existence=packed({"x": np.where(book.present, book.existence, 0.0)[0, 0]})["x"],
        )  # fmt: skip

    def _central_cycle(self, k: int, z: np.ndarray, R: np.ndarray) -> Report:
        """The centralized baseline from a UAV's side (`methods.Centralized.fuse_tracks`):
        upload its scan, take the node's tracks and target where its download came (else
        keep its tracks, predicted); follow the node's label, or under faults its
        previous label if it still holds it confirmed, else its best confirmed track."""
        s, one = self.setting, int(self.n > 1)
        if self.radio.central[k]:
            scan = {"z": z, "R": R, "uav": self.believed}
            self.radio.send(k, [part("upload", 0, scan)], to=self.n)
        content, offered = self._tracks_download(k)
        sent, delivered = counted(
            s.delay, lambda: [self.radio.transmitted(k, "upload", 1, 0, to=self.n)], offered
        )
        book, mean, cov = self.book, self.mean, self.cov
        target = -1
        if content is not None:
            K = self.scenario.track_slots
            book = manage.Book(
                **{
                    f: content[f].reshape(1, 1, K)
                    for f in ("label", "hits", "scans", "misses", "stamp", *self.spec.book)
                },
                status=content["status"].astype(np.int8).reshape(1, 1, K),
                serial=content["serial"].reshape(1, 1),
            )
            mean, cov = content["mean"][None, None], content["cov"][None, None]
            target = int(content["target"])
            if s.delay > 0:  # the node's tracks of k - 2d (at the start: of 0), sent at k - d
                mean, cov = forwarded(s, mean, cov, max(k - 2 * s.delay, 0), k)
            scan = (z[None, None], R[None, None], np.ones((1, 1, len(z)), dtype=bool))
            ok = download_admitted(book, mean, cov, scan, self.believed[None, None], s)
            if ok is not None:  # the slots the gate refuses stay as this UAV had them
                book = manage.where(ok, book, self.book)
                mean = np.where(ok[..., None], mean, self.mean)
                cov = np.where(ok[..., None, None], cov, self.cov)
        slot_bids, best, plan_seconds = self._plan(book, mean)
        labels, confirmed = book.label[0, 0], book.confirmed[0, 0]
        follow = target if target >= 0 or not s.faulty else self.target
        held = np.array([follow]) if follow >= 0 else np.zeros(0, dtype=np.int64)
        slot = _slot_of(0 if held.size else -1, held, labels, confirmed, slot_bids)
        report = self._report(
            k, slot, best, book, mean, cov, slot_bids, one, (sent, delivered), plan_seconds
        )
        tracker = self.ctx.const.tracker
        self.book = manage.survive(book, self.scenario)
        self.modes = None  # the node keeps the modes of an IMM
        self.mean, self.cov = estimation.predict(mean, cov, tracker.A, tracker.Q)
        return report

    def _tracks_download(self, k: int):
        """The node's download sent `delay` cycles ago (its checked content, or None when
        it did not come, or none was sent yet) and (offered, came) as `UavAgent.upload`
        counts it."""
        s, one = self.setting, int(self.n > 1)
        mailbox, node, then = self.mailbox, self.n, k - self.radio.delay
        if then < 0:  # nothing sent yet
            return None, []
        lost = bool(self.radio.lost(then, "download", 0, np.array(node), self.me))
        expect = self.radio.central[then] and not lost
        expect = expect and self.radio.affords(then, self.me, "download")  # sent to it at all
        if expect:  # two rounds: the node waits up to a round's deadline for the uploads
            mailbox.wait(
                lambda: (
                    mailbox.content(then, "download", node, 0) is not None or mailbox.is_gone(node)
                ),
                time.monotonic() + 2 * self.radio.deadline,
            )
        content = mailbox.content(then, "download", node, 0) if expect else None
        if expect and content is None:  # late, or the node's token went: it never came
            self.radio.missed("download", 1)
        if content is not None:
            content, reasons = self.spec.tracks(content)
            dropped(self.mailbox, reasons)
        mine = int(self.radio.alive[then][self.me]) if s.faulty else one
        mine *= int(self.radio.affords(then, self.me, "download"))
        return content, [(mine, mine * int(content is not None))]

    def _close(self, scanned, agreed: team.TrackSet, changed, book) -> None:
        """The tracks predicted to the next scan (`simulation.Tracking.close`)."""
        tracker = self.ctx.const.tracker
        if scanned.modes is not None:  # an IMM: fused tracks restart their modes
            modes = manage.restart(scanned.modes, changed == 2, agreed.mean, agreed.cov, tracker)
            self.mean, self.cov, self.modes = tracker.close(
                scanned.mean, scanned.cov, modes, agreed.mean, agreed.cov
            )
        else:
            self.mean, self.cov = estimation.predict(agreed.mean, agreed.cov, tracker.A, tracker.Q)
        self.book = manage.survive(book, self.scenario)
        if agreed.tombs is not None:
            self.tombs = agreed.tombs

    # ------------------------------------------------------------ fusion

    def _track_content(self, k: int, own: team.TrackSet):
        """content(state): what each consensus round sends of the tracks, every slot or,
        with ``fusion.trigger`` or the compact encoding, the slots `team.Listing` picks
        (as the batch's `methods.base.track_listing`), listed (`listed_slots`); keeps what it
        told of each slot."""
        s = self.setting
        if s.trigger is None and not s.compact:
            return lambda state: _content(state[0])
        first = None
        if s.trigger is not None:
            first = team.triggered(own, self.told, self.told_labels, k, s.trigger, s.refresh)
        how = team.Listing(first=first, codec=s.codec)
        K = own.status.shape[-1]
        told = np.full((1, 1, K), np.nan) if self.told is None else self.told.copy()
        told_labels = np.full((1, 1, K), -1) if self.told_labels is None else self.told_labels
        told_labels = told_labels.copy()
        if s.trigger is not None:
            self.told, self.told_labels = told, told_labels
        sent: list[team.TrackSet] = []  # the tracks of each round so far

        def content(state) -> dict[str, np.ndarray]:
            tracks = state[0]
            r = len(sent) + 1
            mask = how.mask(r, tracks, sent[-1] if sent else None)
            sent.append(tracks)
            if self.radio.affords(k, self.me, "consensus", r):  # what the share sends
                told[mask] = estimation.confidence(tracks.cov)[mask]
                told_labels[mask] = tracks.label[mask]
            out = listed_slots(tracks, mask[0, 0], s.codec)
            if packs("consensus", s.tuples):  # its rows in one byte array
                out = pack_rows(out, self.spec.contents("consensus") or {})
            return out

        return content

    def _agree(self, state, contents: dict[int, dict], k: int = 0, admit=None):
        """One round of `team.agree_round` over this UAV's closed neighbourhood at cycle
        k: itself and the senders whose tracks arrived, in index order (the senders'
        tracks beyond the run's plausibility bounds left out, `messages.Spec.tracks`, and
        those under a label of this UAV's own it has not issued, `_issued`); with
        ``faults.delay`` their estimates predicted to k (`methods.base.forwarded`); with
        ``robust.gate`` the offers `admit` refuses left out (`methods.base.gated_tracks`,
        on this UAV's row)."""
        own, changed = state
        offered = {}
        for q, content in contents.items():
            content, reasons = self.spec.tracks(
                unlisted_slots(content, self.scenario.track_slots, self.setting.codec)
            )
            if self.setting.delay > 0:  # sent cycles ago: predicted to this scan
                mean, cov = forwarded(
                    self.setting, content["mean"], content["cov"], k - self.setting.delay, k
                )
                content = dict(content, mean=mean, cov=cov)
            dropped(self.mailbox, reasons)
            offered[q] = self._issued(content)
        ids = sorted({self.me, *offered})
        where = ids.index(self.me)

        def stacked(name: str, mine: np.ndarray, dtype=None) -> np.ndarray:
            rows = [mine if q == self.me else offered[q][name] for q in ids]
            out = np.stack(rows)[None]
            return out if dtype is None else out.astype(dtype)

        tracks = team.TrackSet(
            mean=stacked("mean", own.mean[0, 0]),
            cov=stacked("cov", own.cov[0, 0]),
            label=stacked("label", own.label[0, 0], np.int64),
            status=stacked("status", own.status[0, 0], np.int8),
            stamp=stacked("stamp", _stamp(own), np.int64),
            tombs=None if own.tombs is None else stacked("tombs", own.tombs[0, 0], np.int64),
        )
        where, links = closed(ids, self.me)
        every = np.zeros(tracks.status.shape, dtype=np.int8)
        every[0, where] = changed[0, 0]
        mine_only = None if admit is None else _own_row(admit)
        rule = self.setting.rule
        out, now = team.agree_round(tracks, every, tracks, links, self.threshold, rule, mine_only)
        mine = team.TrackSet(
            mean=out.mean[:, where : where + 1],
            cov=out.cov[:, where : where + 1],
            label=out.label[:, where : where + 1],
            status=out.status[:, where : where + 1],
            stamp=None if out.stamp is None else out.stamp[:, where : where + 1],
            tombs=None if out.tombs is None else out.tombs[:, where : where + 1],
        )
        return mine, now[:, where : where + 1]

    def _issued(self, content: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """A sender's tracks without those under a label of this UAV's it has not issued
        (taken as empty slots, counted as "label not issued"): holding one, this UAV
        would issue it again at a later birth and hold it twice, which its own
        messages' check refuses. So whatever it adopts, its labels stay distinct."""
        label = content["label"]
        team = (self.me, self.n)
        bad = manage.unissued(label, self.serial, self.scenario.n_targets, team)
        if not bad.any():
            return content
        dropped(self.mailbox, {"label not issued": int(bad.sum())})
        status = np.where(bad, 0, content["status"])
        return dict(content, status=status, label=np.where(bad, -1, label))

    # ------------------------------------------------------------ assignment

    def _greedy(self, slot_bids, labels, confirmed):
        """The greedy baseline: the best bid among its own confirmed tracks' labels
        (ties to the lowest label)."""
        held = np.unique(labels[confirmed])
        start = timing.start()
        column = int(assignment.greedy(_by_label(slot_bids, labels, confirmed, held)))
        return column, timing.since(start), (0, 0)

    def _auction(self, k: int, slot_bids, labels, alive):
        """Bids by label to the neighbours, then the auction over the labels this UAV
        knows (`UavAgent.solve`). Returns (column, the labels of the columns, seconds,
        messages (sent, delivered))."""
        n, s = self.n, self.setting
        confirmed = ~np.isnan(slot_bids)
        sent_labels = np.where(confirmed, labels, -1)
        stamp = np.array(k, dtype=np.int64)
        beacon, inbox, more = self.heard(
            k, {"bids": slot_bids, "label": sent_labels, "stamp": stamp}
        )
        contents = {} if inbox is None else inbox.contents
        known = np.unique(
            np.concatenate([labels[confirmed], *(c["label"] for c in contents.values())])
        )
        known = known[known >= 0]
        if known.size == 0:  # nothing to follow: the auction has no column
            return -1, known, np.zeros(2), more
        own = _by_label(slot_bids, labels, confirmed, known)
        if inbox is None:  # nothing has arrived yet: alone
            members = np.zeros(n, dtype=bool)
            view = np.broadcast_to(own, (n, known.size)).copy()
            target, seconds = self.solve(view, members, alive, own)
            return target, known, seconds, more
        got, offered, stamps = np.zeros(n, dtype=bool), np.zeros((n, known.size)), np.zeros(n, int)
        for q, c in contents.items():
            got[q], stamps[q] = True, c["stamp"]
            offered[q] = _by_label(c["bids"], c["label"], c["label"] >= 0, known)
        heard = got
        if beacon is not None:
            heard = np.zeros(n, dtype=bool)
            heard[list(beacon.contents)] = True
        held = None
        if self.held is not None:  # the bids held of each sender, by the labels known now
            value, when = np.zeros((n, known.size)), np.full(n, -1, dtype=np.int64)
            for q, (were, bids, sent_at) in self.kept.items():
                value[q] = _by_label(bids, were, were >= 0, known)
                when[q] = sent_at
            held = Held(value, when)
        members, view, stamp = bid_view(got, offered, stamps, heard, held, s.stale)
        if self.held is not None:
            self.kept = {
                int(q): (known, view[q].copy(), int(stamp[q])) for q in np.flatnonzero(stamp >= 0)
            }
            self.held = held
        target, seconds = self.solve(view.copy(), members, alive, own)
        return target, known, seconds, more


def _own_row(admit: team.Admit) -> team.Admit:
    """`admit` of a batch whose receivers are this UAV alone: every offer is to row 0."""

    def mine(row, sender, mean, cov, slot, own) -> np.ndarray:
        return admit(np.zeros_like(row), sender, mean, cov, slot, own)

    return mine


def _content(tracks: team.TrackSet) -> dict[str, np.ndarray]:
    """A round's consensus content: this UAV's slots (`messages.Spec` "consensus")."""
    assert tracks.stamp is not None and tracks.tombs is not None
    return {
        "mean": tracks.mean[0, 0],
        "cov": tracks.cov[0, 0],
        "label": tracks.label[0, 0],
        "status": tracks.status[0, 0].astype(np.int64),
        "stamp": tracks.stamp[0, 0],
        "tombs": tracks.tombs[0, 0],
    }


def listed_slots(
    tracks: team.TrackSet, mask: np.ndarray, codec: Codec | None
) -> dict[str, np.ndarray]:
    """A round's listed consensus content (`radio.described`): the slots of `mask` (K,)
    with their estimates, labels and stamps, and the tombstones; with a `codec`, its
    estimates and 32-bit integers."""
    assert tracks.stamp is not None and tracks.tombs is not None
    slots = np.flatnonzero(mask)
    mean, cov = tracks.mean[0, 0, slots], tracks.cov[0, 0, slots]
    label, stamp = tracks.label[0, 0, slots], tracks.stamp[0, 0, slots]
    tombs = tracks.tombs[0, 0]
    if codec is not None:
        return {
            "slots": slots.astype("<u2"), **codec.pack(mean, cov),
            "label": label.astype("<u4"), "stamp": stamp.astype("<i4"),
            "tombs": tombs.astype("<i4"),
        }  # fmt: skip
    return {
        "slots": slots.astype(np.int64), "mean": mean, "cov": cov,
        "label": label.astype(np.int64), "stamp": stamp.astype(np.int64), "tombs": tombs,
    }  # fmt: skip


def unlisted_slots(
    content: dict[str, np.ndarray], K: int, codec: Codec | None
) -> dict[str, np.ndarray]:
    """A consensus content as every slot's (`listed_slots` undone): a slot not listed is
    empty (mean 0, covariance I, label -1, stamp 0), a listed one confirmed; an encoded
    content's estimates unpacked by the run's `codec`, as the batch's `team.Listing`
    delivers them. A full content is as it is."""
    if "slots" not in content:
        return content
    slots = content["slots"].astype(np.int64)
    mean, cov = np.zeros((K, 4)), np.broadcast_to(np.eye(4), (K, 4, 4)).copy()
    label, status = np.full(K, -1, dtype=np.int64), np.zeros(K, dtype=np.int64)
    stamp = np.zeros(K, dtype=np.int64)
    if codec is None:
        mean[slots], cov[slots] = content["mean"], content["cov"]
    else:
        mean[slots], cov[slots] = codec.unpack(content)
    label[slots], status[slots] = content["label"], team.CONFIRMED
    stamp[slots] = content["stamp"]
    return {
        "mean": mean, "cov": cov, "label": label, "status": status, "stamp": stamp,
        "tombs": content["tombs"].astype(np.int64),
    }  # fmt: skip


def _stamp(tracks: team.TrackSet) -> np.ndarray:
    assert tracks.stamp is not None  # a UAV's tracks carry their stamps
    return tracks.stamp[0, 0]


def _by_label(bids: np.ndarray, labels: np.ndarray, confirmed: np.ndarray, known: np.ndarray):
    """Bids per slot (K,) laid out by the labels `known` (L,) sorted: the bid of the
    confirmed slot holding each, 0 where none does (`tracks.columns.bids`)."""
    out = np.zeros(known.size)
    slots = np.flatnonzero(confirmed)
    at = np.searchsorted(known, labels[slots])
    inside = (at < known.size) & (known[np.minimum(at, known.size - 1)] == labels[slots])
    out[at[inside]] = np.nan_to_num(bids[slots[inside]])
    return out


def _slot_of(column: int, known: np.ndarray, labels, confirmed, slot_bids) -> int:
    """The slot followed (`tracks.columns.slot_of`): the one holding the assigned label,
    else the best own confirmed track, else -1."""
    if column >= 0:
        match = np.flatnonzero(confirmed & (labels == known[column]))
        if match.size:
            return int(match[0])
    if not confirmed.any():
        return -1
    return int(np.argmax(np.where(confirmed, slot_bids, -np.inf)))


class TrackedCentral(CentralAgent):
    """The central node of the centralized baseline with unknown association: one
    multi-sensor tracker (`methods.Centralized.fuse_tracks`) on the scans uploaded, one
    UAV's after another in index order, then (without faults) one assignment of every
    UAV to the node's confirmed labels; each living UAV downloads the node's tracks, their
    book and its label."""

    def __init__(self, scenario, faults, link, mailbox, deadline, prior) -> None:
        super().__init__(scenario, faults, link, mailbox, deadline)
        mean, cov = prior  # (M, 4), (M, 4, 4): the briefed targets
        book, mean, cov = manage.briefed(
            mean[None, None], cov[None, None], scenario.track_slots, scenario.tracker.briefing
        )
        modes = self.ctx.const.tracker.start(mean, cov)[2]
        self.node = manage.Slots(book=book, mean=mean, cov=cov, modes=modes)

    def cycle(self, k: int, tick: dict[str, np.ndarray], central: bool = True) -> Report:
        s, n, scenario = self.setting, self.n, self.scenario
        tracker = self.ctx.const.tracker
        alive = tick["alive"]
        self.radio.begin(k, np.zeros(n, dtype=bool), alive, afford=tick.get("afford"))
        start = timing.start()
        uploads, offered = self.uploads(k)
        processed = uploads is not None  # with delay: none before the first arrive
        uploads = uploads or {}
        node = self.node
        for _, content in sorted(uploads.items()):  # the scans of k - delay
            scanned = manage.scan(
                node.book, node.mean, node.cov, content["z"][None, None],
                content["R"][None, None], np.ones((1, 1, len(content["z"])), dtype=bool),
                content["uav"][None, None], np.ones((1, 1), dtype=bool), scenario,
                node.modes, tracker, k - s.delay,
            )  # fmt: skip
            node = manage.Slots(
                book=scanned.book, mean=scanned.mean, cov=scanned.cov, modes=scanned.modes
            )
        targets = np.full(n, -1, dtype=np.int64)
        if processed:  # one assignment of the UAVs heard from to the node's labels
            heard = np.zeros((1, n), dtype=bool)
            reported = np.zeros((1, n, 5))
            for i, content in uploads.items():
                heard[0, i], reported[0, i] = True, content["uav"]
            targets = node_targets(node, reported, heard, s, scenario)[0]
        book = node.book
        shared = {
            "mean": node.mean[0, 0], "cov": node.cov[0, 0], "label": book.label[0, 0],
            "status": book.status[0, 0].astype(np.int64), "stamp": book.stamp[0, 0],
            "hits": book.hits[0, 0], "scans": book.scans[0, 0], "misses": book.misses[0, 0],
            **{name: getattr(book, name)[0, 0] for name in self.spec.book},
            "serial": np.array(book.serial[0, 0], dtype=np.int64),
        }  # fmt: skip
        contents = {
            int(i): dict(shared, target=np.array(targets[i], dtype=np.int64))
            for i in np.flatnonzero(alive)
        }
        if processed:  # its tracks predicted to the next scan it takes
            mean, cov, modes = tracker.close(node.mean, node.cov, node.modes, node.mean, node.cov)
            self.node = manage.Slots(
                book=manage.survive(book, self.scenario), mean=mean, cov=cov, modes=modes
            )
        return self.downloads(k, alive, contents, offered, start)
