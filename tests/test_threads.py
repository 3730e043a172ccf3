"""BLAS threads are set in one place, on ``import uavtrack``, for every entry point."""

import json
import os
import subprocess
import sys

import pytest

from uavtrack import _process

pytestmark = pytest.mark.integration  # each probe is a fresh interpreter

PROBE = (
    "import json, sys\n"
    "{before}"
    "import uavtrack\n"
    "loaded = 'numpy' in sys.modules\n"
    "import numpy, threadpoolctl\n"
    "info = threadpoolctl.threadpool_info()\n"
    "blas = [p['num_threads'] for p in info if p['user_api'] == 'blas']\n"
    "print(json.dumps({{'loaded': loaded, 'blas': blas, 'how': uavtrack._process.describe(),\n"
    "                  'child': __import__('os').environ.get('OPENBLAS_NUM_THREADS')}}))\n"
)


def probe(before: str = "", **env: str) -> dict:
    """What BLAS runs on in a fresh interpreter that imports uavtrack."""
    environ = {k: v for k, v in os.environ.items() if k not in _process.THREAD_VARIABLES}
    environ.pop(_process.VARIABLE, None)
    environ.update(env)
    out = subprocess.run(
        [sys.executable, "-c", PROBE.format(before=before)],
        capture_output=True,
        text=True,
        env=environ,
        check=True,
    )
    return json.loads(out.stdout)


def native() -> int:
    """BLAS threads of a numpy loaded without uavtrack and without thread variables."""
    environ = {k: v for k, v in os.environ.items() if k not in _process.THREAD_VARIABLES}
    code = (
        "import numpy, threadpoolctl\n"
        "print([p['num_threads'] for p in threadpoolctl.threadpool_info()"
        " if p['user_api'] == 'blas'][0])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=environ)
    return int(out.stdout)


def test_importing_uavtrack_pins_blas_to_one_thread_before_numpy_loads():
    seen = probe()
    assert seen["loaded"] is False  # the environment is set before numpy reads it
    assert seen["blas"] and set(seen["blas"]) == {1}
    assert seen["how"] == "1 (environment)"
    assert seen["child"] == "1"  # worker processes and agent programs inherit it


def test_numpy_loaded_first_is_limited_through_threadpoolctl():
    seen = probe(before="import numpy\n")
    assert set(seen["blas"]) == {1}
    assert seen["how"] == "1 (threadpoolctl)"
    assert seen["child"] == "1"


def test_the_variable_sets_the_count():
    seen = probe(UAVTRACK_BLAS_THREADS="2")
    assert set(seen["blas"]) == {2}
    seen = probe(before="import numpy\n", UAVTRACK_BLAS_THREADS="2")
    assert set(seen["blas"]) == {2}


def test_a_users_thread_variable_and_keep_are_respected():
    seen = probe(OPENBLAS_NUM_THREADS="2")
    assert set(seen["blas"]) == {2}
    assert seen["how"] == "kept (OPENBLAS_NUM_THREADS=2)"
    seen = probe(UAVTRACK_BLAS_THREADS="keep")
    assert set(seen["blas"]) == {native()}
    assert seen["child"] is None


@pytest.mark.parametrize("value", ["0", "two", "-1"])
def test_a_bad_value_is_one_line_on_the_command_line(value, tmp_path):
    environ = dict(os.environ, UAVTRACK_BLAS_THREADS=value)
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "uavtrack.cli",
            "run",
            "--steps",
            "2",
            "--json",
            str(tmp_path / "r.json"),
        ],
        capture_output=True,
        text=True,
        env=environ,
    )
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [
        f"uavtrack: error: UAVTRACK_BLAS_THREADS={value!r}: give a positive number of threads, "
        "or 'keep' to leave BLAS as it is"
    ]
    assert not (tmp_path / "r.json").exists()


def test_version_is_answered_without_loading_the_command_line():
    code = (
        "import sys\n"
        "sys.argv = ['uavtrack', '--version']\n"
        "from uavtrack._console import main\n"
        "main()\n"
        "assert not {'typer', 'numpy', 'pydantic'} & set(sys.modules), sorted(sys.modules)\n"
    )
    fast = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    full = subprocess.run(
        [sys.executable, "-m", "uavtrack.cli", "--version"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert fast.stdout == full.stdout and fast.stdout.startswith("uavtrack ")


def test_help_of_a_command_loads_neither_numpy_nor_the_scenario_model():
    code = (
        "import sys\n"
        "from uavtrack.cli import main\n"
        "assert main(['run', '--help']) == 0\n"
        "assert not {'numpy', 'uavtrack.config'} & set(sys.modules)\n"
    )
    subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
