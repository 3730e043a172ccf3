"""Each UAV's track slots and their life: association of a scan, update, initiation,
M-of-N confirmation and deletion (``tracker.association`` gnn or jpda).

A UAV holds K slots (`Scenario.track_slots`); a slot is empty, tentative or confirmed.
Each scan, in this order:

1. association of the scan with the present tracks (`association.gnn` or `.jpda`), the
   detection probability of a track being P_D where its predicted position lies inside
   the UAV's observation disk or a measurement lies in its gate, and 0 elsewhere (no
   measurement of it can come);
2. the update: the Kalman update on the measurement taken (gnn) or the PDA update
   (jpda, the moment-matched mixture of the hypotheses; a tentative track's on its most
   probable hypothesis alone, `_firm`);
3. the counters: a track *in view* (predicted inside the disk) met a measurement when one
   lies in its gate; a confirmed track in view that met none coasts with its covariance
   inflated (`MANOEUVRE_STD`), so that its gate grows back over a target it lost; a
   tentative track is confirmed when it met a measurement in M of its first N scans in
   view (``tracker.confirm``) and deleted when it no longer can; a confirmed track is
   deleted after ``tracker.delete_misses`` consecutive scans in view without one (its
   label then goes to the team as a tombstone, `team.bury`: evidence that nothing is
   there); a track's stamp is the last step a measurement met it; any
   track is deleted when its position std exceeds ``tracker.delete_std`` or it lies
   outside the field (`OUTSIDE`);
4. initiation: each measurement no track claimed starts a tentative track in an empty
   slot (single-point: the converted position with its covariance R, zero velocity with
   the broad std ``tracker.birth_velocity_std``), in the scan's order until the slots are
   full. Its label is new to the team: n_targets + serial * N + i for UAV i's serial-th
   birth, so that no two UAVs ever start the same label.

The mission starts with the scenario's initial belief as confirmed tracks of every UAV
under the labels 0 .. n_targets - 1 (the briefing the paper's filters start from): with
P_D = 1 and no clutter, as long as every measurement lies in its track's gate, the tracks
are the paper's filters and the run is its run (a test holds it to that); a measurement
outside its gate is where the runs part.
"""

# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .. import estimation, sensing
from ..config import Scenario, TrackerModel
from . import association

EMPTY, TENTATIVE, CONFIRMED = 0, 1, 2
"""Track statuses."""

STATUS_NAMES = {EMPTY: "empty", TENTATIVE: "tentative", CONFIRMED: "confirmed"}
"""Each status's name, as the outputs (tables, bags, recordings) write it."""

MANOEUVRE_STD = 2.3
"""A confirmed track predicted in view with no measurement in its gate coasts with the
process noise of a white acceleration of this std [m/s^2] added (the IMM's jump mode,
``tracker.manoeuvre_std``): the CV filter of the paper is overconfident where a target
turns at a wall and near the nadir (its mean NEES is near 40 where 4 is consistent, see
the docs, Trackers), so more of its true innovations than the 1 % of a consistent filter
fall outside a 99 % gate, and a gate that does not grow would never take the target
back. An additive noise, not a factor, keeps a track coasting on clutter from
gaining an unbounded velocity."""

OUTSIDE = 0.25
"""A track farther outside the field than this fraction of its side is deleted: the
targets stay in the field (they turn back at its walls), so such a track follows
nothing; one made of clutter may otherwise lead the UAV that follows it away."""

BIRTH_GATE = 1.0 - 1e-6
"""A measurement inside this gate probability of a present track starts no track. Near
the nadir the converted measurement's error has heavy tails (the ground range of a
slant range just above the altitude, eq. 5, errs by metres outward while R's radial
std stays a few metres), so a target's own measurement can fall outside the
association gate (``tracker.gate_probability``); it then updates nothing, but starting
a second track of the same target from it would split the team's bids."""


@dataclass(frozen=True, kw_only=True)
class Book:
    """The bookkeeping of every UAV's slots (B, N, K): label int64 (-1 empty), status
    int8 (`EMPTY`, `TENTATIVE`, `CONFIRMED`), hits int64 (of a tentative track, the scans
    in view that met a measurement), scans int64 (its scans in view), misses int64
    (consecutive scans in view without a measurement), serial (B, N) int64, the births
    of each UAV so far, and stamp (B, N, K) int64, the last step a measurement met the
    track anywhere in the team as far as the UAV knows (`team.TrackSet`)."""

    label: np.ndarray
    status: np.ndarray
    hits: np.ndarray
    scans: np.ndarray
    misses: np.ndarray
    serial: np.ndarray
    stamp: np.ndarray

    @property
    def present(self) -> np.ndarray:
        return self.status != EMPTY

    @property
    def confirmed(self) -> np.ndarray:
        return self.status == CONFIRMED


def briefed(mean: np.ndarray, cov: np.ndarray, slots: int) -> tuple[Book, np.ndarray, np.ndarray]:
    """The mission's start: each UAV's prior of each target (mean (B, N, M, 4), cov
    (B, N, M, 4, 4)) as its confirmed tracks 0 .. M - 1 in the first M of `slots` slots.
    Returns (book, mean (B, N, K, 4), cov (B, N, K, 4, 4)); empty slots hold 0 and I."""
    B, N, M = mean.shape[:3]
    if slots < M:
        raise ValueError(f"{slots} track slots cannot hold the {M} briefed targets")
    out_mean = np.zeros((B, N, slots, 4))
    out_cov = np.broadcast_to(np.eye(4), (B, N, slots, 4, 4)).copy()
    out_mean[:, :, :M], out_cov[:, :, :M] = mean, cov
    label = np.full((B, N, slots), -1, dtype=np.int64)
    label[:, :, :M] = np.arange(M)
    status = np.zeros((B, N, slots), dtype=np.int8)
    status[:, :, :M] = CONFIRMED
    zeros = np.zeros((B, N, slots), dtype=np.int64)
    book = Book(
        label=label,
        status=status,
        hits=zeros,
        scans=zeros.copy(),
        misses=zeros.copy(),
        serial=np.zeros((B, N), dtype=np.int64),
        stamp=zeros.copy(),
    )
    return book, out_mean, out_cov


@dataclass(frozen=True, kw_only=True)
class Slots:
    """Tracks with their filters: the book, mean (B, N, K, 4), cov (B, N, K, 4, 4) and
    with an IMM the modes of each slot (None for the Kalman filter)."""

    book: Book
    mean: np.ndarray
    cov: np.ndarray
    modes: estimation.Modes | None = None


@dataclass(frozen=True, kw_only=True)
class Scanned:
    """What a UAV's scan did to its tracks: the updated mean and cov, the book, and per
    slot met (B, N, K) bool (a measurement lay in its gate while in view), in_view
    (B, N, K) bool, born (B, N, K) bool (a track started this scan), with an IMM
    (``tracker.model = "imm"``) each slot's modes, and dead (B, N, K) the labels of the
    confirmed tracks deleted after missing in view (-1 elsewhere): evidence that nothing
    is there, which the team's fusion spreads (`team.bury`)."""

    mean: np.ndarray
    cov: np.ndarray
    book: Book
    met: np.ndarray
    in_view: np.ndarray
    born: np.ndarray
    modes: estimation.Modes | None = None
    dead: np.ndarray | None = None


def scan(
    book: Book,
    mean: np.ndarray,
    cov: np.ndarray,
    z: np.ndarray,
    R: np.ndarray,
    valid: np.ndarray,
    believed: np.ndarray,
    alive: np.ndarray,
    scenario: Scenario,
    modes: estimation.Modes | None = None,
    tracker: estimation.Tracker | None = None,
    k: int = 0,
    team: tuple[int, int] | None = None,
) -> Scanned:
    """One scan of every UAV's tracker (steps 1-4 of the module's docstring).

    book and mean (B, N, K, 4), cov (B, N, K, 4, 4) predicted to this scan; z (B, N, Z, 2),
    R (B, N, Z, 2, 2), valid (B, N, Z) the scan (`tracks.scan.Scan`); believed (B, N, 5)
    where each UAV believes it is; alive (B, N) (a failed UAV's tracks stay as they are).

    With an IMM (modes: each slot's `estimation.Modes`, predicted; tracker its
    `estimation.Tracker`) the association reads the combined estimate and each mode is
    updated with the association's weights: gnn, the mode-matched update on the
    measurement taken (`estimation.imm_update`); jpda, the PDA update of each mode with the
    track's weights beta and its mode probability in proportion to c_j L_j, L_j =
    1 - P_D P_G + P_D / lambda sum_z N(z; H x_j, S_j) over the gated measurements (the
    IMM-PDA of Bar-Shalom, Willett and Tian, Tracking and Data Fusion, 2011). A track born
    from one measurement starts every mode there, at the stationary mode probabilities.

    team: (the first UAV's index, the team's size) when the rows are part of a team (a
    UAV's program runs its own row: (its index, N)); new labels are unique in the team.
    """
    B, N, K = book.label.shape
    Z = z.shape[2]
    sensor, settings = scenario.sensor, scenario.tracker
    present = book.present & alive[..., None]
    in_view = present & sensing.in_view(believed[:, :, None, :], mean, sensor)
    density = sensor.clutter_rate / (
        np.pi * sensing.observation_radius(believed[..., 2], sensor) ** 2
    )
    P = B * N
    m, P_, zz, RR = (
        mean.reshape(P, K, 4),
        cov.reshape(P, K, 4, 4),
        z.reshape(P, Z, 2),
        R.reshape(P, Z, 2, 2),
    )
    ok = (valid & alive[..., None]).reshape(P, Z)
    inn = association.innovations(m, P_, zz, RR)
    gated = association.gate(inn.d2, present.reshape(P, K), ok, settings.gate_probability)
    # a track can be detected where it is predicted in view, or where a measurement
    # (which is in view) lies in its gate: a target entering the disk is met at once
    pd = sensor.detection_probability * (in_view.reshape(P, K) | gated.any(axis=-1))
    dens = np.maximum(density.reshape(P), np.finfo(float).tiny)
    new_mean, new_cov = m, P_  # updated below: by the filter, or as the modes combine
    if settings.association == "gnn":
        take = association.gnn(inn, gated, pd, dens, settings.gate_probability)
        unused = association.unused_gnn(take, ok)
        if modes is None:
            new_mean, new_cov = association.assigned_update(m, P_, zz, RR, take)
        else:
            row, slot = np.nonzero(take >= 0)
            flat = _rows(modes, P)
            flat = estimation.imm_update(
                flat, take >= 0, zz[row, take[row, slot]], RR[row, take[row, slot]]
            )
            modes = _unrows(flat, mean.shape[:3])
    else:
        beta = association.jpda(inn, gated, pd, dens, settings.gate_probability)
        unused = association.unused_jpda(gated, ok)
        beta = _firm(beta, (book.status == TENTATIVE).reshape(P, K))
        if modes is None:
            new_mean, new_cov = association.pda_update(m, P_, zz, RR, beta)
        else:
            modes = _unrows(
                _imm_pda(_rows(modes, P), zz, RR, beta, gated, pd, dens, settings), mean.shape[:3]
            )
    if modes is not None:
        new_mean, new_cov = estimation.combine(modes)
    new_mean, new_cov = new_mean.reshape(mean.shape), new_cov.reshape(cov.shape)
    near = (inn.d2 <= association.threshold(BIRTH_GATE)) & ok[:, None, :]
    near &= present.reshape(P, K, 1)
    unused &= ~near.any(axis=1)
    met = gated.any(axis=-1).reshape(B, N, K) & in_view
    before = book
    book = _count(book, met, in_view, new_cov, scenario, new_mean)
    book = replace(book, stamp=np.where(met, k, book.stamp))
    lost = (
        (before.status == CONFIRMED)
        & (book.status == EMPTY)
        & (before.misses + 1 >= settings.delete_misses)
        & in_view
    )
    dead = np.where(lost, before.label, -1)
    new_mean = np.where(present[..., None], new_mean, mean)
    new_cov = np.where(present[..., None, None], new_cov, cov)
    coast = in_view & book.confirmed & ~gated.any(axis=-1).reshape(B, N, K)
    jump = estimation.process_noise(scenario.dt, MANOEUVRE_STD, MANOEUVRE_STD)
    new_cov = np.where(coast[..., None, None], new_cov + jump, new_cov)
    book, new_mean, new_cov, born = _births(
        book, new_mean, new_cov, zz, RR, unused, scenario.n_targets,
        settings.birth_velocity_std, team or (0, N),
    )  # fmt: skip
    book = replace(book, stamp=np.where(born, k, book.stamp))
    if modes is not None:
        if tracker is None:
            raise ValueError("modes given without their tracker")
        modes = restart(modes, born, new_mean, new_cov, tracker)
    return Scanned(
        mean=new_mean,
        cov=new_cov,
        book=book,
        met=met,
        in_view=in_view,
        born=born,
        modes=modes,
        dead=dead,
    )


def _firm(beta: np.ndarray, tentative: np.ndarray) -> np.ndarray:
    """JPDA's weights (P, K, Z + 1) with each tentative track's put on its most probable
    hypothesis: a track that may not exist is updated on one measurement or none, as GNN
    would, since the mixture of a clutter-born track spreads its covariance over every
    measurement in its gate, which widens the gate, gathers more clutter and confirms it."""
    if not tentative.any():
        return beta
    firm = np.zeros_like(beta)
    np.put_along_axis(firm, np.argmax(beta, axis=-1)[..., None], 1.0, axis=-1)
    return np.where(tentative[..., None], firm, beta)


def restart(
    modes: estimation.Modes,
    where: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    tracker: estimation.Tracker,
) -> estimation.Modes:
    """Every mode of the slots `where` (B, N, K) at the estimate there (mean, cov), at
    the stationary mode probabilities: a track new to its UAV."""
    if not where.any():
        return modes
    fresh = tracker.start(mean, cov)[2]
    assert fresh is not None
    pick = where[..., None]
    return estimation.Modes(
        np.where(pick[..., None], fresh.mean, modes.mean),
        np.where(pick[..., None, None], fresh.cov, modes.cov),
        np.where(pick, fresh.prob, modes.prob),
    )


def _rows(modes: estimation.Modes, P: int) -> estimation.Modes:
    M = modes.prob.shape[-1]
    K = modes.prob.shape[-2]
    return estimation.Modes(
        modes.mean.reshape(P, K, M, 4),
        modes.cov.reshape(P, K, M, 4, 4),
        modes.prob.reshape(P, K, M),
    )


def _unrows(modes: estimation.Modes, lead: tuple[int, ...]) -> estimation.Modes:
    M = modes.prob.shape[-1]
    return estimation.Modes(
        modes.mean.reshape(lead + (M, 4)),
        modes.cov.reshape(lead + (M, 4, 4)),
        modes.prob.reshape(lead + (M,)),
    )


def _imm_pda(
    modes: estimation.Modes,
    z: np.ndarray,
    R: np.ndarray,
    beta: np.ndarray,
    gated: np.ndarray,
    pd: np.ndarray,
    density: np.ndarray,
    settings: TrackerModel,
) -> estimation.Modes:
    """The IMM-PDA update of `scan`'s docstring, rows (P, K, M, ...)."""
    P, K, M = modes.prob.shape
    flat_mean = modes.mean.reshape(P, K * M, 4)
    flat_cov = modes.cov.reshape(P, K * M, 4, 4)
    wide = np.repeat(beta, M, axis=1)  # every mode of a track: its track's weights
    mean, cov = association.pda_update(flat_mean, flat_cov, z, R, wide)
    inn = association.innovations(flat_mean, flat_cov, z, R)
    lik = np.where(np.repeat(gated, M, axis=1), np.exp(inn.log_lik), 0.0).sum(axis=-1)
    detect = np.repeat(np.broadcast_to(pd, (P, K)), M, axis=1)
    L = 1.0 - detect * settings.gate_probability + detect / density[:, None] * lik
    post = modes.prob * L.reshape(P, K, M)
    total = post.sum(axis=-1, keepdims=True)
    prob = np.where(total > 0, post / np.where(total > 0, total, 1.0), modes.prob)
    return estimation.Modes(mean.reshape(P, K, M, 4), cov.reshape(P, K, M, 4, 4), prob)


def _count(
    book: Book,
    met: np.ndarray,
    in_view: np.ndarray,
    cov: np.ndarray,
    scenario: Scenario,
    mean: np.ndarray | None = None,
) -> Book:
    """M-of-N confirmation and deletion (step 3): met (B, N, K), a measurement in the
    track's gate while in view; mean (B, N, K, 4) the tracks' estimates (None: no
    deletion by place), a track farther outside the field than `OUTSIDE` is deleted."""
    tracker = scenario.tracker
    outside = np.zeros(met.shape, dtype=bool)
    if mean is not None:
        margin = OUTSIDE * scenario.field_size
        xy = mean[..., :2]
        outside = ((xy < -margin) | (xy > scenario.field_size + margin)).any(axis=-1)
    M, Nc = tracker.confirm
    tentative = book.status == TENTATIVE
    hits = book.hits + (tentative & met)
    scans = book.scans + (tentative & in_view)
    misses = np.where(met, 0, book.misses + in_view)
    status = book.status.copy()
    status[tentative & (hits >= M)] = CONFIRMED
    hopeless = tentative & (hits + (Nc - scans) < M)
    lost = (book.status == CONFIRMED) & (misses >= tracker.delete_misses)
    spread = np.sqrt(cov[..., 0, 0] + cov[..., 1, 1]) > tracker.delete_std
    gone = (hopeless | lost | spread | outside) & book.present
    status[gone] = EMPTY
    return replace(
        book,
        label=np.where(gone, -1, book.label),
        status=status,
        hits=np.where(gone, 0, hits),
        scans=np.where(gone, 0, scans),
        misses=np.where(gone, 0, misses),
    )


def _births(
    book: Book,
    mean: np.ndarray,
    cov: np.ndarray,
    z: np.ndarray,
    R: np.ndarray,
    unused: np.ndarray,
    n_targets: int,
    velocity_std: float,
    team: tuple[int, int],
) -> tuple[Book, np.ndarray, np.ndarray, np.ndarray]:
    """Tentative tracks from the measurements no track claimed (step 4): the r-th unused
    measurement of a row, by position (x, then y), goes to its r-th empty slot and takes
    its r-th new label, so that the order in which a scan arrives changes nothing. The
    s-th birth of UAV i of a team of n takes label n_targets + s n + i (team: (the index
    of the UAV of the first row, n)): unique in the team without a word exchanged."""
    B, N, K = book.label.shape
    P = B * N
    empty = (book.status == EMPTY).reshape(P, K)
    slot_rank = np.cumsum(empty, axis=1) - 1
    order = np.lexsort((z[..., 1], z[..., 0], ~unused), axis=-1)  # unused first, by place
    meas_rank = np.empty(unused.shape, dtype=np.int64)
    np.put_along_axis(meas_rank, order, np.arange(unused.shape[1])[None, :], axis=1)
    n_born = np.minimum(unused.sum(axis=1), empty.sum(axis=1))  # (P,)
    take = unused & (meas_rank < n_born[:, None])
    row, which = np.nonzero(take)
    rank = meas_rank[row, which]
    # the slot of each birth: the rank-th empty slot of its row
    _, eslot = np.nonzero(empty & (slot_rank < n_born[:, None]))
    slot = np.empty_like(row)
    order = np.lexsort((rank, row))
    slot[order] = eslot  # both sorted by (row, rank): births and the slots they fill
    serial = book.serial.reshape(P)
    first, size = team
    label = n_targets + (serial[row] + rank) * size + first + row % N
    mean, cov = mean.reshape(P, K, 4).copy(), cov.reshape(P, K, 4, 4).copy()
    mean[row, slot] = 0.0
    mean[row, slot, :2] = z[row, which]
    cov[row, slot] = 0.0
    cov[row, slot, :2, :2] = R[row, which]
    cov[row, slot, 2, 2] = cov[row, slot, 3, 3] = velocity_std**2
    out = {
        name: getattr(book, name).reshape(P, K).copy()
        for name in ("label", "status", "hits", "scans", "misses")
    }
    out["label"][row, slot] = label
    out["status"][row, slot] = TENTATIVE
    out["hits"][row, slot] = 1
    out["scans"][row, slot] = 1
    out["misses"][row, slot] = 0
    born = np.zeros((P, K), dtype=bool)
    born[row, slot] = True
    new_book = Book(
        **{name: value.reshape(B, N, K) for name, value in out.items()},
        serial=(serial + n_born).reshape(B, N),
        stamp=book.stamp,
    )
    return new_book, mean.reshape(B, N, K, 4), cov.reshape(B, N, K, 4, 4), born.reshape(B, N, K)


def unissued(label: np.ndarray, serial: int, n_targets: int, team: tuple[int, int]) -> np.ndarray:
    """Which labels (...,) are UAV i's own that it has not issued yet: n_targets + s n + i
    with s >= serial (team: (i, n)). No honest UAV holds one, since only i issues them,
    and a UAV that took one would issue it again at a later birth, holding it twice: a
    receiver leaves such offered tracks out (the agent form, `agents.tracked`)."""
    me, n = team
    own = (label >= n_targets) & ((label - n_targets) % n == me)
    return own & ((label - n_targets) // n >= serial)


def after_fusion(
    book: Book,
    label: np.ndarray,
    status: np.ndarray,
    changed: np.ndarray,
    scenario: Scenario,
    stamp: np.ndarray | None = None,
) -> Book:
    """The book after the team's fusion (`team.agree`): each slot's label and status as
    agreed; a track new to the UAV (changed 2) starts its counters afresh (confirmed, no
    misses), an emptied slot (3) clears them; a fused one (1) keeps its own."""
    fresh = (changed == 2) | (changed == 3)
    return replace(
        book,
        label=label,
        status=status.astype(np.int8),
        hits=np.where(fresh, 0, book.hits),
        scans=np.where(fresh, 0, book.scans),
        misses=np.where(fresh, 0, book.misses),
        stamp=book.stamp if stamp is None else stamp,
    )


def broadcast(book: Book, n: int) -> Book:
    """A central node's book (B, 1, K) as every one of n UAVs' (B, n, K)."""
    return Book(
        **{
            name: np.repeat(getattr(book, name), n, axis=1)
            for name in ("label", "status", "hits", "scans", "misses", "stamp")
        },
        serial=np.repeat(book.serial, n, axis=1),
    )


def where(take: np.ndarray, a: Book, b: Book) -> Book:
    """Per UAV (take (B, N) bool) the slots of book a, else those of b."""
    pick = take[..., None]
    return Book(
        **{
            name: np.where(pick, getattr(a, name), getattr(b, name))
            for name in ("label", "status", "hits", "scans", "misses", "stamp")
        },
        serial=np.where(take, a.serial, b.serial),
    )
