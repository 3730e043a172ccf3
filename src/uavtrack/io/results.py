"""A results folder of `uavtrack reproduce`, `sweep`, `robustness` or `trackers`, read
only: each finished job file (``raw/*.json``: the job, its seconds and its per-trial
metrics, with the SHA-256 of their canonical JSON) that is intact. The folder itself is
written by `uavtrack.experiments.store`; `tables` reads it through here.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from .._files import read_json
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
    `left_out` (a later run of the experiment computes it again). Refused in one line: a
    folder whose manifest is missing or unreadable, and an intact job file under another
    job's name (a copy: its trials would be counted twice, the other job's not at all)."""
    root = Path(root).expanduser()
    manifest(root)
    for path in sorted((root / "raw").glob("*.json")):
        body: dict[str, Any] = {}
        try:
            record = read_json(path)
            body = {k: record[k] for k in ("job", "seconds", "metrics")}
            intact = checksum(body) == record["sha256"]
        except (OSError, ValueError, KeyError, TypeError):
            intact = False
        if not intact:
            if left_out is not None:
                left_out.append(path.name)
            continue
        key = body["job"].get("key") if isinstance(body["job"], dict) else None
        if key != path.stem:
            raise UsageError(
                f"{path}: holds the result of job {str(key)[:120]!r}, not of the job its name "
                "says (a copy under another name?); move it away and run the experiment again"
            )
        yield body["job"], body["metrics"]


def manifest(root: str | Path) -> dict[str, Any]:
    """A results folder's manifest (what its results were made with), refused in one
    line when it is missing, not JSON, or holds no scenario that uavtrack reads."""
    from ..config import Scenario, ScenarioError

    path = Path(root).expanduser() / "manifest.json"
    if not os.path.lexists(path):
        raise UsageError(f"{path.parent}: not a uavtrack results folder (no manifest.json)")
    try:
        data = read_json(path)
        if not isinstance(data, dict) or not isinstance(data.get("scenario"), dict):
            raise ValueError("no scenario in it")
        Scenario.from_dict(data["scenario"], origin="its scenario")
    except (OSError, UnicodeDecodeError, ValueError, ScenarioError) as exc:
        raise UsageError(f"{path}: cannot be read ({str(exc)[:200]})") from None
    return data
