"""Distributed fusion by max-consensus with per-UAV stopping (eqs. 26-27, Theorem 1).

Per target j, UAV i repeatedly adopts, among itself and its one-hop neighbours, the
(estimate, covariance, confidence) tuple with the highest confidence (eq. 27,
Algorithm 2 lines 17-24). UAV i runs D_i rounds, D_i the depth of the shortest-path
tree rooted at i in its connected component (its eccentricity); Theorem 1 shows that
this is the fewest rounds after which i holds its component's maximum.

The UAVs do not read the global graph: D_i is learned by a flooding protocol in
which each UAV sends its neighbours the set of UAV identifiers it knows to be within
reach (`learn_depth`). A UAV that has finished its rounds keeps relaying its final
tuple to neighbours still iterating: on the path m - j - i, j needs one round but i
needs two, and receives m's value only through j. Messages travel along links only,
so nothing crosses from one component to another.

The module has two layers:

* the per-round, per-receiver rules `flood` and `adopt`: what one UAV does with what
  it received, given ``delivered``, the links its messages crossed (`network.Links`, in
  the dense or the edge-list form);
* the drivers `learn_depth` and `consensus`, which run rounds over a `radio.Radio`
  (with its faults: lost and late messages, a round budget) and count messages.

`eccentricity`, `consensus_rounds`, `fuse` and `max_consensus` run the same drivers on
a plain graph with a perfect radio. All functions broadcast over a leading trial axis.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields

import numpy as np

from . import network
from .faults import Faults
from .radio import Inbox, Radio, RadioState

# ------------------------------------------------------------------ the tuples


@dataclass(frozen=True, kw_only=True)
class Estimates:
    """The consensus tuples: per (UAV, target), the estimate a UAV holds and what travels
    with it. Leading axes (B, N, M) [trial, UAV, target] in the batch, (M,) in an agent
    (a stack of candidates (1, n, M) while it adopts); a field is None where an exchange
    does not carry it.

    gamma: (B, N, M) the confidence 1 / trace P (eq. 22); -inf: no estimate.
    mean: (B, N, M, 4) the estimate [m, m/s], when tuples travel by value.
    cov: (B, N, M, 4, 4) its covariance P.
    stamp: (B, N, M) int, the step the estimate is of (with delay, an earlier cycle's).
    source: (B, N, M) int, the UAV whose local estimate it is: without delay the tuples
    travel as this index, the estimate looked up where it is needed (`gather`).
    origin: (B, N, M) int, the same sent by value with an agent's tuple
    (`agents.messages.Spec`).
    """

    gamma: np.ndarray | None = None
    mean: np.ndarray | None = None
    cov: np.ndarray | None = None
    stamp: np.ndarray | None = None
    source: np.ndarray | None = None
    origin: np.ndarray | None = None

    def items(self) -> list[tuple[str, np.ndarray]]:
        """The fields carried, (name, array), in the order above (that of a message's
        content)."""
        return [(f.name, v) for f in fields(self) if (v := getattr(self, f.name)) is not None]

    def map(self, f: Callable[[np.ndarray], np.ndarray]) -> Estimates:
        """`f` of every field carried."""
        return Estimates(**{name: f(value) for name, value in self.items()})

    @classmethod
    def of(cls, content: Mapping[str, np.ndarray]) -> Estimates:
        """The tuple fields of a message's content (its other entries left out)."""
        return cls(**{f.name: content[f.name] for f in fields(cls) if f.name in content})


def required(value: np.ndarray | None, name: str) -> np.ndarray:
    """A field of `Estimates` that the exchange at hand carries (`name` for the error):
    tuples by value carry mean and cov, tuples by index their source, and so on. A
    record without it is a caller's mistake, reported here rather than as an operation
    on None further on."""
    if value is None:
        raise ValueError(f"the consensus tuples carry no {name}")
    return value


# ------------------------------------------------------------------ the rules


def flood(known: np.ndarray, offered: np.ndarray, delivered: network.Links) -> np.ndarray:
    """One round of the D_i protocol for every receiver: K_i <- K_i united with the
    sets K_q offered by the other senders whose message was delivered (a receiver's own
    set is its current one, not what it offered, which with delay is an old one).

    known, offered: (B, N, N) bool [trial, UAV, identifier]. Returns (B, N, N) bool.
    In the edge form only the receivers with links (`network.Links.into`) can grow.
    """
    if delivered.edges:  # one segment per receiver, its self-link included
        t, i, q = delivered.edge_list
        out = known.copy()
        if t.size:
            if known is offered:  # without delay a self-link offers the current set
                rows = offered[t, q]
            else:
                rows = np.where(delivered.own[:, None], known[t, i], offered[t, q])
            heard = np.logical_or.reduceat(rows, delivered.starts, axis=0)
            out[delivered.heads] = heard
        return out
    grown = np.matmul(delivered.others, offered.astype(np.float64)) > 0
    return known | grown


def adopt(
    own: np.ndarray,
    offered: np.ndarray,
    delivered: network.Links,
    admitted: np.ndarray | None = None,
) -> np.ndarray:
    """One round of eq. (27) for every receiver: per target, the sender whose tuple has
    the highest confidence among the receiver itself (its own current tuple) and the
    senders whose message was delivered (their offered tuple); ties go to the lowest
    sender index. A tuple of confidence -inf (no estimate) is never adopted.

    own, offered: (B, N, M) confidences; admitted: which tuples each receiver may adopt
    (`gate.admitted`, in the layout of `delivered`; None: all); a receiver with none
    keeps its own. Returns (B, N, M) the chosen sender (the receiver's own index: keep
    its tuple). In the edge form a receiver without links (`network.Links.into`) keeps
    its own.
    """
    n = own.shape[1]
    if delivered.edges:  # one segment per receiver, its self-link included
        t, i, q = delivered.edge_list
        best = identity(own.shape)
        if t.size:
            if own is offered:  # without delay a self-link offers the current tuple
                values = offered[t, q]  # (E, M)
            else:
                values = np.where(delivered.own[:, None], own[t, i], offered[t, q])
            if admitted is not None:
                values = np.where(admitted, values, -np.inf)
            top = np.maximum.reduceat(values, delivered.starts, axis=0)
            lowest = np.where(values == top[delivered.ordinal], q[:, None], n)
            chosen = np.minimum.reduceat(lowest, delivered.starts, axis=0)
            if admitted is not None:  # nothing to adopt: keep its own
                chosen = np.where(np.isneginf(top), delivered.heads[1][:, None], chosen)
            best[delivered.heads] = chosen
        return best
    values = offered[:, None, :, :] + delivered.penalty
    if own is not offered:  # what a UAV offered is not its current tuple (delay)
        idx = np.arange(n)
        values[:, idx, idx] = own
    if admitted is None:
        return np.argmax(values, axis=-2)  # first maximum = lowest index
    values = np.where(admitted, values, -np.inf)
    best = np.argmax(values, axis=-2)
    none = np.isneginf(np.max(values, axis=-2))
    return np.where(none, np.arange(n)[:, None], best)


def intersect(
    mean: np.ndarray, cov: np.ndarray, weight: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Covariance intersection of n estimates with convex weights (Julier and Uhlmann):
    P^-1 = sum_i w_i P_i^-1, x = P sum_i w_i P_i^-1 x_i.

    Whatever the correlation between the estimates, the result is consistent if each of
    them is (P is then an upper bound of the fused error's covariance). mean (..., n, 4),
    cov (..., n, 4, 4), weight (..., n) non-negative, summing to 1 (an estimate of weight
    0 takes no part). Returns (..., 4) and (..., 4, 4).
    """
    info = np.linalg.inv(cov) * weight[..., None, None]  # w_i P_i^-1
    fused_info = info.sum(axis=-3)
    vector = np.einsum("...nij,...nj->...i", info, mean)
    fused = np.linalg.inv(fused_info)
    fused = 0.5 * (fused + np.swapaxes(fused, -1, -2))
    return np.einsum("...ij,...j->...i", fused, vector), fused


def fast_weights(cov: np.ndarray, present: np.ndarray) -> np.ndarray:
    """The closed-form weights of fast covariance intersection (Niehsen 2002, for n
    estimates Franken and Huepper 2005): w_i proportional to 1 / trace(P_i), the
    confidence of eq. (22), among the estimates `present`. cov (..., n, 4, 4), present
    (..., n) bool with at least one True. Returns (..., n)."""
    gamma = np.where(present, 1.0 / np.trace(cov, axis1=-2, axis2=-1), 0.0)
    return gamma / gamma.sum(axis=-1, keepdims=True)


def intersect_round(
    own: Estimates,
    offered: Estimates,
    delivered: network.Links,
    admitted: np.ndarray | None = None,
) -> Estimates:
    """One round of covariance intersection for every receiver (`fusion.rule` =
    covariance_intersection, beside `adopt`): per target, the receiver's own current
    estimate and the estimates delivered to it, fused by `intersect` with the weights of
    `fast_weights` (each proportional to its confidence 1 / trace P).

    own, offered: `Estimates` with mean and cov; other fields keep the receiver's own.
    An estimate of confidence -inf (none) or not `admitted` (`gate.admitted`, in the
    layout of `delivered`; None: all) takes no part.
    Returns the receivers' new tuples, gamma the confidence of the fused covariance.
    A receiver that heard nobody, or has nothing to fuse, keeps its own.
    """
    from .estimation import confidence

    out = dict(own.items())
    usable = _usable(offered, own, delivered, admitted)
    own_mean, own_cov = required(own.mean, "mean"), required(own.cov, "cov")
    offered_mean, offered_cov = required(offered.mean, "mean"), required(offered.cov, "cov")
    if delivered.edges:  # one segment per receiver, its self-link included
        t, i, q = delivered.edge_list
        if not t.size:
            return own
        is_own = delivered.own[:, None]
        mean = np.where(is_own[..., None], own_mean[t, i], offered_mean[t, q])
        cov = np.where(is_own[..., None, None], own_cov[t, i], offered_cov[t, q])
        weight = 1.0 / np.trace(cov, axis1=-2, axis2=-1)  # (E, M)
        if usable is not None:
            weight = np.where(usable, weight, 0.0)
        info = np.linalg.inv(cov) * weight[..., None, None]
        vector = np.einsum("emij,emj->emi", info, mean)
        total = np.add.reduceat(weight, delivered.starts, axis=0)
        nothing = total == 0  # every estimate left out: the receiver keeps its own
        total = np.where(nothing, 1.0, total)
        fused_info = np.add.reduceat(info, delivered.starts, axis=0) / total[..., None, None]
        fused_vector = np.add.reduceat(vector, delivered.starts, axis=0) / total[..., None]
        if nothing.any():  # a placeholder, replaced by its own below
            fused_info[nothing] = np.eye(4)
        fused = np.linalg.inv(fused_info)
        fused = 0.5 * (fused + np.swapaxes(fused, -1, -2))
        heads = delivered.heads
        mean_out = np.einsum("smij,smj->smi", fused, fused_vector)
        if nothing.any():
            mean_out = np.where(nothing[..., None], own_mean[heads], mean_out)
            fused = np.where(nothing[..., None, None], own_cov[heads], fused)
        out["mean"], out["cov"] = own_mean.copy(), own_cov.copy()
        out["mean"][heads] = mean_out
        out["cov"][heads] = fused
    else:
        n = own_mean.shape[1]
        idx = np.arange(n)
        # candidates [trial, receiver, sender, target]: what each sender offered, and
        # on the diagonal the receiver's own current estimate
        mean = np.repeat(offered_mean[:, None], n, axis=1)
        cov = np.repeat(offered_cov[:, None], n, axis=1)
        mean[:, idx, idx], cov[:, idx, idx] = own_mean, own_cov
        present = np.broadcast_to(delivered.matrix[..., None], mean.shape[:-1])
        nothing = None  # with every candidate usable, none is left without
        if usable is not None:
            present = present & usable
            nothing = ~np.any(present, axis=2)
            present = present | (nothing[:, :, None] & np.eye(n, dtype=bool)[..., None])
        mean, cov, present = (np.moveaxis(x, 2, 3) for x in (mean, cov, present))
        out["mean"], out["cov"] = intersect(mean, cov, fast_weights(cov, present))
        if nothing is not None and nothing.any():  # exactly its own
            out["mean"] = np.where(nothing[..., None], own_mean, out["mean"])
            out["cov"] = np.where(nothing[..., None, None], own_cov, out["cov"])
    out["gamma"] = confidence(out["cov"])
    return Estimates(**out)


def _usable(
    offered: Estimates, own: Estimates, delivered: network.Links, admitted: np.ndarray | None
) -> np.ndarray | None:
    """Which candidate estimates may take part, in the layout of `delivered` (None:
    all): admitted, and of finite confidence."""
    gamma, mine = offered.gamma, own.gamma
    if gamma is None or mine is None:  # tuples without confidence (all finite, then)
        return admitted
    if admitted is None and np.isfinite(gamma).all() and np.isfinite(mine).all():
        return None
    t, i, q = delivered.pairs()
    if delivered.edges:
        value = np.where(delivered.own[:, None], mine[t, i], gamma[t, q])
    else:
        value = np.where((i == q)[..., None], mine[t, i], gamma[t, q])
    usable = np.isfinite(value)
    return usable if admitted is None else usable & admitted


def combine(
    rule: str,
    own: Estimates,
    offered: Estimates,
    delivered: network.Links,
    admitted: np.ndarray | None = None,
    score: Callable[[Estimates], np.ndarray] | None = None,
) -> Estimates:
    """One round of the consensus rule (``fusion.rule``) for every receiver: eq. (27),
    `adopt` then `pick`, each receiver taking per target the most confident of its own
    tuple and those delivered (`score`, default the confidence gamma); or
    covariance_intersection, `intersect_round`. The one function the batch's rounds
    (`consensus`) and each agent's (`agents.agent.UavAgent`) call."""
    if rule == "covariance_intersection":
        return intersect_round(own, offered, delivered, admitted)
    score = score if score is not None else (lambda t: required(t.gamma, "gamma"))
    best = adopt(score(own), score(offered), delivered, admitted)
    return pick(own, offered, best, delivered.heads if delivered.edges else None)


def pick(
    own: Estimates,
    offered: Estimates,
    best: np.ndarray,
    rows: tuple[np.ndarray, np.ndarray] | None = None,
) -> Estimates:
    """The tuples the receivers adopt: field by field, own[i] where best is i, else
    offered[best]. Fields are arrays (B, N, M, ...). rows: the (trial, receiver) index
    arrays of the only receivers whose choice may differ from their own (None: all)."""
    B, n, m = best.shape
    j = np.arange(m)
    if rows is None:
        b = np.arange(B)[:, None, None]
        keep = best == np.arange(n)[:, None]
    else:
        b, i = rows
        best, keep = best[b, i], best[b, i] == i[:, None]  # (R, M)
        b = b[:, None]
    out: dict[str, np.ndarray] = {}
    for name, value in own.items():
        chosen = getattr(offered, name)[b, best, j]
        mask = keep.reshape(keep.shape + (1,) * (chosen.ndim - keep.ndim))
        if rows is None:
            out[name] = np.where(mask, value, chosen)
        else:
            out[name] = value.copy()
            out[name][rows] = np.where(mask, value[rows], chosen)
    return Estimates(**out)


# ------------------------------------------------------------------ the drivers


@dataclass(frozen=True, kw_only=True)
class Depth:
    """Outcome of the D_i protocol: depth (B, N) rounds learned; sent and delivered (B,)
    messages (one per link into a receiver still running, per round); largest (B, N):
    the most members of any closed neighbourhood the UAV belongs to (its own and its
    neighbours'), learned in round 2 from the sets K_q(1) = N_q its neighbours send;
    ran (B, N): the rounds each UAV ran, the one it stopped in included."""

    depth: np.ndarray
    sent: np.ndarray
    delivered: np.ndarray
    largest: np.ndarray
    ran: np.ndarray


def learn_depth(radio: Radio, running: np.ndarray, budget: int | None = None) -> Depth:
    """D_i learned by flooding known identifiers to neighbours (Remark 1).

    After round r UAV i knows K_i(r), the UAVs within r hops: K_i(r) = K_i(r-1) united
    with the K_l(r-1) its neighbours l sent. The first round that teaches i nothing new
    shows its ball has covered its component, so i stops with D_i = r - 1: it needs no
    knowledge of the team size. A lost message can make that happen early. A UAV that
    stopped keeps answering its neighbours with the set it stopped with (without losses
    that set is its whole component, so nothing is lost by freezing it). With a round
    `budget`, a UAV still learning after `budget` rounds takes D_i = budget.

    running: (B, N) bool, the UAVs taking part (the living).
    """
    B, n = running.shape
    known = np.zeros((B, n, n), dtype=bool)
    idx = np.arange(n)
    known[:, idx, idx] = running  # K(0): each UAV knows itself
    depth = np.zeros((B, n), dtype=np.int64)
    ran = np.zeros((B, n), dtype=np.int64)
    largest = np.ones((B, n), dtype=np.int64)  # a UAV alone (it stops in round 1)
    sent, delivered = np.zeros(B, dtype=np.int64), np.zeros(B, dtype=np.int64)
    running = running.copy()
    r = 0
    while running.any():
        r += 1
        ran[running] = r
        radio.send("flood", {"known": known})
        inbox = radio.receive("flood", r)
        if inbox is None:  # nothing in flight yet: nothing to learn
            depth[running] = r - 1
            break
        sent, delivered = count(inbox, running, sent, delivered)
        links = inbox.delivered.into(running)
        if r == 2:  # the sets sent now are the senders' closed neighbourhoods
            mine, theirs = known.sum(axis=-1), inbox.content["known"].sum(axis=-1)
            best = adopt(mine[..., None], theirs[..., None], links)[..., 0]
            b = np.arange(B)[:, None]
            largest = np.where(best == idx, mine, theirs[b, best])
        grown = flood(known, inbox.content["known"], links)
        stopped = running & ~(grown != known).any(axis=-1)
        depth[stopped] = r - 1
        # a UAV that stopped keeps answering with what it knew when it stopped
        known = np.where(running[..., None], grown, known)
        running &= ~stopped
        if budget is not None and r >= budget:
            depth[running] = budget
            break
    radio.send("flood", {"known": known})  # the final sets, for later rounds (with delay)
    return Depth(depth=depth, sent=sent, delivered=delivered, largest=largest, ran=ran)


def count(
    inbox: Inbox, receiving: np.ndarray, sent: np.ndarray, delivered: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Add a round's messages to the totals (B,): one per link into a receiving UAV,
    sent over `inbox.links`, delivered over `inbox.delivered`."""
    into = inbox.links.incoming()
    now = np.einsum("bn,bn->b", into, receiving)
    if inbox.delivered is inbox.links:  # nothing lost
        return sent + now, delivered + now
    return sent + now, delivered + np.einsum("bn,bn->b", inbox.delivered.incoming(), receiving)


@dataclass(frozen=True, kw_only=True)
class Outcome:
    """Outcome of the consensus rounds: the tuples each UAV holds (`Estimates`), sent and
    delivered (B,) messages, and with `Sending` the tuples each UAV's message of round r
    carried, carried[r - 1] (B, N), and the confidence of the last tuple each UAV sent of
    each target this cycle, last (B, N, M) (NaN: none)."""

    tuples: Estimates
    sent: np.ndarray
    delivered: np.ndarray
    carried: list[np.ndarray] | None = None
    last: np.ndarray | None = None


@dataclass(frozen=True)
class Sending:
    """Which tuples a UAV's consensus messages carry (``fusion.trigger``, ``radio.encoding``
    compact): in round 1 those of `first` (B, N, M) bool (None: all); in a later round,
    with `changes`, only those that changed since its previous round (else all); past its
    rounds (from rounds + 1) it repeats its last round's message, as an agent's final
    message does. A tuple not carried is offered with confidence -inf: never adopted.

    Without losses this loses nothing in the later rounds: a tuple that did not change
    since the previous round was offered then, and max-consensus only ever raises a
    receiver's confidence, so it cannot win now what it did not win then: every UAV ends
    with the confidence sending everything gives, and with the same tuple unless
    confidences tie exactly (a re-offered tuple of equal confidence from a lower index
    would have taken the receiver's place). A property test holds both. What the first
    round leaves out (`triggered`) is never offered in the cycle: its receivers keep what
    they hold."""

    first: np.ndarray | None = None
    changes: bool = False
    view: Callable[[Estimates], tuple[np.ndarray, ...]] | None = None
    """What of a tuple counts as its change (arrays (B, N, M, ...)): by default every
    field; the batch's tuples by index give the values they stand for."""
    until: np.ndarray | None = None
    """The rounds (B, N) each UAV's share of a limited radio lets it send
    (`radio.Budget`): what it would have sent after them does not count as sent
    (`Outcome.last`); None: all."""

    def mask(self, r: int, tuples: Estimates, previous: Estimates | None) -> np.ndarray:
        """The tuples carried in round r from the current and the previous round's: only
        those with an estimate (a confidence above -inf)."""
        gamma = required(tuples.gamma, "gamma")
        has = np.isfinite(gamma)
        if r == 1 or previous is None:
            return has if self.first is None else self.first & has
        if not self.changes:
            return has
        view = self.view or (lambda t: tuple(value for _, value in t.items()))
        changed = np.zeros(gamma.shape, dtype=bool)
        for now, before in zip(view(tuples), view(previous), strict=True):
            changed |= (now != before).reshape(gamma.shape + (-1,)).any(axis=-1)
        return changed & has


def triggered(
    gamma: np.ndarray, told: np.ndarray | None, k: int, trigger: float, refresh: int
) -> np.ndarray | None:
    """``fusion.trigger``: the tuples (..., M) a UAV sends in a cycle's first round, those
    whose confidence `gamma` moved by more than `trigger` of the confidence it last sent,
    `told` (NaN: never sent); None (all) in a refresh cycle (k a multiple of `refresh`)
    or before anything was sent."""
    if told is None or k % refresh == 0:
        return None
    with np.errstate(invalid="ignore"):  # -inf - -inf: no estimate then and now
        moved = np.abs(gamma - told) > trigger * np.abs(told)
    return np.isnan(told) | moved


def carrying(tuples: Estimates, mask: np.ndarray) -> Estimates:
    """The tuples as a message carries them: those not in `mask` with confidence -inf."""
    gamma = required(tuples.gamma, "gamma")
    return dataclasses.replace(tuples, gamma=np.where(mask, gamma, -np.inf))


def consensus(
    radio: Radio,
    tuples: Estimates,
    rounds: np.ndarray,
    score: Callable[[Estimates], np.ndarray] | None = None,
    receive: Callable[[Estimates], Estimates] | None = None,
    rule: str = "max_consensus",
    admit: Callable[[Estimates, Estimates, network.Links], np.ndarray] | None = None,
    sending: Sending | None = None,
) -> Outcome:
    """Run the max-consensus update (27), UAV i for rounds[i] rounds, over the radio.

    In round t every UAV transmits its current tuple; UAV i with t <= rounds[i] adopts,
    per target, the tuple of highest confidence among its own and those delivered to it
    (`adopt`); UAVs past their rounds keep their tuple and keep transmitting.

    tuples: `Estimates` with gamma, (B, N, M) confidence; its other fields travel with
    the tuple (the index of the UAV whose estimate it is, or the estimate itself).
    score(tuples) gives the confidences compared (default tuples.gamma); receive(tuples)
    turns what arrives into what is compared and adopted (default: as it is). rule
    "covariance_intersection" fuses instead (`intersect_round`; the tuples then carry
    mean and cov). admit(own, offered, links): which offered tuples each receiver
    may adopt (`gate.admitted`; None: all). sending: which tuples the messages carry
    (`Sending`; None: all, the paper's).
    """
    score = score or (lambda t: required(t.gamma, "gamma"))
    B = rounds.shape[0]
    if rule not in ("max_consensus", "covariance_intersection"):
        raise ValueError(f"unknown fusion rule {rule!r}")
    sent, delivered = np.zeros(B, dtype=np.int64), np.zeros(B, dtype=np.int64)
    carried: list[np.ndarray] = []
    previous: Estimates | None = None
    frozen = last = None
    top = int(rounds.max(initial=0))
    for r in range(1, top + 2):
        content = tuples
        if sending is not None:
            mask = sending.mask(r, tuples, previous)
            if frozen is not None:  # past its rounds: its last round's message again
                mask = np.where(np.greater(r, rounds + 1)[..., None], frozen, mask)
            final = np.equal(r, rounds + 1)[..., None]
            frozen = mask if frozen is None else np.where(final, mask, frozen)
            gamma = required(tuples.gamma, "gamma")
            on_air = mask & np.less_equal(r, rounds + 1)[..., None]
            if sending.until is not None:
                on_air &= np.less_equal(r, sending.until)[..., None]
            last = np.full(gamma.shape, np.nan) if last is None else last
            last = np.where(on_air, gamma, last)
            carried.append(mask.sum(axis=-1))
            previous, content = tuples, carrying(tuples, mask)
        radio.send("consensus", content)  # after the last round: the final tuples
        if r > top:  # (for later rounds, with delay)
            break
        inbox = radio.receive("consensus", r)
        active = rounds >= r
        if inbox is None:
            continue
        offered: Estimates = inbox.content if receive is None else receive(inbox.content)
        sent, delivered = count(inbox, active, sent, delivered)
        links = inbox.delivered.into(active)
        admitted = None if admit is None else admit(tuples, offered, links)
        fused = combine(rule, tuples, offered, links, admitted, score)
        if links.edges:  # only the active receivers have links: only their rows change
            tuples = fused
        else:  # the receivers past their rounds keep their tuples
            tuples = Estimates(
                **{
                    name: np.where(
                        active.reshape(active.shape + (1,) * (value.ndim - 2)),
                        getattr(fused, name),
                        value,
                    )
                    for name, value in tuples.items()
                }
            )
    if sending is None:
        return Outcome(tuples=tuples, sent=sent, delivered=delivered)
    return Outcome(tuples=tuples, sent=sent, delivered=delivered, carried=carried, last=last)


# ------------------------------------------------------------------ on a plain graph


def perfect_radio(adjacency: np.ndarray, form: str = "auto") -> Radio:
    """A radio without faults over a batch of graphs (B, N, N) (diagonal ignored)."""
    from .config import FaultModel

    adj = network.without_self_loops(adjacency)
    # every field of FaultModel has a default, given to Field positionally, which
    # pyright's dataclass_transform does not read as one
    model = FaultModel()
    faults = Faults(model, np.zeros((adj.shape[0], 2), dtype=np.uint32), adj.shape[-1])
    alive = np.ones(adj.shape[:2], dtype=bool)
    return Radio(0, network.links(adj, form), alive, faults, RadioState())


def _flat(adjacency: np.ndarray, confidence: np.ndarray | None = None) -> np.ndarray:
    """The graphs as (B, N, N), after checking them against the confidences (..., N, M)."""
    adjacency = np.asarray(adjacency)
    if adjacency.ndim < 2 or adjacency.shape[-1] != adjacency.shape[-2]:
        raise ValueError(f"adjacency must be (..., N, N), got shape {adjacency.shape}")
    if confidence is not None:
        lead, n = confidence.shape[:-2], confidence.shape[-2]
        if confidence.ndim < 2 or adjacency.shape != lead + (n, n):
            raise ValueError(
                f"adjacency {adjacency.shape} does not match confidence {confidence.shape}: "
                "expected (..., N, N) for confidence (..., N, M)"
            )
        if not np.all(np.isfinite(confidence)):
            raise ValueError("confidence must be finite")
    return adjacency.astype(bool).reshape((-1,) + adjacency.shape[-2:])


def eccentricity(adjacency: np.ndarray, form: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """D_i of every UAV learned by `learn_depth` on a graph with a perfect radio.

    adjacency: (..., N, N) bool, symmetric; the diagonal is ignored. Returns (D (..., N)
    int, messages (...,)): one per link into a receiver still running, per round.
    """
    lead = adjacency.shape[:-2]
    radio = perfect_radio(_flat(adjacency), form)
    out = learn_depth(radio, np.ones(radio.now.alive.shape, dtype=bool))
    return out.depth.reshape(adjacency.shape[:-1]), out.sent.reshape(lead)


def consensus_rounds(
    confidence: np.ndarray, adjacency: np.ndarray, rounds: np.ndarray, form: str = "auto"
) -> np.ndarray:
    """Max-consensus (27) on a graph with a perfect radio, UAV i for rounds[i] rounds.

    confidence: (..., N, M); adjacency: (..., N, N) bool (diagonal ignored); rounds:
    (..., N) int. Returns source (..., N, M): index of the UAV whose initial tuple i holds.
    """
    radio = perfect_radio(_flat(adjacency, confidence), form)
    n, m = confidence.shape[-2:]
    gamma = confidence.reshape(-1, n, m)
    out = consensus(
        radio, Estimates(gamma=gamma, source=identity(gamma.shape)), rounds.reshape(-1, n)
    )
    return required(out.tuples.source, "source").reshape(confidence.shape)


@dataclass(frozen=True)
class Consensus:
    """Outcome of one fusion phase on a graph.

    source: (..., N, M) index of the UAV whose local estimate of target j UAV i holds.
    rounds: (..., N) D_i, the rounds UAV i ran.
    messages: (...,) tuples sent (one per link into a receiver still iterating, per round).
    protocol_messages: (...,) messages of the D_i protocol.
    """

    source: np.ndarray
    rounds: np.ndarray
    messages: np.ndarray
    protocol_messages: np.ndarray


def fuse(confidence: np.ndarray, adjacency: np.ndarray, form: str = "auto") -> Consensus:
    """The fusion phase on a graph: the D_i protocol, then the rounds.

    A user-given adjacency may mark a UAV as its own neighbour; the diagonal is ignored.
    """
    radio = perfect_radio(_flat(adjacency, confidence), form)
    n, m = confidence.shape[-2:]
    gamma = confidence.reshape(-1, n, m)
    depth = learn_depth(radio, np.ones(gamma.shape[:2], dtype=bool))
    out = consensus(radio, Estimates(gamma=gamma, source=identity(gamma.shape)), depth.depth)
    lead = adjacency.shape[:-2]
    return Consensus(
        required(out.tuples.source, "source").reshape(confidence.shape),
        depth.depth.reshape(lead + (n,)),
        out.sent.reshape(lead),
        depth.sent.reshape(lead),
    )


def max_consensus(
    confidence: np.ndarray, adjacency: np.ndarray, form: str = "auto"
) -> tuple[np.ndarray, np.ndarray]:
    """Max-consensus with per-UAV stopping, Algorithm 2 lines 15-25.

    confidence: (..., N, M) floats (gamma = 1/trace P); adjacency: (..., N, N) symmetric
    bool, diagonal ignored. Returns (source (..., N, M), rounds (..., N)): source[i, j]
    is the UAV whose estimate of target j UAV i holds after the protocol, rounds[i] = D_i.
    """
    result = fuse(confidence, adjacency, form)
    return result.source, result.rounds


def identity(shape: tuple[int, ...]) -> np.ndarray:
    """source[..., i, j] = i: every UAV holds its own estimates."""
    source = np.empty(shape, dtype=np.int64)
    source[...] = np.arange(shape[-2])[:, None]
    return source


def gather(source: np.ndarray, values: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Pick values[..., source[i, j], j, ...] for every (i, j).

    source: (B, N, M); values: (B, N, M, *event). Returns (B, N, M, *event), a new
    array, or `out` (C-contiguous, of that shape, not `values`) filled.
    """
    B, n, m = source.shape
    if not source.size:
        return values.copy()
    # rows of the flattened (B * N * M, event) array: one `take` copies whole rows,
    # two to three times faster than indexing (b, source, j) on large teams
    rows = (np.arange(B)[:, None, None] * n + source) * m + np.arange(m)
    flat = values.reshape(B * n * m, -1)
    if out is None:
        return np.take(flat, rows.reshape(-1), axis=0).reshape(values.shape)
    # every row index is valid: "clip" changes nothing but lets take write straight
    # into `out` (with "raise" it fills a temporary first)
    np.take(flat, rows.reshape(-1), axis=0, out=out.reshape(flat.shape), mode="clip")
    return out
