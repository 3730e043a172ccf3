"""``centralized``: every UAV uploads its tables to a central node whatever the radio
range; the node takes the most confident estimate of each target over the team
(max-consensus on the complete graph), plans for every UAV it heard from and solves one
global assignment, and sends each UAV the fused estimates and its target. A lost upload
leaves the UAV out of the central fusion and assignment; a lost download leaves it with
its own estimates and its previous target.
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
from ..config import Scenario
from ..radio import counted, part_bytes
from ..robust import gate
from ..tracks import columns, manage
from .base import Assigned, Fused, FusedTracks, Inputs, Local, Method, Setting, forwarded, wire


class Centralized(Method):
    """A central node with everyone's data: global fusion, one global assignment."""

    name = "centralized"
    central = True

    @staticmethod
    def on_air(inputs: Inputs, rows: np.ndarray | None = None) -> None:
        """The frames of a cycle as the agent form sends them: each living UAV uploads
        one to the central node (with tracks its scan of `rows` measurements (B, N)),
        the node sends each one its download."""
        radio, alive = inputs.radio, inputs.alive
        up, down = wire(inputs, "upload", rows), wire(inputs, "download")
        radio.on_air(part_bytes("upload", 0, -1, up), 1, radio.afforded(alive), node=True)
        radio.from_node(part_bytes("download", 0, -1, down), 1, radio.afforded(alive, "served"))

    def fuse(self, inputs: Inputs) -> Fused:
        self.on_air(inputs)
        if not inputs.setting.faulty:
            return self._perfect(inputs)
        return self._over_links(inputs)

    @staticmethod
    def _perfect(inputs: Inputs) -> Fused:
        b, n, _ = inputs.gamma.shape
        source = np.broadcast_to(np.argmax(inputs.gamma, axis=-2)[:, None, :], inputs.gamma.shape)
        rounds = np.full((b, n), 1 if n > 1 else 0, dtype=np.int64)
        # every UAV uploads its table and downloads the fused one
        messages = np.full(b, 2 * n if n > 1 else 0, dtype=np.int64)
        mean, cov = fusion.gather(source, inputs.mean), fusion.gather(source, inputs.cov)
        s, measured = inputs.setting, inputs.measured
        if s.gate is not None and measured is not None:  # as `take_download`
            use = gate.agreeing(mean, cov, measured, s.gate, (inputs.mean, inputs.cov))
            mean = np.where(use[..., None], mean, inputs.mean)
            cov = np.where(use[..., None, None], cov, inputs.cov)
        return Fused(mean=mean, cov=cov, rounds=rounds, sent=messages, delivered=messages.copy())

    @staticmethod
    def _over_links(inputs: Inputs) -> Fused:
        """Uploads, the central node's work, downloads, with faults."""
        s, radio, k = inputs.setting, inputs.radio, inputs.k
        B, n, m = inputs.gamma.shape
        tuples = fusion.Estimates(
            gamma=inputs.gamma, mean=inputs.mean, cov=inputs.cov, stamp=np.full((B, n, m), k)
        )
        sent = radio.afforded(inputs.alive)  # the uploads sent: what the shares afford
        radio.send("upload", {"estimates": tuples, "uavs": inputs.believed, "alive": sent})
        upload, up_ok = radio.receive_central("upload")
        arrived: list[
            tuple[np.ndarray, np.ndarray]
        ] = []  # (sent, delivered) of the uploads and downloads that arrive now
        seconds = np.zeros((B, n, 2))
        if upload is None:
            down, down_target = nothing_heard(B, n, m), np.full((B, n), -1, dtype=np.int64)
        else:
            up_ok = up_ok & upload["alive"]
            arrived.append((upload["alive"].sum(axis=1), up_ok.sum(axis=1)))
            start = timing.start()
            down, down_target = central_node(
                upload["estimates"], up_ok, upload["uavs"], s, k, timing
            )
            seconds += timing.since(start) / B
        served = radio.afforded(inputs.alive, "served")  # the downloads the node's share sends
        radio.send("download", {"estimates": down, "target": down_target, "alive": served})
        download, down_ok = radio.receive_central("download")
        mean, cov = inputs.mean, inputs.cov
        target = None
        if download is not None:
            down_ok = down_ok & inputs.alive
            arrived.append((download["alive"].sum(axis=1), down_ok.sum(axis=1)))
            mean, cov = take_download(
                mean, cov, download["estimates"], down_ok, s, k, inputs.measured
            )
            target = np.where(down_ok, download["target"], -1)
        rounds = np.where(inputs.alive, 1, 0)
        sent, delivered = counted(
            s.delay,
            lambda: (radio.transmitted_central(p) for p in ("upload", "download")),
            arrived,
        )
        return Fused(
            mean=mean,
            cov=cov,
            rounds=rounds,
            sent=sent,
            delivered=delivered,
            seconds=seconds,
            target=target,
        )

    def fuse_tracks(self, inputs: Inputs, local: Local) -> FusedTracks:
        """One multi-sensor tracker at the central node: each UAV uploads its scan, the
        node runs the association rule of the run on the scans one UAV after another
        (`manage.scan` on its own tracks, the UAV's disk as the sensor's), and every UAV
        downloads the node's tracks. A lost upload leaves that scan out; a lost download
        leaves the UAV with the tracks it downloaded before, predicted.

        With ``faults.delay`` d the node takes at cycle k the scans of k - d (its tracks
        run d steps behind, and stay at the start until the first scans arrive), and a
        UAV takes at k the download sent at k - d, whose tracks are of k - 2d: predicted
        to k (`forwarded`)."""
        s, radio, alive = inputs.setting, inputs.radio, inputs.alive
        scenario = s.scenario
        if scenario is None or local.central is None:
            raise ValueError("the central tracker needs the scenario and its own tracks")
        B, n = alive.shape
        self.on_air(inputs, local.valid.sum(axis=-1))
        scans = {"z": local.z, "R": local.R, "valid": local.valid, "uavs": inputs.believed}
        heard, take, upload = alive, alive, None
        sent = delivered = np.full(B, 2 * n if n > 1 else 0, dtype=np.int64)
        if s.faulty:  # the uploads sent: what the shares afford
            radio.send("upload", {"alive": radio.afforded(alive), **scans})
            upload, up_ok = radio.receive_central("upload")
            heard = up_ok & upload["alive"] if upload is not None else np.zeros_like(alive)
            if upload is not None:
                scans = upload
        node, when = local.central, inputs.k - s.delay  # the step of the scans taken now
        if upload is not None or not s.faulty:
            for i in range(n):
                one = slice(i, i + 1)
                scanned = manage.scan(
                    node.book, node.mean, node.cov, scans["z"][:, one], scans["R"][:, one],
                    scans["valid"][:, one], scans["uavs"][:, one], heard[:, one], scenario,
                    node.modes, local.tracker, when,
                )  # fmt: skip
                node = manage.Slots(
                    book=scanned.book, mean=scanned.mean, cov=scanned.cov, modes=scanned.modes
                )
        book, mean, cov = node.book, node.mean, node.cov
        target = None
        if s.faulty:  # the downloads the node's share sends, each with its label to follow
            label = np.full((B, n), -1, dtype=np.int64)
            if upload is not None:
                label = node_targets(node, scans["uavs"], heard, s, scenario)
            served = radio.afforded(alive, "served")
            content = {"alive": served, "book": book, "mean": mean, "cov": cov, "target": label}
            radio.send("download", content)
            download, down_ok = radio.receive_central("download")
            take = np.zeros_like(alive)
            arrived = []
            if upload is not None:
                arrived.append((upload["alive"].sum(axis=1), heard.sum(axis=1)))
            if download is not None:
                take = down_ok & alive & download["alive"]
                arrived.append((download["alive"].sum(axis=1), take.sum(axis=1)))
                book, mean, cov = download["book"], download["mean"], download["cov"]
                target = np.where(take, download["target"], -1)
                if s.delay > 0:  # tracks of k - 2d (at the start: of 0), sent at k - d
                    at = max(inputs.k - 2 * s.delay, 0)
                    mean, cov = forwarded(s, mean, cov, at, inputs.k)
            sent, delivered = counted(
                s.delay,
                lambda: (radio.transmitted_central(p) for p in ("upload", "download")),
                arrived,
            )
        every = manage.broadcast(book, n)
        pick = take[..., None]
        scan = (local.z, local.R, local.valid)
        ok = download_admitted(every, mean, cov, scan, inputs.believed, s)
        if ok is not None:  # the slots the gate refuses stay as the UAV had them
            pick = pick & ok
            if not s.faulty:  # the UAVs' tracks may now differ from the node's: its labels
                target = node_targets(node, inputs.believed, alive, s, scenario)
        out = manage.where(pick, every, local.book)
        return FusedTracks(
            book=out,
            mean=np.where(pick[..., None], mean, local.mean),
            cov=np.where(pick[..., None, None], cov, local.cov),
            changed=np.where(pick & out.present, 1, 0).astype(np.int8),
            rounds=np.where(alive, 1 if n > 1 else 0, 0),
            sent=sent,
            delivered=delivered,
            central=node if upload is not None or not s.faulty else None,
            target=target,
        )

    def assign(self, inputs: Inputs, fused: Fused, bids: np.ndarray) -> Assigned:
        B, n, _ = bids.shape
        none = np.zeros(B, dtype=np.int64)
        if not inputs.setting.faulty and fused.target is not None:  # the node's labels
            return Assigned(
                target=np.where(inputs.alive, fused.target, -1),
                seconds=np.zeros((B, n, 2)) if fused.seconds is None else fused.seconds,
                sent=none,
                delivered=none,
            )
        if not inputs.setting.faulty:
            known = None if inputs.columns is None else inputs.columns.labels >= 0
            target, seconds = assignment.centralized(bids, clock=timing, known=known)
            return Assigned(
                target=target,
                seconds=np.repeat(seconds[:, None], n, axis=1),
                sent=none,
                delivered=none,
            )
        # the node's target if its download arrived, else the previous one, else the own best
        target = fused.target if fused.target is not None else np.full((B, n), -1)
        target = np.where(target >= 0, target, inputs.previous)
        target = np.where(target >= 0, target, assignment.greedy(bids, inputs.holds))
        target = np.where(inputs.alive, target, -1)
        assert fused.seconds is not None, "the fusion under faults times the central node"
        return Assigned(target=target, seconds=fused.seconds, sent=none, delivered=none)


def download_admitted(
    book: manage.Book,
    mean: np.ndarray,
    cov: np.ndarray,
    scan: tuple[np.ndarray, np.ndarray, np.ndarray],
    believed: np.ndarray,
    setting: Setting,
) -> np.ndarray | None:
    """``robust.gate`` with tracks on the central node's download: which slots each UAV
    takes (B, N, K). A confirmed slot must agree with a measurement of the UAV's scan
    unless it lies out of the UAV's view (`gate.tracks_admitted`; a centralized UAV
    keeps no track of its own to check against). book (B, N, K): the download as each
    UAV reads it; mean (B, 1 or N, K, 4), cov; scan: z (B, N, Z, 2), R, valid; believed
    (B, N, 5). None without the gate. The agent form calls it on its own row."""
    if setting.gate is None or setting.scenario is None:
        return None
    B, N, K = book.label.shape
    if not K:
        return np.ones((B, N, K), dtype=bool)
    z, R, valid = scan
    Z = valid.shape[-1]
    rows = B * N
    scanned = gate.Scanned(
        z=z.reshape(rows, Z, 2), R=R.reshape(rows, Z, 2, 2), valid=valid.reshape(rows, Z),
        uav=believed.reshape(rows, -1), recent=np.zeros((rows, K), dtype=bool),
    )  # fmt: skip
    m = np.broadcast_to(mean, (B, N, K, 4)).reshape(-1, 4)
    P = np.broadcast_to(cov, (B, N, K, 4, 4)).reshape(-1, 4, 4)
    row = np.repeat(np.arange(rows), K)
    none = np.full(row.shape, -1)
    sensor = setting.scenario.sensor
    ok = gate.tracks_admitted(row, none, m, P, none, (m, P), scanned, sensor, setting.gate)
    return ok.reshape(B, N, K) | ~book.confirmed


def nothing_heard(B: int, n: int, m: int) -> fusion.Estimates:
    """A download that carries no estimate (confidence -inf): the node heard nobody."""
    return fusion.Estimates(
        gamma=np.full((B, n, m), -np.inf),
        mean=np.zeros((B, n, m, 4)),
        cov=np.zeros((B, n, m, 4, 4)),
        stamp=np.zeros((B, n, m), dtype=np.int64),
    )


def node_targets(
    node: manage.Slots,
    uavs: np.ndarray,
    heard: np.ndarray,
    setting: Setting,
    scenario: Scenario,
) -> np.ndarray:
    """The label each UAV heard from is to follow (B, N) (-1: none, or not heard), with
    tracks: bids planned from the states the UAVs reported, `uavs` (B, N, 5), over the
    node's confirmed tracks (N = 1 slots), one global assignment of the UAVs heard
    (`heard` (B, N)) to their labels, as `central_node` does with known targets."""
    B, n = heard.shape
    slot_bids = np.full(heard.shape + node.book.label.shape[-1:], np.nan)
    t, i = np.nonzero(heard)
    if t.size:  # planned for the UAVs heard from alone
        slot_bids[t, i] = setting.plan(uavs[t, i][None], node.mean[t, 0][None])[0][0]
    slot_bids = manage.weighed(slot_bids, node.book, scenario)
    confirmed = np.repeat(node.book.confirmed, n, axis=1) & heard[..., None]
    slot_bids = np.where(confirmed, slot_bids, np.nan)
    cols = columns.of(np.repeat(node.book.label, n, axis=1), confirmed)
    value = columns.bids(np.nan_to_num(slot_bids), cols)
    column, _ = assignment.centralized(value, heard, known=cols.labels >= 0)  # its labels
    b = np.arange(B)[:, None]
    return np.where(column >= 0, cols.labels[b, np.maximum(column, 0)], -1)


def central_node(
    got: fusion.Estimates,
    heard: np.ndarray,
    uavs: np.ndarray,
    setting: Setting,
    k: int,
    clock: assignment.Clock | None = None,
) -> tuple[fusion.Estimates, np.ndarray]:
    """The central node's work on the uploads it received.

    got: the uploaded tuples (B, N, M, ...) (gamma, mean, cov, stamp); heard
    (B, N): whose upload arrived; uavs (B, N, 5): the states they reported. Per target
    the most confident uploaded estimate (ties to the lowest UAV), predicted forward with
    ``robust.stale``; bids of every UAV heard from, planned from its reported state; one
    global assignment over them. Returns the download of every UAV (the fused tuples,
    (B, N, M, ...), confidence -inf where the node heard nobody) and its target (B, N),
    -1 for a UAV not heard from. clock: the caller's, on whose set-up a first load of
    the exact solver is counted (`assignment.load_solver`); it is read for nothing else.
    """
    B, n, m = fusion.required(got.gamma, "gamma").shape
    if setting.stale:
        got = setting.forward(got, k)
    score = np.where(heard[..., None], fusion.required(got.gamma, "gamma"), -np.inf)
    best = np.argmax(score, axis=1)  # per target, the most confident uploader
    b, j = np.arange(B)[:, None], np.arange(m)
    central = got.map(lambda value: value[b, best, j])  # (B, M, ...)
    value = np.zeros((B, n, m))  # bids of the UAVs heard from, planned from their reports
    t, i = np.nonzero(heard)
    if t.size:
        mean = fusion.required(central.mean, "mean")
        value[t, i] = setting.plan(uavs[t, i][None], mean[t][None])[0][0]
    targets, _ = assignment.centralized(value, heard, assignment.set_up_only(clock))
    anyone = np.any(heard, axis=1)  # (B,): numpy's stubs type the method as maybe a scalar
    empty = nothing_heard(B, n, m)
    down = fusion.Estimates(
        **{
            key: np.where(
                anyone.reshape((B,) + (1,) * array.ndim),
                np.repeat(array[:, None], n, axis=1),
                getattr(empty, key),
            )
            for key, array in central.items()
        }
    )
    return down, np.where(anyone[:, None], targets, -1)


def take_download(
    mean: np.ndarray,
    cov: np.ndarray,
    got: fusion.Estimates,
    arrived: np.ndarray,
    setting: Setting,
    k: int,
    measured: gate.Measured | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A UAV's estimates after the central node's download: the downloaded tuple of each
    target where it arrived and carries one (predicted forward with ``robust.stale``)
    and, with ``robust.gate``, agrees with the UAV's measurement (`gate.agreeing`), its
    own otherwise. mean (B, N, M, 4), cov (B, N, M, 4, 4); got: the downloaded tuples
    (gamma, mean, cov, stamp); arrived (B, N)."""
    if setting.stale:
        got = setting.forward(got, k)
    got_mean, got_cov = fusion.required(got.mean, "mean"), fusion.required(got.cov, "cov")
    use = arrived[..., None] & np.isfinite(fusion.required(got.gamma, "gamma"))  # (B, N, M)
    if setting.gate is not None and measured is not None:
        use &= gate.agreeing(got_mean, got_cov, measured, setting.gate, (mean, cov))
    return (
        np.where(use[..., None], got_mean, mean),
        np.where(use[..., None, None], got_cov, cov),
    )
