"""Executing job lists: an output folder that never loses work, and two engines.

The folder holds ``manifest.json`` (what the results were made with: scenario, plan,
seed, uavtrack version and a hash of its code) and one JSON file per finished job in
``raw/``, each written to a temporary file and renamed, so an interruption (Ctrl-C, a
killed worker, a full stop) loses only the jobs in flight. Running the same command
again skips the finished jobs. A job that raises is recorded in ``failed/`` with its
error and the others go on; it is retried on the next run. A folder made with a
different scenario, plan or code is refused rather than mixed.

Engines: ``local`` runs jobs in joblib worker processes; ``dask`` submits them to a
Dask cluster (`--address`) or to a `LocalCluster` it starts. Results always come back
to this process, which writes them, so workers need no shared file system.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from ._version import __version__
from .config import ScenarioError
from .experiments import Job, run_job
from .files import write_json


def code_hash() -> str:
    """SHA-256 over the package's source files: results of other code are not mixed in."""
    digest = hashlib.sha256()
    package = Path(__file__).parent
    for path in sorted(package.rglob("*.py")):
        digest.update(path.relative_to(package).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


class Store:
    """An experiment folder: manifest, finished jobs in raw/, failures in failed/."""

    def __init__(self, root: Path, manifest: dict[str, Any]) -> None:
        self.root = Path(root)
        self.raw = self.root / "raw"
        self.failed = self.root / "failed"
        self.manifest = {**manifest, "uavtrack": __version__, "code": code_hash()}
        path = self.root / "manifest.json"
        if path.exists():
            try:
                old = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                raise ScenarioError(f"{path} is unreadable ({exc}); use another --out") from None
            problem = mismatch(old, self.manifest)
            if problem:
                raise ScenarioError(
                    f"{self.root} holds results made with {problem}; "
                    "use another --out or remove the folder"
                )
        elif self.root.exists() and any(self.root.iterdir()):
            raise ScenarioError(f"{self.root} is not empty and is not an uavtrack results folder")
        self.raw.mkdir(parents=True, exist_ok=True)
        self.failed.mkdir(exist_ok=True)
        if not path.exists():
            write_json(path, self.manifest)

    def path(self, job: Job) -> Path:
        return self.raw / f"{job.key}.json"

    def done(self, job: Job) -> bool:
        return self.path(job).exists()

    def save(self, job: Job, metrics: dict[str, Any], seconds: float) -> None:
        write_json(
            self.path(job), {"job": describe_job(job), "seconds": seconds, "metrics": metrics}
        )
        (self.failed / f"{job.key}.json").unlink(missing_ok=True)

    def fail(self, job: Job, error: str) -> None:
        write_json(self.failed / f"{job.key}.json", {"job": describe_job(job), "error": error})

    def load(self, job: Job) -> dict[str, Any]:
        return json.loads(self.path(job).read_text(encoding="utf-8"))["metrics"]


def describe_job(job: Job) -> dict[str, Any]:
    return {
        "kind": job.kind,
        "label": job.label,
        "method": job.method,
        "first": job.first,
        "count": job.count,
        "seed": job.seed,
    }


def mismatch(old: dict[str, Any], new: dict[str, Any]) -> str:
    """What differs between two manifests, in words ('' when they agree)."""
    if old.get("code") != new.get("code"):
        return f"different uavtrack code (version {old.get('uavtrack')}, code {old.get('code')})"
    for section in ("kind", "seed"):
        if old.get(section) != new.get(section):
            return f"a different {section} ({old.get(section)!r}, now {new.get(section)!r})"
    for section in ("plan", "scenario"):
        was, now = _flat(old.get(section) or {}), _flat(new.get(section) or {})
        diffs = [
            f"{k} {was.get(k)!r}, now {now.get(k)!r}"
            for k in sorted(was.keys() | now.keys())
            if was.get(k) != now.get(k)
        ]
        if diffs:
            more = f" and {len(diffs) - 3} more" if len(diffs) > 3 else ""
            return f"a different {section} ({'; '.join(diffs[:3])}{more})"
    return ""


def _flat(data: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out = {}
    for key, value in data.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


# ------------------------------------------------------------------ execution


def guarded(job: Job) -> tuple[str, dict[str, Any] | None, str | None, float]:
    """run_job that reports an exception instead of raising it (runs on workers)."""
    start = time.perf_counter()
    try:
        return job.key, run_job(job), None, time.perf_counter() - start
    except Exception:  # a failed job is recorded; the others go on
        return job.key, None, traceback.format_exc(limit=8), time.perf_counter() - start


class EngineError(RuntimeError):
    """The engine lost a worker or its cluster; finished jobs are saved."""


def local_engine(jobs: Sequence[Job], workers: int) -> Iterator[tuple]:
    """Run jobs in joblib worker processes; yield results as they finish."""
    if workers == 1:
        for job in jobs:
            yield guarded(job)
        return
    from joblib import Parallel, delayed
    from joblib.externals.loky.process_executor import TerminatedWorkerError

    try:
        yield from Parallel(n_jobs=workers, return_as="generator_unordered")(
            delayed(guarded)(job) for job in jobs
        )
    except TerminatedWorkerError as exc:
        raise EngineError(f"a worker process died ({str(exc).splitlines()[-2].strip()})") from None


def dask_engine(jobs: Sequence[Job], workers: int, address: str | None) -> Iterator[tuple]:
    """Run jobs on a Dask cluster (or a LocalCluster of `workers` processes)."""
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise ScenarioError('--engine dask needs Dask: pip install "uavtrack[dask]"') from None
    if address:
        cluster, client = None, Client(address, timeout="20s")
    else:
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
        )
        client = Client(cluster)
    from distributed.scheduler import KilledWorker

    try:
        futures = [
            client.submit(guarded, job, key=f"uavtrack-{job.key}", pure=False) for job in jobs
        ]
        for future in as_completed(futures):
            try:
                yield future.result()
            except KilledWorker as exc:
                raise EngineError(f"Dask workers died running {exc.task}") from None
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def execute(
    jobs: Sequence[Job],
    store: Store,
    engine: str = "local",
    workers: int | None = None,
    address: str | None = None,
    progress: bool = True,
    on_result: Callable[[Job], None] | None = None,
) -> tuple[int, list[Job]]:
    """Run the jobs not yet in the store. Returns (jobs skipped, jobs that failed)."""
    workers = workers or default_workers()
    todo = [job for job in jobs if not store.done(job)]
    skipped = len(jobs) - len(todo)
    by_key = {job.key: job for job in todo}
    failed: list[Job] = []
    if not todo:
        return skipped, failed
    stream = (
        local_engine(todo, workers) if engine == "local" else dask_engine(todo, workers, address)
    )
    with _progress(progress, len(jobs), skipped) as advance:
        for key, metrics, error, seconds in stream:
            job = by_key[key]
            if error is None:
                store.save(job, metrics, seconds)
            else:
                store.fail(job, error)
                failed.append(job)
            advance()
            if on_result is not None:
                on_result(job)
    return skipped, failed


def default_workers() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


class _progress:
    """A rich progress bar: jobs done of total, rate, time left (a no-op when disabled)."""

    def __init__(self, enabled: bool, total: int, done: int) -> None:
        self.enabled, self.total, self.done = enabled, total, done

    def __enter__(self) -> Callable[[], None]:
        if not self.enabled:
            return lambda: None
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self.bar = Progress(
            TextColumn("[bold]jobs"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[rate]}"),
            TextColumn("elapsed"),
            TimeElapsedColumn(),
            TextColumn("left"),
            TimeRemainingColumn(),
            transient=False,
        )
        self.bar.start()
        self.task = self.bar.add_task("jobs", total=self.total, completed=self.done, rate="")
        self.start, self.fresh = time.perf_counter(), 0

        def advance() -> None:
            self.fresh += 1
            rate = self.fresh / max(time.perf_counter() - self.start, 1e-9)
            self.bar.update(self.task, advance=1, rate=f"{rate:.2f} jobs/s")

        return advance

    def __exit__(self, *exc) -> None:
        if self.enabled:
            self.bar.stop()
