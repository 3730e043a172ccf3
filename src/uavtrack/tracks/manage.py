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

from dataclasses import dataclass, field, replace

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
    of each UAV so far, stamp (B, N, K) int64, the last step a measurement met the
    track anywhere in the team as far as the UAV knows (`team.TrackSet`), existence
    (B, N, K) float64, the track's probability of existence (``tracker.confirmation =
    "existence"``; carried but unread under m_of_n), and close (B, N, K) int64, the scans
    in view in a row the track lay inside another's position gate (``tracker.merge``);
    both are zeros when not given."""

    label: np.ndarray
    status: np.ndarray
    hits: np.ndarray
    scans: np.ndarray
    misses: np.ndarray
    serial: np.ndarray
    stamp: np.ndarray
    existence: np.ndarray = field(default_factory=lambda: np.zeros(0))
    close: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def __post_init__(self) -> None:  # a book made without them: no existence, no count
        for name in ("existence", "close"):
            value = getattr(self, name)
            if value.shape != self.label.shape:
                if value.size:
                    raise ValueError(f"book {name} {value.shape} is not label's {self.label.shape}")
                object.__setattr__(self, name, np.zeros(self.label.shape, dtype=value.dtype))

    @property
    def present(self) -> np.ndarray:
        return self.status != EMPTY

    @property
    def confirmed(self) -> np.ndarray:
        return self.status == CONFIRMED


SLOT_FIELDS = ("label", "status", "hits", "scans", "misses", "stamp", "existence", "close")
"""The fields of a `Book` with one value per slot (serial has one per UAV)."""

BRIEFED_EXISTENCE = 0.99
"""The existence probability of a briefed target's track (``tracker.confirmation =
"existence"``): the briefing says the target is there, but not 1, from which no miss
could ever lower it."""


EXISTENCE_CAP = 0.999
"""The largest existence probability a track takes. Uncapped, a track met for a while
reaches 1 to rounding, and the misses of a target gone (each multiplies the odds
r / (1 - r) by 1 - P_D P_G) would take tens of scans to delete it; from 0.999, five
misses in view in a row at P_D 0.9 fall below a deletion threshold of 0.05, as
likely for a target that is there (1e-5) as three misses of the M-of-N rule at P_D 0.7."""


def sent_fields(settings: TrackerModel) -> tuple[str, ...]:
    """The `Book` fields beyond M-of-N's a central node's download carries: existence
    with ``tracker.confirmation = "existence"``, close with ``tracker.merge``; a run
    without them sends the bytes it always sent."""
    return ("existence",) * (settings.confirmation == "existence") + ("close",) * bool(
        settings.merge
    )


def briefed(
    mean: np.ndarray, cov: np.ndarray, slots: int, briefing: bool = True
) -> tuple[Book, np.ndarray, np.ndarray]:
    """The mission's start: each UAV's prior of each target (mean (B, N, M, 4), cov
    (B, N, M, 4, 4)) as its confirmed tracks 0 .. M - 1 in the first M of `slots` slots;
    without `briefing` (``tracker.briefing``) no track at all. Returns (book, mean
    (B, N, K, 4), cov (B, N, K, 4, 4)); empty slots hold 0 and I."""
    if not briefing:
        mean, cov = mean[:, :, :0], cov[:, :, :0]
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
        existence=np.where(status == CONFIRMED, BRIEFED_EXISTENCE, 0.0),
        close=zeros.copy(),
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
    exists = settings.confirmation == "existence"
    r = book.existence.reshape(P, K)
    weigh = pd * r if exists else pd  # JIPDA: a track detected only if it exists
    new_mean, new_cov = m, P_  # updated below: by the filter, or as the modes combine
    beta = None
    if settings.association == "gnn":  # which measurement, given that the track exists
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
        beta = association.jpda(inn, gated, weigh, dens, settings.gate_probability)
        unused = association.unused_jpda(gated, ok)
    if exists:
        after = existence_update(r, inn, gated, pd, dens, settings.gate_probability, beta)
        book = replace(book, existence=np.where(present, after.reshape(B, N, K), book.existence))
        if beta is not None:  # the state is updated given that the track exists
            beta = given_existence(beta, r, pd, settings.gate_probability)
    if beta is not None:
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
    if exists:  # a confirmed track whose existence fell below the threshold where it was looked for
        missing = before.existence < settings.existence[1]
    else:
        missing = before.misses + 1 >= settings.delete_misses
    lost = (before.status == CONFIRMED) & (book.status == EMPTY) & missing & in_view
    dead = np.where(lost, before.label, -1)
    new_mean = np.where(present[..., None], new_mean, mean)
    new_cov = np.where(present[..., None, None], new_cov, cov)
    if settings.merge:
        book = merge(book, new_mean, new_cov, in_view, settings)
    coast = in_view & book.confirmed & ~gated.any(axis=-1).reshape(B, N, K)
    jump = estimation.process_noise(scenario.dt, MANOEUVRE_STD, MANOEUVRE_STD)
    new_cov = np.where(coast[..., None, None], new_cov + jump, new_cov)
    book, new_mean, new_cov, born = _births(
        book, new_mean, new_cov, zz, RR, unused, scenario.n_targets,
        settings.birth_velocity_std, team or (0, N),
    )  # fmt: skip
    book = replace(
        book,
        existence=np.where(born, settings.birth_existence, book.existence),
        close=np.where(born, 0, book.close),
    )
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
    if tracker.confirmation == "existence":  # thresholds on the existence probability
        confirm, delete = tracker.existence
        status[tentative & (book.existence >= confirm)] = CONFIRMED
        hopeless = tentative & (book.existence < delete)
        lost = (book.status == CONFIRMED) & (book.existence < delete)
    else:
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
        existence=np.where(gone, 0.0, book.existence),
        close=np.where(gone, 0, book.close),
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
        existence=book.existence,
        close=book.close,
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
    # a track confirmed by the team (adopted, or a tentative one fused with a confirmed
    # offer) exists at least as surely as a confirmation says
    confirmed = (status == CONFIRMED) & ((changed == 2) | (book.status != CONFIRMED))
    floor = scenario.tracker.existence[0]
    existence = np.where(confirmed, np.maximum(book.existence, floor), book.existence)
    return replace(
        book,
        label=label,
        status=status.astype(np.int8),
        hits=np.where(fresh, 0, book.hits),
        scans=np.where(fresh, 0, book.scans),
        misses=np.where(fresh, 0, book.misses),
        stamp=book.stamp if stamp is None else stamp,
        existence=np.where(changed == 3, 0.0, np.where(changed == 2, floor, existence)),
        close=np.where(fresh, 0, book.close),
    )


def broadcast(book: Book, n: int) -> Book:
    """A central node's book (B, 1, K) as every one of n UAVs' (B, n, K)."""
    return Book(
        **{name: np.repeat(getattr(book, name), n, axis=1) for name in SLOT_FIELDS},
        serial=np.repeat(book.serial, n, axis=1),
    )


def where(take: np.ndarray, a: Book, b: Book) -> Book:
    """Per UAV (take (B, N) bool), or per slot (take (B, N, K)), the slots of book a,
    else those of b; a UAV's serial is a's where it takes any slot of a."""
    pick = take if take.ndim == 3 else take[..., None]
    return Book(
        **{name: np.where(pick, getattr(a, name), getattr(b, name)) for name in SLOT_FIELDS},
        serial=np.where(pick.any(axis=-1), a.serial, b.serial),
    )


def existence_update(
    r: np.ndarray,
    inn: association.Innovations,
    gated: np.ndarray,
    pd: np.ndarray,
    density: np.ndarray,
    gate_probability: float,
    beta: np.ndarray | None = None,
) -> np.ndarray:
    """Each track's existence probability after a scan, r (P, K) before it.

    Without `beta` (gnn), the integrated PDA's (Musicki, Evans and Stankovic, IEEE TAC
    1994): r' = L r / (1 - r + L r), L = 1 - P_D P_G + P_D / lambda sum_z N(z; H x, S)
    over the gated measurements. With the JIPDA weights `beta` (P, K, Z + 1) of the
    association, whose detection probability was P_D r: r' = (1 - beta_0) + beta_0 r
    (1 - P_D P_G) / (1 - P_D P_G r), the track detected or, missed, existing unseen;
    for a track alone in its cluster the two are the same. pd (P, K) is P_D where the
    track can be detected (0 elsewhere: r is unchanged), density (P,) lambda."""
    if beta is None:
        lik = np.where(gated, np.exp(inn.log_lik), 0.0).sum(axis=-1)
        L = 1.0 - pd * gate_probability + pd / density[:, None] * lik  # > 0: P_G < 1
        with np.errstate(over="ignore"):  # L = inf (no clutter): r' = 1
            after = r / (r + (1.0 - r) / L)
    else:
        after = (1.0 - beta[..., 0]) + beta[..., 0] * _unseen(r, pd, gate_probability)
    return np.where(r > 0, np.minimum(after, EXISTENCE_CAP), r)


def given_existence(
    beta: np.ndarray, r: np.ndarray, pd: np.ndarray, gate_probability: float
) -> np.ndarray:
    """JIPDA's weights beta (P, K, Z + 1), computed with P_D r, conditioned on the track's
    existence (Musicki and Evans 2004): beta_j / r' for a measurement and beta_0 r (1 -
    P_D P_G) / (1 - P_D P_G r) / r' for the miss, r' = (1 - beta_0) + beta_0 r (1 - P_D
    P_G) / (1 - P_D P_G r) the existence after the scan (uncapped). The state's update
    reads these: a track that may not exist still takes the measurement it would take
    if it did. Rows with r' = 0 (no track) keep their weights."""
    out = beta.copy()
    out[..., 0] = beta[..., 0] * _unseen(r, pd, gate_probability)
    total = out.sum(axis=-1, keepdims=True)
    return np.where(total > 0, out / np.where(total > 0, total, 1.0), beta)


def _unseen(r: np.ndarray, pd: np.ndarray, gate_probability: float) -> np.ndarray:
    """P(the track exists | it was missed) = r (1 - P_D P_G) / (1 - P_D P_G r)."""
    detect = pd * gate_probability
    return (1.0 - detect) * r / np.maximum(1.0 - detect * r, np.finfo(float).tiny)


def survive(book: Book, scenario: Scenario) -> Book:
    """Each track's existence predicted one step (``tracker.survival``); the book as it
    is under ``tracker.confirmation = "m_of_n"``. Called where the tracks are
    predicted: the simulator's and the agents' cycles, the central node's."""
    settings = scenario.tracker
    if settings.confirmation != "existence":
        return book
    return replace(book, existence=book.existence * settings.survival)


def merge(
    book: Book, mean: np.ndarray, cov: np.ndarray, in_view: np.ndarray, settings: TrackerModel
) -> Book:
    """Tracks of one row that hold one target, merged (``tracker.merge`` = W scans).

    Two present tracks in view are close when their position difference lies inside the
    gate of the sum of their position covariances (d2 <= chi2.ppf(P_G, 2)); a track's
    `close` counts the scans in view in a row it was close to another (a scan out of view
    leaves it). Close tracks whose counts both reached W are one target's: each group of
    them (connected by closeness) keeps its most confident track (1/trace P; ties: the
    smaller label), which takes the group's smallest label, its newest stamp, its
    largest existence, and is confirmed if any was; the others are emptied. A target
    followed twice is then followed once, under the label the team knew first; two
    targets crossing stay apart, since two sure tracks a few metres apart are far
    outside each other's gate, and one that a UAV lost coasts with a wide gate for
    fewer than W scans in view before it is deleted."""
    B, N, K = book.label.shape
    P = B * N
    look = (book.present & in_view).reshape(P, K)
    V = int(look.sum(axis=1).max()) if P else 0
    if V < 2:
        return replace(book, close=np.where(in_view, 0, book.close))
    order = np.argsort(~look, axis=1, kind="stable")[:, :V]  # the slots in view first
    ok = np.take_along_axis(look, order, axis=1)
    xy = np.take_along_axis(mean.reshape(P, K, 4)[..., :2], order[..., None], axis=1)
    pp = cov.reshape(P, K, 4, 4)[..., :2, :2]
    pp = np.take_along_axis(pp, order[..., None, None], axis=1)
    d = xy[:, :, None] - xy[:, None, :]  # (P, V, V, 2)
    S = pp[:, :, None] + pp[:, None, :]
    det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
    d2 = (S[..., 1, 1] * d[..., 0] ** 2 - 2 * S[..., 0, 1] * d[..., 0] * d[..., 1]
          + S[..., 0, 0] * d[..., 1] ** 2) / np.maximum(det, np.finfo(float).tiny)  # fmt: skip
    near = (d2 <= association.threshold(settings.gate_probability)) & ok[:, :, None] & ok[:, None]
    near &= ~np.eye(V, dtype=bool)
    row = np.arange(P)[:, None]
    close = book.close.reshape(P, K).copy()
    counted = np.where(near.any(axis=-1), close[row, order] + 1, 0)
    close[row, order] = np.where(ok, counted, close[row, order])
    ripe = ok & (counted >= settings.merge)
    pair = near & ripe[:, :, None] & ripe[:, None, :]
    out = {name: getattr(book, name).reshape(P, K).copy() for name in SLOT_FIELDS}
    out["close"] = close
    if pair.any():
        p, a, b = np.nonzero(pair)
        n_groups, group = association.components(p * V + a, p * V + b, P * V)
        members = np.unique(np.concatenate([p * V + a, p * V + b]))
        g = group[members]
        mp, mv = members // V, members % V
        slot = order[mp, mv]
        lab = out["label"][mp, slot]
        trace = cov.reshape(P, K, 4, 4)[mp, slot].trace(axis1=-2, axis2=-1)
        keep = np.zeros(n_groups, dtype=np.int64)  # the most confident member of each group
        first = np.lexsort((lab, trace, g))
        starts = np.r_[True, g[first][1:] != g[first][:-1]]
        keep[g[first][starts]] = first[starts]
        smallest = np.full(n_groups, np.iinfo(np.int64).max)
        np.minimum.at(smallest, g, lab)
        newest = np.full(n_groups, np.iinfo(np.int64).min)
        np.maximum.at(newest, g, out["stamp"][mp, slot])
        surest = np.zeros(n_groups)
        np.maximum.at(surest, g, out["existence"][mp, slot])
        sure = np.zeros(n_groups, dtype=bool)
        np.logical_or.at(sure, g, out["status"][mp, slot] == CONFIRMED)
        gone = np.ones(members.size, dtype=bool)
        gone[keep[g[first][starts]]] = False
        for name in ("label", "status", "hits", "scans", "misses", "stamp", "existence", "close"):
            out[name][mp[gone], slot[gone]] = -1 if name == "label" else 0
        w = keep[g[first][starts]]
        gw = g[w]
        out["label"][mp[w], slot[w]] = smallest[gw]
        out["stamp"][mp[w], slot[w]] = newest[gw]
        out["existence"][mp[w], slot[w]] = surest[gw]
        out["status"][mp[w], slot[w]] = np.where(sure[gw], CONFIRMED, out["status"][mp[w], slot[w]])
        out["close"][mp[w], slot[w]] = 0
    return replace(book, **{name: value.reshape(B, N, K) for name, value in out.items()})


def weighed(bids: np.ndarray, book: Book, scenario: Scenario) -> np.ndarray:
    """Each slot's bid (B, N, K) times its track's existence probability with
    ``planner.existence``: the information a UAV expects from a track that may not be
    there (all of it if it is, none if not). Unchanged otherwise. Called by the
    simulator's, the agents' and the central node's planning."""
    if not scenario.planner.existence:
        return bids
    return bids * book.existence
