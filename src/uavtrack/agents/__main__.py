"""``python -m uavtrack.agents RUN PROGRAM ENDPOINT [LISTEN]``: one program of a swarm
over Zenoh (started by `uavtrack swarm`; `uavtrack agent` is the documented way)."""

import os
import sys

from .program import serve
from .swarm import watch_parent
from .transport import ZenohTransport


def main(argv: list[str]) -> int:
    run, me, endpoint = argv[0], int(argv[1]), argv[2]
    listen = argv[3] if len(argv) > 3 else "tcp/127.0.0.1:0"
    watch_parent(os.getppid())
    transport = ZenohTransport([listen], [endpoint])
    try:
        served = serve(transport, run, me)
    except KeyboardInterrupt:
        return 130
    finally:
        transport.close()
    return 0 if served.end in ("done", "failed") else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
