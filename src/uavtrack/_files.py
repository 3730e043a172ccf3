"""File output that never leaves a partial or misplaced file.

Every file is written to a temporary file beside its target and renamed over it, so a
reader (or a rerun after an interruption) sees either the old file or the complete new
one. The target must be a regular file or not exist yet: a directory, a device or a
pipe given as an output is refused, never replaced. JSON is strict: NaN and infinity,
which JSON cannot represent, are written as null.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from .errors import UsageError

_UMASK = os.umask(0)
os.umask(_UMASK)


def check_output(path: str | Path, option: str, force: bool | None = None) -> Path:
    """Refuse early an output file that cannot be written, before any long computation.

    The target must not exist (with `force`, it may be a regular file, then replaced;
    None: a file the command always writes anew, as a results folder's report), and its
    folder must exist and take a file (tried, not read off the permission bits). `option`
    names the argument in the message (``--trace``).
    """
    path = Path(path).expanduser()
    if path.is_dir():
        raise UsageError(f"{option}: {path} is a directory; give a file name")
    if path.exists() and not path.is_file():
        raise UsageError(f"{option}: {path} exists and is not a regular file")
    if force is False and os.path.lexists(path):
        raise UsageError(f"{option}: {path} exists; give a new name, or --force to replace it")
    parent = path.resolve().parent
    if not parent.is_dir():
        raise UsageError(f"{option}: directory {parent} does not exist")
    try:  # a real write: permission bits say nothing to root, or on /proc
        with tempfile.NamedTemporaryFile(dir=parent, prefix=".uavtrack-probe-"):
            pass
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise UsageError(f"{option}: cannot write in directory {parent} ({reason})") from None
    return path


def check_outputs(folder: str | Path, names: list[str]) -> None:
    """Refuse, before any computation, a results folder where one of the files a command
    will write (`names`) exists as something it cannot replace (a directory, a device,
    a link)."""
    folder = Path(folder).expanduser()
    for name in names:
        path = folder / name
        if path.is_symlink() or (path.exists() and not path.is_file()):
            raise UsageError(
                f"{path} exists and is not a regular file; uavtrack writes its {name} there "
                "(move it away or use another --out)"
            )


def check_distinct(outputs: dict[str, str | Path | None]) -> None:
    """Refuse two outputs of one command at one path: the second would replace the first.
    `outputs` maps each option to its path (None: not asked for)."""
    seen: dict[Path, str] = {}
    for option, path in outputs.items():
        if path is None or path == "":
            continue
        where = Path(path).expanduser().resolve()
        if where in seen:
            raise UsageError(f"{seen[where]} and {option} name the same file {path}; give two")
        seen[where] = option


def _taken(path: Path, option: str, what: str) -> None:
    """Refuse a path that exists, a link included (even one to nothing: a rename would
    replace the link, not make what it points to)."""
    if path.is_symlink() and not path.exists():
        raise UsageError(
            f"{option}: {path} is a link to {os.readlink(path)}, which does not exist; "
            f"give a new name for {what}"
        )
    if os.path.lexists(path):
        raise UsageError(f"{option}: {path} exists; give a new name for {what}")


def check_new_folder(path: str | Path, option: str, what: str, force: bool = False) -> Path:
    """Refuse early an output folder that exists (or is a link) or cannot be made: one
    line naming `option` (``--bag``) and `what` goes in it (``the bag``); with `force`,
    the line says that a folder is never replaced."""
    path = Path(path).expanduser()
    if path.exists():
        never = " (--force replaces files, never a folder)" if force else ""
        raise UsageError(f"{option}: {path} exists; give a new folder for {what}{never}")
    _taken(path, option, what)
    if not path.parent.is_dir():
        raise UsageError(f"{option}: directory {path.parent} does not exist")
    if not os.access(path.parent, os.W_OK):
        raise UsageError(f"{option}: cannot write in directory {path.parent}")
    return path


def check_new_file(path: str | Path, option: str, what: str, force: bool = False) -> Path:
    """Refuse early an output file that exists (or is a link, even to nothing) or cannot
    be written: one line naming `option` (``--out``) and `what` goes in it (``the
    netCDF``). With `force` a regular file that exists is replaced (a link is not)."""
    path = Path(path).expanduser()
    if path.is_file() and not path.is_symlink():
        if not force:
            raise UsageError(
                f"{option}: {path} exists; give a new name for {what}, or --force to replace it"
            )
    else:
        _taken(path, option, what)
    return check_output(path, option)


@contextmanager
def new_folder(path: str | Path) -> Iterator[Path]:
    """Yield a path, not yet made, in a temporary folder beside `path`: the caller makes
    the folder there and fills it; on success it is renamed to `path`, which appears
    only complete. On any exception nothing is left."""
    path = Path(path)
    work = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}."))
    try:
        yield work / path.name
        os.rename(work / path.name, path)
        WRITTEN.append(path)
    finally:
        shutil.rmtree(work, ignore_errors=True)


@contextmanager
def replacing(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path in `path`'s folder; on success it replaces `path`.

    The temporary name keeps the target's suffix, so writers that choose a format by
    extension (matplotlib, Pillow) work. On any exception the temporary file is removed;
    an OSError (a full disk) names `path`.
    """
    path = Path(path)
    if path.exists() and not path.is_file():
        raise UsageError(f"{path} exists and is not a regular file; not replacing it")
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)
        os.replace(tmp, path)
        WRITTEN.append(path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        if exc.filename is None or exc.filename == tmp:  # name the file the user asked for
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


JSON_BYTES = 16 << 20
"""The largest JSON file uavtrack reads back (a manifest, a job file) [bytes]: a job of
ten trials takes a few KiB."""


def read_json(path: str | Path) -> Any:
    """A JSON file uavtrack wrote, read back: ValueError (one line) for one that is not a
    regular file, larger than `JSON_BYTES`, not JSON, or nested too deeply to parse."""
    path = Path(path)
    if not path.is_file() or path.is_symlink() and not path.resolve().is_file():
        raise ValueError("not a regular file")
    with open(path, "rb") as file:
        raw = file.read(JSON_BYTES + 1)
    if len(raw) > JSON_BYTES:
        raise ValueError(f"larger than {JSON_BYTES >> 20} MiB")
    try:
        return json.loads(raw.decode("utf-8"))
    except RecursionError:
        raise ValueError("nested too deeply") from None


WRITTEN: list[Path] = []
"""Every file and folder written whole by this process, in order: what an interrupted
command says it leaves on disk."""


def plain(data: Any) -> Any:
    """`data` with numpy scalars and arrays as Python values and non-finite floats as None."""
    if isinstance(data, dict):
        return {str(k): plain(v) for k, v in data.items()}
    if isinstance(data, list | tuple):
        return [plain(v) for v in data]
    if hasattr(data, "tolist"):  # numpy arrays and scalars
        return plain(data.tolist())
    if isinstance(data, float) and not math.isfinite(data):
        return None
    return data


def dumps(data: Any, indent: int | None = None) -> str:
    """Strict JSON text of `data` (see `plain`)."""
    return json.dumps(plain(data), indent=indent, allow_nan=False)


def write_json(path: str | Path, data: Any) -> None:
    """JSON, atomically (non-finite numbers as null)."""
    write_text(path, dumps(data, indent=1))


def write_text(path: str | Path, text: str) -> None:
    """Text, atomically."""
    with replacing(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_bytes(path: str | Path, data: bytes | memoryview) -> None:
    """Bytes, atomically: a full disk is a plain OSError naming `path`, and leaves no
    file. Formats whose writers cannot recover from a failed write (HDF5, Rerun's file
    sink) are built in memory and written through here."""
    with replacing(path) as tmp:
        tmp.write_bytes(data)


def write_npz(path: str | Path, arrays: dict[str, Any]) -> None:
    """A compressed .npz archive at exactly `path`, atomically.

    numpy appends ``.npz`` to a file *name* that lacks it, so the archive is written
    through an open file object, which numpy leaves alone.
    """
    import numpy as np

    with replacing(path) as tmp, open(tmp, "wb") as handle:
        np.savez_compressed(handle, **arrays)
