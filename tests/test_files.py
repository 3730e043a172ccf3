import json
import os
import subprocess
import sys

import numpy as np
import pytest

from uavtrack import _files
from uavtrack.errors import UsageError


@pytest.mark.parametrize("name", ["run.trace", "t", "T.NPZ", "with space.npz"])
def test_npz_lands_at_exactly_the_path_given(tmp_path, name):
    path = tmp_path / name
    path.write_text("earlier content")
    _files.write_npz(path, {"a": np.arange(3), "b": np.eye(2)})
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # nothing hidden beside it
    with np.load(path) as npz:
        assert np.array_equal(npz["a"], np.arange(3)) and np.array_equal(npz["b"], np.eye(2))


def test_outputs_that_are_not_regular_files_are_refused(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    folder = tmp_path / "folder"
    folder.mkdir()
    for path, message in (
        (fifo, "exists and is not a regular file"),
        (folder, "is a directory"),
        ("/dev/null", "exists and is not a regular file"),
        (tmp_path / "missing" / "x.npz", "does not exist"),
    ):
        with pytest.raises(UsageError, match=message):
            _files.check_output(path, "--trace")
    with pytest.raises(UsageError, match="not a regular file"), _files.replacing(fifo):
        pass
    assert fifo.exists() and not fifo.is_file()  # left alone


def test_json_is_strict_and_writes_null_for_non_finite(tmp_path):
    data = {"a": float("nan"), "b": [1.0, float("inf")], "c": np.float64(2.5), "d": np.arange(2)}
    text = _files.dumps(data)
    assert json.loads(text) == {"a": None, "b": [1.0, None], "c": 2.5, "d": [0, 1]}
    _files.write_json(tmp_path / "x.json", data)

    def refuse(constant):
        raise ValueError(constant)

    assert json.loads((tmp_path / "x.json").read_text(), parse_constant=refuse)["a"] is None


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    with pytest.raises(RuntimeError), _files.replacing(tmp_path / "x.npz") as tmp:
        tmp.write_bytes(b"partial")
        raise RuntimeError("disk full")
    assert not any(tmp_path.iterdir())
    with _files.replacing(tmp_path / "y.json") as tmp:
        tmp.write_text("{}")
    assert [p.name for p in tmp_path.iterdir()] == ["y.json"]
    assert (tmp_path / "y.json").stat().st_mode & 0o777 != 0o600


SMALL_DISK = """
import os, resource, signal, sys
limit = int(sys.argv[1])
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG
resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
os.execv(sys.executable, [sys.executable, *sys.argv[2:]])
"""


def on_a_small_disk(folder, limit: int, *args, timeout: float = 300):
    """Run ``python ARGS`` in `folder` as if the disk had room for `limit` bytes per file:
    writes beyond them fail (EFBIG, through RLIMIT_FSIZE, no privileges needed) as a
    full disk makes them fail (ENOSPC). The timeout only stops a command that hangs."""
    command = [sys.executable, "-c", SMALL_DISK, str(limit), *map(str, args)]
    return subprocess.run(command, cwd=folder, capture_output=True, text=True, timeout=timeout)


@pytest.mark.integration
def test_bytes_on_a_full_disk_fail_naming_the_file_and_leave_nothing(tmp_path):
    code = "from uavtrack import _files; _files.write_bytes('out.bin', bytes(100_000))"
    proc = on_a_small_disk(tmp_path, 40_000, "-c", code)
    assert proc.returncode == 1 and "OSError" in proc.stderr
    assert "out.bin" in proc.stderr.splitlines()[-1] and "File too large" in proc.stderr
    assert list(tmp_path.iterdir()) == []
    _files.write_bytes(tmp_path / "out.bin", memoryview(b"abc"))
    assert (tmp_path / "out.bin").read_bytes() == b"abc"


def test_a_link_to_nothing_is_no_new_output(tmp_path):
    link = tmp_path / "out"
    link.symlink_to(tmp_path / "gone")
    (tmp_path / "taken.nc").write_text("mine")
    for check in (_files.check_new_folder, _files.check_new_file):
        with pytest.raises(UsageError, match=f"{link} is a link to {tmp_path / 'gone'}, which"):
            check(link, "--out", "the tables")
    with pytest.raises(UsageError, match="taken.nc exists; give a new name for the netCDF"):
        _files.check_new_file(tmp_path / "taken.nc", "--out", "the netCDF")
    assert _files.check_new_file(tmp_path / "new.nc", "--out", "the netCDF") == tmp_path / "new.nc"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "taken.nc"]
