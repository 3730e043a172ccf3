"""`Scenario`: every parameter of a run, validated, documented, loadable from TOML; its
parts are in `config.parts`, its TOML reading and writing in `config.toml`.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Iterator
from numbers import Integral
from pathlib import Path
from typing import Any

from pydantic import (
    BaseModel,
    Field,
    ValidationError,
    model_validator,
)

from ..errors import ScenarioError
from .parts import (
    MAX_ALTITUDE,
    EstimationModel,
    EvaluationModel,
    FaultModel,
    Float,
    FusionModel,
    G,
    Int,
    Part,
    PlannerModel,
    RadioModel,
    RobustModel,
    SensorModel,
    TargetModel,
    TrackerModel,
    UAVModel,
    WindModel,
)
from .toml import describe_errors, dump_toml, read_toml, set_dotted

QUANTIZED_FIELD = 30_000.0
"""Largest field the quantized encoding takes [m]: float16 reaches 65504, and estimates
may lie beyond the field by up to its side (targets near a wall, UAVs' guesses)."""

PRESETS = Path(__file__).with_name("presets")
"""The shipped scenario presets, one TOML file each (`Scenario.from_toml` by name)."""


def presets() -> list[str]:
    """The names of the shipped presets."""
    return sorted(p.stem for p in PRESETS.glob("*.toml"))


def config_file(path: str | Path) -> Path:
    """The file a config names: the path itself, or for a bare name (no folder, no
    suffix) that is no file the shipped preset of that name; a one-line `ScenarioError`
    when neither exists."""
    path = Path(path)
    if path.exists() or path.name != str(path) or path.suffix:
        return path  # a file (`read_toml` says why one cannot be read)
    shipped = PRESETS / f"{path.name}.toml"
    if shipped.is_file():
        return shipped
    names = ", ".join(presets())
    raise ScenarioError(f"no config file {path} (nor a preset of that name: {names})")


class Scenario(Part):
    """Every parameter of one simulated mission.

    Defaults are the paper's Sec. 7.1 experiment (5 UAVs, 4 targets, r_C = 50 m,
    FOV 10 deg, 500 steps) completed with the assumptions documented per field.
    """

    n_uavs: Int = Field(
        default=5, ge=1, le=10_000, description="number of UAVs N^u, 1 to 10000; paper Sec. 7.1"
    )
    n_targets: Int = Field(
        default=4, ge=1, le=10_000, description="number of targets N^t, 1 to 10000; paper Sec. 7.1"
    )
    steps: Int = Field(
        default=500,
        ge=1,
        le=10_000_000,
        description="simulated decision cycles, 1 to 10^7; paper Sec. 7",
    )
    dt: Float = Field(
        default=0.5,
        gt=0,
        le=10,
        description=(
            "time step Delta T [s], (0, 10]; assumed: 2 Hz decisions, a common rate for small "
            "fixed-wing UAVs; the paper does not give it; calibrated with uav.altitude against "
            "the paper's Fig. 5 (see the docs, Calibration)"
        ),
    )
    comm_range: Float = Field(
        default=50.0,
        ge=0,
        le=100_000,
        description="communication range r_C, 3-D distance [m], [0, 100000]; paper Sec. 7.1",
    )
    field_size: Float = Field(
        default=200.0,
        gt=0,
        le=100_000,
        description=(
            "side of the square field the targets move in [m], (0, 100000]; assumed: the paper "
            "does not give it; it sets how often r_C connects the UAVs that compete for a target"
        ),
    )
    uav: UAVModel = Field(default_factory=UAVModel, description="UAV kinematics (eq. 1)")
    wind: WindModel = Field(
        default_factory=WindModel, description="wind and turbulence (uav.dynamics = jsbsim)"
    )
    sensor: SensorModel = Field(default_factory=SensorModel, description="sensor (eq. 2-4)")
    target: TargetModel = Field(default_factory=TargetModel, description="targets (eq. 13-15)")
    estimation: EstimationModel = Field(
        default_factory=EstimationModel, description="initial belief"
    )
    tracker: TrackerModel = Field(
        default_factory=TrackerModel, description="local filters (eq. 22-25)"
    )
    fusion: FusionModel = Field(default_factory=FusionModel, description="fusion (eq. 26-27)")
    radio: RadioModel = Field(
        default_factory=RadioModel, description="the radio's encoding (not in the paper)"
    )
    planner: PlannerModel = Field(
        default_factory=PlannerModel, description="planning (Algorithm 1)"
    )
    evaluation: EvaluationModel = Field(
        default_factory=EvaluationModel, description="scoring of the estimates (OSPA, GOSPA)"
    )
    faults: FaultModel = Field(
        default_factory=FaultModel, description="communication faults, failures, GPS error"
    )
    robust: RobustModel = Field(
        default_factory=RobustModel, description="robustness mechanisms (off: the paper)"
    )

    def __init__(self, **data: Any) -> None:
        # one line naming the field, as for files and overrides, not pydantic's report
        try:
            super().__init__(**data)
        except ValidationError as exc:
            raise ScenarioError(describe_errors(exc, Scenario().model_dump())) from None

    @model_validator(mode="after")
    def _altitude_count(self) -> Scenario:
        if self.uav.altitudes is not None and len(self.uav.altitudes) != self.n_uavs:
            raise ValueError(
                f"uav.altitudes has {len(self.uav.altitudes)} entries but n_uavs is {self.n_uavs}"
            )
        for uav, step in self.faults.failures:
            if uav >= self.n_uavs:
                raise ValueError(
                    f"faults.failures names UAV {uav}, which does not exist "
                    f"(n_uavs is {self.n_uavs}: UAVs 0 to {self.n_uavs - 1})"
                )
            if step >= self.steps:
                raise ValueError(
                    f"faults.failures names step {step}, after the run's last step "
                    f"{self.steps - 1}; it would never happen"
                )
        heights = self.altitudes()
        if min(heights) <= 0 or max(heights) > MAX_ALTITUDE:
            lowest, highest = min(heights), max(heights)
            fits = 2 * min(self.uav.altitude, MAX_ALTITUDE - self.uav.altitude) / self.n_uavs
            raise ValueError(
                f"uav.altitude {self.uav.altitude:g} m and uav.altitude_spacing "
                f"{self.uav.altitude_spacing:g} m put the {self.n_uavs} UAVs between "
                f"{lowest:g} and {highest:g} m, outside (0, {MAX_ALTITUDE:g}] m; "
                f"set uav.altitude_spacing to {fits:.3g} m or less, or grow the whole scenario "
                f"to this team with --team {self.n_uavs}x{self.n_targets} (Scenario.scaled), "
                "which keeps the altitude band"
            )
        return self

    @model_validator(mode="after")
    def _births(self) -> Scenario:
        """Targets that come and go (target.stay) need tracks to find the new ones, and
        bids weighed by existence (planner.existence) tracks that have one."""
        t = self.target
        if 0 < t.stay < 1:
            raise ValueError(
                f"target.stay {t.stay:g} must be 0 (every target stays) or at least 1 step "
                "(a target leaves with probability 1/stay per step)"
            )
        if t.stay == 0 and t.away != TargetModel.model_fields["away"].default:
            raise ValueError(
                "target.away needs target.stay > 0 (it does nothing otherwise); set "
                "target.stay or leave target.away unset"
            )
        if self.planner.existence and (
            not self.tracker.unlabelled or self.tracker.confirmation != "existence"
        ):
            raise ValueError(
                "planner.existence needs tracks with an existence probability: set "
                "tracker.association=jpda (or gnn) with tracker.confirmation=existence, or "
                "leave planner.existence unset"
            )
        if t.stay > 0 and not self.tracker.unlabelled:
            raise ValueError(
                "target.stay > 0 (targets that come and go) needs tracker.association = gnn "
                "or jpda: known association holds one filter per target for the whole run"
            )
        return self

    @model_validator(mode="after")
    def _quantized(self) -> Scenario:
        """Float16 positions reach 65504 m: a field that runs past it cannot be quantized."""
        if self.radio.encoding == "quantized" and self.field_size > QUANTIZED_FIELD:
            raise ValueError(
                f"radio.encoding = quantized sends positions as float16, which reach "
                f"{QUANTIZED_FIELD:,.0f} m with room for the field's margin; field_size "
                f"{self.field_size:,.0f} m is larger: use the compact encoding"
            )
        return self

    @model_validator(mode="after")
    def _tracks(self) -> Scenario:
        """What tracks of unknown association cannot do yet, said before a run starts."""
        if not self.tracker.unlabelled:
            return self
        if self.radio.encoding != "full" and self.labels >= 2**31:
            raise ValueError(
                f"radio.encoding = {self.radio.encoding} sends team labels in 32 bits, and a "
                f"run of "
                f"{self.steps} steps of {self.n_uavs} UAVs may issue {self.labels:,}: "
                "shorten the run or send the full encoding"
            )
        if self.track_slots < self.n_targets:
            raise ValueError(
                f"tracker.max_tracks {self.tracker.max_tracks} cannot hold the "
                f"{self.n_targets} targets every UAV starts with; give at least {self.n_targets}"
            )
        return self

    @model_validator(mode="after")
    def _models(self) -> Scenario:
        """A setting of a model that is not on would do nothing: refuse it."""
        tracks = ("max_tracks", "gate_probability", "confirm", "delete_misses", "delete_std")
        tracks += ("birth_velocity_std", "confirmation", "merge", "existence", "birth_existence")
        tracks += ("survival", "briefing")
        counted = ("confirm", "delete_misses")
        for group, value, wanted, on, names in (
            (
                self.target.manoeuvre,
                self.target.motion,
                "target.motion = manoeuvring",
                "manoeuvring",
                tuple(type(self.target.manoeuvre).model_fields),
            ),
            (
                self.tracker,
                self.tracker.model,
                "tracker.model = imm",
                "imm",
                ("manoeuvre_std", "turn_rates_deg", "transition"),
            ),
            (
                self.tracker,
                "tracks" if self.tracker.unlabelled else "known",
                "tracker.association = gnn or jpda",
                "tracks",
                tracks,
            ),
            (
                self.tracker,
                self.tracker.confirmation,
                "tracker.confirmation = existence",
                "existence",
                ("existence", "birth_existence", "survival"),
            ),
            (
                self.tracker,
                self.tracker.confirmation,
                "tracker.confirmation = m_of_n",
                "m_of_n",
                counted,
            ),
        ):
            if value == on:
                continue
            fields = type(group).model_fields
            for name in names:
                if getattr(group, name) != fields[name].get_default(call_default_factory=True):
                    prefix = "target.manoeuvre" if group is self.target.manoeuvre else "tracker"
                    if on == "tracks":
                        raise ValueError(
                            f"{prefix}.{name} needs {wanted} (it does nothing otherwise); set "
                            f"tracker.association=gnn (or jpda) or leave {prefix}.{name} unset"
                        )
                    raise ValueError(
                        f"{prefix}.{name} needs {wanted} (it does nothing otherwise); set "
                        f"{wanted.replace(' = ', '=')} or leave {prefix}.{name} unset"
                    )
        return self

    @model_validator(mode="after")
    def _airspeed(self) -> Scenario:
        """``uav.min_speed``: a second control of the avoidance filter, for the unicycle."""
        slow = self.uav.min_speed
        if slow is None:
            return self
        if slow >= self.uav.speed:
            raise ValueError(
                f"uav.min_speed {slow:g} must be below uav.speed {self.uav.speed:g}; lower it "
                "or leave it unset"
            )
        least = 2.0 * G * self.dt * math.tan(math.radians(self.uav.bank_angle_deg)) / math.pi
        if slow < least:
            raise ValueError(
                f"uav.min_speed {slow:g} turns the backup loiter more than a quarter turn a "
                f"step (dt {self.dt:g} s, bank {self.uav.bank_angle_deg:g} deg): give at "
                f"least {math.ceil(least * 100) / 100:g} m/s"
            )
        if self.planner.avoidance == "none":
            raise ValueError(
                "uav.min_speed needs planner.avoidance = loiter (it does nothing otherwise); "
                "set planner.avoidance=loiter or leave uav.min_speed unset"
            )
        if self.uav.dynamics == "jsbsim":
            raise ValueError(
                "uav.min_speed flies the unicycle: JSBSim's autopilot holds the trimmed "
                "airspeed, and a commanded airspeed for it is not built; leave it unset"
            )
        return self

    @model_validator(mode="after")
    def _measured(self) -> Scenario:
        """``planner.avoidance_model = "measured"``: its tables predict one step from a
        beacon of this step, at one speed."""
        if self.planner.avoidance_model == "unicycle":
            return self
        if self.planner.avoidance == "none":
            raise ValueError(
                "planner.avoidance_model = measured needs planner.avoidance = loiter (it does "
                "nothing otherwise); set planner.avoidance=loiter or leave it unset"
            )
        if self.faults.delay > 0 or self.faults.loss > 0:
            raise ValueError(
                "planner.avoidance_model = measured needs every beacon fresh (its tables "
                "predict one step, not a stale beacon's many); leave faults.delay and "
                "faults.loss 0 or use planner.avoidance_model=unicycle"
            )
        if self.radio.bandwidth_bps is not None:
            raise ValueError(
                "planner.avoidance_model = measured needs every beacon heard (a shared radio "
                "may leave one unsent); leave radio.bandwidth_bps unset or use "
                "planner.avoidance_model=unicycle"
            )
        if self.uav.min_speed is not None:
            raise ValueError(
                "planner.avoidance_model = measured flies one speed: leave uav.min_speed "
                "unset or use planner.avoidance_model=unicycle"
            )
        if self.wind.turbulence != "none":
            raise ValueError(
                "planner.avoidance_model = measured needs still or steady air: in turbulence "
                "its tables' errors reach tens of metres (a margin of 140 m for light "
                "turbulence); leave wind.turbulence none or use planner.avoidance_model=unicycle"
            )
        return self

    @model_validator(mode="after")
    def _flight(self) -> Scenario:
        calm = self.wind.speed == 0 and self.wind.turbulence == "none"
        if self.uav.dynamics == "unicycle" and not calm:
            raise ValueError(
                "wind needs uav.dynamics = jsbsim (the paper's unicycle flies in still air); "
                "set uav.dynamics=jsbsim or leave wind.speed 0 and wind.turbulence none"
            )
        flown = UAVModel.model_fields
        for name in ("aircraft", "jsbsim_rate_hz"):
            value = getattr(self.uav, name)
            if self.uav.dynamics == "unicycle" and value != flown[name].default:
                raise ValueError(
                    f"uav.{name} {value!r} needs uav.dynamics = jsbsim (the unicycle flies no "
                    f"aircraft); set uav.dynamics=jsbsim or leave uav.{name} unset"
                )
        if self.wind.speed >= self.uav.speed:
            raise ValueError(
                f"wind.speed {self.wind.speed:g} m/s must be below uav.speed "
                f"{self.uav.speed:g} m/s: a UAV could not make way against it"
            )
        return self  # whether JSBSim can fly it: `flight.jsbsim.check`, where a flight starts

    @property
    def prunes(self) -> bool:
        """Whether the planner may leave bids unscored (``planner.prune``): only where
        every UAV knows the neighbourhoods its bids serve, i.e. bids are neither lost nor
        late and the D_i flooding has the two rounds that tell a UAV its neighbours'."""
        f = self.faults
        return (
            self.planner.prune
            and f.loss == 0
            and f.delay == 0
            and (f.round_budget is None or f.round_budget >= 2)
        )

    @property
    def track_slots(self) -> int:
        """Track slots K per UAV with unknown association (``tracker.max_tracks``, whose 0
        means twice n_targets plus 4)."""
        return self.tracker.max_tracks or 2 * self.n_targets + 4

    @property
    def labels(self) -> int:
        """With unknown association the run's team labels are below this: the briefed
        targets', then a UAV starts at most K tracks a scan, each under a label of its
        own (`tracks.manage`)."""
        return self.n_targets + (self.track_slots * (self.steps + 1) + 1) * self.n_uavs

    def acceleration_std(self) -> tuple[float, float]:
        """Std of the targets' white acceleration per axis [m/s^2], as eq. (15) is read
        (`target.noise_form`): sigma itself, or sigma / dT for the printed matrix, whose
        Gamma = [dT/2, 1] is a velocity increment of std sigma per step."""
        scale = 1.0 if self.target.noise_form == "acceleration" else 1.0 / self.dt
        return self.target.sigma_1 * scale, self.target.sigma_2 * scale

    def scaled(self, n_uavs: int, n_targets: int) -> Scenario:
        """This scenario grown (or shrunk) to a team of n_uavs UAVs and n_targets targets
        at the same density.

        * the field's area grows with the number of vehicles (UAVs plus targets), so each
          UAV meets as many radio neighbours and targets per square metre;
        * the UAVs keep this scenario's altitude band (lowest to highest), their spacing
          shrunk to fit the team;
        * the UAVs start spread over the whole field (``uav.start_spread`` = the field;
          a start on a grid keeps its spacing):
          a team taking off from one small square, as the 5 UAVs of the paper do, would
          start with every UAV in radio range of a hundred others at 1000 UAVs.

        Everything else is unchanged. Assumed (the paper runs one team size); the
        documentation's Performance page measures with it.
        """
        for name, value in (("n_uavs", n_uavs), ("n_targets", n_targets)):
            if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
                raise ScenarioError(f"{name} must be a positive integer, got {value!r}")
        heights = self.altitudes()
        band = max(heights) - min(heights)
        area = (n_uavs + n_targets) / (self.n_uavs + self.n_targets)
        field_size = self.field_size * math.sqrt(area)
        return self.with_overrides(
            {
                "n_uavs": int(n_uavs),
                "n_targets": int(n_targets),
                "field_size": field_size,
                "uav.altitudes": None,
                "uav.altitude": (max(heights) + min(heights)) / 2,
                "uav.altitude_spacing": band / (n_uavs - 1) if n_uavs > 1 else 0.0,
                # a grid keeps its spacing; a square grows to the field
                "uav.start_spread": self.uav.start_spread
                if self.uav.start == "grid"
                else field_size,
            },
            origin=f"team {n_uavs}x{n_targets}",
        )

    def start_side(self) -> float:
        """The side of the square the UAVs start in [m]: ``uav.start_spread``, or for
        ``uav.start = "grid"`` the grid's (columns - 1 spacings)."""
        if self.uav.start == "grid":
            return self.uav.start_spread * (math.ceil(math.sqrt(self.n_uavs)) - 1)
        return self.uav.start_spread

    def altitudes(self) -> list[float]:
        """Altitude h_i of each UAV [m], centred on `uav.altitude`."""
        if self.uav.altitudes is not None:
            return list(self.uav.altitudes)
        mid = (self.n_uavs - 1) / 2
        return [
            self.uav.altitude + (i - mid) * self.uav.altitude_spacing for i in range(self.n_uavs)
        ]

    # ------------------------------------------------------------------ I/O

    @classmethod
    def from_toml(cls, path: str | Path) -> Scenario:
        """Load a scenario from a TOML file; missing fields keep their defaults. A bare
        name that is no file names a shipped preset (`presets`): "one-altitude", "realistic"."""
        file = config_file(path)
        origin = str(path) if file == Path(path) else f"preset {path}"
        return cls.from_dict(read_toml(file), origin=origin)

    @classmethod
    def from_dict(cls, data: dict[str, Any], origin: str = "scenario") -> Scenario:
        """Validate a (nested) dict; raise ScenarioError with one line naming the field."""
        try:
            return cls.model_validate(data)
        except ValidationError as exc:
            raise ScenarioError(
                f"{origin}: {describe_errors(exc, Scenario().model_dump())}"
            ) from None
        except ScenarioError as exc:  # raised by __init__, which validation calls
            raise ScenarioError(f"{origin}: {exc}") from None

    def with_overrides(self, overrides: dict[str, Any], origin: str = "override") -> Scenario:
        """A copy with dotted fields replaced, e.g. ``{"sensor.half_fov_deg": 10}``.

        `origin` names where the values came from in error messages (``--set``, a sweep).
        """
        data = self.model_dump()
        for dotted, value in overrides.items():
            set_dotted(data, dotted, value)
        return Scenario.from_dict(data, origin=origin)

    def to_dict(self) -> dict[str, Any]:
        """The scenario as plain JSON types (lists for tuples); `from_dict` reads it back."""
        return self.model_dump(mode="json")

    def digest(self) -> str:
        """A short SHA-256 of the scenario's canonical JSON: equal scenarios, equal digests."""
        text = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def value(self, dotted: str) -> Any:
        """The value of a dotted field, e.g. ``value("sensor.half_fov_deg")``."""
        node: Any = self
        for key in dotted.split("."):
            node = getattr(node, key)
        return node

    def unit(self, dotted: str) -> str:
        """The unit of a dotted field as written in its description (``m``, ``deg``), or ''."""
        for name, _, doc in self.describe():
            if name == dotted:
                found = re.search(r"\[([^\]]+)\]", doc)
                return found.group(1) if found and found.group(1) != "-" else ""
        raise ScenarioError(f"unknown scenario field '{dotted}'")

    def to_toml(self, comments: bool = False) -> str:
        """The scenario as TOML text (round-trips through `from_toml`); with `comments`,
        each field's unit, range and source above it, and the fields not set (None) as
        commented-out lines."""
        data = self.model_dump(mode="json", exclude_none=True)
        if not comments:
            return dump_toml(data)
        docs = {name: doc for name, _, doc in self.describe()}
        unset = [name for name, value, _ in self.describe() if value is None]
        return dump_toml(data, docs, unset)

    def describe(self) -> list[tuple[str, Any, str]]:
        """Every leaf field as (dotted name, value, description)."""
        return list(_describe(self, ""))


def _describe(model: BaseModel, prefix: str) -> Iterator[tuple[str, Any, str]]:
    for name, info in type(model).model_fields.items():
        value = getattr(model, name)
        if isinstance(value, BaseModel):
            yield from _describe(value, f"{prefix}{name}.")
        else:
            yield f"{prefix}{name}", value, info.description or ""
