"""What an honest member of a run can claim: bounds derived from the scenario's physics.

A UAV's messages make claims: where it is, where each target is and how fast it goes,
how certain it is of that (a covariance P and its confidence gamma = 1 / trace P,
eq. 22), how much it would gain from tracking each target (a bid, the sum over the
horizon of det G, Algorithm 1). Some claims no honest UAV can make in a given run,
whatever its faults; `Bounds` holds the limits, and the agents' message rules
(`agents.messages.Spec`) say which one a claim breaks. The limits are loose by design
(an honest claim never comes near them): they keep a lying member to claims that are
physically possible and that keep every receiver's arithmetic finite; telling a
plausible lie from the truth is the work of the measurement gate (`gate`,
``robust.gate``).

* Positions: a UAV flies at most at its ground speed (airspeed plus wind, doubled for
  the autopilot), and an estimate moves at most at the estimate speed below; neither
  gets farther from the field in the run (duration T = steps x dT) than that speed for
  T, plus six GPS standard deviations and six prior standard deviations.
* Speeds: a target's velocity is a random walk (eq. 13) whose components stay within
  six standard deviations, 6 (sigma_v0 + sigma_a sqrt(T)) (plus the manoeuvres'
  largest speed); an estimate's velocity can be further off by the velocity that six
  standard deviations of measurement error (the largest converted-measurement std, at
  the disk's edge, plus the GPS error) make over one step.
* Covariances: symmetric positive definite, with eigenvalues within [floor, cap]. No
  filter of the run can be more certain than one fed at every step with the sensor's
  best possible accuracy: the Kalman recursion (eqs. 23-25) is monotone in the prior
  and in R, each UAV's estimate takes in at most one measurement per step whatever it
  adopts (max-consensus adopts one UAV's tuple; covariance intersection's convex
  weights cannot beat its most certain input), and the best converted measurement has
  R >= r_best I (`best_accuracy`). So the recursion with R = r_best I from the prior
  bounds every honest covariance below; floor is half the smallest eigenvalue it
  reaches. No estimate is less certain than the prior predicted over the whole run
  without a measurement, with the tracker's largest process noise: cap is 100 times
  its largest eigenvalue.
* Confidences: gamma = 1 / trace P, to 1e-9 relative.
* Bids: in [0, horizon x det G's bound at the nadir of the lowest UAV] (the bound of
  `sensing.fisher_det_bound` is non-increasing in range), doubled for an autopilot's
  altitude error.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import estimation, sensing
from ..config import MAX_ALTITUDE, Scenario

SIGMAS = 6.0
"""Standard deviations within which a Gaussian quantity of the run is taken to stay."""
CONSISTENT = 1e-9
"""Relative tolerance of gamma = 1 / trace P and of the symmetry of P."""
RICCATI_STEPS = 20_000
"""Most steps of the covariance recursion computed for `Bounds.floor`; a recursion that
has not settled by then (no process noise) gives floor 0: positive definite only."""


@dataclass(frozen=True, kw_only=True)
class Bounds:
    """Limits of an honest claim in one run (see the module docstring).

    low, high: the range of any x or y [m]; altitude: (lowest, highest) [m]; uav_speed:
    a UAV's largest speed [m/s]; speed: an estimate's largest speed [m/s]; floor, cap:
    the smallest and largest eigenvalue of an estimate's covariance [m^2, m^2/s^2];
    bid: the largest bid [m^-4 summed over the horizon]; unscored: whether a bid may
    be NaN (not scored: ``planner.prune`` in a run where bids are neither lost nor late);
    adopted: the floor of a filter that took in an estimate at `floor` (the recursion
    from floor I), which an honest UAV misled by a member may reach.
    """

    low: float
    high: float
    altitude: tuple[float, float]
    uav_speed: float
    speed: float
    floor: float
    cap: float
    bid: float
    unscored: bool
    adopted: float = 0.0

    @classmethod
    def of(cls, scenario: Scenario) -> Bounds:
        T = scenario.steps * scenario.dt
        gps = SIGMAS * scenario.faults.position_std
        uav_speed = 2.0 * (scenario.uav.speed + scenario.wind.speed)
        error = worst_accuracy(scenario) + scenario.faults.position_std  # one measurement's
        speed = target_speed(scenario) + math.sqrt(2.0) * SIGMAS * error / scenario.dt
        spread = max(0.0, scenario.start_side() - scenario.field_size) / 2
        margin = (
            max(uav_speed, speed) * T
            + spread
            + gps
            + SIGMAS * scenario.estimation.initial_position_std
        )
        heights = scenario.altitudes()
        floor = covariance_floor(scenario)
        return cls(
            low=-margin,
            high=scenario.field_size + margin,
            altitude=(0.0, MAX_ALTITUDE),
            uav_speed=uav_speed,
            speed=speed,
            floor=floor,
            cap=covariance_cap(scenario),
            bid=largest_bid(scenario, heights),
            unscored=scenario.prunes,
            adopted=covariance_floor(scenario, floor * np.eye(4)),
        )


def target_speed(scenario: Scenario) -> float:
    """The largest speed of a target in the run [m/s]: each velocity component within
    `SIGMAS` standard deviations of its random walk (eq. 13), plus the manoeuvres'
    largest speed (``target.motion = manoeuvring``)."""
    T = scenario.steps * scenario.dt
    walk = scenario.target.initial_velocity_std + max(scenario.acceleration_std()) * math.sqrt(
        T + scenario.dt
    )
    extra = scenario.target.manoeuvre.speed_max if scenario.target.motion == "manoeuvring" else 0
    return extra + math.sqrt(2.0) * SIGMAS * walk


def _edges(scenario: Scenario) -> np.ndarray:
    return sensing.edge_range(np.asarray(scenario.altitudes()), scenario.sensor)


def worst_accuracy(scenario: Scenario) -> float:
    """The largest std of a converted measurement of the run [m]: at the edge of the
    highest UAV's disk, the larger of the radial (d_O / r_O) sigma_d and the tangential
    r_O sigma_theta (eqs. 3, 10-12)."""
    s = scenario.sensor
    d_edge = _edges(scenario).max()
    sigma_d, sigma_theta = sensing.noise_std(d_edge, d_edge, s)
    r = d_edge * math.sin(s.alpha)
    return float(max(sigma_d * d_edge / r, r * sigma_theta))


def best_accuracy(scenario: Scenario) -> float:
    """r_best [m^2]: every converted measurement of the run has R >= r_best I.

    R's eigenvalues are the radial (d / r_J sigma_d)^2 >= sigma_d^2 >= k_d^2 (r_J <= d
    away from the nadir) and the tangential (r_J sigma_theta)^2 >= 2 h sigma_d
    (k_theta d / d_O)^2 (r_J >= sqrt(2 h sigma_d), `sensing.convert`), smallest at the
    nadir d = h; h is taken 10% below the lowest UAV for an autopilot's altitude error.
    """
    s = scenario.sensor
    h = 0.9 * min(scenario.altitudes())
    tangential = 2.0 * h * s.k_d * (s.k_theta * math.cos(s.alpha)) ** 2
    return min(s.k_d**2, tangential)


def _prior(scenario: Scenario) -> np.ndarray:
    e = scenario.estimation
    return np.diag([e.initial_position_std**2] * 2 + [e.initial_velocity_std**2] * 2)


def covariance_floor(scenario: Scenario, start: np.ndarray | None = None) -> float:
    """The smallest eigenvalue an honest covariance can have in the run, halved (see the
    module docstring): the Kalman recursion from the prior (or from `start`) with a
    measurement of R = r_best I at every step and the tracker's smallest process noise."""
    A = estimation.transition(scenario.dt)
    Q = estimation.process_noise(scenario.dt, *scenario.acceleration_std())
    R = best_accuracy(scenario) * np.eye(2)
    P = _prior(scenario) if start is None else start
    low = np.inf
    for _ in range(min(scenario.steps, RICCATI_STEPS)):
        _, updated = estimation.update(np.zeros(4), P, np.zeros(2), R)
        low = min(low, float(np.linalg.eigvalsh(updated)[0]))
        following = A @ updated @ A.T + Q
        if np.allclose(following, P, rtol=1e-12, atol=0.0):
            break  # settled: every later step repeats this one
        P = following
    else:
        if scenario.steps > RICCATI_STEPS:
            return 0.0
    return 0.5 * low


def covariance_cap(scenario: Scenario) -> float:
    """The largest eigenvalue an honest covariance can have in the run, times 100: the
    prior predicted over the whole run with no measurement, with the largest process
    noise of the tracker (eq. 23 in closed form: A^K P0 A^K' + sum A^i Q A^i')."""
    sigma = max(scenario.acceleration_std())
    if scenario.tracker.model == "imm":
        sigma = max(sigma, *scenario.tracker.manoeuvre_std)
    T = (scenario.steps + 1) * scenario.dt
    e = scenario.estimation
    # per axis: position variance p0 + v0 T^2 + sigma^2 T^3 / 3 bounds the sum's, and
    # the velocity variance v0 + sigma^2 T; the 2 x 2 block's eigenvalue is below the sum
    position = e.initial_position_std**2 + e.initial_velocity_std**2 * T * T + sigma**2 * T**3
    velocity = e.initial_velocity_std**2 + sigma**2 * T
    return 100.0 * (position + velocity)


def largest_bid(scenario: Scenario, heights: list[float]) -> float:
    """The largest bid of the run: the horizon times `sensing.fisher_det_bound` at the
    nadir of each UAV (the bound is non-increasing in range, and a discount weighs each
    step at most 1), the largest over the UAVs, doubled for an autopilot's altitude
    error."""
    h = np.asarray(heights)
    bound = sensing.fisher_det_bound(h, sensing.edge_range(h, scenario.sensor), scenario.sensor)
    return 2.0 * scenario.planner.horizon * float(np.max(bound))
