"""Real flight: trackwing in JSBSim, its autopilot, wind and turbulence, and the run
forms that fly it (batch, environment, agents)."""

import math
import os
import sys

import numpy as np
import pytest

import uavtrack
from uavtrack import Scenario, ScenarioError
from uavtrack.config import G
from uavtrack.flight import check as check_flight
from uavtrack.testing import assert_same_trace

jsbsim = pytest.importorskip("jsbsim")

from uavtrack.flight import jsbsim as flight  # noqa: E402

JSBSIM = {"uav.dynamics": "jsbsim"}


def fleet(overrides=None, uavs=None, seed=0):
    """One trial's fleet of `uavs` (Nu, 5) starting states (default: one UAV at the
    field centre heading +x at 425 m)."""
    scenario = Scenario(n_uavs=1).with_overrides({**JSBSIM, **(overrides or {})})
    if uavs is None:
        uavs = np.array([[100.0, 100.0, 425.0, 15.0, 0.0]])
    seeds = [np.random.SeedSequence(seed)]
    return scenario, flight.Fleet(scenario, seeds, uavs[None])


def fly(scenario, aircraft, bank, seconds):
    """Hold `bank` [rad] for `seconds`; the states (cycles, Nu, 5) after each cycle."""
    uavs = aircraft.states()
    alive = np.ones(uavs.shape[:2], dtype=bool)
    out = []
    for _ in range(round(seconds / scenario.dt)):
        uavs = aircraft.fly(uavs, np.full(uavs.shape[:2], bank), alive)
        out.append(uavs[0].copy())
    return np.array(out)


@pytest.mark.integration
def test_trackwing_trims_at_the_scenario_speed_and_holds_it():
    alpha, elevator, throttle, theta = flight.trim(
        flight.model_path("trackwing"), 425.0, 15.0, 1 / 120
    )
    # CL = m g / (q S) = 0.371 at 15 m/s and 425 m: alpha = (CL - CL_0) / CL_alpha
    assert alpha == pytest.approx((0.371 - 0.25) / 5.25, abs=2e-3)
    assert theta == pytest.approx(alpha, abs=1e-6)  # level flight: no climb angle
    assert -0.2 < elevator < 0.2 and 0.1 < throttle < 0.5
    scenario, aircraft = fleet()
    path = fly(scenario, aircraft, 0.0, 10.0)
    assert np.abs(path[:, :, 2] - 425.0).max() < 0.05  # altitude [m]
    assert np.abs(path[:, :, 3] - 15.0).max() < 0.02  # ground speed = airspeed in calm air
    assert np.abs(path[:, :, 4]).max() < 1e-3  # the course does not drift
    # 10 s at 15 m/s along +x
    assert path[-1, 0, 0] - 100.0 == pytest.approx(150.0, abs=0.5)
    assert abs(aircraft.bank()[0, 0]) < 1e-3


@pytest.mark.integration
@pytest.mark.parametrize("bank_deg", [45.0, -45.0, 30.0])
def test_a_steady_coordinated_turn_turns_at_g_tan_phi_over_v(bank_deg):
    scenario, aircraft = fleet({"uav.bank_angle_deg": abs(bank_deg)})
    bank = math.radians(bank_deg)
    path = fly(scenario, aircraft, bank, 20.0)
    steady = path[-20:, 0]  # the last 10 s
    rate = np.diff(np.unwrap(steady[:, 4])) / scenario.dt
    expected = G * math.tan(bank) / 15.0
    assert rate.mean() == pytest.approx(expected, rel=0.05)
    assert np.sign(rate.mean()) == np.sign(bank)  # positive bank turns left, as eq. (1)
    assert aircraft.bank()[0, 0] == pytest.approx(bank, abs=math.radians(1.0))
    assert np.abs(steady[:, 2] - 425.0).max() < 3.0  # the altitude hold in a turn [m]
    assert np.abs(aircraft.read("velocities/vt-fps") * flight.FT - 15.0).max() < 0.3
    assert abs(aircraft.read("aero/beta-deg")[0, 0]) < 1.0  # coordinated: no sideslip


@pytest.mark.integration
def test_the_bank_is_reached_within_half_a_cycle_or_so():
    # the roll response from level to 45 deg: 63% of the step within 0.35 s, 95% within
    # 0.8 s (the documented roll times come from `uavtrack flight`, which measures them)
    scenario, aircraft = fleet({"dt": 0.05})
    alive = np.ones((1, 1), dtype=bool)
    uavs, bank = aircraft.states(), []
    for _ in range(30):
        uavs = aircraft.fly(uavs, np.full((1, 1), math.radians(45)), alive)
        bank.append(aircraft.bank()[0, 0])
    bank = np.degrees(bank)
    t = 0.05 * (1 + np.arange(30))
    assert t[np.argmax(bank >= 0.63 * 45)] <= 0.35
    assert t[np.argmax(bank >= 0.95 * 45)] <= 0.8
    assert bank.max() < 48  # no large overshoot


@pytest.mark.integration
@pytest.mark.parametrize(
    "course, ground_speed",
    [(0.0, 20.0), (math.pi, 10.0), (math.pi / 2, math.sqrt(15**2 - 5**2))],
)
def test_the_wind_adds_to_the_airspeed_over_the_ground(course, ground_speed):
    # wind from 270 deg (west) at 5 m/s blows towards +x: flying +x the UAV makes
    # 15 + 5 m/s over the ground, flying -x 15 - 5; flying north it crabs into the wind
    start = np.array([[100.0, 100.0, 425.0, 15.0, course]])
    scenario, aircraft = fleet({"wind.speed": 5.0, "wind.direction_deg": 270.0}, start)
    path = fly(scenario, aircraft, 0.0, 10.0)
    assert path[-1, 0, 3] == pytest.approx(ground_speed, abs=0.1)
    assert abs(aircraft.read("velocities/vt-fps")[0, 0] * flight.FT - 15.0) < 0.05
    if course == math.pi / 2:  # crabbing: the nose points into the wind, the course holds
        assert np.abs(path[-5:, 0, 4] - course).max() < 0.02
        heading = math.pi / 2 - aircraft.read("attitude/psi-rad")[0, 0]
        crab = (heading - course + math.pi) % (2 * math.pi) - math.pi
        assert crab == pytest.approx(math.asin(5 / 15), abs=0.02)


@pytest.mark.integration
def test_turbulence_is_seeded_by_the_trial_and_differs_between_uavs():
    scenario = Scenario(steps=20).with_overrides({**JSBSIM, "wind.turbulence": "moderate"})
    a = uavtrack.simulate(scenario, "distributed", seed=4)
    b = uavtrack.simulate(scenario, "distributed", seed=4)
    assert_same_trace(a.trace, b.trace)
    calm = uavtrack.simulate(scenario.with_overrides({"wind.turbulence": "none"}), seed=4)
    assert not np.array_equal(a.trace.uavs[1:], calm.trace.uavs[1:])
    # two UAVs of the trial feel different gusts: their speeds vary differently
    speeds = a.trace.uavs[:, :, 3]
    assert not np.allclose(speeds[:, 0] - speeds[0, 0], speeds[:, 1] - speeds[0, 1])


@pytest.mark.integration
def test_a_trial_is_the_same_alone_and_in_a_batch():
    scenario = Scenario(steps=15).with_overrides({**JSBSIM, "wind.turbulence": "light"})
    seeds = [uavtrack.trial_seed(7, t) for t in range(2)]
    batch = uavtrack.simulation.run(scenario, "distributed", seeds, trace=True)
    alone = uavtrack.simulation.run(scenario, "distributed", seeds[1:], trace=True)
    assert_same_trace(batch.traces[1], alone.traces[0])


def test_the_default_unicycle_flies_the_paper_model():
    # the State's autopilot is the unicycle of eq. (1), the same function the planner uses
    state, _, _ = uavtrack.simulation.initial_state(Scenario(), [np.random.SeedSequence(0)])
    from uavtrack.flight.unicycle import Unicycle

    assert state.flight == Unicycle(0.5)
    bank = np.array([[0.3, -0.2, 0.0, 0.1, 0.7]])
    alive = np.array([[True, True, False, True, True]])
    flown = state.flight.fly(state.uavs, bank, alive)
    expected = uavtrack.world.fly(state.uavs, bank, 0.5)
    assert np.array_equal(flown[alive], expected[alive])
    assert np.array_equal(flown[~alive], state.uavs[~alive])  # a failed UAV stays down


@pytest.mark.integration
def test_jsbsim_flies_the_method_close_to_the_unicycle():
    # the same trial, the same decisions at first: the aircraft follows the unicycle's
    # path to within metres over the first cycles, and the team still tracks
    scenario = Scenario(steps=40)
    real = uavtrack.simulate(scenario.with_overrides(JSBSIM), seed=1)
    paper = uavtrack.simulate(scenario, seed=1)
    assert np.allclose(real.trace.uavs[0], paper.trace.uavs[0], atol=1e-6)  # same start
    gap = np.linalg.norm(real.trace.uavs[1, :, :2] - paper.trace.uavs[1, :, :2], axis=-1)
    assert gap.max() < 1.5
    assert real.observation_rate > 0.4


@pytest.mark.integration
def test_jsbsim_writes_no_files(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scenario = Scenario(steps=3).with_overrides(JSBSIM)
    uavtrack.simulate(scenario, seed=0)
    assert os.listdir(tmp_path) == []


@pytest.mark.integration
def test_the_environment_flies_jsbsim_as_the_simulator_does():
    pytest.importorskip("pettingzoo")
    from uavtrack.env import parallel_env

    scenario = Scenario(steps=8).with_overrides({**JSBSIM, "wind.speed": 4.0})
    env = parallel_env(scenario=scenario)
    env.reset(seed=2)
    while env.agents:
        env.step({})
    assert_same_trace(env.result().trace, uavtrack.simulate(scenario, seed=2).trace)


@pytest.mark.integration
@pytest.mark.parametrize("method", ["distributed", "centralized"])
def test_the_agent_form_flies_jsbsim_as_the_batch_does(method):
    pytest.importorskip("msgspec")
    from uavtrack.agents import run_swarm

    scenario = Scenario(steps=10).with_overrides({**JSBSIM, "wind.turbulence": "light"})
    swarm = run_swarm(scenario, method, seed=3, transport="memory")
    assert_same_trace(swarm.result.trace, uavtrack.simulate(scenario, method, seed=3).trace)


# ---------------------------------------------------------------- refused input


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"wind.speed": 5.0}, "wind needs uav.dynamics = jsbsim"),
        ({"wind.turbulence": "light"}, "wind needs uav.dynamics = jsbsim"),
        ({**JSBSIM, "wind.speed": -1.0}, "wind.speed: Input should be greater than or equal"),
        ({**JSBSIM, "wind.direction_deg": 360.0}, "wind.direction_deg: Input should be less"),
        ({**JSBSIM, "wind.turbulence": "gale"}, "wind.turbulence: Input should be 'none'"),
        ({"uav.dynamics": "6dof"}, "uav.dynamics: Input should be 'unicycle' or 'jsbsim'"),
        ({**JSBSIM, "uav.aircraft": "nosuch"}, "uav.aircraft 'nosuch' is neither"),
        pytest.param(
            {**JSBSIM, "uav.aircraft": "c172x"},
            "has no uavtrack autopilot",
            marks=pytest.mark.integration,
        ),
        ({**JSBSIM, "uav.jsbsim_rate_hz": 10.0}, "uav.jsbsim_rate_hz: Input should be greater"),
        pytest.param(
            {**JSBSIM, "uav.speed": 4.0}, "cannot fly level at 4 m/s", marks=pytest.mark.integration
        ),
        ({**JSBSIM, "wind.speed": 15.0}, "wind.speed 15 m/s must be below uav.speed 15 m/s"),
    ],
)
def test_bad_flight_settings_are_refused_in_one_line(overrides, message):
    with pytest.raises(ScenarioError, match=message) as info:
        scenario = Scenario(steps=2).with_overrides(overrides)
        uavtrack.simulate(scenario, seed=0, trace=False)
    assert "\n" not in str(info.value)


def test_without_jsbsim_the_setting_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "jsbsim", None)  # import jsbsim fails
    flight.check_aircraft.cache_clear()
    try:
        flown = Scenario().with_overrides(JSBSIM)  # built and read without JSBSim
        with pytest.raises(ScenarioError, match=r"needs JSBSim.*\.\[flight\]") as info:
            check_flight(flown)
    finally:
        flight.check_aircraft.cache_clear()
    assert "\n" not in str(info.value)
    Scenario()  # the default needs no JSBSim


# ---------------------------------------------------------------- the command line


def run_cli(capsys, *args):
    from uavtrack import cli

    code = cli.main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.integration
def test_run_flies_jsbsim_with_one_setting(capsys):
    import json

    args = ("run", "--set", "steps=12", "--set", "uav.dynamics=jsbsim", "--json", "--seed", "1")
    code, out, err = run_cli(capsys, *args, "--set", "wind.speed=6")
    assert code == 0, err
    data = json.loads(out)
    scenario = Scenario(steps=12).with_overrides({**JSBSIM, "wind.speed": 6.0})
    assert data["observation_rate"] == uavtrack.simulate(scenario, seed=1).observation_rate
    assert data["scenario"]["wind"]["speed"] == 6.0


@pytest.mark.parametrize(
    "args, message",
    [
        (("run", "--set", "wind.speed=5"), "wind needs uav.dynamics = jsbsim"),
        pytest.param(
            ("run", "--set", "uav.dynamics=jsbsim", "--set", "uav.aircraft=c172x"),
            "autopilot",
            marks=pytest.mark.integration,
        ),
        (("compare", "--set", "uav.dynamics=jsbsim", "--set", "wind.turbulence=2"), "turbulence"),
        (("flight", "--quick", "--set", "uav.dynamics=jsbsim"), "flight sets uav.dynamics"),
        (("flight", "--quick", "--set", "planner.wind=true"), "do not set planner.wind"),
        (("flight", "--quick", "--set", "wind.speed=3"), "do not set wind.speed"),
        (("run", "--set", "uav.aircraft=c172x"), "uav.aircraft 'c172x' needs uav.dynamics"),
        (("run", "--set", "uav.jsbsim_rate_hz=200"), "needs uav.dynamics = jsbsim"),
    ],
)
def test_bad_flight_input_on_the_command_line_is_one_line(capsys, tmp_path, args, message):
    code, out, err = run_cli(
        capsys, *args, *(("--out", str(tmp_path / "f")) * (args[0] == "flight"))
    )
    assert code == 2 and message in err and err.count("\n") == 1, err
    assert not (tmp_path / "f").exists()


@pytest.mark.integration
def test_flight_writes_its_report_and_figure(tmp_path, capsys):
    import json

    from PIL import Image

    out = tmp_path / "f"
    code, stdout, err = run_cli(capsys, "flight", "--quick", "--out", str(out), "--no-progress")
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary["conditions"]) == ["unicycle", "jsbsim, wind 10 m/s"]
    windy = summary["conditions"]["jsbsim, wind 10 m/s"]
    unicycle = summary["conditions"]["unicycle"]
    for method in ("distributed", "centralized", "greedy"):
        rates = [windy["methods"][method]["mean"], unicycle["methods"][method]["mean"]]
        against = windy["against_unicycle"][method]["mean"]
        assert against == pytest.approx(rates[0] - rates[1])  # paired on the same trials
    auto = summary["autopilot"]
    assert 0 < auto["step"]["t63_s"] < auto["step"]["t95_s"] < 1.0
    assert abs(auto["turn"]["left"]["relative_error"]) < 0.05
    assert auto["turn"]["right"]["rate_rad_s"] < 0 < auto["turn"]["left"]["rate_rad_s"]
    report = (out / "report.md").read_text()
    assert "| jsbsim, wind 10 m/s |" in report and "| level to +phi |" in report
    with Image.open(out / "flight.png") as im:
        assert im.size[0] > 1000


@pytest.mark.integration
def test_a_users_own_aircraft_folder_flies(tmp_path):
    import shutil

    # a user's model: trackwing copied under another name, its mass raised by 20%
    folder = tmp_path / "heavywing"
    shutil.copytree(flight.AIRCRAFT / "trackwing", folder)
    text = (folder / "trackwing.xml").read_text()
    (folder / "trackwing.xml").unlink()
    text = text.replace('name="trackwing"', 'name="heavywing"')
    text = text.replace('<emptywt unit="KG"> 2.5 </emptywt>', '<emptywt unit="KG"> 3.0 </emptywt>')
    (folder / "heavywing.xml").write_text(text)
    scenario = Scenario(steps=6).with_overrides({**JSBSIM, "uav.aircraft": str(folder)})
    alpha = flight.trim(folder, 425.0, 15.0, 1 / 120)[0]
    # 20% more weight needs 20% more lift: CL 0.445 instead of 0.371
    assert alpha == pytest.approx((1.2 * 0.371 - 0.25) / 5.25, abs=2e-3)
    assert uavtrack.simulate(scenario, seed=0).trace.uavs.shape == (6, 5, 5)


@pytest.mark.integration
def test_the_wind_aware_planner_changes_nothing_without_wind():
    scenario = Scenario(steps=15)
    aware = scenario.with_overrides({"planner.wind": True})
    assert_same_trace(
        uavtrack.simulate(aware, seed=2).trace, uavtrack.simulate(scenario, seed=2).trace
    )
    windy = scenario.with_overrides({**JSBSIM, "wind.speed": 8.0, "wind.direction_deg": 200.0})
    plain = uavtrack.simulate(windy, seed=2)
    knows = uavtrack.simulate(windy.with_overrides({"planner.wind": True}), seed=2)
    assert np.array_equal(plain.trace.uavs[0], knows.trace.uavs[0])  # the same start
    assert not np.array_equal(plain.trace.bids, knows.trace.bids)  # planned otherwise


def entity_folder(tmp_path, where):
    """trackwing copied as `entitywing`, one of its files declaring an external entity
    that names a file beside it: referenced in the text of the model (which JSBSim skips)
    or in an attribute of its autopilot (where JSBSim fails)."""
    import shutil

    secret = tmp_path / "secret.txt"
    secret.write_text("not part of any model")
    folder = tmp_path / "entitywing"
    shutil.copytree(flight.AIRCRAFT / "trackwing", folder)
    (folder / "trackwing.xml").rename(folder / "entitywing.xml")
    if where == "model":
        path, root = folder / "entitywing.xml", "<fdm_config"
        before, after = "<fileheader>", "<fileheader><note>&leak;</note>"
    else:
        path, root = folder / "Systems" / "autopilot.xml", "<system"
        before, after = '<system name="uavtrack-autopilot">', '<system name="&leak;">'
    text = path.read_text().replace('name="trackwing"', 'name="entitywing"')
    doctype = f'<!DOCTYPE {root[1:]} [ <!ENTITY leak SYSTEM "{secret.as_uri()}"> ]>\n'
    start = text.index(root)
    text = text[:start] + doctype + text[start:].replace(before, after, 1)
    path.write_text(text)
    return folder, path


@pytest.mark.parametrize("where", ["model", "autopilot"])
def test_an_aircraft_file_declaring_an_entity_is_refused_in_one_line(capsys, tmp_path, where):
    folder, path = entity_folder(tmp_path, where)
    args = ("run", "--steps", "2", "--set", "uav.dynamics=jsbsim")
    code, out, err = run_cli(capsys, *args, "--set", f"uav.aircraft={folder}")
    assert code == 2 and err.count("\n") == 1, err
    assert f"{path.resolve()} declares a DTD" in err
    assert "external entities and DTDs are refused" in err
    assert "not part of any model" not in out + err


@pytest.mark.integration
def test_a_model_jsbsim_cannot_parse_is_refused_in_one_line(tmp_path, monkeypatch):
    # past uavtrack's own reading of the XML, JSBSim's parse error is one line too
    folder, _ = entity_folder(tmp_path, "autopilot")
    monkeypatch.setattr(flight, "check_xml", lambda folder: None)
    with pytest.raises(ScenarioError, match="JSBSim could not load the model in") as info:
        check_flight(Scenario().with_overrides({**JSBSIM, "uav.aircraft": str(folder)}))
    assert "reference to external entity in attribute" in str(info.value)
    assert "\n" not in str(info.value)


def test_an_aircraft_file_that_is_not_xml_is_refused_in_one_line(tmp_path):
    import shutil

    folder = tmp_path / "trackwing"
    shutil.copytree(flight.AIRCRAFT / "trackwing", folder)
    (folder / "Systems" / "autopilot.xml").write_text("<system><property>&nosuch;</system>")
    with pytest.raises(ScenarioError, match=r"autopilot.xml is not well-formed XML \(") as info:
        check_flight(Scenario().with_overrides({**JSBSIM, "uav.aircraft": str(folder)}))
    assert "\n" not in str(info.value)
