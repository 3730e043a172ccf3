"""What an agent observes, the team's state and the rewards: one builder for every form
of the environment (parallel, AEC, vector), batched over trials.

Everything here takes the arrays of one cycle for B trials (a `View`) and returns
arrays with leading axes (B, Nu): the parallel and AEC environments are the case B = 1.

Scales (so that every entry is of order one): positions in the world frame are taken
from the field's centre in units of half its side; distances from the UAV as
log(1 + d / rho), rho the observation radius h tan(alpha) at the scenario's altitude;
speeds in units of the UAV's airspeed; a standard deviation sigma as log(sigma / rho).
Every entry is clipped to [-BOUND, BOUND] and missing entries are 0 with their mask 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from ..config import Scenario
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
    "det G of the Fisher information the planner scores, as a gain over the prior)",
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
    in each UAV's disk; k the step.
    """

    k: int
    believed: np.ndarray
    uavs: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    links: np.ndarray
    alive: np.ndarray
    observed: np.ndarray


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
        self.max_targets = _count("max_targets", max_targets, nt, 1)
        self.max_neighbours = _count("max_neighbours", max_neighbours, nu - 1, 0)
        if observation == "dict" and (max_targets is not None or max_neighbours is not None):
            raise ValueError("max_targets and max_neighbours apply to observation='box' only")
        self.scenario, self.form = scenario, observation
        self.half = scenario.field_size / 2
        self.rho = scenario.uav.altitude * math.tan(scenario.sensor.alpha)
        self.speed, self.altitude = scenario.uav.speed, scenario.uav.altitude
        self.size = len(OWN) + self.max_targets * len(TARGET)
        self.size += self.max_neighbours * len(NEIGHBOUR)
        self.state_size = 1 + nu * len(UAV_STATE) + nt * len(TARGET_STATE)
        box = lambda n: spaces.Box(-BOUND, BOUND, (n,), np.float32)  # noqa: E731
        self.state_space = box(self.state_size)
        if observation == "box":
            self.observation_space = box(self.size)
        else:
            raw = lambda *shape: spaces.Box(-np.inf, np.inf, shape, np.float64)  # noqa: E731
            self.observation_space = spaces.Dict(
                {
                    "uav": raw(5),
                    "estimates": raw(nt, 4),
                    "covariance": raw(nt, 3),
                    "neighbours": spaces.MultiBinary(nu),
                }
            )

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
            P = view.cov
            return {
                "uav": np.array(view.believed, dtype=np.float64),
                "estimates": np.array(view.mean, dtype=np.float64),
                "covariance": np.stack([P[..., 0, 0], P[..., 1, 1], P[..., 0, 1]], axis=-1),
                "neighbours": view.links.astype(np.int8),
            }
        B, Nu = view.alive.shape
        own = self._own(view)
        targets = self._targets(view)
        parts = [own, targets.reshape(B, Nu, -1)]
        if self.max_neighbours:
            parts.append(self._neighbours(view).reshape(B, Nu, -1))
        out = np.concatenate(parts, axis=-1)
        out = np.where(view.alive[..., None], out, 0.0)  # a failed UAV observes nothing
        return np.clip(out, -BOUND, BOUND).astype(np.float32)

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
                view.observed.astype(np.float64),
            ],
            axis=-1,
        )
        rows = np.where(present[..., None], rows, 0.0)
        return _nearest(rows, np.where(present, d, np.inf), self.max_targets)

    def _neighbours(self, view: View) -> np.ndarray:
        """(B, Nu, max_neighbours, len(NEIGHBOUR)), nearest in radio range first."""
        u = view.believed
        c, s = np.cos(u[..., 4])[..., None], np.sin(u[..., 4])[..., None]
        dx = u[:, None, :, 0] - u[..., 0:1]
        dy = u[:, None, :, 1] - u[..., 1:2]
        Nu = u.shape[1]
        linked = view.links & ~np.eye(Nu, dtype=bool)
        d = np.hypot(dx, dy)
        safe = np.where(d > 0, d, 1.0)
        turn = u[:, None, :, 4] - u[..., 4:5]
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
        in it, 1/trace P) and whether any UAV sees it."""
        B, Nu = view.alive.shape
        uav_rows = self._uav_rows(view.uavs, view.alive)
        best, m, P = team_best(view.mean, view.cov, view.alive)
        present = best >= 0
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
                view.observed.any(axis=1).astype(np.float64),
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
    kind: str, observed: np.ndarray, prior: np.ndarray, posterior: np.ndarray
) -> np.ndarray:
    """What the actions at cycle k earn, (B, Nu), from the next cycle: observed (B, Nu,
    Nt) the targets in each UAV's disk; prior and posterior (B, Nu, Nt, 4, 4) each UAV's
    covariances before and after its own measurements (only "information" reads them).
    See `REWARDS`."""
    check_reward(kind)
    nt = observed.shape[-1]
    if kind == "team":
        team = observed.any(axis=1).sum(axis=-1) / nt
        return np.broadcast_to(team[:, None], observed.shape[:2]).astype(np.float64)
    if kind == "difference":
        alone = observed & (observed.sum(axis=1, keepdims=True) == 1)
        return alone.sum(axis=-1) / nt
    gain = 0.5 * (_logdet2(prior) - _logdet2(posterior))  # "information"
    return np.where(observed, gain, 0.0).sum(axis=-1)


def check_reward(kind: str) -> str:
    if kind not in REWARDS:
        raise ValueError(f"reward must be one of {sorted(REWARDS)}, got {kind!r}")
    return kind


def _logdet2(P: np.ndarray) -> np.ndarray:
    """log det of the position block (..., 2, 2) of covariances (..., 4, 4)."""
    det = P[..., 0, 0] * P[..., 1, 1] - P[..., 0, 1] * P[..., 1, 0]
    return np.log(np.maximum(det, 1e-300))


def _nearest(rows: np.ndarray, distance: np.ndarray, count: int) -> np.ndarray:
    """The `count` rows (..., n, f) of smallest distance (..., n), in that order (ties:
    by index); missing rows (distance inf) come last, as their zeros."""
    order = np.argsort(distance, axis=-1, kind="stable")[..., :count]
    return np.take_along_axis(rows, order[..., None], axis=-2)


def _count(name: str, value: int | None, most: int, least: int) -> int:
    if value is None:
        return most
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise TypeError(f"{name} must be an integer, not {type(value).__name__}")
    if not least <= value <= most:
        raise ValueError(f"{name} must be in [{least}, {most}] for this scenario, got {value}")
    return int(value)
