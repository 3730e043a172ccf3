"""Whether this process was stopped: SIGSTOP, a suspended machine, a debugger.

While a process is stopped none of its threads runs, and nothing it owes the network
goes out: no Zenoh keep-alive, no answer. Its peers see it silent; past the Zenoh
session's lease (`transport.LEASE`) they close their sessions with it, and their
clients connect again as soon as it answers (Zenoh retries every 1 to 4 s). Whatever
was in flight on a closed session is gone. A process that was stopped must not take
what follows (tokens gone, reports that do not come) for its peers' faults.

A daemon thread ticks every `TICK` seconds; a tick that comes `SLACK` seconds or more
late means that the process did not run meanwhile: it was stopped, or starved on an
overloaded machine, which does the same to its sessions. `Stops.resumed` is when the
last such stop ended (monotonic clock) and `Stops.seconds` how long it lasted.
"""

from __future__ import annotations

import threading
import time

TICK = 0.1
"""Seconds between two ticks of the watching thread."""
SLACK = 1.0
"""Seconds a tick may come late before the process counts as having been stopped."""


class Stops:
    """The stops of this process (see the module docstring); `watch` starts the thread."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.resumed: float | None = None
        self.seconds = 0.0
        self._thread: threading.Thread | None = None

    def saw(self, seconds: float, now: float) -> None:
        """A stop of `seconds` seconds ended at `now` (monotonic clock)."""
        with self.lock:
            if self.resumed is None or now >= self.resumed:
                self.resumed, self.seconds = now, seconds

    def since(self, moment: float) -> bool:
        """Whether a stop ended at or after `moment` (monotonic clock)."""
        with self.lock:
            return self.resumed is not None and self.resumed >= moment

    def tick(self, last: float, now: float) -> None:
        """The thread's tick at `now`, the previous one at `last`."""
        late = now - last - TICK
        if late >= SLACK:
            self.saw(late, now)

    def watch(self) -> Stops:
        """Start the watching thread, once per process; returns self."""
        with self.lock:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="stops", daemon=True)
                self._thread.start()
        return self

    def _run(self) -> None:
        last = time.monotonic()
        while True:
            time.sleep(TICK)
            now = time.monotonic()
            self.tick(last, now)
            last = now


STOPS = Stops()
"""This process's stops."""
