import math

import pytest
from pydantic import ValidationError

import uavtrack
from uavtrack import Scenario, ScenarioError, SensorModel


def test_defaults_are_the_paper_experiment():
    s = Scenario()
    assert (s.n_uavs, s.n_targets, s.steps, s.comm_range) == (5, 4, 500, 50.0)
    assert s.sensor == SensorModel(k_d=0.1056, k_r=10.07, k_theta=0.01, half_fov_deg=5.0)
    assert s.uav.speed == 15.0 and s.target.sigma_1 == s.target.sigma_2 == 0.16


def test_every_field_documents_unit_and_source():
    for name, _, doc in Scenario().describe():
        assert doc, name
        assert (
            ("paper" in doc)
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
        ({"uav.altitude": 10, "uav.altitude_spacing": 10}, "altitude <= 0"),
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
