"""Atomic file output: write to a temporary file beside the target, then rename it.

A reader (or a rerun after an interruption) therefore sees either the old file or the
complete new one, never a partial file.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

_UMASK = os.umask(0)
os.umask(_UMASK)


@contextmanager
def replacing(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path in `path`'s folder; on success it replaces `path`.

    The temporary name keeps the target's suffix, so writers that choose a format by
    extension (matplotlib, Pillow) work. On any exception the temporary file is removed.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json(path: str | Path, data: Any) -> None:
    """JSON, atomically."""
    with replacing(path) as tmp:
        tmp.write_text(json.dumps(data, indent=1), encoding="utf-8")


def write_text(path: str | Path, text: str) -> None:
    """Text, atomically."""
    with replacing(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
