"""The package type-checks: pyright, configured by pyproject.toml's [tool.pyright]
(standard everywhere, strict on the model and cycle), finds no error in src."""

import importlib.util
import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).parent.parent
CONFIG = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pyright"]


def test_every_strict_path_exists():
    # pyright passes over a strict path that names nothing: a moved module would
    # leave strict checking without a word
    missing = [path for path in CONFIG["strict"] if not (ROOT / path).exists()]
    assert not missing, f"[tool.pyright] strict names missing paths: {missing}"


@pytest.mark.integration
def test_pyright_finds_no_error_in_the_package():
    if importlib.util.find_spec("pyright") is None:
        pytest.skip("pyright is not installed (the test extra installs it)")
    env = {**os.environ, "PYRIGHT_PYTHON_IGNORE_WARNINGS": "1"}  # no look for a newer one
    done = subprocess.run(
        [sys.executable, "-m", "pyright", "--outputjson", "--pythonpath", sys.executable],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=1800,  # about 30 s on 2 cores; the bound only stops a hung checker
    )
    try:
        report = json.loads(done.stdout)
    except json.JSONDecodeError:
        pytest.fail(
            f"pyright gave no report (exit {done.returncode}):\n{done.stdout}\n{done.stderr}"
        )
    errors = [d for d in report["generalDiagnostics"] if d["severity"] == "error"]
    shown = "\n".join(
        f"{Path(d['file']).relative_to(ROOT)}:{d['range']['start']['line'] + 1}: "
        f"{d['message']} ({d.get('rule', '')})"
        for d in errors
    )
    assert report["summary"]["errorCount"] == len(errors) == 0, f"pyright:\n{shown}"
    assert done.returncode == 0, done.stderr
    # every module of the package was checked, not an empty selection
    modules = list((ROOT / "src" / "uavtrack").rglob("*.py"))
    assert report["summary"]["filesAnalyzed"] == len(modules)
