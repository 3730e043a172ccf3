"""A process started by uavtrack (a worker, a UAV program) ends with the process that
started it, even when that one is killed with SIGKILL.

Two ways, both cheap and both needed: the kernel's parent-death signal on Linux
(``prctl(PR_SET_PDEATHSIG)``, at once), and a thread that checks every half second
whether the parent changed (anywhere, and for a parent that died before the signal was
asked for). Imports nothing heavy: a program calls it before it loads numpy.
"""

from __future__ import annotations

import os
import signal
import threading
import time

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
