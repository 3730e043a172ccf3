"""Each UAV a JSBSim fixed-wing aircraft: the decision is the setpoint of its autopilot.

Every cycle the world sets each aircraft's bank setpoint to the decided bank angle (limited
to the action set's phi) and JSBSim integrates the aircraft and its autopilot (roll hold,
altitude hold at the UAV's altitude, airspeed hold at V, sideslip hold; the autopilot is a
JSBSim system of the aircraft's model, `aircraft/<name>/Systems/autopilot.xml`) at
`uav.jsbsim_rate_hz` through the cycle, in the scenario's wind and turbulence.

Frames: the scenario's x axis points east and y north; its origin is latitude 0,
longitude 0 on JSBSim's WGS84 Earth, and the local east and north distances are the
longitude and latitude times the ellipsoid's radii of curvature there (at 14 km from the
origin the flat map is off by less than 1e-5 of the distance). A UAV's state (x, y, h, V,
heading) is the aircraft's position, its height above sea level, its ground speed and its
course over ground (the direction it moves in, counterclockwise from +x as in eq. 1): what
its navigation (GPS) tells it. The bank angle of eq. (1) turns left when positive; JSBSim's
turns right, so the setpoint is its negative.

Trim: each aircraft starts in trimmed level flight at its altitude and airspeed. The trim
solves for the angle of attack, the elevator and the throttle that zero the accelerations
u', w' and q' (Newton's method on JSBSim's own equations, the aircraft held still), once per
(model, altitude, airspeed, rate), in still air: a steady wind moves the air mass, not the
trim.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cache
from pathlib import Path
from xml.parsers import expat

import numpy as np

from ..config import Scenario
from ..errors import RunError, ScenarioError, install_hint
from ..world import HEADING, H, V, X, Y, flight_stream

FT = 0.3048
"""Metres per foot (JSBSim's properties are in feet)."""

WGS84_A = 6378137.0
WGS84_E2 = 6.69437999014e-3
EAST = WGS84_A
"""Metres of easting per radian of longitude at the origin (latitude 0)."""
NORTH = WGS84_A * (1.0 - WGS84_E2)
"""Metres of northing per radian of latitude at the origin (the meridian's radius)."""

TURBULENCE = {"none": (0, 0.0), "light": (3, 25.0), "moderate": (4, 50.0), "severe": (6, 75.0)}
"""JSBSim's milspec severity (probability of exceedance index) and wind at 20 ft [ft/s]
per intensity, the reference values of MIL-F-8785C as JSBSim's FGWinds documents them."""

TUSTIN = 4
"""atmosphere/turb-type of JSBSim's Dryden turbulence in its Tustin form."""

AIRCRAFT = Path(__file__).parent / "aircraft"
"""The JSBSim models uavtrack ships (one folder each)."""

INTERFACE = (
    "uavtrack/engaged",
    "uavtrack/roll-cmd-rad",
    "uavtrack/bank-limit-rad",
    "uavtrack/altitude-cmd-ft",
    "uavtrack/airspeed-cmd-fps",
    "uavtrack/pitch-trim-rad",
    "uavtrack/throttle-trim",
)
"""The properties a model's autopilot answers (its Systems/autopilot.xml documents them)."""


def _module():
    try:
        import jsbsim
    except ImportError:
        raise ValueError(
            "uav.dynamics = jsbsim needs JSBSim, which the flight extra installs: "
            + install_hint("flight")
        ) from None
    jsbsim.FGJSBBase().debug_lvl = 0  # JSBSim prints a banner and notes at level 1
    return jsbsim


def model_path(aircraft: str) -> Path:
    """The folder of the model `aircraft` names: one of uavtrack's, one that ships with
    JSBSim, or a folder `.../<name>` holding `<name>.xml` (whose XML `check_xml` reads
    first)."""
    if Path(aircraft).name == aircraft:  # a bare name (a path would replace the root)
        for folder in (
            AIRCRAFT / aircraft,
            Path(_module().get_default_root_dir()) / "aircraft" / aircraft,
        ):
            if (folder / f"{folder.name}.xml").is_file():
                return folder
    folder = Path(aircraft).expanduser()
    if (folder / f"{folder.name}.xml").is_file():
        folder = folder.resolve()
        check_xml(folder)
        return folder
    raise ValueError(
        f"uav.aircraft {aircraft!r} is neither a model of uavtrack's (trackwing) or of "
        "JSBSim's nor a folder <name> holding <name>.xml"
    )


class _Declared(Exception):
    """A DTD met while reading a model's XML."""


def check_xml(folder: Path) -> None:
    """Refuse (ValueError, one line naming the file) a model folder with an XML file that
    declares a DTD or is not well-formed.

    A DTD is where entities are declared, and an external entity makes an XML parser read
    another file or URL into the model; JSBSim's parser skips such a reference in text but
    fails with an exception on one in an attribute. No model needs a DTD, so each ``*.xml``
    of the folder is read by Python's expat first, which stops at ``<!DOCTYPE`` before any
    declaration in it is read, and JSBSim only ever sees files without one. (JSBSim's own
    models and systems, which are not checked, use internal entities as named constants.)
    """

    def declared(*_) -> None:
        raise _Declared

    for path in sorted(folder.rglob("*.xml")):
        parser = expat.ParserCreate()
        parser.StartDoctypeDeclHandler = declared
        try:
            with path.open("rb") as file:
                parser.ParseFile(file)
        except _Declared:
            raise ValueError(
                f"uav.aircraft: {path} declares a DTD (<!DOCTYPE> at line "
                f"{parser.CurrentLineNumber}): external entities and DTDs are refused in "
                "aircraft files; remove the declaration"
            ) from None
        except expat.ExpatError as exc:
            raise ValueError(f"uav.aircraft: {path} is not well-formed XML ({exc})") from None
        except OSError as exc:
            raise ValueError(f"uav.aircraft: cannot read {path}: {exc.strerror}") from None


def _load(folder: Path, dt: float):
    """A JSBSim instance with the model of `folder` loaded, writing no files."""
    jsbsim = _module()
    root = jsbsim.get_default_root_dir()
    fdm = jsbsim.FGFDMExec(root)
    fdm.set_debug_level(0)
    try:
        loaded = fdm.load_model_with_paths(
            folder.name, str(folder.parent), str(Path(root) / "engine"), str(Path(root) / "systems")
        )
    except jsbsim.BaseError as exc:  # e.g. a malformed file it reads outside the folder
        message = " ".join(str(exc).split())
        raise ValueError(
            f"uav.aircraft: JSBSim could not load the model in {folder}: {message}"
        ) from None
    if not loaded:
        raise ValueError(f"uav.aircraft: JSBSim could not load the model in {folder}")
    fdm.disable_output()  # some models ask for CSV output: none here
    fdm.set_dt(dt)
    return fdm


@cache
def check_aircraft(aircraft: str) -> None:
    """Refuse (ValueError, one line) a model JSBSim cannot load or whose autopilot does
    not answer uavtrack's interface."""
    folder = model_path(aircraft)
    fdm = _load(folder, 1 / 120)
    manager = fdm.get_property_manager()
    missing = [p for p in INTERFACE if not manager.hasNode(p)]
    if missing:
        raise ValueError(
            f"uav.aircraft {aircraft!r} has no uavtrack autopilot (no property {missing[0]}): "
            "give it a copy of trackwing's Systems/autopilot.xml with gains tuned for it"
        )


def substeps(scenario: Scenario) -> int:
    """JSBSim steps per cycle: dt x uav.jsbsim_rate_hz, rounded (at least one)."""
    return max(1, round(scenario.dt * scenario.uav.jsbsim_rate_hz))


def check(scenario: Scenario) -> None:
    """Refuse (ValueError, one line) a scenario whose aircraft cannot be flown: a model
    that does not load, has no uavtrack autopilot, or cannot fly level at the scenario's
    airspeed at its lowest and highest altitude."""
    check_aircraft(scenario.uav.aircraft)
    folder = model_path(scenario.uav.aircraft)
    dt = scenario.dt / substeps(scenario)
    heights = scenario.altitudes()
    for altitude in {min(heights), max(heights)}:
        trim(folder, float(altitude), scenario.uav.speed, dt)


@cache
def trim(folder: Path, altitude: float, airspeed: float, dt: float) -> tuple[float, ...]:
    """(alpha [rad], elevator command [-1, 1], throttle [0, 1], pitch [rad]) of level
    flight at `altitude` [m] and true `airspeed` [m/s] in still air."""
    fdm = _load(folder, dt)
    x = np.array([0.05, 0.0, 0.3])
    fdm.set_trim_status(True)  # actuators follow their commands at once

    def accelerations(x: np.ndarray) -> np.ndarray:
        _initial(fdm, 0.0, 0.0, altitude, airspeed, 0.0, x)
        return np.array(
            [
                fdm["accelerations/udot-ft_sec2"],
                fdm["accelerations/wdot-ft_sec2"],
                fdm["accelerations/qdot-rad_sec2"],
            ]
        )

    r = np.full(3, np.inf)  # no residual yet
    for _ in range(30):
        r = accelerations(x)
        if np.abs(r).max() < 1e-8:
            break
        J = np.empty((3, 3))
        for j in range(3):
            d = np.zeros(3)
            d[j] = 1e-6
            J[:, j] = (accelerations(x + d) - r) / 1e-6
        try:
            x = x - np.linalg.solve(J, r)
        except np.linalg.LinAlgError:  # beyond the stall the lift no longer answers alpha
            x = np.full(3, np.nan)
            break
    if not np.isfinite(x).all() or np.abs(r).max() >= 1e-8:
        raise ValueError(
            f"uav.aircraft {folder.name!r} cannot fly level at {airspeed:g} m/s and "
            f"{altitude:g} m (its trim does not converge); change uav.speed or uav.altitude"
        )
    if not (-1 <= x[1] <= 1 and 0 <= x[2] <= 1 and -0.1 < x[0] < 0.3):
        raise ValueError(
            f"uav.aircraft {folder.name!r} cannot fly level at {airspeed:g} m/s and "
            f"{altitude:g} m (it would need angle of attack {math.degrees(x[0]):.0f} deg, "
            f"elevator {x[1]:.2f} and throttle {x[2]:.2f}); "
            "change uav.speed or uav.altitude"
        )
    theta = fdm["attitude/theta-rad"]
    return float(x[0]), float(x[1]), float(x[2]), float(theta)


def _initial(
    fdm,
    x: float,
    y: float,
    altitude: float,
    airspeed: float,
    course: float,
    trimmed,
    wind: tuple[float, float] = (0.0, 0.0),
) -> float:
    """Place the aircraft at (x, y, altitude) flying level over the ground towards
    `course` (eq. 1's heading) at true `airspeed`, in the steady `wind` (the air mass's
    velocity east, north [m/s]), crabbed into the wind, with the trimmed alpha, elevator
    and throttle. Returns the ground speed [m/s]."""
    alpha, elevator, throttle = trimmed[:3]
    w = np.asarray(wind, dtype=float)
    along = np.array([math.cos(course), math.sin(course)])
    across = w[0] * along[1] - w[1] * along[0]
    if abs(across) >= airspeed:
        raise ScenarioError(
            f"wind.speed {math.hypot(*w):g} m/s: a UAV at {airspeed:g} m/s cannot hold its course "
            "across it; lower wind.speed below uav.speed"
        )
    ground = float(w @ along + math.sqrt(airspeed**2 - across**2))
    air = ground * along - w  # the velocity through the air mass: where the nose points
    fdm["uavtrack/engaged"] = 0
    fdm["ic/lat-geod-rad"] = y / NORTH
    fdm["ic/long-gc-rad"] = x / EAST
    fdm["ic/h-sl-ft"] = altitude / FT
    fdm["ic/psi-true-rad"] = (math.pi / 2 - math.atan2(air[1], air[0])) % (2 * math.pi)
    fdm["ic/theta-rad"] = alpha  # level flight: the pitch is the angle of attack
    fdm["ic/phi-rad"] = 0.0
    fdm["ic/vn-fps"] = ground * along[1] / FT
    fdm["ic/ve-fps"] = ground * along[0] / FT
    fdm["ic/vd-fps"] = 0.0
    # the wind last: JSBSim keeps the ground velocity and derives the airspeed from it
    fdm["ic/vw-mag-fps"] = math.hypot(*w) / FT
    fdm["ic/vw-dir-deg"] = math.degrees(math.atan2(w[0], w[1]))  # towards, clockwise from N
    fdm["fcs/pitch-trim-cmd-norm"] = elevator
    fdm["uavtrack/throttle-trim"] = throttle
    fdm.run_ic()
    return ground


class Fleet:
    """B x Nu JSBSim aircraft, one per UAV of each trial, flown a cycle at a time.

    scenario: the run's; seeds: one SeedSequence per trial (turbulence is seeded from its
    flight stream); uavs (B, Nu, 5): where each UAV starts (position, altitude, heading).
    """

    def __init__(
        self, scenario: Scenario, seeds: Sequence[np.random.SeedSequence], uavs: np.ndarray
    ) -> None:
        B, Nu = uavs.shape[:2]
        self.shape = (B, Nu)
        self.substeps = substeps(scenario)
        dt = scenario.dt / self.substeps
        folder = model_path(scenario.uav.aircraft)
        wind = scenario.wind
        air = wind.velocity()
        severity, at_20ft = TURBULENCE[wind.turbulence]
        airspeed = scenario.uav.speed
        self.aircraft = []
        for b, seed in enumerate(seeds):
            streams = np.random.default_rng(flight_stream(seed)).integers(1, 2**31 - 1, Nu)
            for i in range(Nu):
                x, y, h, _, course = uavs[b, i]
                fdm = _load(folder, dt)
                fdm["simulation/randomseed"] = int(streams[i])
                try:
                    trimmed = trim(folder, float(h), airspeed, dt)
                except ValueError as exc:  # an altitude between those `check` tried
                    raise ScenarioError(str(exc)) from None
                _initial(fdm, x, y, h, airspeed, course, trimmed, air)
                if severity:  # after the initial conditions, which start at zero speed
                    fdm["atmosphere/randomseed"] = int(streams[i])
                    fdm["atmosphere/turb-type"] = TUSTIN
                    fdm["atmosphere/turbulence/milspec/windspeed_at_20ft_AGL-fps"] = at_20ft
                    fdm["atmosphere/turbulence/milspec/severity"] = severity
                fdm["uavtrack/pitch-trim-rad"] = trimmed[3]
                fdm["uavtrack/altitude-cmd-ft"] = h / FT
                fdm["uavtrack/airspeed-cmd-fps"] = airspeed / FT
                fdm["uavtrack/bank-limit-rad"] = math.radians(scenario.uav.bank_angle_deg)
                fdm["uavtrack/engaged"] = 1
                self.aircraft.append(fdm)

    def fly(self, uavs: np.ndarray, bank: np.ndarray, alive: np.ndarray) -> np.ndarray:
        """One cycle: each living aircraft's bank setpoint set to `bank` (B, Nu) [rad,
        positive left], then `substeps` JSBSim steps. Returns the states (B, Nu, 5)."""
        out = uavs.copy()
        Nu = self.shape[1]
        for n, fdm in enumerate(self.aircraft):
            b, i = divmod(n, Nu)
            if not alive[b, i]:
                continue  # a failed UAV is down where it failed
            fdm["uavtrack/roll-cmd-rad"] = -float(bank[b, i])
            for _ in range(self.substeps):
                fdm.run()
            out[b, i] = self._state(fdm, b, i)
        return out

    def states(self) -> np.ndarray:
        """Every aircraft's state now (B, Nu, 5)."""
        B, Nu = self.shape
        out = np.empty((B, Nu, 5))
        for n, fdm in enumerate(self.aircraft):
            b, i = divmod(n, Nu)
            out[b, i] = self._state(fdm, b, i)
        return out

    def bank(self) -> np.ndarray:
        """Every aircraft's bank angle now (B, Nu) [rad, positive left as in eq. 1]."""
        return -np.array([fdm["attitude/phi-rad"] for fdm in self.aircraft]).reshape(self.shape)

    def read(self, name: str) -> np.ndarray:
        """A JSBSim property of every aircraft (B, Nu), e.g. ``velocities/vt-fps``."""
        return np.array([fdm[name] for fdm in self.aircraft]).reshape(self.shape)

    @staticmethod
    def _state(fdm, b: int, i: int) -> np.ndarray:
        state = np.empty(5)
        north = fdm["velocities/v-north-fps"] * FT
        east = fdm["velocities/v-east-fps"] * FT
        state[X] = fdm["position/long-gc-rad"] * EAST
        state[Y] = fdm["position/lat-geod-rad"] * NORTH
        state[H] = fdm["position/h-sl-ft"] * FT
        state[V] = math.hypot(east, north)
        state[HEADING] = math.atan2(north, east)
        if not np.isfinite(state).all() or state[H] <= 0:
            raise RunError(
                f"the aircraft of UAV {i} in trial {b} left controlled flight "
                f"(altitude {state[H]:.0f} m); its autopilot cannot fly this scenario"
            )
        return state
