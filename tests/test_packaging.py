"""What a user receives: the licence in the repository and in the built wheel, and a
citation file that the CFF tools read."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import uavtrack

ROOT = Path(__file__).resolve().parents[1]


def test_the_citation_file_is_valid_cff_and_names_this_version():
    cffconvert = pytest.importorskip("cffconvert")
    citation = cffconvert.Citation((ROOT / "CITATION.cff").read_text())
    citation.validate()  # raises on a file the schema of CFF 1.2.0 refuses
    assert citation.cffobj["version"] == uavtrack.__version__
    assert citation.cffobj["license"] == "MIT"
    assert "The uavtrack developers" in citation.as_bibtex()


def test_the_licence_is_mits_and_the_package_says_so():
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "Permission is hereby granted" in text
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert 'license = "MIT"' in pyproject and 'license-files = ["LICENSE"]' in pyproject


@pytest.mark.integration  # builds the wheel with pip, in a process of its own
def test_the_built_wheel_carries_the_licence(tmp_path):
    built = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(ROOT)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert built.returncode == 0, built.stderr
    (wheel,) = tmp_path.glob("uavtrack-*.whl")
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        (licence,) = [n for n in names if n.endswith(".dist-info/licenses/LICENSE")]
        assert archive.read(licence).decode() == (ROOT / "LICENSE").read_text()
        (metadata,) = [n for n in names if n.endswith(".dist-info/METADATA")]
        lines = archive.read(metadata).decode().splitlines()
    assert "License-Expression: MIT" in lines and "License-File: LICENSE" in lines
    # the data a fresh install needs: the shipped presets and policies (policy:bc)
    assert "uavtrack/config/presets/realistic.toml" in names
    shipped = {f"uavtrack/env/policies/{n}.npz" for n in ("bc", "bc-ppo", "bc-jpda")}
    assert shipped <= set(names)
