"""What a process uavtrack runs (a command, a worker, a UAV program, a library entry
point) takes from its machine, read or set in this one place: its BLAS threads, the
memory available to it, and its end with the process that started it. Imports nothing
heavy: a program calls it before it loads numpy.

BLAS threads, set on ``import uavtrack``, for every command, worker, agent program and
library entry point:

uavtrack's arrays are small per call (a cycle of the default team is about 200 numpy
calls on 4 to 260 elements) or, for large teams, memory-bound; a second BLAS thread
then costs more in hand-off than it gains. On the 2-core development machine the
distributed cycle of 300 UAVs and 300 targets took 84 ms of CPU with one thread and
183 ms with two. So uavtrack runs BLAS on one thread unless told otherwise:

* ``UAVTRACK_BLAS_THREADS=n`` sets n threads; ``UAVTRACK_BLAS_THREADS=keep`` leaves
  BLAS as it is.
* A thread count already in the environment (``OMP_NUM_THREADS``,
  ``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS``, ...) is the user's choice and is kept.
* Otherwise, one thread. Before numpy loads this goes through the environment (so
  worker processes and agent programs inherit it); when numpy was loaded first, through
  threadpoolctl, for this process.

The end with its parent: a process started by uavtrack ends with the process that
started it, even when that one is killed with SIGKILL. Two ways, both cheap and both
needed: the kernel's parent-death signal on Linux (``prctl(PR_SET_PDEATHSIG)``, at
once), and a thread that checks every half second whether the parent changed (anywhere,
and for a parent that died before the signal was asked for).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

VARIABLE = "UAVTRACK_BLAS_THREADS"
THREAD_VARIABLES = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "BLIS_NUM_THREADS",
)
DEFAULT = 1


class ThreadsError(ValueError):
    """``UAVTRACK_BLAS_THREADS`` holds a value that cannot be used."""


state: dict[str, str | None] = {"how": None, "problem": None}


def wanted() -> int | None:
    """The thread count asked for: an int, or None to leave BLAS alone. Raises ThreadsError
    naming the variable for a value that is not a positive integer or 'keep'."""
    text = os.environ.get(VARIABLE)
    if text is None or not text.strip():
        return DEFAULT
    text = text.strip()
    if text.lower() == "keep":
        return None
    try:
        count = int(text)
    except ValueError:
        count = 0
    if count < 1:
        raise ThreadsError(
            f"{VARIABLE}={text!r}: give a positive number of threads, "
            "or 'keep' to leave BLAS as it is"
        )
    return count


def pin() -> str:
    """Set BLAS threads as the module docstring says; returns how it was done. Never
    raises: a bad ``UAVTRACK_BLAS_THREADS`` leaves BLAS alone and is reported by `check`."""
    try:
        count = wanted()
    except ThreadsError as exc:
        state["problem"] = str(exc)
        state["how"] = "not pinned (bad value)"
        return state["how"]
    given = [name for name in THREAD_VARIABLES if os.environ.get(name, "").strip()]
    if count is None:
        how = "kept (UAVTRACK_BLAS_THREADS=keep)"
    elif given and VARIABLE not in os.environ:
        how = f"kept ({given[0]}={os.environ[given[0]]})"
    elif "numpy" not in sys.modules:
        for name in THREAD_VARIABLES:
            os.environ[name] = str(count)
        how = f"{count} (environment)"
    else:
        how = _limit(count)
    state["how"] = how
    return how


def _limit(count: int) -> str:
    """Limit the loaded BLAS with threadpoolctl; the environment too, for child processes."""
    for name in THREAD_VARIABLES:
        os.environ[name] = str(count)
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return "not pinned (numpy was loaded first and threadpoolctl is missing)"
    threadpool_limits(count, user_api="blas")
    return f"{count} (threadpoolctl)"


def check() -> None:
    """Raise ThreadsError if ``UAVTRACK_BLAS_THREADS`` could not be used (the command
    line turns it into its one-line error)."""
    if state["problem"] is not None:
        raise ThreadsError(state["problem"])


def describe() -> str:
    """How BLAS threads were set in this process, for benchmark records."""
    return state["how"] or "not set"


PR_SET_PDEATHSIG = 1


def die_with(parent: int) -> None:
    """End this process when `parent` is gone, and now if it already is."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    except (OSError, AttributeError):  # not Linux: the watch alone
        pass
    if os.getppid() != parent:
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="uavtrack-parent-watch").start()


M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4
"""glibc's `mallopt` parameters."""

KEPT = {"trim": 512 * 2**20, "mappings": 0}
"""What `keep_freed_memory` asks of glibc's allocator: memory freed at the top of the
heap is kept up to `trim` bytes (by default 128 KiB, raised as large blocks come and
go), and no block gets a mapping of its own (by default every block above 128 KiB to
32 MiB, so every large temporary is fresh pages), so freed blocks serve the next ones."""

_kept: list[bool] = []


def keep_freed_memory() -> bool:
    """Ask glibc's allocator to keep freed memory for reuse instead of returning it to
    the kernel and mapping fresh pages for the next array (`KEPT`); once per process, for
    a run whose state is large (`simulation.run`). Each fresh page costs a fault and the
    kernel's zeroing: at 1000 x 1000 about 1,500 minor faults per step without this
    (with the run's full-size arrays reused), 56 with it (steps 5 to 19, mean), and a
    lower peak (961 MiB from 985). Whether it was set (False where the C library is not
    glibc)."""
    if _kept:
        return _kept[0]
    done = False
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None)
            mallopt = libc.mallopt
            done = bool(mallopt(M_MMAP_MAX, KEPT["mappings"])) and bool(
                mallopt(M_TRIM_THRESHOLD, KEPT["trim"])
            )
        except (OSError, AttributeError):  # not glibc
            done = False
    _kept.append(done)
    return done


def available_memory() -> int:
    """Bytes of memory available to new allocations (MemAvailable on Linux)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as info:
            for line in info:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return 2**62  # unknown: do not refuse
