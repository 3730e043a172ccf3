"""The parts of a scenario (sensor, UAV, wind, targets, tracker, fusion, evaluation,
estimation, planner, faults, robustness), each a validated pydantic model.

Each field states its unit and its source: a paper equation or section, or
"assumed" with the reason. The paper (Sec. 7) gives V, k_d, k_r, k_theta,
sigma_1, sigma_2, the team sizes, r_C, the FOV, trials and steps, and the shape of
the action set; everything else is an assumption, chosen for physical consistency
(see the documentation's Parameters page).
"""

from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Annotated, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    Strict,
    field_validator,
    model_validator,
)

G = 9.81
"""Gravitational acceleration [m/s^2], eq. (1)."""


def _integer(value: object) -> object:
    """Integers of any kind (numpy's too) become int; anything else is left to fail."""
    if isinstance(value, bool):  # an Integral at run time, refused by the strict field
        return value
    if isinstance(value, Integral):
        return int(value)
    return value


def _real(value: object) -> object:
    """Real numbers of any kind (ints, numpy floats) become float; bools and text fail."""
    if isinstance(value, bool):  # a Real at run time, refused by the strict field
        return value
    if isinstance(value, Real):
        return float(value)
    return value


Int = Annotated[int, BeforeValidator(_integer), Strict()]
"""An integer field: true, 5.0 or "5" are refused rather than read as 1 or 5."""


Float = Annotated[float, BeforeValidator(_real), Strict()]
"""A float field: ints are accepted, booleans and text are refused; inf and NaN too."""


class Part(BaseModel):
    """The base of every part and of the scenario: unknown fields are refused, a model is
    immutable (so hashable and shareable), defaults are validated as given values are,
    and inf and NaN are refused."""

    model_config = ConfigDict(
        extra="forbid", frozen=True, validate_default=True, allow_inf_nan=False
    )


class SensorModel(Part):
    """Range-bearing sensor with a distance-dependent noise (eq. 2-4)."""

    k_d: Float = Field(
        default=0.1056,
        gt=0,
        le=1000,
        description="range-noise scale [m], (0, 1000]; paper eq. (3), Sec. 7",
    )
    k_r: Float = Field(
        default=10.07,
        ge=0,
        le=100,
        description="range-noise growth rate [-], [0, 100]; paper eq. (3), Sec. 7",
    )
    k_theta: Float = Field(
        default=0.01,
        gt=0,
        le=1,
        description="bearing-noise scale [rad], (0, 1]; paper eq. (3), Sec. 7",
    )
    half_fov_deg: Float = Field(
        default=5.0,
        gt=0,
        lt=90,
        description=(
            "half field of view alpha [deg], (0, 90); paper Sec. 7.1 (FOV 2*alpha = 10 deg)"
        ),
    )

    detection_probability: Float = Field(
        default=1.0,
        gt=0,
        le=1,
        description=(
            "probability P_D that a target inside the observation disk is detected in a scan "
            "[-], (0, 1]; 1: the paper's ideal sensor; each (UAV, target, scan) is drawn from "
            "the trial's own detection stream, so the paper's draws are the same at any value"
        ),
    )
    clutter_rate: Float = Field(
        default=0.0,
        ge=0,
        le=1000,
        description=(
            "mean number of false measurements per UAV and scan [-], [0, 1000]; 0: the paper's "
            "sensor; a Poisson count, uniform over the observation disk and converted through "
            "the same range-bearing noise model (eq. 2-12)"
        ),
    )

    @property
    def alpha(self) -> float:
        """Half field of view [rad]."""
        return math.radians(self.half_fov_deg)

    @property
    def ideal(self) -> bool:
        """Whether every target in view is detected and nothing false is seen (the paper)."""
        return self.detection_probability == 1.0 and self.clutter_rate == 0.0


MAX_ALTITUDE = 20_000.0
"""Highest flight altitude accepted [m] (above any fixed-wing UAV's ceiling)."""


class UAVModel(Part):
    """Fixed-wing UAVs at constant speed and altitude, bank-angle actions (eq. 1)."""

    speed: Float = Field(
        default=15.0, gt=0, le=300, description="airspeed V [m/s], (0, 300]; paper Sec. 7"
    )
    min_speed: Float | None = Field(
        default=None,
        gt=0,
        le=300,
        description=(
            "slowest airspeed the avoidance filter may fly a UAV at [m/s], (0, speed); beyond "
            "the paper, whose UAVs fly at one speed: a second control, with "
            "planner.avoidance = loiter; every UAV's backup manoeuvre is then the loiter at "
            "this speed, whose radius shrinks with its square, and the filter slows a UAV "
            "before it bends its path (docs: One altitude); the planner plans at speed; the "
            "backup turns at most a quarter turn a step; the unicycle only (the MAVLink and "
            "ROS 2 outputs carry the bank alone); not set: the paper's constant speed"
        ),
    )
    bank_angle_deg: Float = Field(
        default=45.0,
        gt=0,
        lt=90,
        description=(
            "bank angle phi of the action set {-phi, 0, +phi} [deg], (0, 90); assumed: the "
            "paper does not give it; 45 deg, a usual limit for small fixed-wing UAVs, gives a "
            "turn radius V^2/(g tan phi) = 22.9 m, inside the 37 m observation disk"
        ),
    )
    altitude: Float = Field(
        default=425.0,
        gt=0,
        le=MAX_ALTITUDE,
        description=(
            "mean flight altitude [m], (0, 20000]; assumed: the observation radius h tan(alpha) "
            "must exceed the turn radius for a UAV to orbit a target in view (37 m against "
            "23 m at 425 m); calibrated with dt against the paper's Fig. 5 (see the docs, "
            "Calibration)"
        ),
    )
    altitude_spacing: Float = Field(
        default=5.0,
        ge=-1000,
        le=1000,
        description=(
            "altitude difference between consecutive UAVs [m], [-1000, 1000] (negative: UAV 0 "
            "flies highest); assumed: the paper flies each UAV at its own altitude; 5 m keeps "
            "the team's spread (20 m for 5 UAVs) well inside r_C = 50 m; results barely "
            "depend on it (0 to 10 m tried)"
        ),
    )
    altitudes: tuple[Annotated[Float, Field(gt=0, le=MAX_ALTITUDE)], ...] | None = Field(
        default=None,
        description=(
            "explicit per-UAV altitudes [m], each in (0, 20000], overriding altitude and "
            "altitude_spacing; length n_uavs; not set by default"
        ),
    )
    separation: Float = Field(
        default=0.0,
        ge=0,
        le=1000,
        description=(
            "minimum horizontal distance between two UAVs closer than "
            "uav.vertical_separation in altitude [m], [0, 1000]; 0: no minimum (the "
            "paper's layered team needs none); beyond the paper (its Sec. 8 leaves "
            "horizontal avoidance out): a pair closer at a step is a loss of separation, "
            "counted in every run"
        ),
    )
    vertical_separation: Float = Field(
        default=5.0,
        gt=0,
        le=1000,
        description=(
            "altitude difference below which two UAVs share an altitude band and must keep "
            "uav.separation horizontally [m], (0, 1000]; assumed: 5 m, so the paper's "
            "layers 5 m apart (uav.altitude_spacing) are separated, about twice the "
            "altitude a small UAV's autopilot holds to"
        ),
    )
    start_spread: Float = Field(
        default=20.0,
        ge=0,
        le=100_000,
        description=(
            "side of the square around the field centre where UAVs start [m], [0, 100000] "
            '(uav.start = "grid": the distance between neighbours of the grid); '
            "assumed: the team takes off together"
        ),
    )
    start: Literal["square", "grid"] = Field(
        default="square",
        description=(
            "how the UAVs start [-], (square, grid); square: uniform positions in the square "
            "of side uav.start_spread and uniform headings (the random draws of every "
            "run); grid: a square grid of spacing uav.start_spread at the field centre, "
            "every UAV heading north, the draws made and set aside (targets and priors "
            "stay those of square); beyond the paper: a team at one altitude that arrives "
            "in formation, so that no two start closer than the spacing "
            "(planner.avoidance needs a start without conflict)"
        ),
    )
    dynamics: Literal["unicycle", "jsbsim"] = Field(
        default="unicycle",
        description=(
            "how the world flies a UAV [-], (unicycle, jsbsim); unicycle: the paper's eq. (1), "
            "the bank angle turns the heading at once; jsbsim: a JSBSim fixed-wing aircraft "
            "(uav.aircraft) whose autopilot holds the bank angle, altitude and airspeed, "
            "integrated at uav.jsbsim_rate_hz; beyond the paper (its Sec. 8 names the "
            "simplified kinematics as its first limit); the planner keeps eq. (1) either way"
        ),
    )
    aircraft: str = Field(
        default="trackwing",
        min_length=1,
        max_length=200,
        description=(
            "the JSBSim model flown with uav.dynamics = jsbsim; beyond the paper: trackwing "
            "(uavtrack's 2.5 kg UAV, trimmed at 15 m/s), a model shipped with JSBSim, or the "
            "folder of another model; its autopilot must answer uavtrack's (docs, Real flight)"
        ),
    )
    jsbsim_rate_hz: Float = Field(
        default=120.0,
        ge=50,
        le=1000,
        description=(
            "rate JSBSim integrates the aircraft and runs its autopilot [Hz], [50, 1000]; "
            "beyond the paper; JSBSim's default 120 Hz; each cycle of dt is split into "
            "round(dt x rate) steps"
        ),
    )


class WindModel(Part):
    """Steady wind and JSBSim's turbulence, felt by the aircraft of uav.dynamics = jsbsim."""

    speed: Float = Field(
        default=0.0,
        ge=0,
        le=50,
        description=(
            "steady wind speed [m/s], [0, 50]; beyond the paper; the autopilot holds the "
            "airspeed, so a UAV's ground speed grows downwind and shrinks upwind"
        ),
    )
    direction_deg: Float = Field(
        default=0.0,
        ge=0,
        lt=360,
        description=(
            "direction the wind blows from [deg], [0, 360), clockwise from the scenario's +y "
            "axis (north), as a weather report gives it: 270 blows towards +x; beyond the paper"
        ),
    )
    turbulence: Literal["none", "light", "moderate", "severe"] = Field(
        default="none",
        description=(
            "beyond the paper: JSBSim's Dryden turbulence (MIL-F-8785C, Tustin form) at the "
            "intensities of "
            "the milspec: light, moderate, severe (wind at 20 ft of 15, 30, 45 kt, probability "
            "of exceedance 1e-2, 1e-3, 1e-5), or none; seeded from each trial's flight stream"
        ),
    )

    def velocity(self) -> tuple[float, float]:
        """The air mass's velocity (east, north) = (+x, +y) [m/s]: it moves away from
        the direction the wind blows from."""
        towards = math.radians(self.direction_deg) + math.pi  # clockwise from north
        return self.speed * math.sin(towards), self.speed * math.cos(towards)


class ManoeuvreModel(Part):
    """Manoeuvring targets (target.motion = "manoeuvring"), beyond the paper: each target
    flies segments of random length, each straight or a coordinated turn, at a new speed
    or stopping, with the white acceleration of eq. (15) on top."""

    interval: Float = Field(
        default=8.0,
        gt=0,
        le=1000,
        description=(
            "mean length of a segment [s], (0, 1000], exponentially distributed; assumed: a "
            "ground vehicle changes what it does every few seconds"
        ),
    )
    turn_probability: Float = Field(
        default=0.5,
        ge=0,
        le=1,
        description="probability that a segment is a turn [-], [0, 1]; assumed: half of them",
    )
    turn_rate_max_deg: Float = Field(
        default=15.0,
        ge=0,
        le=90,
        description=(
            "largest turn rate [deg/s], [0, 90], a turn's rate uniform in +-it; assumed: a "
            "vehicle at 3 m/s turning at 15 deg/s follows an 11 m radius"
        ),
    )
    speed_max: Float = Field(
        default=3.0,
        gt=0,
        le=50,
        description=(
            "largest speed [m/s], (0, 50], a segment's speed uniform in [speed_max / 4, "
            "speed_max]; assumed: slow vehicles, as target.initial_velocity_std"
        ),
    )
    stop_probability: Float = Field(
        default=0.15,
        ge=0,
        le=1,
        description="probability that a segment is a stop [-], [0, 1]; assumed",
    )
    acceleration_max: Float = Field(
        default=0.5,
        gt=0,
        le=20,
        description=(
            "largest acceleration along the path when the speed changes [m/s^2], (0, 20]; "
            "assumed: a gentle vehicle"
        ),
    )


class TargetModel(Part):
    """Ground targets: nearly constant velocity with white acceleration noise (eq. 13-15)."""

    sigma_1: Float = Field(
        default=0.16,
        ge=0,
        le=10,
        description=(
            "acceleration-noise std along x [m/s^2], [0, 10] (a velocity increment per "
            "step [m/s] with target.noise_form = 'printed'); paper eq. (15), Sec. 7"
        ),
    )
    sigma_2: Float = Field(
        default=0.16,
        ge=0,
        le=10,
        description=(
            "acceleration-noise std along y [m/s^2], [0, 10] (a velocity increment per "
            "step [m/s] with target.noise_form = 'printed'); paper eq. (15), Sec. 7"
        ),
    )
    initial_velocity_std: Float = Field(
        default=1.0,
        ge=0,
        le=50,
        description=(
            "std of each initial velocity component [m/s], [0, 50]; assumed: slow ground "
            "vehicles or pedestrians; the paper says only that targets move randomly"
        ),
    )
    motion: Literal["ncv", "manoeuvring"] = Field(
        default="ncv",
        description=(
            "how targets move [-], (ncv, manoeuvring); ncv: the paper's nearly constant "
            "velocity (eq. 13); manoeuvring: beyond the paper, straight legs, coordinated "
            "turns, speed changes and stops (target.manoeuvre), reflected at the walls"
        ),
    )
    manoeuvre: ManoeuvreModel = Field(
        default_factory=ManoeuvreModel, description="manoeuvres (target.motion = manoeuvring)"
    )
    stay: Float = Field(
        default=0.0,
        ge=0,
        le=1e6,
        description=(
            "mean steps a target stays in the field [steps], 0 or [1, 1e6]; 0: every target "
            "stays the whole run, the paper's fixed set; beyond the paper: each leaves with "
            "probability 1/stay per step (a death) and a new one enters after a mean of "
            "target.away steps (a birth), where the hidden motion has taken it"
        ),
    )
    away: Float = Field(
        default=100.0,
        ge=1,
        le=1e6,
        description=(
            "mean steps a target's place stays empty before a new target enters [steps], "
            "[1, 1e6] (target.stay > 0); assumed 100: with stay 200 a third of the places "
            "are empty in the long run, so the team keeps finding new targets"
        ),
    )
    noise_form: Literal["acceleration", "printed"] = Field(
        default="acceleration",
        description=(
            "reading of eq. (15) [-]: 'acceleration' takes sigma as a white acceleration "
            "[m/s^2] (Q = sigma^2 [[dT^4/4, dT^3/2], [dT^3/2, dT^2]] per axis), 'printed' "
            "as the printed matrix sigma^2 [[dT^2/4, dT/2], [dT/2, 1]], a velocity "
            "increment of std sigma per step; the two agree at dT = 1 s; assumed "
            "'acceleration' (sigma keeps its unit at any time step); filter and truth alike"
        ),
    )


class TrackerModel(Part):
    """The local filter of each (UAV, target): the paper's Kalman filter or an IMM."""

    model: Literal["cv", "imm"] = Field(
        default="cv",
        description=(
            "the filter [-], (cv, imm); cv: the paper's nearly-constant-velocity Kalman filter "
            "(eq. 22-25); imm: beyond the paper, an interacting multiple model filter whose "
            "first mode is that filter and whose other modes have the larger accelerations "
            "of tracker.manoeuvre_std; fusion and planning read its combined estimate"
        ),
    )
    manoeuvre_std: tuple[Annotated[Float, Field(gt=0, le=100)], ...] = Field(
        default=(0.5, 2.3),
        min_length=1,
        max_length=5,
        description=(
            "white-acceleration std of each further IMM mode [m/s^2], each in (0, 100], 1 to "
            "5 modes; assumed: 0.5 m/s^2 covers the manoeuvring targets' turns and stops, "
            "2.3 m/s^2 a reflection at a wall; tuned on 16 trials of each target motion for "
            "a mean NEES near 4 (docs, Trackers)"
        ),
    )
    turn_rates_deg: tuple[Annotated[Float, Field(gt=0, le=90)], ...] = Field(
        default=(),
        max_length=3,
        description=(
            "turn rates of further IMM modes [deg/s], each in (0, 90], at most 3: each adds "
            "two coordinated-turn modes (left and right at that known rate, the paper's "
            "noise), after the manoeuvre modes; none by default (docs, Trackers, measures "
            "them against the noise-only modes)"
        ),
    )
    transition: tuple[tuple[Annotated[Float, Field(ge=0, le=1)], ...], ...] = Field(
        default=((0.95, 0.04, 0.01), (0.10, 0.85, 0.05), (0.30, 0.30, 0.40)),
        description=(
            "IMM mode transition matrix [-], entries in [0, 1], each row summing to 1, one "
            "row and column per mode (the cv mode first); p_ij = P(mode j at k+1 | mode i "
            "at k); assumed: a manoeuvre lasts several cycles, a jump one or two"
        ),
    )

    association: Literal["known", "gnn", "jpda"] = Field(
        default="known",
        description=(
            "how measurements meet tracks [-], (known, gnn, jpda); known: the paper's, each "
            "measurement arrives labelled with its target and each UAV keeps one filter per "
            "target; gnn and jpda: beyond the paper, a UAV receives an unlabelled set of "
            "measurements and keeps up to tracker.max_tracks tracks, global nearest neighbour "
            "(the exact assignment of the gated measurements) or joint probabilistic data "
            "association (exact joint events per cluster of gated tracks)"
        ),
    )
    max_tracks: Int = Field(
        default=0,
        ge=0,
        le=1000,
        description=(
            "track slots per UAV with gnn or jpda [-], 0 to 1000; 0: twice n_targets plus 4; "
            "assumed: room for every target, a false track per target and a few more"
        ),
    )
    gate_probability: Float = Field(
        default=0.99,
        gt=0,
        lt=1,
        description=(
            "gate probability P_G [-], (0, 1): a measurement may meet a track when its "
            "squared innovation distance is below the chi-square(2) quantile of P_G; the same "
            "quantile of chi-square(4) gates track-to-track association; assumed: 0.99, "
            "the usual choice (Stone Soup's examples, Bar-Shalom)"
        ),
    )
    confirm: tuple[Annotated[Int, Field(ge=1, le=20)], Annotated[Int, Field(ge=1, le=20)]] = Field(
        default=(4, 5),
        description=(
            "M-of-N confirmation (M, N) [scans], each 1 to 20, M <= N: a tentative track is "
            "confirmed when it met a measurement in M of its first N scans in view (its "
            "birth the first), and deleted when it can no longer; assumed: 4 of 5, "
            "measured against 2 of 3, the common choice: the gate of a track born from "
            "one converted measurement (radial std up to 6 m) holds a false measurement "
            "with probability near 0.08 per scan at 2 per scan, and 2 of 3 confirmed "
            "enough of them to lower the distributed rate at P_D 0.9 to 0.47 (0.69 with "
            "4 of 5; 20 trials; docs: Missed detections, clutter and unknown association)"
        ),
    )
    delete_misses: Int = Field(
        default=3,
        ge=1,
        le=1000,
        description=(
            "a confirmed track is deleted after this many consecutive scans in view without "
            "a measurement [scans], 1 to 1000, and the deletion travels to the team (a "
            "tombstone); assumed: 3 misses happen with probability 0.001 at P_D = 0.9 "
            "(0.027 at 0.7) on a target that is there, and a false track dies sooner; "
            "measured against 5 (docs: Missed detections, clutter and unknown association)"
        ),
    )
    delete_std: Float = Field(
        default=40.0,
        gt=0,
        le=100_000,
        description=(
            "a track whose position std sqrt(trace of its position covariance) exceeds this "
            "is deleted [m], (0, 100000]; assumed: about the observation radius (37 m), past "
            "which the estimate no longer says where to look; a false track that no UAV "
            "sees any more lives until then"
        ),
    )
    confirmation: Literal["existence", "m_of_n"] = Field(
        default="existence",
        description=(
            "how tracks are confirmed and deleted [-], (existence, m_of_n); existence: "
            "beyond the paper, each track carries its probability of existence (integrated "
            "PDA, JIPDA with jpda: P_D times it in the association weights, updated by "
            "detections and misses, predicted with tracker.survival), confirmed at or "
            "above the first of tracker.existence and deleted below the second; m_of_n: "
            "tracker.confirm and tracker.delete_misses count scans (the rule before "
            "existence; its results as they were); assumed: existence, measured against "
            "m_of_n at P_D 0.9 and 2 clutter per scan: distributed rate 0.772 against "
            "0.700 (known 0.799), centralized GOSPA 6.4 against 13.6 m (docs: Track "
            "existence)"
        ),
    )
    existence: tuple[Annotated[Float, Field(gt=0, lt=1)], Annotated[Float, Field(gt=0, lt=1)]] = (
        Field(
            default=(0.95, 0.05),
            description=(
                "existence thresholds (confirm, delete) [-], each in (0, 1), delete below "
                "confirm and below tracker.birth_existence; assumed: 0.95 and 0.05, a false "
                "track then confirmed with probability near 0.05 (docs: Track existence)"
            ),
        )
    )
    birth_existence: Float = Field(
        default=0.1,
        gt=0,
        lt=1,
        description=(
            "existence probability of a track born from one measurement [-], (0, 1), "
            "between the two of tracker.existence; "
            "assumed: 0.1, so that two more detections near the track's centre confirm it "
            "(0.81, then 0.99 at 2 clutter per scan) and a scan without one deletes it "
            "(docs: Track existence)"
        ),
    )
    survival: Float = Field(
        default=0.99,
        gt=0,
        le=1,
        description=(
            "probability that a track's target is still there one step later [-], (0, 1]; "
            "assumed: 0.99, a track no UAV sees falls from confirmation to deletion in "
            "about 300 steps (docs: Track existence)"
        ),
    )
    merge: Int = Field(
        default=0,
        ge=0,
        le=100,
        description=(
            "beyond the paper: tracks of one UAV (or of the central node) that lie within "
            "each other's position gate (tracker.gate_probability on the sum of their "
            "covariances) in this many scans in view in a row are one target's: the less "
            "confident goes, the other keeps the smaller label [scans], 0 to 100; 0: no "
            "merging; assumed: 0, since existence leaves next to no duplicates to merge "
            "(3 changed the centralized GOSPA from 6.36 to 6.44 m, 10 trials; with m_of_n "
            "it lowers duplicates from 0.077 to 0.033 per target and step; docs: Track "
            "existence)"
        ),
    )
    briefing: bool = Field(
        default=True,
        description=(
            "true or false [-]: whether the mission starts with every target a confirmed "
            "track of every UAV (the initial belief the paper's filters start from); "
            "false: beyond the paper, no track at the start, and the team must find the "
            "targets; assumed: true, the paper's start"
        ),
    )
    birth_velocity_std: Float = Field(
        default=2.0,
        gt=0,
        le=100,
        description=(
            "velocity std of a track born from one measurement [m/s], (0, 100]; assumed: "
            "twice the targets' initial velocity spread, broad enough for any target"
        ),
    )

    @model_validator(mode="after")
    def _confirm_order(self) -> TrackerModel:
        if self.confirm[0] > self.confirm[1]:
            raise ValueError(f"confirm {self.confirm}: M must not exceed N")
        confirm, delete = self.existence
        if not delete < self.birth_existence < confirm:
            raise ValueError(
                f"existence {self.existence} and birth_existence {self.birth_existence}: "
                "need delete < birth_existence < confirm"
            )
        return self

    @model_validator(mode="after")
    def _square(self) -> TrackerModel:
        m = 1 + len(self.manoeuvre_std) + 2 * len(self.turn_rates_deg)
        if len(self.transition) != m or any(len(row) != m for row in self.transition):
            raise ValueError(
                f"transition must be {m} x {m} (one row and column per mode: the cv "
                f"mode, {len(self.manoeuvre_std)} of tracker.manoeuvre_std and "
                f"{2 * len(self.turn_rates_deg)} of tracker.turn_rates_deg)"
            )
        for i, row in enumerate(self.transition):
            if abs(sum(row) - 1.0) > 1e-9:
                raise ValueError(f"transition row {i} sums to {sum(row):g}, not 1")
        return self

    @property
    def unlabelled(self) -> bool:
        """Whether each UAV's measurements come as an unlabelled scan that its tracks read
        (gnn, jpda); with known association (the oracle) each names its target. The one
        reading of the association that the cycle's forms and outputs branch on."""
        return self.association != "known"


class FusionModel(Part):
    """How a UAV combines its estimate with its neighbours' (Algorithm 2, lines 15-25)."""

    rule: Literal["max_consensus", "covariance_intersection"] = Field(
        default="max_consensus",
        description=(
            "the fusion rule of each consensus round [-], (max_consensus, "
            "covariance_intersection); max_consensus: the paper's eq. (27), adopt the most "
            "confident tuple; covariance_intersection: beyond the paper, fuse the received "
            "estimates by covariance intersection with weights 1 / trace(P) (fast CI), "
            "consistent whatever their correlation; the consensus of distributed and greedy "
            "(centralized has no consensus: its node takes each target's best upload)"
        ),
    )
    trigger: Float | None = Field(
        default=None,
        ge=0,
        le=10,
        description=(
            "event-triggered consensus [-], 0 to 10; beyond the paper: a UAV sends a "
            "target's tuple in a cycle's first round only when its confidence changed by "
            "more than this fraction since the UAV last sent that target (or every "
            "fusion.refresh cycles), and in later rounds only when the tuple changed since "
            "its previous round; a tuple not sent is not offered, its receivers keep what "
            "they hold; not set: the paper's exchange, every tuple in every round"
        ),
    )
    refresh: Int = Field(
        default=10,
        ge=1,
        le=1_000_000,
        description=(
            "with fusion.trigger, a UAV sends all its tuples every this many cycles "
            "[cycles], 1 to 10^6; assumed: 10 (5 s at dT = 0.5 s), so that a UAV that met "
            "a new neighbour, or whose messages were lost, is brought up to date within a "
            "few seconds; 1: every cycle (the trigger acts in later rounds only)"
        ),
    )

    @model_validator(mode="after")
    def _refresh(self) -> FusionModel:
        if self.trigger is None and self.refresh != 10:
            raise ValueError(
                f"fusion.refresh {self.refresh} needs fusion.trigger (it does nothing "
                "otherwise); set fusion.trigger or leave fusion.refresh unset"
            )
        return self


class RadioModel(Part):
    """What the radio carries and how (not in the paper, which assumes an ideal radio)."""

    encoding: Literal["full", "compact", "quantized"] = Field(
        default="full",
        description=(
            "how estimates travel [-], (full, compact, quantized); full: float64 states, the "
            "whole covariance, every target in every round (the agent form as it was, beyond "
            "the paper, which does not say); compact, beyond the paper: float32 states, the "
            "covariance's upper triangle (10 of 16 numbers), the confidence recomputed by the "
            "receiver from the covariance it got, and in a cycle's later consensus rounds only "
            "the targets whose tuple changed since the sender's previous round; quantized: as "
            "compact with float16 states and the covariance in 14 bytes (log variances, "
            "correlations), coded conservatively: what arrives has a covariance at least the "
            "sender's, its float16 rounding included (docs: The radio's load)"
        ),
    )
    frames: Literal["unicast", "broadcast"] = Field(
        default="unicast",
        description=(
            "how a message reaches the UAVs in range [-], (unicast, broadcast); unicast: "
            "one frame per receiver, each with its own envelope and tag (the agent form as "
            "it was, beyond the paper, which does not say); broadcast, beyond the paper: "
            "one frame per round to all receivers, its envelope naming them with a tag for "
            "each under that pair's key (docs: Security), as a radio broadcasts; a frame to "
            "one receiver stays a plain one"
        ),
    )
    bandwidth_bps: Float | None = Field(
        default=None,
        gt=0,
        le=1e10,
        description=(
            "the radio channel's capacity [bit/s], (0, 10^10]; beyond the paper: UAVs in "
            "range of each other share it, each an equal part of it per cycle (capacity x dT "
            "/ 8 bytes over its closed neighbourhood; with the centralized method every UAV "
            "and the central node share one channel); what does not fit is not sent: first "
            "the beacon with the bids (the centralized upload), then the rounds of D_i "
            "flooding and consensus in order, each reserved at the largest a round can be, "
            "the central node's downloads in UAV order; not set: unlimited (the paper's "
            "ideal radio)"
        ),
    )


class EvaluationModel(Part):
    """How the estimates are scored against the truth as point sets (not in the paper)."""

    ospa_cutoff: Float = Field(
        default=20.0,
        gt=0,
        le=100_000,
        description=(
            "cut-off c of OSPA and GOSPA [m], (0, 100000]; assumed: about half the "
            "observation radius (37 m): an estimate farther off would not bring its UAV "
            "over the target"
        ),
    )
    ospa_order: Float = Field(
        default=1.0,
        ge=1,
        le=10,
        description="order p of OSPA and GOSPA [-], [1, 10]; assumed: 1, the mean error",
    )


class EstimationModel(Part):
    """Initial belief shared by all UAVs (the paper does not say how filters start)."""

    initial_position_std: Float = Field(
        default=5.0,
        gt=0,
        le=10_000,
        description=(
            "std of the initial position cue and of the prior [m], (0, 10000]; assumed: every "
            "UAV starts with a cue of each target (a consistent Gaussian prior around the truth)"
        ),
    )
    initial_velocity_std: Float = Field(
        default=1.0,
        gt=0,
        le=100,
        description=(
            "prior velocity std [m/s], (0, 100]; assumed: equal to the targets' initial "
            "velocity spread, so the prior is consistent"
        ),
    )


Bool = Annotated[bool, Strict()]
"""A boolean field: true or false only (not 1 or "yes")."""


class PlannerModel(Part):
    """Receding-horizon action search (Algorithm 1, lines 1-4)."""

    horizon: Int = Field(
        default=3,
        ge=2,
        le=10,
        description=(
            "planning horizon h [steps], 2 to 10; assumed: the paper does not give it; 3 steps "
            "(1.5 s) keeps the search at 27 sequences per target; under eq. (1) the bank angle "
            "chosen at step k first moves the UAV at k+2, so h >= 2"
        ),
    )
    discount: Float = Field(
        default=1.0,
        gt=0,
        le=1,
        description=(
            "weight lambda^(t-1) of the t-th step's det G [-], (0, 1]; Algorithm 1 sums "
            "undiscounted (1.0)"
        ),
    )
    prune: Bool = Field(
        default=True,
        description=(
            "true or false; beyond the paper (Algorithm 1 scores every target; the "
            "decisions are the same): score only the bids an assignment can read (a UAV in "
            "neighbourhoods of at most k members needs its k best; greedy its best), "
            "skipping targets whose upper bound of det G cannot reach them; false: score "
            "every bid, so that the "
            "trace holds them all (as it always does when messages can be lost or late)"
        ),
    )
    existence: Bool = Field(
        default=False,
        description=(
            "true or false; beyond the paper, with tracker.confirmation = existence: each "
            "bid times its track's existence probability, the information expected of a "
            "track that may not be there; assumed false: measured at P_D 0.9, 2 clutter, "
            "jpda, 36 paired trials, it lowers the distributed observation rate by 0.028 "
            "(0.018 with target.stay 200), as the team stops visiting targets it has not "
            "seen for a while (docs: Track existence)"
        ),
    )
    wind: Bool = Field(
        default=False,
        description=(
            "true or false; beyond the paper: plan with the steady wind (wind.speed and "
            "wind.direction_deg, as an autopilot's wind estimate gives it): eq. (1) flown in "
            "the air mass at the UAV's airspeed, plus the wind's drift; false: eq. (1) over "
            "the ground at the ground speed, the paper's model"
        ),
    )
    avoidance: Literal["none", "loiter"] = Field(
        default="none",
        description=(
            "collision avoidance at one altitude [-], (none, loiter); none: the paper's "
            "(its UAVs fly at their own altitudes); loiter: each UAV flies its planned "
            "action only if it keeps uav.separation, by the clearance of loiter circles, "
            "from the neighbours whose beacons it heard (their age counted), and otherwise "
            "flies the allowed action the planner scores best (the loiter is always "
            "allowed; airspace.avoidance: what it guarantees and under which "
            "assumptions); beyond the paper (its Sec. 8)"
        ),
    )

    avoidance_model: Literal["unicycle", "measured"] = Field(
        default="unicycle",
        description=(
            "how the avoidance filter predicts a UAV's flight [-], (unicycle, measured); "
            "unicycle: eq. (1), exact for uav.dynamics = unicycle; measured: tables of how "
            "the scenario's aircraft answers each action after its last two, measured by "
            "flying its flight model, with the margin their largest errors need "
            "(airspace.response); beyond the paper"
        ),
    )

    avoidance_margin: Float = Field(
        default=0.0,
        ge=0,
        le=1000,
        description=(
            "distance the avoidance filter adds to uav.separation [m], [0, 1000]; 0: the "
            "unicycle of eq. (1), for which the filter's guarantee is proven; an aircraft "
            'that banks over time (uav.dynamics = "jsbsim") leaves the planner\'s '
            "polygon: planner.avoidance_model = measured predicts it, with the margin its "
            "errors need added to this one (docs: One altitude); beyond the paper"
        ),
    )

    @field_validator("avoidance", mode="before")
    @classmethod
    def _none(cls, value: object) -> object:
        return "none" if value is None else value  # `--set planner.avoidance=none`


class FaultModel(Part):
    """Faults the paper leaves open (Sec. 8); every default means "no fault".

    Realised per trial from its own random stream (`uavtrack.faults`), the same for
    every method, so differences between methods stay paired.
    """

    loss: Float = Field(
        default=0.0,
        ge=0,
        le=1,
        description=(
            "probability [-], [0, 1], that one radio message is lost (each directed link, "
            "round and protocol: beacons, D_i flooding, consensus tuples, bids, uploads, "
            "downloads); beyond the paper (Sec. 8); independent unless burst_length > 1"
        ),
    )
    burst_length: Float = Field(
        default=1.0,
        ge=1,
        le=1000,
        description=(
            "mean length of a link's loss bursts [cycles], [1, 1000]; beyond the paper; 1: "
            "independent losses; "
            "above 1: a Gilbert-Elliott channel per directed link with the same long-run "
            "loss, which needs burst_length >= 1 / (1 - loss)"
        ),
    )
    delay: Int = Field(
        default=0,
        ge=0,
        le=50,
        description=(
            "cycles by which every message arrives late [cycles], 0 to 50; beyond the paper; a "
            "message of round r of cycle k is received in round r of cycle k + delay"
        ),
    )
    round_budget: Int | None = Field(
        default=None,
        ge=1,
        le=1000,
        description=(
            "most rounds a cycle has time for, in the D_i flooding and in the consensus "
            "[rounds], 1 to 1000; beyond the paper; not set: unlimited, as the paper"
        ),
    )
    failure_rate: Float = Field(
        default=0.0,
        ge=0,
        le=1,
        description=(
            "probability [-], [0, 1], per UAV and cycle, that a UAV fails for good (it no "
            "longer senses, sends or counts as observing); beyond the paper"
        ),
    )
    failures: tuple[tuple[Annotated[Int, Field(ge=0)], Annotated[Int, Field(ge=0)]], ...] = Field(
        default=(),
        description=(
            "explicit failures as [uav, step] pairs [-], uav in [0, n_uavs), step in [0, "
            "steps): the UAV is down from that step on; beyond the paper; none by default"
        ),
    )
    position_std: Float = Field(
        default=0.0,
        ge=0,
        le=1000,
        description=(
            "standard deviation of each UAV's own position error per axis (GPS) [m], "
            "[0, 1000], drawn per UAV and cycle; beyond the paper; the UAV converts its "
            "measurements and plans from where it believes it is"
        ),
    )

    @model_validator(mode="after")
    def _bursts(self) -> FaultModel:
        if self.burst_length > 1 and not 0 < self.loss < 1:
            raise ValueError(
                f"burst_length {self.burst_length:g} needs 0 < loss < 1 (at loss {self.loss:g} "
                "every message is lost or none is); use burst_length 1"
            )
        if self.burst_length > 1:
            least = 1.0 / (1.0 - self.loss)
            if self.burst_length < least:
                raise ValueError(
                    f"burst_length {self.burst_length:g} is shorter than {least:.3g}, the mean "
                    f"burst of independent losses at loss {self.loss:g}; use burst_length 1 "
                    f"(independent) or at least {least:.3g}"
                )
        return self

    @field_validator("failures", mode="after")
    @classmethod
    def _sorted(cls, value: tuple[tuple[int, int], ...]) -> tuple[tuple[int, int], ...]:
        return tuple(sorted(value))  # one order: the same failures are the same scenario

    @model_validator(mode="after")
    def _one_failure_per_uav(self) -> FaultModel:
        seen: dict[int, int] = {}
        for uav, step in self.failures:
            if uav in seen:
                raise ValueError(
                    f"failures lists UAV {uav} twice (steps {seen[uav]} and {step}); a UAV "
                    "fails once"
                )
            seen[uav] = step
        return self


class RobustModel(Part):
    """Mechanisms against faults, beyond the paper; off by default (the paper as printed)."""

    extra_rounds: Int = Field(
        default=0,
        ge=0,
        le=100,
        description=(
            "consensus rounds run beyond the D_i a UAV learned [rounds], 0 to 100; beyond the "
            "paper: lost flooding messages make D_i too small; 0: the paper's rule"
        ),
    )
    stale: Bool = Field(
        default=False,
        description=(
            "true or false; beyond the paper: time-stamp consensus tuples and predict stale ones "
            "forward to "
            "the current step before comparing them, and drop from the auction a neighbour "
            "whose bid did not arrive this cycle (instead of using its last bid); false: the "
            "paper's protocol, which has no time stamps"
        ),
    )
    position_noise: Bool = Field(
        default=False,
        description=(
            "true or false; beyond the paper: each UAV adds its own position-error variance "
            "(faults.position_std^2, as its GPS reports it) to the covariance R of every "
            "converted measurement, which the conversion of eq. (5) otherwise ignores"
        ),
    )
    gate: Float | None = Field(
        default=None,
        ge=0.9,
        lt=1,
        description=(
            "probability [-], [0.9, 1), with which an honest estimate passes the measurement "
            "gate; beyond the paper: a UAV adopts (consensus) or takes (centralized download) "
            "no estimate of a target that contradicts its own measurement of the target this "
            "cycle (nu^T (H P H^T + R)^-1 nu above the chi-square quantile -2 ln(1 - p); "
            "0.9999: 18.4), its own estimate included, nor, within robust.gate_memory cycles "
            "of its last measurement of the target, one that contradicts its own estimate the "
            "same way; a neighbour caught on one target is believed on none in that round; "
            "with tracks (gnn, jpda) an offered track must agree with the receiver's slot of "
            "its label if the receiver's own scans met it within robust.gate_memory cycles, "
            "else with a measurement of its scan unless it lies out of view (a centralized "
            "UAV checks the download's tracks by its scan alone); "
            "assumed as an option against a member that lies with high confidence; not set: "
            "the paper's rule, the most confident estimate is adopted"
        ),
    )
    gate_memory: Int = Field(
        default=12,
        ge=0,
        le=10_000_000,
        description=(
            "cycles after a UAV last measured a target (the initial cue counts as a "
            "measurement at step 0) during which robust.gate checks estimates of the target "
            "against the UAV's own [cycles], 0 to 10^7; needs robust.gate; assumed: 12 (6 s "
            "at dT = 0.5 s), long enough to bridge a tracking UAV's gaps in view, short enough "
            "that an estimate of a target reflected at a wall (which the filter's model does "
            "not know) is still near its prediction; 4 to 16 measured in the docs (Faults and "
            "robustness)"
        ),
    )

    @model_validator(mode="after")
    def _memory(self) -> RobustModel:
        if self.gate is None and self.gate_memory != 12:
            raise ValueError(
                f"robust.gate_memory {self.gate_memory} needs robust.gate (it does nothing "
                "otherwise); set robust.gate or leave robust.gate_memory unset"
            )
        return self
