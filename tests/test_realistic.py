"""The realistic preset and `uavtrack realistic`: the preset loads with every realism on,
the swarm and the environment run it as the batch does, and the command refuses bad
input, writes its tables and figure, and resumes."""

from __future__ import annotations

import json

import pandas as pd
import pytest

import uavtrack
from uavtrack import cli
from uavtrack.experiments import realistic
from uavtrack.testing import assert_same_trace


def preset(steps: int = 12) -> uavtrack.Scenario:
    return uavtrack.Scenario.from_toml("realistic").with_overrides({"steps": steps})


def test_the_preset_turns_every_realism_on():
    s = preset()
    assert s.sensor.detection_probability == 0.9 and s.sensor.clutter_rate == 2.0
    assert s.tracker.association == "jpda" and s.tracker.model == "imm"
    assert s.fusion.rule == "covariance_intersection" and s.target.motion == "manoeuvring"
    assert s.faults.loss == 0.2 and s.faults.burst_length > 1 and s.faults.delay == 1
    assert s.radio.bandwidth_bps == 1e6 and s.radio.encoding == "compact"
    assert s.fusion.trigger is not None and s.planner.avoidance != "none"
    # its radio reaches the sound range of its separation at its delay
    import math

    from uavtrack.airspace.avoidance import sound_range

    bank = math.radians(s.uav.bank_angle_deg)
    need = sound_range(s.uav.separation, s.uav.speed, bank, s.dt, s.faults.delay)
    assert need <= s.comm_range < need + 1.0


def test_every_cell_removes_what_it_names_and_only_that():
    base = preset()
    for method in realistic.METHODS:
        for variant in realistic.variants():
            cell = realistic.scenario_of(base, method, variant)
            if variant.startswith("without "):
                for field, value in realistic.REMOVED[variant[8:]].items():
                    part, _, name = field.partition(".")
                    got = getattr(getattr(cell, part), name) if name else getattr(cell, part)
                    assert got == value, (variant, field)
    central = realistic.scenario_of(base, "centralized", "preset")
    assert central.radio.encoding == "full" and central.fusion.trigger is None


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--set", "comm_range=-3"], "comm_range"),
        (["--trials", "0"], "--trials"),
        (["--set", "faults.delay=-1"], "faults.delay"),
    ],
)
def test_realistic_refuses_bad_input_in_one_line_and_writes_nothing(tmp_path, args, named, capsys):
    out = tmp_path / "r"
    code = cli.main(["realistic", "--quick", *args, "--out", str(out)])
    _, err = capsys.readouterr()
    assert code == 2 and named in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.integration  # worker processes
def test_uavtrack_realistic_writes_its_tables_and_figure_and_resumes(tmp_path, capsys):
    from PIL import Image

    out = tmp_path / "r"
    args = ["realistic", "--quick", "--steps", "15", "--out", str(out), "--no-progress"]
    assert cli.main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    cells = summary["methods"]["distributed"]["cells"]
    assert set(cells) == set(realistic.variants())
    assert cells["preset"]["gain"]["mean"] == 0.0  # the preset against itself
    rows = pd.json_normalize(  # read back by an independent library
        [
            {"method": m, "cell": c, **v}
            for m, r in summary["methods"].items()
            for c, v in r["cells"].items()
        ]  # fmt: skip
    )
    assert len(rows) == 3 * len(realistic.variants())
    assert rows["observation_rate"].between(0, 1).all()
    report = (out / "report.md").read_text()
    assert "oracle-sensor rate" in report and "![realistic](realistic.png)" in report
    with Image.open(out / "realistic.png") as image:
        assert image.size[0] > 1000
    capsys.readouterr()
    assert cli.main(args) == 0  # everything already done
    assert "0 jobs run" in capsys.readouterr().out


@pytest.mark.integration  # a swarm of programs
@pytest.mark.parametrize("method", ["distributed", "greedy", "centralized"])
def test_a_swarm_in_the_preset_decides_as_the_batch(method):
    from uavtrack.agents import run_swarm

    case = realistic.scenario_of(preset(), method, "preset")
    batch = uavtrack.simulate(case, method, seed=2)
    swarm = run_swarm(case, method, seed=2, transport="memory")
    assert batch.trace is not None and swarm.result.trace is not None
    assert_same_trace(swarm.result.trace, batch.trace)


@pytest.mark.integration  # processes over Zenoh
def test_a_zenoh_swarm_in_the_preset_decides_as_the_batch():
    pytest.importorskip("zenoh")
    from uavtrack.agents import run_swarm

    case = preset(8)
    swarm = run_swarm(case, "distributed", seed=3, transport="zenoh")
    batch = uavtrack.simulate(case, "distributed", seed=3)
    assert_same_trace(swarm.result.trace, batch.trace)
    assert swarm.transport == "zenoh" and swarm.traffic.dropped == 0


def test_the_environment_runs_the_preset_as_the_batch():
    pytest.importorskip("pettingzoo")
    from uavtrack.env import parallel_env

    case = preset(10)
    env = parallel_env(case, method_for_others="distributed")
    env.reset(seed=5)
    while env.agents:
        env.step({})
    reference = uavtrack.simulate(case, "distributed", seed=5)
    assert_same_trace(env.result().trace, reference.trace)
