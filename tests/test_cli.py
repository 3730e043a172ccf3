import json
import subprocess
import sys

import numpy as np
import pytest

from uavtrack import cli
from uavtrack.files import replacing


def run_cli(capsys, *args):
    code = cli.main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def test_run_json(capsys):
    code, out, err = run_cli(
        capsys, "run", "--set", "steps=30", "--json", "--method", "greedy", "--seed", "4"
    )
    assert code == 0, err
    data = json.loads(out)
    assert data["method"] == "greedy" and data["seed"] == 4
    assert set(data) >= {"observation_rate", "per_target", "rmse", "nees"}
    assert len(data["per_target"]) == 4
    assert data["observation_rate"] == pytest.approx(np.mean(data["per_target"]))
    assert data["scenario"]["steps"] == 30


def test_run_table_and_set_nested(capsys):
    code, out, _ = run_cli(
        capsys,
        "run",
        "--set",
        "steps=20",
        "--set",
        "sensor.half_fov_deg=10",
        "--set",
        "n_targets=2",
    )
    assert code == 0
    assert "observation rate" in out and "target 1" in out and "target 2" not in out


def test_config_file_and_override_precedence(capsys, tmp_path):
    config = tmp_path / "s.toml"
    config.write_text("steps = 15\nn_targets = 3\n[sensor]\nhalf_fov_deg = 8.0\n")
    code, out, _ = run_cli(capsys, "run", "--config", str(config), "--set", "n_targets=2", "--json")
    data = json.loads(out)
    assert code == 0 and data["scenario"]["steps"] == 15
    assert data["scenario"]["n_targets"] == 2 and data["scenario"]["sensor"]["half_fov_deg"] == 8.0


def test_trace_file(capsys, tmp_path):
    path = tmp_path / "t.npz"
    code, _, err = run_cli(capsys, "run", "--set", "steps=12", "--trace", str(path))
    assert code == 0, err
    with np.load(path) as npz:
        assert npz["targets"].shape == (12, 4, 4)
        assert npz["uavs"].shape == (12, 5, 5)
        assert npz["mean"].shape == (12, 5, 4, 4)
        assert npz["cov"].shape == (12, 5, 4, 4, 4)
        assert npz["observed"].shape == (12, 5, 4) and npz["observed"].dtype == bool
        assert npz["assignment"].shape == (12, 5) and npz["rounds"].shape == (12, 5)
    assert [p.name for p in tmp_path.iterdir()] == ["t.npz"]


BAD = [
    (["run", "--set", "foo=1"], "unknown scenario field 'foo'"),
    (["run", "--set", "sensor.fov=1"], "unknown scenario field 'sensor.fov'"),
    (["run", "--set", "n_uavs=abc"], "n_uavs: Input should be a valid integer"),
    (["run", "--set", "comm_range=-10"], "comm_range: Input should be greater than or equal to 0"),
    (["run", "--set", "n_uavs=0"], "n_uavs: Input should be greater than or equal to 1"),
    (
        ["run", "--set", "sensor.half_fov_deg=90"],
        "sensor.half_fov_deg: Input should be less than 90",
    ),
    (["run", "--set", "steps"], "--set expects FIELD=VALUE"),
    (["run", "--method", "best"], "'best' is not one of"),
    (["run", "--seed", "-3"], "--seed"),
    (["run", "--config", "/nonexistent/s.toml"], "cannot read config file"),
    (["run", "--bogus"], "No such option: --bogus"),
    (["nocommand"], "No such command"),
]


@pytest.mark.parametrize("args,message", BAD)
def test_bad_input_exits_2_with_one_line(capsys, tmp_path, args, message):
    trace = tmp_path / "out.npz"
    code, out, err = run_cli(capsys, *args, *(["--trace", str(trace)] if args[0] == "run" else []))
    assert code == 2
    assert message in err
    assert err.count("\n") == 1 and err.startswith("uavtrack: error: ")
    assert "Traceback" not in err + out
    assert not any(tmp_path.iterdir())  # nothing half-written


def test_malformed_config_file(capsys, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[sensor\nk_d = 1\n")
    code, _, err = run_cli(capsys, "run", "--config", str(bad))
    assert code == 2 and "not valid TOML" in err and err.count("\n") == 1
    typo = tmp_path / "typo.toml"
    typo.write_text("n_uav = 3\n")
    code, _, err = run_cli(capsys, "run", "--config", str(typo))
    assert code == 2 and "unknown field 'n_uav'" in err


def test_trace_into_missing_directory(capsys, tmp_path):
    code, _, err = run_cli(
        capsys, "run", "--set", "steps=5", "--trace", str(tmp_path / "no" / "t.npz")
    )
    assert code == 2 and "does not exist" in err


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    with pytest.raises(RuntimeError), replacing(tmp_path / "x.npz") as tmp:
        tmp.write_bytes(b"partial")
        raise RuntimeError("disk full")
    assert not any(tmp_path.iterdir())
    with replacing(tmp_path / "y.json") as tmp:
        tmp.write_text("{}")
    assert [p.name for p in tmp_path.iterdir()] == ["y.json"]
    assert oct((tmp_path / "y.json").stat().st_mode & 0o777) != oct(0o600)


def test_params_lists_every_field(capsys):
    code, out, _ = run_cli(capsys, "params", "--toml")
    assert code == 0 and "comm_range = 50.0" in out and "[sensor]" in out


def test_console_script_exit_code():
    proc = subprocess.run(
        [sys.executable, "-m", "uavtrack.cli", "run", "--set", "planner.horizon=0"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    expected = "--set: planner.horizon: Input should be greater than or equal to 2 (got 0)"
    assert proc.stderr.strip() == f"uavtrack: error: {expected}"
