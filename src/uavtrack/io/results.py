"""A results folder of `uavtrack reproduce`, `sweep`, `robustness` or `trackers`, read
only: each finished job file (``raw/*.json``: the job, its seconds and its per-trial
metrics, with the SHA-256 of their canonical JSON) that is intact. The folder itself is
written by `uavtrack.experiments.store`; `tables` reads it through here.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..errors import UsageError


def checksum(body: dict[str, Any]) -> str:
    """SHA-256 of the canonical JSON of a job file's body."""
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def read_jobs(
    root: str | Path, left_out: list[str] | None = None
) -> Iterator[tuple[dict[str, Any], dict[str, Any]]]:
    """The intact job files of a results folder, read only: (job, metrics) each, in the
    order of their names. A file whose checksum fails is skipped and its name appended to
    `left_out` (a later run of the experiment computes it again); a folder without a
    manifest is refused in one line."""
    root = Path(root).expanduser()
    if not (root / "manifest.json").is_file():
        raise UsageError(f"{root}: not a uavtrack results folder (no manifest.json)")
    for path in sorted((root / "raw").glob("*.json")):
        body: dict[str, Any] = {}
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
            body = {k: record[k] for k in ("job", "seconds", "metrics")}
            intact = checksum(body) == record["sha256"]
        except (OSError, ValueError, KeyError, TypeError):
            intact = False
        if intact:
            yield body["job"], body["metrics"]
        elif left_out is not None:
            left_out.append(path.name)
