"""Methods from other packages: a plugin installed with pip is a method of every command."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration  # plugins installed with pip, used by commands

EXAMPLE = Path(__file__).parents[1] / "examples" / "custom_method.py"

PYPROJECT = """\
[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "uavtrack-sequential"
version = "0.1"
dependencies = ["uavtrack"]

[project.entry-points."uavtrack.methods"]
sequential = "custom_method:SequentialAuction"

[tool.setuptools]
py-modules = ["custom_method"]
"""


@pytest.fixture(scope="module")
def plugin_site(tmp_path_factory):
    """A plugin package made of the example, installed with pip into its own folder."""
    root = tmp_path_factory.mktemp("plugin")
    package = root / "uavtrack-sequential"
    package.mkdir()
    (package / "custom_method.py").write_text(EXAMPLE.read_text())
    (package / "pyproject.toml").write_text(PYPROJECT)
    site = root / "site"
    # as a user would: pip builds it in its own environment (setuptools from the index)
    done = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
         "--target", str(site), str(package)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    return site


def uavtrack(site: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]),
    }
    return subprocess.run(
        [sys.executable, "-m", "uavtrack.cli", *args],
        capture_output=True, text=True, env=env, cwd=cwd, timeout=600,
    )  # fmt: skip


def test_importing_the_example_runs_nothing_and_registers_nothing():
    code = (
        "import runpy, uavtrack.methods.registry as r\n"
        f"ns = runpy.run_path({str(EXAMPLE)!r}, run_name='custom_method')\n"
        "assert 'sequential' not in r.names(), r.names()\n"
        "assert ns['SequentialAuction'].name == 'sequential'\n"
        "print('imported')\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "imported\n"  # no experiment ran at import


def test_a_plugin_installed_with_pip_is_a_method_of_every_command(plugin_site, tmp_path):
    proc = uavtrack(plugin_site, "run", "--method", "sequential", "--steps", "30", "--json",
                    cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    run = json.loads(proc.stdout)
    assert run["method"] == "sequential" and 0 <= run["observation_rate"] <= 1
    proc = uavtrack(plugin_site, "compare", "--method", "distributed", "--method", "sequential",
                    "--trials", "3", "--steps", "30", "--json", cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    assert list(data["methods"]) == ["distributed", "sequential"]
    assert data["paired"]["distributed - sequential"]["observation_rate"]["trials"] == 3
    # a sweep runs its jobs in worker processes, which find the plugin too
    proc = uavtrack(plugin_site, "sweep", "comm_range", "0", "80", "--method", "sequential",
                    "--trials", "2", "--steps", "20", "--workers", "2", "--out",
                    str(tmp_path / "sweep"), cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "sweep" / "summary.json").read_text())
    assert list(summary["methods"]) == ["sequential"]
    help_text = uavtrack(plugin_site, "run", "--help", cwd=tmp_path).stdout
    assert "sequential" in help_text


def test_the_plugin_decides_by_its_own_rule(plugin_site):
    # with r_C = 0 every neighbourhood is the UAV alone, where any auction rule takes the
    # UAV's best bid: the plugin then decides exactly as the paper's method and as greedy
    code = (
        "import numpy as np, uavtrack\n"
        "s = uavtrack.Scenario(steps=40, comm_range=0.0)\n"
        "a = uavtrack.simulate(s, 'sequential', seed=3).trace\n"
        "b = uavtrack.simulate(s, 'greedy', seed=3).trace\n"
        "assert np.array_equal(a.assignment, b.assignment)\n"
        "s = uavtrack.Scenario(steps=80)\n"
        "a = uavtrack.simulate(s, 'sequential', seed=3).trace\n"
        "b = uavtrack.simulate(s, 'distributed', seed=3).trace\n"
        "print(int((a.assignment != b.assignment).sum()))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(plugin_site)}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                          timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert int(proc.stdout) > 0  # its own rule: not the Hungarian assignment everywhere


def test_a_broken_plugin_is_named_in_one_line_where_it_is_used(tmp_path):
    site = tmp_path / "site"
    info = site / "broken_plugin-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: broken-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[uavtrack.methods]\nbroken = no_such_module:Method\n")
    message = (
        "uavtrack: error: method 'broken' cannot be loaded from no_such_module:Method: "
        "ModuleNotFoundError: No module named 'no_such_module'"
    )
    proc = uavtrack(site, "run", "--method", "broken", "--steps", "5", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr.strip() == message
    out = tmp_path / "sweep"
    proc = uavtrack(site, "sweep", "comm_range", "25", "--method", "broken", "--trials", "1",
                    "--steps", "5", "--out", str(out), cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 2 and proc.stderr.strip() == message and not out.exists()
    # commands that do not use it are not held up by it
    proc = uavtrack(site, "run", "--steps", "5", "--json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    proc = uavtrack(site, "compare", "--trials", "1", "--steps", "5", "--json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert list(json.loads(proc.stdout)["methods"]) == ["distributed", "centralized", "greedy"]
