"""Executing job lists: an output folder that never loses work, and two engines.

The folder holds ``manifest.json`` (what the results were made with: scenario, plan,
seed, uavtrack version and a hash of its code) and one JSON file per finished job in
``raw/``, each written to a temporary file and renamed, so an interruption (Ctrl-C, a
killed worker, a full stop) loses only the jobs in flight. Running the same command
again skips the finished jobs. A job that raises is recorded in ``failed/`` with its
error and the others go on; it is retried on the next run. A folder made with a
different scenario, plan or code is refused rather than mixed.

Each job file names what it holds (job key, seed, scenario digest, code hash) and
carries a SHA-256 of its content. A file that does not match its job (edited,
truncated, copied from another folder) is never used: it is moved to ``failed/`` with
the reason and the job is computed again. One run at a time holds the folder: an
exclusive lock (``flock`` on ``.lock``, which records the holder's pid) is taken for the
whole run, and a second run on the same folder is refused.

Engines: ``local`` runs jobs in worker processes (joblib's loky executor); ``dask``
submits them to a Dask cluster (`--address`) or to a `LocalCluster` it starts. Results
always come back to this process, which writes them, so workers need no shared file
system. Local workers exit within a second if this process dies, even by SIGKILL.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import signal
import stat
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Generator, Sequence
from pathlib import Path
from typing import Any

from .. import __version__
from .._files import dumps, read_json, write_json
from .._progress import bar
from ..config import flatten
from ..errors import RunError, UsageError, install_hint
from ..io.results import checksum, read_jobs  # noqa: F401 (read_jobs: public here too)
from ..methods import registry
from .jobs import Job, run_job

LOCK = ".lock"


PRESENTATION = frozenset(
    {
        "_files.py",
        "_progress.py",
        "errors.py",
        "testing.py",
        "experiments/bench.py",
        "experiments/figures.py",
        "experiments/report.py",
        "experiments/robustness.py",
        "experiments/statistics.py",
        "experiments/store.py",
    }
)
"""Modules that do not change a job's numbers (reports, figures, storage), by their path
in the package; the command line (`cli/`) and the pictures (`viz/`) are left out too."""


def code_hash() -> str:
    """SHA-256 over the source files that compute results: results of other code are not
    mixed in, while a change to a report, a figure or the command line keeps them."""
    digest = hashlib.sha256()
    package = Path(__file__).parents[1]  # the uavtrack package
    for path in sorted(package.rglob("*.py")):
        name = path.relative_to(package).as_posix()
        if name in PRESENTATION or name.split("/")[0] in ("cli", "viz"):
            continue
        digest.update(name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


class Store:
    """An experiment folder: manifest, finished jobs in raw/, failures in failed/.

    Use it as a context manager: the folder is locked from opening to closing.
    """

    def __init__(self, root: str | Path, manifest: dict[str, Any]) -> None:
        self.root = Path(root)
        self.raw = self.root / "raw"
        self.failed = self.root / "failed"
        # as JSON holds it (tuples as lists), so a manifest read back compares equal
        self.manifest = json.loads(
            dumps({**manifest, "uavtrack": __version__, "code": code_hash()})
        )
        self.set_aside: list[tuple[str, str]] = []  # (job key, reason) of rejected files
        self._valid: dict[str, dict[str, Any]] = {}
        self._seconds: dict[str, float] = {}
        self._lock = None
        self._open()

    # ------------------------------------------------------------ opening

    def _open(self) -> None:
        root = self.root
        if root.exists() and not root.is_dir():
            raise UsageError(f"results folder {root} exists and is not a folder")
        path = root / "manifest.json"
        if root.is_dir() and not path.exists():
            foreign = [p.name for p in root.iterdir() if p.name not in (LOCK, "raw", "failed")]
            if foreign:
                raise UsageError(f"{root} is not empty and is not an uavtrack results folder")
        try:
            root.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UsageError(f"results folder {root}: cannot create it ({_reason(exc)})") from None
        self._lock = _take_lock(root)
        try:
            if path.exists():
                self._check_manifest(path)
            for folder in (self.root, self.raw, self.failed):
                _check_writable(folder)
            if not path.exists():
                write_json(path, self.manifest)
        except BaseException:
            self.close()
            raise

    def _check_manifest(self, path: Path) -> None:
        try:
            old = read_json(path)
            if not isinstance(old, dict):
                raise ValueError("not a manifest")
        except (OSError, ValueError) as exc:
            raise UsageError(f"{path} is unreadable ({_reason(exc)}); use another --out") from None
        problem = mismatch(old, self.manifest)
        if problem:
            raise UsageError(
                f"{self.root} holds results made with {problem}; "
                "use another --out or remove the folder"
            )

    def close(self) -> None:
        """Release the folder's lock; leave no empty failed/ and no lock file behind."""
        if self._lock is not None:
            try:
                self.failed.rmdir()  # only if empty
            except OSError:
                pass
            try:  # removed while held: a run that opened it meanwhile opens it again
                (self.root / LOCK).unlink()
            except OSError:
                pass
            self._lock.close()  # closing the descriptor releases the flock
            self._lock = None

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------ job files

    def path(self, job: Job) -> Path:
        return self.raw / f"{job.key}.json"

    def identity(self, job: Job) -> dict[str, Any]:
        """What a job file must name to be used for `job`."""
        return {
            **describe_job(job),
            "key": job.key,
            "scenario": job.scenario.digest(),
            "code": self.manifest["code"],
        }

    def done(self, job: Job) -> bool:
        """Whether a valid result of `job` is stored; an invalid file is set aside."""
        if job.key in self._valid:
            return True
        path = self.path(job)
        if not path.exists():
            return False
        problem, record = self._read(job, path)
        if problem:
            self._set_aside(job, path, problem)
            return False
        self._valid[job.key] = record["metrics"]
        self._seconds[job.key] = float(record["seconds"])
        return True

    def _read(self, job: Job, path: Path) -> tuple[str, dict[str, Any]]:
        """(problem, record): problem is '' when the file is `job`'s intact result."""
        try:
            record = read_json(path)
        except (OSError, ValueError) as exc:
            return f"unreadable ({_reason(exc)})", {}
        if not isinstance(record, dict) or set(record) != {"job", "seconds", "metrics", "sha256"}:
            return "not a job file of this uavtrack version", {}
        body = {k: record[k] for k in ("job", "seconds", "metrics")}
        try:
            if checksum(body) != record["sha256"]:
                return "its content does not match its checksum (edited or corrupted)", {}
        except (TypeError, ValueError):
            return "its content does not match its checksum (edited or corrupted)", {}
        expected = self.identity(job)
        for field in ("key", "seed", "first", "count", "method", "scenario", "code", "policy"):
            if record["job"].get(field) != expected.get(field):
                return (
                    f"it was made for another {field} ({record['job'].get(field)!r}, "
                    f"this job has {expected.get(field)!r})"
                ), {}
        return "", record

    def _set_aside(self, job: Job, path: Path, problem: str) -> None:
        """Move a job file that cannot be used to failed/, with the reason beside its
        content, so the job is computed again."""
        try:
            content = path.read_bytes().decode("utf-8", errors="replace")
        except OSError as exc:
            content = f"(unreadable: {_reason(exc)})"
        write_json(
            _unused(self.failed, f"{job.key}.rejected", ".json"),
            {"job": describe_job(job), "reason": problem, "content": content},
        )
        path.unlink()
        self.set_aside.append((job.key, problem))

    def save(self, job: Job, metrics: dict[str, Any], seconds: float) -> None:
        record = {"job": self.identity(job), "seconds": seconds, "metrics": metrics}
        body = json.loads(dumps(record))  # the plain JSON types the file will hold
        write_json(self.path(job), {**body, "sha256": checksum(body)})
        self._valid[job.key] = body["metrics"]
        self._seconds[job.key] = float(body["seconds"])
        (self.failed / f"{job.key}.json").unlink(missing_ok=True)

    def fail(self, job: Job, error: str) -> None:
        write_json(self.failed / f"{job.key}.json", {"job": describe_job(job), "error": error})

    def load(self, job: Job) -> dict[str, Any]:
        if not self.done(job):
            raise RunError(f"the result of job {job.key} is missing from {self.raw}")
        return self._valid[job.key]

    def seconds(self, job: Job) -> float:
        """The compute time a stored job took, whenever it ran."""
        self.load(job)
        return self._seconds[job.key]


def _unused(folder: Path, stem: str, suffix: str) -> Path:
    """``folder/stem.suffix``, or with -2, -3, ... before the suffix: a name not taken, so
    an earlier file is never replaced."""
    path, n = folder / f"{stem}{suffix}", 1
    while path.exists() or path.is_symlink():
        n += 1
        path = folder / f"{stem}-{n}{suffix}"
    return path


def _take_lock(root: Path):
    """Open and exclusively lock ``root/.lock`` (a regular file, never through a link);
    refuse if another process holds it. The lock is the file the path names once it is
    held: a lock file removed by its last holder between the open and the lock is
    opened again."""
    path = root / LOCK
    for _ in range(10):
        handle = _open_lock(root, path)
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno not in (errno.EWOULDBLOCK, errno.EACCES):
                handle.close()
                reason = _reason(exc)
                raise UsageError(f"results folder {root}: cannot lock it ({reason})") from None
            holder = os.pread(handle.fileno(), 32, 0).decode(errors="replace").strip()
            holder = holder or "unknown"
            handle.close()
            raise UsageError(
                f"results folder {root} is in use by another uavtrack run (pid {holder}); "
                "wait for it to finish or use another --out"
            ) from None
        try:
            current = os.stat(path, follow_symlinks=False)
        except FileNotFoundError:
            current = None
        held = os.fstat(handle.fileno())
        if current is not None and (current.st_ino, current.st_dev) == (held.st_ino, held.st_dev):
            break
        handle.close()  # its holder removed it as we opened it: take the new one
    else:
        raise UsageError(f"results folder {root}: cannot lock it (its lock file keeps changing)")
    try:  # unbuffered: a full disk shows here, with the folder's name
        os.ftruncate(handle.fileno(), 0)
        os.pwrite(handle.fileno(), str(os.getpid()).encode(), 0)
    except OSError as exc:
        handle.close()
        raise UsageError(f"results folder {root}: cannot write in it ({_reason(exc)})") from None
    return handle


def _open_lock(root: Path, path: Path):
    """The lock file, opened for reading and writing without following a link."""
    flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags, 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise UsageError(
                f"results folder {root}: {LOCK} is a symbolic link; uavtrack writes only its "
                "own lock file there (remove the link)"
            ) from None
        if exc.errno == errno.EISDIR:
            raise UsageError(f"results folder {root}: {LOCK} is not a regular file") from None
        raise UsageError(f"results folder {root}: cannot write in it ({_reason(exc)})") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise UsageError(f"results folder {root}: {LOCK} is not a regular file")
    return os.fdopen(fd, "rb+", buffering=0)


def _check_writable(folder: Path) -> None:
    """Create `folder` if needed and prove that files can be written in it (a probe file
    of a new name, created exclusively: never an existing file or a link's target)."""
    try:
        folder.mkdir(exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise UsageError(f"results folder {folder}: cannot write in it ({_reason(exc)})") from None


def _reason(exc: BaseException) -> str:
    return exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)


def describe_job(job: Job) -> dict[str, Any]:
    """What a job file names of its job; a learned policy's by its file's digest too,
    so that a result of another file of that name is not taken."""
    out: dict[str, Any] = {
        "kind": job.kind,
        "label": job.label,
        "method": job.method,
        "first": job.first,
        "count": job.count,
        "seed": job.seed,
    }
    if job.method.startswith(registry.POLICY):
        from ..env.policy import digest

        out["policy"] = digest(job.method)
    return out


def mismatch(old: dict[str, Any], new: dict[str, Any]) -> str:
    """What differs between two manifests, in words ('' when they agree)."""
    if old.get("code") != new.get("code"):
        return f"different uavtrack code (version {old.get('uavtrack')}, code {old.get('code')})"
    for section in ("kind", "seed"):
        if old.get(section) != new.get(section):
            return f"a different {section} ({old.get(section)!r}, now {new.get(section)!r})"
    for section in ("plan", "scenario"):
        was, now = flatten(old.get(section) or {}), flatten(new.get(section) or {})
        diffs = [
            f"{k} {was.get(k)!r}, now {now.get(k)!r}"
            for k in sorted(was.keys() | now.keys())
            if was.get(k) != now.get(k)
        ]
        if diffs:
            more = f" and {len(diffs) - 3} more" if len(diffs) > 3 else ""
            return f"a different {section} ({'; '.join(diffs[:3])}{more})"
    return ""


# ------------------------------------------------------------------ execution


def guarded(job: Job) -> tuple[str, dict[str, Any] | None, str | None, float]:
    """run_job that reports an exception instead of raising it (runs on workers)."""
    start = time.perf_counter()
    try:
        return job.key, run_job(job), None, time.perf_counter() - start
    except Exception:  # a failed job is recorded; the others go on
        return job.key, None, traceback.format_exc(limit=8), time.perf_counter() - start


class EngineError(RunError):
    """The engine lost a worker or its cluster; finished jobs are saved."""


def exit_with_parent(parent: int) -> None:
    """Worker initialiser: end this process once `parent` is gone, even by SIGKILL
    (`lifeline.die_with`); Ctrl-C is the parent's to handle."""
    from .._process import die_with

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with(parent)


def local_engine(jobs: Sequence[Job], workers: int) -> Generator[tuple, None, None]:
    """Run jobs in worker processes; yield results as they finish.

    At most two jobs per worker are queued at a time, so an interruption finds little to
    cancel; it stops the workers at once (they ignore Ctrl-C, which is this process's).
    """
    if workers == 1:
        for job in jobs:
            yield guarded(job)
        return
    from concurrent.futures import FIRST_COMPLETED, wait

    from joblib.externals.loky import get_reusable_executor
    from joblib.externals.loky.process_executor import TerminatedWorkerError

    executor = get_reusable_executor(
        max_workers=workers, timeout=30, initializer=exit_with_parent, initargs=(os.getpid(),)
    )
    waiting, running = list(reversed(jobs)), set()
    try:
        while waiting or running:
            while waiting and len(running) < 2 * workers:
                running.add(executor.submit(guarded, waiting.pop()))
            done, running = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                try:
                    yield future.result()
                except TerminatedWorkerError as exc:
                    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
                    raise EngineError(f"a worker process died ({lines[-1]})") from None
    finally:
        if running:  # interrupted or failed: stop the workers now
            _stop(executor)


def stop_workers() -> None:
    """Stop the local engine's idle workers, if any (a command interrupted after its jobs
    finished: its workers would otherwise outlive it, their semaphores reported leaked)."""
    import sys

    module = sys.modules.get("joblib.externals.loky.reusable_executor")
    executor = getattr(module, "_executor", None) if module is not None else None
    if executor is not None:
        _stop(executor)


def _stop(executor) -> None:
    """Kill the executor's workers. Its manager thread may report the jobs it loses
    as it goes down; those reports are expected here and are not shown."""
    hook = threading.excepthook

    def quiet(args) -> None:
        if args.thread is None or "ExecutorManager" not in args.thread.name:
            hook(args)

    threading.excepthook = quiet
    try:
        executor.shutdown(wait=True, kill_workers=True)
    finally:
        threading.excepthook = hook


def check_scheduler(address: str, timeout: float = 5.0) -> None:
    """Refuse at once a Dask scheduler address that nothing answers (tcp:// or tls://)."""
    import socket
    from urllib.parse import urlsplit

    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme not in ("tcp", "tls"):
        return  # other transports are left to Dask
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        host, port = None, None
    if not host or not port:
        raise UsageError(f"--address {address}: expected tcp://HOST:PORT")
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise UsageError(
            f"--address {address}: no Dask scheduler answers there ({reason})"
        ) from None


def dask_engine(
    jobs: Sequence[Job], workers: int, address: str | None
) -> Generator[tuple, None, None]:
    """Run jobs on a Dask cluster (or a LocalCluster of `workers` processes)."""
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise UsageError(f"--engine dask needs Dask: {install_hint('dask')}") from None
    if address:
        try:
            cluster, client = None, Client(address, timeout="10s")
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            reason = " ".join(str(exc).split()) or type(exc).__name__
            raise UsageError(
                f"--address {address}: no Dask scheduler answers there ({reason[:160]})"
            ) from None
    else:
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,  # pyright: ignore[reportArgumentType] (None: no dashboard)
            death_timeout=60,  # a loaded machine starts a worker slowly; orphans end by
            # themselves within seconds of this process, whatever it is
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
    progress: bool | None = True,
    on_result: Callable[[Job], None] | None = None,
) -> tuple[int, list[Job]]:
    """Run the jobs not yet in the store. Returns (jobs skipped, jobs that failed)."""
    workers = workers or available_cores()
    todo = [job for job in jobs if not store.done(job)]
    skipped = len(jobs) - len(todo)
    by_key = {job.key: job for job in todo}
    failed: list[Job] = []
    if not todo:
        return skipped, failed
    workers = min(workers, len(todo))
    stream = (
        local_engine(todo, workers) if engine == "local" else dask_engine(todo, workers, address)
    )
    try:
        with bar(len(jobs), "jobs", "jobs", enabled=progress, completed=skipped) as advance:
            for key, metrics, error, seconds in stream:
                job = by_key[key]
                if error is None:
                    try:
                        store.save(job, metrics, seconds)
                    except OSError as exc:
                        raise RunError(
                            f"cannot save job {job.key} in {store.raw}: {_reason(exc)}"
                        ) from None
                else:
                    store.fail(job, error)
                    failed.append(job)
                advance(1)
                if on_result is not None:
                    on_result(job)
    finally:
        stream.close()  # stops the workers when leaving early
    return skipped, failed


def available_cores() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def resolve_workers(requested: int | None) -> tuple[int, str]:
    """Workers to start, at most the cores available, and a note when capped."""
    cores = available_cores()
    if requested is None:
        return cores, ""
    if requested > cores:
        return cores, f"--workers {requested} capped at {cores}, the cores available"
    return requested, ""
