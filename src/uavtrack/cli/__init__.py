"""Command line: ``uavtrack run | compare | reproduce | sweep | robustness | flight | swarm |
agent | animate | bench | params``.

Exit codes: 0 done; 1 the run failed (finished work is kept); 2 bad input (one line
``uavtrack: error: ...`` on stderr, nothing computed, nothing written); 130
interrupted (Ctrl-C; finished work is kept, no partial file is left); 143 the same
after SIGTERM.
"""

from . import (  # noqa: F401
    bandwidth,
    benchmark,
    experiments,
    export,
    flight,
    robustness,
    sensing,
    separation,
    swarm,
    trackers,
)
from .app import app, entry, main

__all__ = ["app", "entry", "main"]
