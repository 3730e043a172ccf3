"""What an agent observes, the team's state and the rewards: one builder for every form
of the environment (parallel, AEC, vector), batched over trials.

Everything here takes the arrays of one cycle for B trials (a `View`) and returns
arrays with leading axes (B, Nu): the parallel and AEC environments are the case B = 1.

Scales (so that every entry is of order one): positions in the world frame are taken
from the field's centre in units of half its side; distances from the UAV as
log(1 + d / rho), rho the observation radius h tan(alpha) at the scenario's altitude;
speeds in units of the UAV's airspeed; a standard deviation sigma as log(sigma / rho).
Every entry is clipped to [-BOUND, BOUND] and missing entries are 0 with their mask 0.

With tracks of unknown association (``tracker.association`` gnn or jpda) a UAV knows
no target index: its target rows are its *confirmed* tracks after fusion (a `View`
with `label`), "in view" is whether one of its own measurements of this scan lies in
the track's gate (`View.met`), and the state's target rows are the team's confirmed
labels (`Spaces.state`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from ..config import Scenario
from ..errors import ScenarioError
from ..estimation import confidence
from ..metrics import team_best

BOUND = 10.0
"""Every entry of a Box observation or state lies in [-BOUND, BOUND] (clipped)."""

OBSERVATIONS = ("box", "dict")
"""Observation forms: a flat egocentric Box (default), or the raw Dict of earlier versions."""

REWARDS = {
    "team": "the share of targets inside at least one UAV's observation disk at the next "
    "cycle, the same for every agent: the paper's observation rate, per step",
    "difference": "the share of targets that the UAV alone sees at the next cycle: the team "
    "reward minus the team reward without this UAV (a difference reward)",
    "information": "the information the UAV's own measurements at the next cycle bring on the "
    "targets' positions, 1/2 log det(P-) / det(P+) summed over its targets [nats] (the "
    "det G of the Fisher information the planner scores, as a gain over the prior; not "
    "with tracks of unknown association)",
}
"""Reward options, by name: what an action at cycle k earns (see the docs, The environment)."""

UAV_STATE = ("alive", "x", "y", "cos_heading", "sin_heading", "speed", "altitude")
OWN = UAV_STATE + ("progress",)
TARGET = ("present", "cos_bearing", "sin_bearing", "distance", "v_forward", "v_left",
          "log_sigma", "in_view")  # fmt: skip
NEIGHBOUR = ("present", "cos_bearing", "sin_bearing", "distance", "cos_heading", "sin_heading")
TARGET_STATE = ("present", "x", "y", "vx", "vy", "log_sigma", "seen")


@dataclass(frozen=True, kw_only=True)
class View:
    """One cycle of B trials as the environment shows it.

    believed (B, Nu, 5) the UAVs' states as they believe them; uavs (B, Nu, 5) the true
    states; mean (B, Nu, Nt, 4), cov (B, Nu, Nt, 4, 4) each UAV's fused estimates;
    links (B, Nu, Nu) the radio graph; alive (B, Nu); observed (B, Nu, Nt) the targets
    in each UAV's disk (the truth: the rewards read it); k the step.

    With tracks of unknown association mean (B, Nu, K, 4) and cov (B, Nu, K, 4, 4) are
    each UAV's K track slots after fusion, label (B, Nu, K) the team label of each
    confirmed track of a living UAV (-1 in every other slot) and met (B, Nu, K) whether
    one of the UAV's own measurements of this scan lies in that track's gate; both are
    None with the paper's known association.

    heard (B, Nu, 5): each UAV's state as its beacon carried it, which the neighbour
    rows read (None: the believed states); links then says whose beacon each UAV heard.
    detected (B, Nu, Nt): the targets each UAV measured, its "in view" (None: observed;
    the same with a sensor that never misses).
    """

    k: int
    believed: np.ndarray
    uavs: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    links: np.ndarray
    alive: np.ndarray
    observed: np.ndarray
    label: np.ndarray | None = None
    met: np.ndarray | None = None
    heard: np.ndarray | None = None
    detected: np.ndarray | None = None


class Spaces:
    """The observation and state spaces of a scenario and the builders that fill them."""

    def __init__(
        self,
        scenario: Scenario,
        observation: str = "box",
        max_targets: int | None = None,
        max_neighbours: int | None = None,
    ) -> None:
        if observation not in OBSERVATIONS:
            raise ValueError(f"observation must be one of {OBSERVATIONS}, got {observation!r}")
        nu, nt = scenario.n_uavs, scenario.n_targets
        self.tracked = scenario.tracker.unlabelled
        # with tracks a UAV holds up to K slots; its rows default to the n_targets it
        # was briefed on: more confirmed tracks than targets are false or duplicates,
        # and the nearest first keep those that matter to its flight
        rows = scenario.track_slots if self.tracked else nt
        self.max_targets = _count("max_targets", max_targets, rows, 1, nt)
        self.max_neighbours = _count("max_neighbours", max_neighbours, nu - 1, 0, nu - 1)
        if observation == "dict" and (max_targets is not None or max_neighbours is not None):
            raise ValueError("max_targets and max_neighbours apply to observation='box' only")
        self.scenario, self.form = scenario, observation
        self.half = scenario.field_size / 2
        self.rho = scenario.uav.altitude * math.tan(scenario.sensor.alpha)
        self.speed, self.altitude = scenario.uav.speed, scenario.uav.altitude
        self.size = len(OWN) + self.max_targets * len(TARGET)
        self.size += self.max_neighbours * len(NEIGHBOUR)
        # the state's target rows: one per target, or with tracks as many team labels
        # as a UAV's observation has track rows
        self.state_rows = self.max_targets if self.tracked else nt
        self.state_size = 1 + nu * len(UAV_STATE) + self.state_rows * len(TARGET_STATE)
        box = lambda n: spaces.Box(-BOUND, BOUND, (n,), np.float32)  # noqa: E731
        self.state_space = box(self.state_size)
        if observation == "box":
            self.observation_space = box(self.size)
        else:
            raw = lambda *shape: spaces.Box(-np.inf, np.inf, shape, np.float64)  # noqa: E731
            parts = {
                "uav": raw(5),
                "estimates": raw(rows, 4),
                "covariance": raw(rows, 3),
                "neighbours": spaces.MultiBinary(nu),
            }
            if self.tracked:
                top = np.iinfo(np.int64).max
                parts["labels"] = spaces.Box(-1, top, (rows,), np.int64)
            self.observation_space = spaces.Dict(parts)

    def layout(self) -> dict[str, slice]:
        """Where each part of a Box observation lies: own, targets, neighbours (rows of
        len(TARGET) and len(NEIGHBOUR) entries)."""
        a = len(OWN)
        b = a + self.max_targets * len(TARGET)
        return {"own": slice(0, a), "targets": slice(a, b), "neighbours": slice(b, self.size)}

    # ------------------------------------------------------------------ observations

    def observe(self, view: View) -> np.ndarray | dict[str, np.ndarray]:
        """Every UAV's observation: (B, Nu, size) float32, or for the Dict form a dict of
        (B, Nu, ...) arrays. Fresh arrays, never views of the simulator's."""
        if self.form == "dict":
            m, P = view.mean, view.cov
            out = {
                "uav": np.array(view.believed, dtype=np.float64),
                "estimates": np.array(m, dtype=np.float64),
                "covariance": np.stack([P[..., 0, 0], P[..., 1, 1], P[..., 0, 1]], axis=-1),
                "neighbours": view.links.astype(np.int8),
            }
            if view.label is not None:  # a slot not confirmed holds nothing the UAV tracks
                kept = view.label >= 0
                out["estimates"] = np.where(kept[..., None], out["estimates"], 0.0)
                out["covariance"] = np.where(kept[..., None], out["covariance"], 0.0)
                out["labels"] = view.label.copy()
            return out
        B, Nu = view.alive.shape
        own = self._own(view)
        targets = self._targets(view)
        parts = [own, targets.reshape(B, Nu, -1)]
        if self.max_neighbours:
            parts.append(self._neighbours(view).reshape(B, Nu, -1))
        out = np.concatenate(parts, axis=-1)
        out = np.where(view.alive[..., None], out, 0.0)  # a failed UAV observes nothing
        return np.clip(out, -BOUND, BOUND).astype(np.float32)

    def positions(self, observation: np.ndarray) -> np.ndarray:
        """Where Box observations (..., size) say their UAVs are (..., 3), float32: x and
        y as the observation has them, the altitude in the same unit (half the field's
        side), so that UAVs within r_C are within ``comm_range / (field_size / 2)``; a
        failed UAV's (a zero observation) is the field's centre at altitude 0."""
        scale = self.altitude / self.half
        x = np.asarray(observation, dtype=np.float32)
        return np.stack([x[..., 1], x[..., 2], x[..., 6] * np.float32(scale)], axis=-1)

    def _own(self, view: View) -> np.ndarray:
        progress = np.full(view.alive.shape + (1,), view.k / self.scenario.steps)
        return np.concatenate([self._uav_rows(view.believed, view.alive), progress], axis=-1)

    def _uav_rows(self, u: np.ndarray, alive: np.ndarray) -> np.ndarray:
        """(..., len(UAV_STATE)) of UAV states u (..., 5) in the world frame."""
        rows = np.stack(
            [
                alive.astype(np.float64),
                (u[..., 0] - self.half) / self.half,
                (u[..., 1] - self.half) / self.half,
                np.cos(u[..., 4]),
                np.sin(u[..., 4]),
                u[..., 3] / self.speed,
                u[..., 2] / self.altitude,
            ],
            axis=-1,
        )
        return np.where(alive[..., None], rows, 0.0)

    def _targets(self, view: View) -> np.ndarray:
        """(B, Nu, max_targets, len(TARGET)), nearest estimate first."""
        u, m = view.believed, view.mean
        c, s = np.cos(u[..., 4])[..., None], np.sin(u[..., 4])[..., None]
        dx, dy = m[..., 0] - u[..., 0:1], m[..., 1] - u[..., 1:2]
        present = view.alive[..., None] & np.isfinite(m).all(axis=-1)
        in_view = view.observed if view.detected is None else view.detected
        if view.label is not None:  # tracks: the confirmed ones, seen by its own sensor
            present &= view.label >= 0
            in_view = view.met
        d = np.hypot(dx, dy)
        safe = np.where(d > 0, d, 1.0)
        sigma2 = (view.cov[..., 0, 0] + view.cov[..., 1, 1]) / 2
        rows = np.stack(
            [
                present.astype(np.float64),
                np.where(d > 0, (c * dx + s * dy) / safe, 1.0),
                np.where(d > 0, (c * dy - s * dx) / safe, 0.0),
                np.log1p(d / self.rho),
                (c * m[..., 2] + s * m[..., 3]) / self.speed,
                (c * m[..., 3] - s * m[..., 2]) / self.speed,
                0.5 * np.log(np.maximum(sigma2, 1e-300)) - math.log(self.rho),
                np.asarray(in_view, dtype=np.float64),
            ],
            axis=-1,
        )
        rows = np.where(present[..., None], rows, 0.0)
        return _nearest(rows, np.where(present, d, np.inf), self.max_targets)

    def _neighbours(self, view: View) -> np.ndarray:
        """(B, Nu, max_neighbours, len(NEIGHBOUR)), nearest in radio range first."""
        u = view.believed
        v = u if view.heard is None else view.heard  # the neighbours' states, as heard
        c, s = np.cos(u[..., 4])[..., None], np.sin(u[..., 4])[..., None]
        dx = v[:, None, :, 0] - u[..., 0:1]
        dy = v[:, None, :, 1] - u[..., 1:2]
        Nu = u.shape[1]
        linked = view.links & ~np.eye(Nu, dtype=bool)
        d = np.hypot(dx, dy)
        safe = np.where(d > 0, d, 1.0)
        turn = v[:, None, :, 4] - u[..., 4:5]
        rows = np.stack(
            [
                linked.astype(np.float64),
                np.where(d > 0, (c * dx + s * dy) / safe, 1.0),
                np.where(d > 0, (c * dy - s * dx) / safe, 0.0),
                np.log1p(d / self.rho),
                np.cos(turn),
                np.sin(turn),
            ],
            axis=-1,
        )
        rows = np.where(linked[..., None], rows, 0.0)
        return _nearest(rows, np.where(linked, d, np.inf), self.max_neighbours)

    # ------------------------------------------------------------------ state

    def state(self, view: View) -> np.ndarray:
        """The team's global view (B, state_size) float32: the step, every UAV's true
        state, and per target the team's best estimate (the living UAV most confident
        in it, 1/trace P) and whether any UAV sees it. With tracks, per team label
        (`team_tracks`) instead of per target."""
        B, Nu = view.alive.shape
        uav_rows = self._uav_rows(view.uavs, view.alive)
        if view.label is None:
            best, m, P = team_best(view.mean, view.cov, view.alive)
            present, seen = best >= 0, view.observed.any(axis=1)
        else:
            present, m, P, seen = team_tracks(view, self.state_rows)
        sigma2 = (P[..., 0, 0] + P[..., 1, 1]) / 2
        target_rows = np.stack(
            [
                present.astype(np.float64),
                (m[..., 0] - self.half) / self.half,
                (m[..., 1] - self.half) / self.half,
                m[..., 2] / self.speed,
                m[..., 3] / self.speed,
                0.5 * np.log(np.where(present, np.maximum(sigma2, 1e-300), 1.0))
                - math.log(self.rho),
                seen.astype(np.float64),
            ],
            axis=-1,
        )
        target_rows = np.where(present[..., None], target_rows, 0.0)
        out = np.concatenate(
            [
                np.full((B, 1), view.k / self.scenario.steps),
                uav_rows.reshape(B, -1),
                target_rows.reshape(B, -1),
            ],
            axis=-1,
        )
        return np.clip(out, -BOUND, BOUND).astype(np.float32)


def rewards(
    kind: str,
    observed: np.ndarray,
    prior: np.ndarray,
    posterior: np.ndarray,
    present: np.ndarray | None = None,
) -> np.ndarray:
    """What the actions at cycle k earn, (B, Nu), from the next cycle: observed (B, Nu,
    Nt) the targets in each UAV's disk; prior and posterior (B, Nu, Nt, 4, 4) each UAV's
    covariances before and after its own measurements (only "information" reads them);
    present (B, Nt) the targets there (``target.stay``; default every one), whose number
    the shares of "team" and "difference" divide by. See `REWARDS`."""
    check_reward(kind)
    nt = observed.shape[-1]
    if present is not None and not present.all():
        nt = np.maximum(present.sum(axis=-1), 1)[:, None]  # (B, 1)
    if kind == "team":
        team = observed.any(axis=1).sum(axis=-1, keepdims=True) / nt
        return np.broadcast_to(team, observed.shape[:2]).astype(np.float64)
    if kind == "difference":
        alone = observed & (observed.sum(axis=1, keepdims=True) == 1)
        return alone.sum(axis=-1) / nt
    gain = 0.5 * (_logdet2(prior) - _logdet2(posterior))  # "information"
    return np.where(observed, gain, 0.0).sum(axis=-1)


def check_reward(kind: str, scenario: Scenario | None = None) -> str:
    """`kind` if it names a reward `scenario` can pay; a one-line error otherwise."""
    if kind not in REWARDS:
        raise ValueError(f"reward must be one of {sorted(REWARDS)}, got {kind!r}")
    if kind == "information" and scenario is not None:
        if scenario.tracker.unlabelled:
            # its gain compares each target's filter before and after the UAV's own
            # update; a track slot is fused with teammates' tracks, born or emptied
            # within the scan, so no one filter holds the UAV's own gain
            raise ScenarioError(
                f"reward 'information' reads one filter per target; with "
                f"tracker.association = {scenario.tracker.association} give reward "
                "'team' or 'difference'"
            )
    return kind


def team_tracks(view: View, rows: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The team's confirmed tracks as `rows` rows per trial: per team label held
    confirmed by a living UAV (`View.label`) the most confident estimate (1/trace P,
    the lowest UAV and slot on ties, as `metrics.team_best`), in increasing label
    order (the briefed targets' labels 0 .. Nt - 1 first, then the births in the order
    the team started them), the first `rows` labels kept. Returns present (B, rows),
    mean (B, rows, 4), cov (B, rows, 4, 4) (zeros where absent) and seen (B, rows):
    some UAV's own measurement of this scan lies in that label's gate (`View.met`)."""
    assert view.label is not None and view.met is not None
    B, Nu, K = view.label.shape
    n = Nu * K
    label = view.label.reshape(B, n)
    held = label >= 0
    key = np.where(held, label, np.iinfo(np.int64).max)
    cov = np.where(held[..., None, None], view.cov.reshape(B, n, 4, 4), np.eye(4))
    gamma = np.where(held, confidence(cov), -np.inf)
    order = np.lexsort((-gamma, key), axis=-1)  # by label, the most confident first
    ordered = np.take_along_axis(key, order, axis=-1)
    first = np.take_along_axis(held, order, axis=-1)
    first[:, 1:] &= ordered[:, 1:] != ordered[:, :-1]
    rank = np.cumsum(first, axis=-1) - 1
    b, j = np.nonzero(first & (rank < rows))
    at, src = rank[b, j], order[b, j]
    present = np.zeros((B, rows), dtype=bool)
    best_mean, best_cov = np.zeros((B, rows, 4)), np.zeros((B, rows, 4, 4))
    chosen = np.full((B, rows), -1, dtype=np.int64)
    present[b, at] = True
    best_mean[b, at] = view.mean.reshape(B, n, 4)[b, src]
    best_cov[b, at] = cov[b, src]
    chosen[b, at] = label[b, src]
    met = view.met.reshape(B, n) & held
    seen = ((label[:, None, :] == chosen[:, :, None]) & met[:, None, :]).any(axis=-1)
    return present, best_mean, best_cov, seen & present


def _logdet2(P: np.ndarray) -> np.ndarray:
    """log det of the position block (..., 2, 2) of covariances (..., 4, 4)."""
    det = P[..., 0, 0] * P[..., 1, 1] - P[..., 0, 1] * P[..., 1, 0]
    return np.log(np.maximum(det, 1e-300))


def _nearest(rows: np.ndarray, distance: np.ndarray, count: int) -> np.ndarray:
    """The `count` rows (..., n, f) of smallest distance (..., n), in that order (ties:
    by index); missing rows (distance inf) come last, as their zeros."""
    order = np.argsort(distance, axis=-1, kind="stable")[..., :count]
    return np.take_along_axis(rows, order[..., None], axis=-2)


def _count(name: str, value: int | None, most: int, least: int, default: int) -> int:
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise TypeError(f"{name} must be an integer, not {type(value).__name__}")
    if not least <= value <= most:
        raise ValueError(f"{name} must be in [{least}, {most}] for this scenario, got {value}")
    return int(value)
