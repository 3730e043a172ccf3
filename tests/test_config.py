import math
import re

import numpy as np
import pytest
from pydantic import ValidationError

import uavtrack
from uavtrack import Scenario, ScenarioError, SensorModel
from uavtrack.config import parse_value


def test_defaults_are_the_paper_experiment():
    s = Scenario()
    assert (s.n_uavs, s.n_targets, s.steps, s.comm_range) == (5, 4, 500, 50.0)
    assert s.sensor == SensorModel(k_d=0.1056, k_r=10.07, k_theta=0.01, half_fov_deg=5.0)
    assert s.uav.speed == 15.0 and s.target.sigma_1 == s.target.sigma_2 == 0.16


def test_every_field_documents_unit_and_source():
    for name, _, doc in Scenario().describe():
        assert doc, name
        assert (
            ("paper" in doc)  # "paper eq. N" or "beyond the paper" (the fault model)
            or ("assumed" in doc)
            or ("Algorithm" in doc)
            or name == "uav.altitudes"
        ), name


def test_altitudes_distinct_and_centred():
    s = Scenario()
    assert s.altitudes() == [415.0, 420.0, 425.0, 430.0, 435.0]
    s = Scenario(n_uavs=2, uav={"altitudes": [300.0, 320.0]})
    assert s.altitudes() == [300.0, 320.0]


def test_toml_round_trip(tmp_path):
    s = Scenario(
        n_uavs=3,
        comm_range=70.0,
        sensor={"half_fov_deg": 12.5},
        uav={"altitudes": [400.0, 450.0, 500.0]},
    )
    path = tmp_path / "s.toml"
    path.write_text(s.to_toml())
    assert Scenario.from_toml(path) == s


def test_overrides_dotted():
    s = Scenario().with_overrides({"sensor.half_fov_deg": 10, "planner.horizon": 4})
    assert s.sensor.half_fov_deg == 10 and s.planner.horizon == 4
    assert s.sensor.alpha == pytest.approx(math.radians(10))


@pytest.mark.parametrize(
    "overrides,message",
    [
        ({"comm_range": -1}, "comm_range: Input should be greater than or equal to 0"),
        ({"n_uavs": 0}, "n_uavs: Input should be greater than or equal to 1"),
        ({"sensor.half_fov_deg": 90}, "sensor.half_fov_deg: Input should be less than 90"),
        ({"sensor.k_d": "abc"}, "sensor.k_d: Input should be a valid number"),
        ({"nope": 1}, "unknown scenario field 'nope'"),
        ({"sensor.nope": 1}, "unknown scenario field 'sensor.nope'"),
        ({"planner.horizon": 1}, "planner.horizon: Input should be greater than or equal to 2"),
        ({"uav.altitudes": [1.0]}, "uav.altitudes has 1 entries but n_uavs is 5"),
        (
            {"uav.altitude": 10, "uav.altitude_spacing": 10},
            "put the 5 UAVs between -10 and 30 m, outside",
        ),
    ],
)
def test_bad_values_name_the_field(overrides, message):
    with pytest.raises(ScenarioError, match=message.replace("(", r"\(")) as info:
        Scenario().with_overrides(overrides)
    assert "\n" not in str(info.value)


def test_bad_files(tmp_path):
    with pytest.raises(ScenarioError, match="cannot read config file"):
        Scenario.from_toml(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("n_uavs = = 3\n")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        Scenario.from_toml(bad)
    unknown = tmp_path / "unknown.toml"
    unknown.write_text("[sensor]\nfov = 3\n")
    with pytest.raises(ScenarioError, match="unknown field 'sensor.fov'"):
        Scenario.from_toml(unknown)


def test_scenario_is_frozen():
    with pytest.raises(ValidationError, match="frozen"):
        uavtrack.Scenario().n_uavs = 3


@pytest.mark.parametrize(
    "overrides,message",
    [
        ({"field_size": math.inf}, "field_size: Input should be a finite number"),
        ({"dt": math.inf}, "dt: Input should be a finite number"),
        ({"dt": 1e308}, "dt: Input should be less than or equal to 10"),
        ({"comm_range": 1e308}, "comm_range: Input should be less than or equal to 100000"),
        ({"uav.altitude": 1e308}, "uav.altitude: Input should be less than or equal to 20000"),
        ({"sensor.k_d": math.inf}, "sensor.k_d: Input should be a finite number"),
        ({"uav.speed": math.inf}, "uav.speed: Input should be a finite number"),
        ({"target.sigma_1": math.inf}, "target.sigma_1: Input should be a finite number"),
        ({"target.sigma_1": math.nan}, "target.sigma_1: Input should be a finite number"),
        (
            {"uav.altitudes": [400.0, 410.0, math.nan, 430.0, 440.0]},
            "uav.altitudes.2: Input should be a finite number",
        ),
        ({"uav.altitudes": [400.0, 0.0, 1, 2, 3]}, "uav.altitudes.1: Input should be greater"),
        ({"steps": 10**8}, "steps: Input should be less than or equal to 10000000"),
        ({"n_uavs": True}, "n_uavs: Input should be a valid integer"),
        ({"n_uavs": 5.0}, "n_uavs: Input should be a valid integer"),
        ({"n_uavs": "5"}, "n_uavs: Input should be a valid integer"),
        ({"dt": True}, "dt: Input should be a valid number"),
        ({"dt": "0.5"}, "dt: Input should be a valid number"),
    ],
)
def test_non_finite_absurd_and_mistyped_values_are_refused(overrides, message):
    with pytest.raises(ScenarioError, match=message.replace("(", r"\(")) as info:
        Scenario().with_overrides(overrides)
    assert "\n" not in str(info.value)


def test_numbers_of_any_kind_are_accepted():
    s = Scenario(n_uavs=np.int64(3), dt=np.float32(0.25), comm_range=40)
    assert (s.n_uavs, s.dt, s.comm_range) == (3, 0.25, 40.0)
    assert type(s.n_uavs) is int and type(s.comm_range) is float


def test_every_float_field_has_a_documented_finite_range():
    for name, value, doc in Scenario().describe():
        if isinstance(value, bool):
            assert doc.startswith("true or false"), name
            continue
        # every field names its range beside its unit, e.g. "[m], (0, 100000]"
        assert re.search(r"[\[(][^\]()]*, [^\]()]*[\])]|\d+ to \d+", doc), name


def test_altitudes_are_frozen():
    s = Scenario(n_uavs=2, uav={"altitudes": [300.0, 320.0]})
    assert s.uav.altitudes == (300.0, 320.0)
    with pytest.raises(TypeError):
        s.uav.altitudes[0] = 1.0  # a tuple: validation cannot be bypassed in place
    assert Scenario.from_dict(s.to_dict()) == s


def test_override_errors_name_their_origin():
    with pytest.raises(ScenarioError, match=r"^sweep value dt=-1: dt: Input should be greater"):
        Scenario().with_overrides({"dt": -1}, origin="sweep value dt=-1")


def test_negative_altitude_spacing_reverses_the_order():
    s = Scenario().with_overrides({"uav.altitude_spacing": -5})
    assert s.altitudes() == [435.0, 430.0, 425.0, 420.0, 415.0]


def test_units_digest_and_value():
    s = Scenario()
    assert s.unit("comm_range") == "m" and s.unit("sensor.half_fov_deg") == "deg"
    assert s.unit("planner.discount") == "" and s.value("sensor.k_d") == 0.1056
    assert s.digest() == Scenario().digest() != s.with_overrides({"dt": 0.25}).digest()
    with pytest.raises(ScenarioError, match="unknown scenario field 'nope'"):
        s.unit("nope")


def test_parse_value_refuses_line_breaks():
    assert parse_value("[1, 2]") == [1, 2] and parse_value("abc") == "abc"
    with pytest.raises(ScenarioError, match="spans several lines"):
        parse_value("5\nn_uavs = 3")


def test_constructor_errors_are_one_line_scenario_errors():
    for fields, message in (
        ({"dt": math.nan}, "dt: Input should be a finite number (got nan)"),
        ({"foo": 1}, "unknown field 'foo'"),
        ({"sensor": {"half_fov_deg": 95}}, "sensor.half_fov_deg: Input should be less than 90"),
    ):
        with pytest.raises(ScenarioError) as info:
            Scenario(**fields)
        assert str(info.value).startswith(message) and "\n" not in str(info.value)


def test_an_unknown_field_names_the_closest_one_wherever_it_is_given(tmp_path, capsys):
    with pytest.raises(ScenarioError) as info:
        Scenario(comm_rang=80)
    assert str(info.value) == "unknown field 'comm_rang' (did you mean comm_range?)"
    with pytest.raises(ScenarioError) as info:
        Scenario(sensor={"half_fov": 3})
    assert str(info.value) == "unknown field 'sensor.half_fov' (did you mean sensor.half_fov_deg?)"
    with pytest.raises(ScenarioError) as info:
        Scenario(zzzzzz=1)  # nothing close: no guess
    assert str(info.value) == "unknown field 'zzzzzz'"
    path = tmp_path / "typo.toml"
    path.write_text("comm_rang = 80\n[faults]\nlos = 0.2\n")
    from uavtrack import cli

    assert cli.main(["run", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert err == (
        f"uavtrack: error: {path}: unknown field 'faults.los' (did you mean faults.loss?); "
        "unknown field 'comm_rang' (did you mean comm_range?)\n"
    )


def test_none_unsets_an_optional_field():
    assert parse_value("none") is None
    s = Scenario().with_overrides({"faults.round_budget": 3})
    assert (
        s.with_overrides({"faults.round_budget": parse_value("none")}).faults.round_budget is None
    )


def test_a_nested_section_round_trips_through_toml(tmp_path):
    s = Scenario().with_overrides(
        {"target.motion": "manoeuvring", "target.manoeuvre.interval": 2.0, "tracker.model": "imm"}
    )
    for comments in (False, True):
        path = tmp_path / f"s{comments}.toml"
        path.write_text(s.to_toml(comments=comments))
        assert "[target.manoeuvre]" in path.read_text()
        assert Scenario.from_toml(path) == s


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"target.manoeuvre.interval": 2.0}, "target.manoeuvre.interval needs target.motion"),
        ({"tracker.manoeuvre_std": [1.0, 2.0]}, "tracker.manoeuvre_std needs tracker.model = imm"),
        (
            {
                "tracker.turn_rates_deg": [5.0],
                "tracker.transition": [[0.6, 0.1, 0.1, 0.1, 0.1]] * 5,
            },
            "needs tracker.model = imm",
        ),
    ],
)
def test_a_setting_of_a_model_that_is_off_is_refused(overrides, message):
    with pytest.raises(ScenarioError, match=message) as info:
        Scenario().with_overrides(overrides)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"robust.gate": 1.0}, "robust.gate: Input should be less than 1"),
        ({"robust.gate": 0.5}, "robust.gate: Input should be greater than or equal to 0.9"),
        ({"robust.gate": "yes"}, "robust.gate: Input should be a valid number"),
        ({"robust.gate_memory": 3}, "robust.gate_memory 3 needs robust.gate"),
        ({"robust.gate": 0.99, "robust.gate_memory": -1}, "greater than or equal to 0"),
    ],
)
def test_the_measurement_gate_is_refused_outside_its_range(overrides, message):
    with pytest.raises(ScenarioError, match=message) as info:
        Scenario().with_overrides(overrides)
    assert "\n" not in str(info.value)


def test_the_measurement_gate_is_off_by_default_and_round_trips(tmp_path):
    assert Scenario().robust.gate is None
    s = Scenario().with_overrides({"robust.gate": 0.9999, "robust.gate_memory": 5})
    path = tmp_path / "gate.toml"
    path.write_text(s.to_toml())
    assert Scenario.from_toml(path) == s
