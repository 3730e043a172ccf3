"""``python -m uavtrack.agents RUN PROGRAM``: one program of a swarm over Zenoh
(`uavtrack agent` is the documented way to start one by hand).

Its spec comes as one JSON line on standard input, read before anything heavy is
imported: the run, the program's number, the endpoints, Zenoh's options, the program's
key (`security.Credential`) and the pid of the process that started it. It ends with
that process: at once if it is already gone, otherwise as soon as it goes (the kernel's
parent-death signal where there is one, and a watch every half second).

``python -m uavtrack.agents --launcher FD PARENT``: the launcher `uavtrack swarm` starts,
which forks its programs; each runs `launcher.run_program` with its spec, as this
module does.
"""

import json
import sys

from .launcher import main as launch
from .launcher import run_program


def main() -> int:
    if len(sys.argv) == 4 and sys.argv[1] == "--launcher":
        return launch(int(sys.argv[2]), int(sys.argv[3]))
    try:
        spec = json.loads(sys.stdin.readline())
    except (ValueError, OSError):
        print("uavtrack.agents: expected the program's spec on standard input", file=sys.stderr)
        return 2
    return run_program(spec, int(spec["parent"]))


if __name__ == "__main__":
    sys.exit(main())
