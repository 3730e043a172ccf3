"""Command line: ``uavtrack run | compare | params | reproduce | sweep | animate |
bandwidth | bench | export | flight | realistic | replay | robustness | sensing | separation |
swarm | agent | trackers``, each in a module of its name (`app`: run, compare, params
and the shared options;
`experiments`: reproduce, sweep, animate; `benchmark`: bench; `swarm`: swarm, agent).

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
    realistic,
    replay,
    robustness,
    sensing,
    separation,
    swarm,
    trackers,
)
from .app import app, entry, main

__all__ = ["app", "entry", "main"]
