"""Performance measures (paper Sec. 7) accumulated step by step over a batch of trials.

Every per-trial metric is listed once in `METRICS` with its unit and meaning; the
command line, the JSON output and the reports read their labels from there.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from functools import cache
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from .estimation import confidence, nees
from .numerics import chisquare, lsap
from .world import present

if TYPE_CHECKING:
    from .records import Cycle

PER_UAV_SETS = 20
"""Up to this many targets the per-UAV OSPA and GOSPA are computed (an assignment per UAV
and step); above it they are NaN, as their cost would rival the whole cycle's."""
BEST_SETS = 200
"""Up to this many targets the OSPA and GOSPA of the team's best estimates are computed."""

METRICS: dict[str, tuple[str, str]] = {
    "observation_rate": (
        "",
        "mean over targets of the fraction of steps at which the target's true position "
        "lies inside at least one UAV's observation disk (Sec. 7); with targets that come "
        "and go (target.stay), the share of the present target-steps so held",
    ),
    "per_target": (
        "",
        "observation rate of each target (of each place, over the steps a target held it), "
        "numbered from 0",
    ),
    "in_view_std": (
        "",
        "standard deviation over the steps of the fraction of targets in view (of those "
        "present), whose mean over the steps is the observation rate with the paper's fixed "
        "set (one reading of the paper's σ, see the docs, Spread)",
    ),
    "rmse": (
        "m",
        "position RMSE of every UAV's fused estimate of every target, including the stale "
        "estimates of UAVs cut off from the team",
    ),
    "rmse_best": (
        "m",
        "position RMSE of the team's best estimate: per target, the estimate of the UAV "
        "most confident in it (highest 1/trace P)",
    ),
    "nees": (
        "",
        "NEES of every UAV's fused estimate over the 4-D state (4 when consistent), "
        "stale estimates included",
    ),
    "nees_median": (
        "",
        "median of the same NEES samples (3.36 when consistent: the median of chi-square(4)), "
        "read from a histogram of 400 log-spaced bins per decade: within 0.3 %",
    ),
    "nees_inside": (
        "",
        "fraction of the same NEES samples inside the 95 % interval of chi-square(4), "
        "[0.484, 11.14] (0.95 when consistent)",
    ),
    "nees_best": ("", "NEES of the team's best estimate (4 when consistent)"),
    "nees_best_median": ("", "median of the team's best estimate's NEES, as nees_median"),
    "nees_best_inside": (
        "",
        "fraction of the team's best estimate's NEES inside the 95 % interval, as nees_inside",
    ),
    "ospa": (
        "m",
        "OSPA distance (cut-off evaluation.ospa_cutoff, order evaluation.ospa_order) between "
        "the true targets and each UAV's fused estimates, averaged over living UAVs and "
        f"steps; computed up to {PER_UAV_SETS} targets (NaN above)",
    ),
    "ospa_best": (
        "m",
        "OSPA distance between the true targets and the team's best estimates, averaged "
        f"over steps; computed up to {BEST_SETS} targets (NaN above)",
    ),
    "gospa": ("m", "GOSPA distance (alpha = 2) of each UAV's fused estimates, as ospa"),
    "gospa_best": ("m", "GOSPA distance (alpha = 2) of the team's best estimates, as ospa_best"),
    "gospa_missed_best": (
        "",
        "targets per step that GOSPA leaves without a best estimate within the cut-off "
        "(its missed part is c^p / 2 for each)",
    ),
    "gospa_localisation": (
        "m^p",
        "with tracker.association gnn or jpda: the localisation part of gospa (p-th power), "
        "mean per UAV and step (NaN with known association, as the other track metrics)",
    ),
    "gospa_missed": ("m^p", "its missed part, c^p / 2 per target left unmatched"),
    "gospa_false": ("m^p", "its false part, c^p / 2 per confirmed track left unmatched"),
    "switches": (
        "",
        "track switches per target and 100 steps: the label matched to a target changes "
        "(CLEAR MOT mismatches), each UAV's tracks",
    ),
    "fragmentations": ("", "per target and 100 steps, a target in view that loses its track"),
    "unassigned_tracks": (
        "",
        "confirmed tracks GOSPA assigns to no target (within the cut-off), per UAV and step: "
        "duplicates, stale and never-followed tracks together",
    ),
    "unassigned_tracks_per_target": ("", "the same per target and step"),
    "duplicate_tracks": (
        "",
        "unassigned confirmed tracks whose nearest target within the cut-off another track "
        "follows (a target followed twice), per target and step",
    ),
    "stale_tracks": (
        "",
        "the other unassigned confirmed tracks whose label followed a target before (a "
        "track left behind), per target and step",
    ),
    "never_tracks": (
        "",
        "unassigned confirmed tracks that have not followed any target so far (clutter-born), "
        "per target and step",
    ),
    "never_tracks_new": ("", "such tracks new to a UAV, per UAV and 100 steps"),
    "gospa_team": (
        "m",
        "GOSPA (alpha = 2) of the team picture: per team label the confirmed track of the "
        "most confident living UAV that holds it (1/trace P, P its 4 x 4 covariance), "
        "mean per step",
    ),
    "label_purity": (
        "",
        "share of the (UAV, target, step) whose track matched to the target carries the "
        "team's majority label for it among the UAVs that hold a matched track",
    ),
    "ospa2": (
        "m",
        "OSPA(2) (Beard, Vo and Vo 2020, order p, cut-off c) of a UAV's confirmed tracks "
        "against the targets as tracks over windows of 10 steps: a label switch costs",
    ),
    "ospa2_team": ("m", "the same of the team picture (gospa_team's tracks)"),
    "time_to_confirm": (
        "1",
        "steps from a target's first sight without a track to its first matched track (a "
        "count of steps)",
    ),
    "time_to_confirm_team": (
        "1",
        "median steps from a step a target is in some living UAV's view while no UAV holds "
        "a confirmed track of it (met anew, or lost by all) to the first confirmed track "
        "of it held by any UAV; a clock still running when its target leaves is dropped",
    ),
    "never_confirmed": ("", "fraction of those targets never matched by the end"),
    "siap_completeness": ("", "SIAP completeness: fraction of targets with a track"),
    "siap_ambiguity": ("", "SIAP ambiguity: tracks per target that has one (1 is ideal)"),
    "siap_spuriousness": ("", "SIAP spuriousness: fraction of confirmed tracks of no target"),
    "rounds": ("", "consensus rounds per UAV and step (D_i, plus robust.extra_rounds)"),
    "messages": (
        "",
        "radio messages sent per step, all protocols: beacons, D_i flooding, consensus "
        "tuples and bids (distributed), flooding and tuples (greedy), uploads and "
        "downloads (centralized); one per link into a receiver that needs it; with "
        "faults.delay, counted when sent, one per link and round the sender runs (whether "
        "a receiver reads it d cycles later is not known then)",
    ),
    "delivered": ("", "radio messages per step that arrive (messages minus those lost)"),
    "bytes": (
        "byte",
        "radio bytes per UAV and step: every frame the UAVs (and the central node) sent in "
        "the cycle, as the agent form puts it on the wire (MessagePack in an envelope with "
        "a 16-byte tag, one frame per receiver and round), over the team's UAVs; the "
        "transport's own headers are not counted",
    ),
    "conflicts": (
        "",
        "targets per step followed by two or more UAVs while another target has none",
    ),
    "failed": ("", "UAVs failed by the end of the trial (faults; in a swarm, lost programs too)"),
    "separation_losses": (
        "",
        "losses of separation: pairs of living UAVs closer than uav.vertical_separation in "
        "altitude and closer than uav.separation horizontally, summed over the steps "
        "(0 without a minimum; `airspace.separation`)",
    ),
    "separation_min": (
        "m",
        "the smallest horizontal distance between two living UAVs closer than "
        "uav.vertical_separation in altitude, over the steps; NaN if no such pair came "
        "within max(r_C, uav.separation) (the paper's layered team)",
    ),
    "conflict_time": (
        "s",
        "time during which at least one pair of UAVs had lost separation (steps x dt)",
    ),
    "decision_time_ms": (
        "ms",
        "CPU time per cycle of one UAV's own planning and assignment (distributed, greedy) "
        "or of the central node's for the whole team (centralized); measured only when a "
        "trial runs alone, never inside a batch, where numpy's per-call cost is shared",
    ),
    "decision_wall_ms": (
        "ms",
        "the same in wall time, which other work on the machine inflates (see timing)",
    ),
}
"""Per-trial metrics: name -> (unit, meaning)."""


def team_best(
    mean: np.ndarray, cov: np.ndarray, alive: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The team's best estimate of each target, as `Tally` takes it: the most confident
    living UAV's (1/trace P, the lowest index on ties). mean (..., Nu, Nt, 4), cov (...,
    Nu, Nt, 4, 4), alive (..., Nu). Returns the UAV (..., Nt) (-1 when none is alive),
    its estimate (..., Nt, 4) and covariance (..., Nt, 4, 4) (NaN then)."""
    gamma = np.where(alive[..., None], confidence(cov), -np.inf)
    gamma = np.where(np.isnan(gamma), -np.inf, gamma)
    best = np.argmax(gamma, axis=-2)  # (..., Nt)
    chosen = np.take_along_axis(mean, best[..., None, :, None], axis=-3)[..., 0, :, :]
    P = np.take_along_axis(cov, best[..., None, :, None, None], axis=-4)[..., 0, :, :, :]
    anyone = np.any(alive, axis=-1)[..., None]
    return (
        np.where(anyone, best, -1),
        np.where(anyone[..., None], chosen, np.nan),
        np.where(anyone[..., None, None], P, np.nan),
    )


NEES_BINS_PER_DECADE = 400
"""Resolution of `NeesSpread`'s histogram: a median read from it is within a factor
10^(1 / (2 x 400)) = 1.0029 of the samples' median."""
NEES_DECADES = (-6, 10)
"""The histogram's range, 10^-6 to 10^10; samples outside it count in a bin below or above."""


@cache
def nees_interval(dim: int = 4, level: float = 0.95) -> tuple[float, float]:
    """The central `level` interval of chi-square(dim), where the NEES of a consistent
    estimate of a dim-D state falls with probability `level`: [chi2.ppf((1 - level) / 2,
    dim), chi2.ppf((1 + level) / 2, dim)], [0.484, 11.14] for the 4-D state at 95 %."""
    tail = (1.0 - level) / 2.0
    return chisquare.ppf(tail, dim), chisquare.ppf(1.0 - tail, dim)


@dataclass
class NeesSpread:
    """The distribution of NEES samples of each of B trials, in memory that no number of
    samples changes: a histogram for the median and exact counts for the fraction inside
    the 95 % chi-square(4) interval (`nees_interval`).

    The histogram has `NEES_BINS_PER_DECADE` log-spaced bins per decade over
    10^-6 .. 10^10 and a bin on each side for samples outside (NaN counts above). The
    median is the mean of the geometric centres of the bins of the two middle samples
    (of the one when their number is odd), so it is within a factor 10^(1/800) = 1.0029
    of numpy's median (the mean of the two middle samples) whenever that lies in the
    range; outside, it is the range's edge.
    """

    batch: int
    counts: np.ndarray = field(init=False)  # (B, bins + 2)
    inside: np.ndarray = field(init=False)  # (B,)

    def __post_init__(self) -> None:
        low, high = NEES_DECADES
        self.counts = np.zeros((self.batch, (high - low) * NEES_BINS_PER_DECADE + 2), np.int64)
        self.inside = np.zeros(self.batch, np.int64)

    def add(self, q: np.ndarray, counted: np.ndarray | None = None) -> None:
        """Add the samples q (B, ...) of each trial, those where `counted` (broadcast to q)."""
        q = np.asarray(q, dtype=float)
        if counted is not None:
            counted = np.broadcast_to(np.asarray(counted, dtype=bool), q.shape)
            counted = counted.reshape(self.batch, -1)
        q = q.reshape(self.batch, -1)
        width = self.counts.shape[1]
        # in place: a team of 1000 UAVs and 1000 targets gives 10^6 samples a step
        k = np.maximum(q, 0.0)  # a sample <= 0 (rounding of a tiny one) falls below
        with np.errstate(divide="ignore"):
            np.log10(k, out=k)
        k -= NEES_DECADES[0]
        k *= NEES_BINS_PER_DECADE
        np.floor(k, out=k)
        np.nan_to_num(k, copy=False, nan=width, neginf=-1.0, posinf=width)  # NaN: above
        np.clip(k, -1, width - 2, out=k)
        index = k.astype(np.intp)
        index += 1 + width * np.arange(self.batch)[:, None]
        low, high = nees_interval()
        inside = (q >= low) & (q <= high)
        if counted is not None:
            index, inside = index[counted], inside & counted
        self.counts += np.bincount(index.ravel(), minlength=self.counts.size).reshape(
            self.counts.shape
        )
        self.inside += inside.sum(axis=1)

    @property
    def samples(self) -> np.ndarray:
        """Samples added per trial, (B,)."""
        return self.counts.sum(axis=1)

    def median(self) -> np.ndarray:
        """Median of each trial's samples (B,), NaN for a trial without any."""
        n = self.samples
        cum = np.cumsum(self.counts, axis=1)
        low, high = NEES_DECADES
        # bin 0 is below the range, the last above it: their values are the edges
        centre = low + (np.arange(self.counts.shape[1]) - 0.5) / NEES_BINS_PER_DECADE
        centre = 10.0 ** np.clip(centre, low, high)
        value = np.zeros(self.batch)
        for rank in ((n - 1) // 2, n // 2):  # 0-based ranks of the two middle samples
            at = (cum <= rank[:, None]).sum(axis=1)  # the first bin holding more than rank
            value += centre[np.minimum(at, len(centre) - 1)] / 2
        return np.where(n > 0, value, np.nan)

    def inside_fraction(self) -> np.ndarray:
        """Fraction of each trial's samples inside the 95 % interval (B,), NaN without any."""
        n = self.samples
        return np.where(n > 0, self.inside / np.maximum(n, 1), np.nan)


_Mask = np.ndarray | None


@dataclass(kw_only=True)
class Tally:
    """Running sums over the steps of a batch of B trials (Nu UAVs, Nt targets), fed
    one `records.Cycle` at a time.

    Failed UAVs count in nothing: their estimates leave the RMSE and NEES, their rounds
    the mean. NEES is computed in blocks of steps covering about 4000 filters: few
    numpy calls, and the block stays in cache; beside its sum, its distribution (median,
    fraction inside the 95 % interval) is kept in a `NeesSpread` per kind. Decision
    times are kept only when `timed` (one trial alone); otherwise they are NaN.
    """

    batch: int
    n_uavs: int
    n_targets: int
    timed: bool = False
    cutoff: float = 20.0
    order: float = 1.0
    steps: int = 0
    log: list[dict[str, np.ndarray]] | None = None
    """With a list: each step's own values of the metrics that are means over the steps
    (`tracks.scoring.series`), appended as the steps are added."""
    observed: np.ndarray = field(init=False)
    sums: dict[str, np.ndarray] = field(init=False)
    spread: dict[str, NeesSpread] = field(init=False)  # nees, nees_best
    # per step: mean, cov, best_mean, best_cov, truth, alive (None: everyone)
    _pending: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, _Mask]] = (
        field(init=False, repr=False)
    )
    _block: int = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.observed = np.zeros((self.batch, self.n_targets))
        self.present = np.zeros((self.batch, self.n_targets))  # steps each target was there
        names = (
            "squared_error", "squared_error_best", "nees", "nees_best", "rounds", "messages",
            "delivered", "bytes", "conflicts", "decision", "wall", "decided", "pairs", "best",
            "alive", "in_view_sq", "in_view", "shared", "ospa", "ospa_best", "gospa",
            "gospa_best", "gospa_missed_best",
        )  # fmt: skip
        self.sums = {name: np.zeros(self.batch) for name in names}
        self.spread = {name: NeesSpread(self.batch) for name in ("nees", "nees_best")}
        self.failed = np.zeros(self.batch)
        self._pending = []
        self._block = int(np.clip(4096 // (self.batch * self.n_uavs * self.n_targets), 1, 64))

    def add(self, cycle: Cycle, truth: np.ndarray) -> None:
        """Add one step: a `records.Cycle` and the true targets (B, Nt, 4)."""
        s = self.sums
        self.steps += 1
        alive = cycle.alive
        everyone = bool(alive.all())
        in_view = cycle.observed.any(axis=1)
        self.observed += in_view
        here = present(truth)  # targets that come and go are NaN while away
        self.present += here
        if here.all():
            share = in_view.mean(axis=1)
        else:  # the share of the targets there, of steps with any there
            there = here.any(axis=1)
            share = np.where(there, in_view.sum(axis=1) / np.maximum(here.sum(axis=1), 1), np.nan)
        s["in_view_sq"] += np.nan_to_num(np.square(share))
        s["in_view"] += np.nan_to_num(share)
        s["shared"] += ~np.isnan(share)
        if self.log is not None:
            living, anyone = np.maximum(alive.sum(axis=1), 1), alive.any(axis=1)
            self.log.append({
                "observation_rate": share,
                "rounds": np.where(
                    anyone, np.where(alive, cycle.rounds, 0).sum(axis=1) / living, np.nan
                ),
                "messages": cycle.messages * 1.0, "delivered": cycle.delivered * 1.0,
                "bytes": (cycle.bytes.sum(axis=1) + cycle.node_bytes) / self.n_uavs,
                "conflicts": cycle.conflicts * 1.0,
            })  # fmt: skip
        anyone = alive.any(axis=1)
        if getattr(cycle, "label", None) is None:  # tracks are scored by their labels
            self._estimates(cycle, truth, everyone)
        if everyone:
            s["rounds"] += cycle.rounds.mean(axis=1)
        else:
            s["rounds"] += np.where(
                anyone, (cycle.rounds * alive).sum(axis=1) / np.maximum(alive.sum(axis=1), 1), 0
            )
        s["alive"] += anyone
        s["messages"] += cycle.messages
        s["delivered"] += cycle.delivered
        s["bytes"] += (cycle.bytes.sum(axis=1) + cycle.node_bytes) / self.n_uavs
        s["conflicts"] += cycle.conflicts
        for name, key in (("decision_time_ms", "decision"), ("decision_wall_ms", "wall")):
            decision = getattr(cycle, name)
            if not everyone:  # only the living decide
                counted = np.isfinite(decision)
                decision = np.where(counted, decision, 0.0).sum(axis=1) / np.maximum(
                    counted.sum(axis=1), 1
                )
            else:
                decision = decision.mean(axis=1)
            s[key] += decision
        s["decided"] += np.isfinite(cycle.decision_time_ms).any(axis=1) if not everyone else 1
        self.failed = (~alive).sum(axis=1).astype(float)

    def _estimates(self, cycle: Cycle, truth: np.ndarray, everyone: bool) -> None:
        """The errors of every UAV's estimate of every target, and of the team's best."""
        s, alive = self.sums, cycle.alive
        mean, cov = cycle.mean, cycle.cov
        err = mean[..., :2] - truth[:, None, :, :2]
        squared = err * err
        if not everyone:
            squared = np.where(alive[:, :, None, None], squared, 0.0)
        s["squared_error"] += squared.sum(axis=(1, 2, 3))
        s["pairs"] += alive.sum(axis=1) * self.n_targets
        # the team's best estimate of each target: its most confident UAV (lowest on ties)
        gamma = confidence(cov) if cycle.confidence is None else cycle.confidence
        if not everyone:
            gamma = np.where(alive[..., None], gamma, -np.inf)
        best = np.argmax(gamma, axis=1)  # (B, Nt)
        anyone = alive.any(axis=1)
        b, j = np.arange(best.shape[0])[:, None], np.arange(best.shape[1])
        best_mean, best_cov = mean[b, best, j], cov[b, best, j]
        err = best_mean[..., :2] - truth[..., :2]
        s["squared_error_best"] += np.where(anyone, (err * err).sum(axis=(1, 2)), 0.0)
        s["best"] += anyone * self.n_targets
        if self.log is not None:
            pairs = np.where(alive.any(axis=1), alive.sum(axis=1) * self.n_targets, np.nan)
            self.log[-1]["rmse"] = np.sqrt(squared.sum(axis=(1, 2, 3)) / pairs)
            self.log[-1]["rmse_best"] = np.where(
                anyone, np.sqrt((err * err).sum(axis=(1, 2)) / self.n_targets), np.nan
            )
        if self._block > 1:  # held past this call: copies, as the caller may reuse its arrays
            mean, cov = mean.copy(), cov.copy()
        self._pending.append((mean, cov, best_mean, best_cov, truth, None if everyone else alive))
        if len(self._pending) == self._block:
            self._flush()

    def _sets(
        self, mean: np.ndarray, best_mean: np.ndarray, truth: np.ndarray, alive: np.ndarray
    ) -> None:
        """OSPA and GOSPA of the pending steps (S, B, ...): each living UAV's estimates
        and the best ones, computed for the steps at once and added step by step (the
        sums are those of one step at a time, bit for bit)."""
        s, c, p = self.sums, self.cutoff, self.order
        X = truth[..., :2]
        anyone = np.any(alive, axis=2)  # (S, B)
        if not alive.all():  # a failed UAV's estimates are NaN; its scores are masked out
            mean = np.where(alive[..., None, None], mean, 0.0)
            best_mean = np.where(anyone[..., None, None], best_mean, 0.0)
        logged = self.log[len(self.log) - X.shape[0] :] if self.log is not None else []
        if self.n_targets <= PER_UAV_SETS:
            d, g = ospa_and_gospa(X[:, :, None], mean[..., :2], c, p)  # (S, B, Nu)
            d, gd = np.where(alive, d, 0.0), np.where(alive, g.distance, 0.0)
            for step in range(d.shape[0]):
                s["ospa"] += d[step].sum(axis=1)
                s["gospa"] += gd[step].sum(axis=1)
            living = np.where(anyone, alive.sum(axis=2), np.nan)  # (S, B)
            for step, entry in enumerate(logged):
                entry["ospa"] = d[step].sum(axis=1) / living[step]
                entry["gospa"] = gd[step].sum(axis=1) / living[step]
        if self.n_targets <= BEST_SETS:
            d, g = ospa_and_gospa(X, best_mean[..., :2], c, p)  # (S, B)
            d, gd = np.where(anyone, d, 0.0), np.where(anyone, g.distance, 0.0)
            missed = np.where(anyone, g.missed / (c**p / 2), 0.0)
            for step in range(d.shape[0]):
                s["ospa_best"] += d[step]
                s["gospa_best"] += gd[step]
                s["gospa_missed_best"] += missed[step]
            for step, entry in enumerate(logged):
                entry["ospa_best"] = np.where(anyone[step], d[step], np.nan)
                entry["gospa_best"] = np.where(anyone[step], gd[step], np.nan)

    def _flush(self) -> None:
        if self._pending:
            masks = [p[5] for p in self._pending]
            mean, cov, best_mean, best_cov, truth = (  # one step: no copy
                parts[0][None] if len(parts) == 1 else np.stack(parts)
                for parts in list(zip(*self._pending, strict=True))[:5]
            )
            q = nees(mean, cov, truth[:, :, None])  # (S, B, Nu, Nt)
            alive = np.stack([np.ones(q.shape[1:3], dtype=bool) if m is None else m for m in masks])
            self._sets(mean, best_mean, truth, alive)
            best = nees(best_mean, best_cov, truth)  # (S, B, Nt)
            trials_first = (np.moveaxis(q, 1, 0), np.moveaxis(best, 1, 0))
            if any(m is not None for m in masks):
                anyone = np.any(alive, axis=2)  # (S, B)
                self.spread["nees"].add(trials_first[0], np.moveaxis(alive, 1, 0)[..., None])
                self.spread["nees_best"].add(trials_first[1], anyone.T[..., None])
                q = np.where(alive[..., None], q, 0.0)
                best = np.where(anyone[..., None], best, 0.0)
            else:
                self.spread["nees"].add(trials_first[0])
                self.spread["nees_best"].add(trials_first[1])
            self.sums["nees"] += q.sum(axis=(0, 2, 3))
            self.sums["nees_best"] += best.sum(axis=(0, 2))
            if self.log is not None:
                pairs = alive.sum(axis=2) * self.n_targets  # (S, B)
                anyone = np.any(alive, axis=2)
                logged = self.log[len(self.log) - q.shape[0] :]
                for step, entry in enumerate(logged):
                    entry["nees"] = np.where(
                        pairs[step] > 0, q[step].sum(axis=(1, 2)) / np.maximum(pairs[step], 1),
                        np.nan,
                    )  # fmt: skip
                    entry["nees_best"] = np.where(
                        anyone[step], best[step].sum(axis=1) / self.n_targets, np.nan
                    )
            self._pending = []

    def _set_summary(self) -> dict[str, np.ndarray]:
        s = self.sums
        # the steps averaged over, NaN where nothing was scored (or too many targets)
        uav_steps = np.where(
            (s["pairs"] > 0) & (self.n_targets <= PER_UAV_SETS), s["pairs"] / self.n_targets, np.nan
        )
        steps = np.where(
            (s["best"] > 0) & (self.n_targets <= BEST_SETS), s["best"] / self.n_targets, np.nan
        )
        return {
            "ospa": s["ospa"] / uav_steps,
            "ospa_best": s["ospa_best"] / steps,
            "gospa": s["gospa"] / uav_steps,
            "gospa_best": s["gospa_best"] / steps,
            "gospa_missed_best": s["gospa_missed_best"] / steps,
        }

    def _in_view_std(self, rate: np.ndarray) -> np.ndarray:
        """The standard deviation over the steps of the share of targets in view (of
        those present, over the steps with any present)."""
        s = self.sums
        if self.fixed:  # the mean of the shares is the rate
            return np.sqrt(np.maximum(s["in_view_sq"] / self.steps - rate**2, 0.0))
        n = np.maximum(s["shared"], 1)
        return np.sqrt(np.maximum(s["in_view_sq"] / n - (s["in_view"] / n) ** 2, 0.0))

    @property
    def fixed(self) -> bool:
        """Whether every target was present at every step so far (the paper's fixed set)."""
        return bool((self.present == self.steps).all())

    def per_target(self) -> np.ndarray:
        """Observation rate of each target, (B, Nt): the share of the steps it was
        present at which some UAV held it in view (NaN for a target never present)."""
        if self.fixed:
            return self.observed / self.steps
        return np.where(self.present > 0, self.observed / np.maximum(self.present, 1), np.nan)

    def observation_rate(self) -> np.ndarray:
        """The observation rate of each trial (B,): the mean of `per_target`, or, with
        targets that come and go, the share of present target-steps in view."""
        if self.fixed:
            return self.per_target().mean(axis=1)
        return self.observed.sum(axis=1) / np.maximum(self.present.sum(axis=1), 1)

    def summary(self) -> dict[str, np.ndarray]:
        """Per-trial metrics of `METRICS`, each an array over the batch (per_target (B, Nt))."""
        self._flush()
        per_target = self.per_target()
        s = self.sums
        # nothing to average (every UAV failed from the start): NaN, not a perfect score
        pairs = np.where(s["pairs"] > 0, s["pairs"], np.nan)
        targets = np.where(s["best"] > 0, s["best"], np.nan)
        decided = np.where(s["decided"] > 0, s["decided"], np.nan)
        untimed = np.full(self.batch, np.nan)
        decision = s["decision"] / decided if self.timed else untimed
        wall = s["wall"] / decided if self.timed else untimed
        rate = self.observation_rate()
        return {
            "observation_rate": rate,
            "per_target": per_target,
            "in_view_std": self._in_view_std(rate),
            "rmse": np.sqrt(s["squared_error"] / pairs),
            "rmse_best": np.sqrt(s["squared_error_best"] / targets),
            "nees": s["nees"] / pairs,
            "nees_median": self.spread["nees"].median(),
            "nees_inside": self.spread["nees"].inside_fraction(),
            "nees_best": s["nees_best"] / targets,
            "nees_best_median": self.spread["nees_best"].median(),
            "nees_best_inside": self.spread["nees_best"].inside_fraction(),
            **self._set_summary(),
            "rounds": s["rounds"] / np.where(s["alive"] > 0, s["alive"], np.nan),
            "messages": s["messages"] / self.steps,
            "delivered": s["delivered"] / self.steps,
            "bytes": s["bytes"] / self.steps,
            "conflicts": s["conflicts"] / self.steps,
            "failed": self.failed,
            "decision_time_ms": decision,
            "decision_wall_ms": wall,
        }


def rank_names(n: int) -> list[str]:
    """Names of the places of n sorted rates: lowest, 2nd lowest, ..., highest."""
    if n == 1:
        return ["only"]
    ordinal = {2: "2nd", 3: "3rd"}
    middle = [f"{ordinal.get(k, f'{k}th')} lowest" for k in range(2, n)]
    return ["lowest", *middle, "highest"]


def sorted_rates(per_target: np.ndarray) -> np.ndarray:
    """Each trial's target rates from lowest to highest (the paper's Fig. 6), (..., Nt)."""
    return np.sort(per_target, axis=-1)


def mean_std(values: np.ndarray, axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Mean and sample standard deviation (ddof = 1) over an axis, ignoring NaN.

    NaN marks a value that was not measured (a decision time inside a batch). With
    fewer than two values the standard deviation is undefined: NaN (null in JSON).
    """
    values = np.asarray(values, dtype=float)
    n = np.sum(~np.isnan(values), axis=axis)
    total = np.nansum(values, axis=axis)
    mean = np.where(n > 0, total / np.maximum(n, 1), np.nan)
    dev = np.where(np.isnan(values), 0.0, values - np.expand_dims(mean, axis))
    var = np.sum(dev * dev, axis=axis) / np.maximum(n - 1, 1)
    return mean, np.where(n > 1, np.sqrt(var), np.nan)


# ------------------------------------------------------------------ set distances


class GOSPA(NamedTuple):
    """GOSPA and its parts; with alpha = 2, localisation + missed + false = distance^p
    (the parts are in the p-th power, as in Rahmathullah et al. and Stone Soup)."""

    distance: np.ndarray | float
    localisation: np.ndarray | float
    missed: np.ndarray | float
    false: np.ndarray | float


def ospa(X: np.ndarray, Y: np.ndarray, c: float, p: float = 1.0) -> np.ndarray | float:
    """OSPA distance of order p with cut-off c between the point sets X (..., m, d) and
    Y (..., n, d) (Schuhmacher, Vo and Vo 2008), over any leading axes that broadcast.

    With m <= n: ((min over matchings of sum of min(d, c)^p over the m pairs
    + c^p (n - m)) / n)^(1/p); 0 for two empty sets. The matching minimises the sum of
    the cut distances to the power p, which is the metric's definition. (Stone Soup's
    OSPAMetric matches on the plain distances, the same thing only at p = 1.)
    """
    return ospa_and_gospa(X, Y, c, p)[0]


def gospa(X: np.ndarray, Y: np.ndarray, c: float, p: float = 1.0, alpha: float = 2.0) -> GOSPA:
    """GOSPA distance (Rahmathullah, Garcia-Fernandez and Svensson 2017) between the
    true points X (..., m, d) and the estimates Y (..., n, d), over leading axes that
    broadcast: with m <= n, (min over matchings of sum of min(d, c)^p over the m pairs
    + c^p / alpha (n - m))^(1/p), alpha in (0, 2].

    At alpha = 2 (the usual choice, and Stone Soup's) it splits into localisation
    (pairs closer than c), missed (c^p / 2 per true point left without a close
    estimate) and false (c^p / 2 per such estimate); for other alpha the parts are NaN.
    """
    return ospa_and_gospa(X, Y, c, p, alpha)[1]


def ospa_and_gospa(
    X: np.ndarray, Y: np.ndarray, c: float, p: float = 1.0, alpha: float = 2.0
) -> tuple[np.ndarray | float, GOSPA]:
    """`ospa` and `gospa` of the same sets from one matching: both minimise the sum of
    the cut distances to the power p over matchings of min(m, n) pairs."""
    if not 0 < alpha <= 2:
        raise ValueError(f"alpha must be in (0, 2], got {alpha}")
    cost, m, n = cut_costs(X, Y, c, p)
    total, local, paired = _optimal(cost, c**p)
    big = max(m, n)
    if big:
        spread = ((total + c**p * abs(n - m)) / big) ** (1.0 / p)
    else:
        spread = np.zeros(cost.shape[:-2])
    distance = (total + c**p / alpha * abs(n - m)) ** (1.0 / p)
    if alpha == 2:
        missed, false = c**p / 2 * (m - paired), c**p / 2 * (n - paired)
    else:
        local = missed = false = np.full(distance.shape, np.nan)
    return _scalar(spread), GOSPA(*(_scalar(v) for v in (distance, local, missed, false)))


def cut_costs(X: ArrayLike, Y: ArrayLike, c: float, p: float) -> tuple[np.ndarray, int, int]:
    """min(|x - y|, c)^p for every pair, (..., m, n), with the set sizes."""
    if not (np.isfinite(c) and c > 0):
        raise ValueError(f"the cut-off c must be a positive number, got {c}")
    if not (np.isfinite(p) and p >= 1):
        raise ValueError(f"the order p must be a number >= 1, got {p}")
    X, Y = np.asarray(X, dtype=float), np.asarray(Y, dtype=float)
    if X.ndim < 2 or Y.ndim < 2 or X.shape[-1] != Y.shape[-1]:
        raise ValueError(
            f"X and Y must be point sets (..., m, d) and (..., n, d) of the same d; "
            f"got shapes {X.shape} and {Y.shape}"
        )
    if not (np.isfinite(X).all() and np.isfinite(Y).all()):
        raise ValueError("X and Y must hold finite coordinates (NaN or inf found)")
    lead = np.broadcast_shapes(X.shape[:-2], Y.shape[:-2])
    X = np.broadcast_to(X, lead + X.shape[-2:])
    Y = np.broadcast_to(Y, lead + Y.shape[-2:])
    diff = X[..., :, None, :] - Y[..., None, :, :]
    dist = np.sqrt(np.einsum("...k,...k->...", diff, diff))
    return np.minimum(dist, c) ** p, X.shape[-2], Y.shape[-2]


def matching(cost: np.ndarray) -> np.ndarray:
    """A matching of min(m, n) pairs of least total cost, per leading index of the costs
    (..., m, n): the column matched to each row (..., m), -1 for a row left out (m > n).

    Square problems up to `SMALL_SETS` try every matching at once (the first of equal
    ones); the others are `lsap.solve`'s (scipy's `linear_sum_assignment`), one per index.
    """
    shape, (m, n) = cost.shape[:-2], cost.shape[-2:]
    if 0 < m == n <= SMALL_SETS:  # no loop over the leading axes
        chosen = cost[..., np.arange(n), _permutations(n)]  # (..., n!, n)
        return _permutations(n)[np.argmin(chosen.sum(axis=-1), axis=-1)]
    match = np.full(shape + (m,), -1, dtype=np.intp)
    if m and n:
        for index in np.ndindex(shape):
            rows, cols = lsap.solve(cost[index])
            match[index][rows] = cols
    return match


def _optimal(cost: np.ndarray, cut: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per leading index, for the `matching` of min(m, n) pairs of least total cost: the
    total, the part of the pairs closer than the cut, and how many those are."""
    shape, (m, n) = cost.shape[:-2], cost.shape[-2:]
    match = matching(cost)
    if 0 < m == n <= SMALL_SETS:
        chosen = np.take_along_axis(cost, match[..., None], axis=-1)[..., 0]
        close = chosen < cut
        return chosen.sum(axis=-1), np.where(close, chosen, 0.0).sum(axis=-1), close.sum(-1)
    total, local, paired = np.zeros(shape), np.zeros(shape), np.zeros(shape)
    if m and n:
        for index in np.ndindex(shape):
            rows = np.flatnonzero(match[index] >= 0)  # in order, as the pairs were summed
            chosen = cost[index][rows, match[index][rows]]
            close = chosen < cut
            total[index], local[index], paired[index] = (
                chosen.sum(),
                chosen[close].sum(),
                close.sum(),
            )
    return total, local, paired


SMALL_SETS = 6
"""Square problems up to this size are solved by trying all n! matchings at once."""


@cache
def _permutations(n: int) -> np.ndarray:
    return np.array(list(itertools.permutations(range(n))), dtype=np.intp)


def _scalar(value: np.ndarray):
    """A 0-d result as a float, anything else as it is."""
    return float(value) if np.ndim(value) == 0 else value
