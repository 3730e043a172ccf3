"""``python -m uavtrack.agents RUN PROGRAM``: one program of a swarm over Zenoh, started
by `uavtrack swarm` (`uavtrack agent` is the documented way to start one by hand).

Its spec comes as one JSON line on standard input, read before anything heavy is
imported: the run, the program's number, the endpoints, Zenoh's options, the program's
key (`security.Credential`) and the pid of the process that started it. It ends with
that process: at once if it is already gone, otherwise as soon as it goes (the kernel's
parent-death signal where there is one, and a watch every half second).
"""

import json
import sys

from .._process import die_with


def main() -> int:
    try:
        spec = json.loads(sys.stdin.readline())
    except (ValueError, OSError):
        print("uavtrack.agents: expected the program's spec on standard input", file=sys.stderr)
        return 2
    die_with(int(spec["parent"]))
    from .program import serve
    from .security import Credential
    from .transport import ZenohOptions, ZenohTransport, zenoh_reason

    credential = Credential.from_json(spec["credential"]) if spec["credential"] else None
    options = ZenohOptions(**spec["zenoh"])
    try:  # this program's own TLS files, named if its peers would refuse them
        options.check(spec["connect"])
    except ValueError as exc:
        print(f"program {spec['program']}: {exc}", file=sys.stderr)
        return 2
    try:
        transport = ZenohTransport([], spec["connect"], options)
    except Exception as exc:  # the world is already gone, or its endpoint refuses
        print(f"program {spec['program']}: cannot join: {zenoh_reason(exc)}", file=sys.stderr)
        return 1
    try:
        served = serve(
            transport,
            spec["run"],
            int(spec["program"]),
            credential=credential,
            ros2=spec.get("ros2"),
        )
    except KeyboardInterrupt:
        return 130
    finally:
        transport.close()
    if served.end in ("done", "failed"):
        return 0
    at = f" at step {served.at}" if served.at >= 0 else ""
    why = f": {served.why}" if served.why else ""
    print(f"program {spec['program']}: {served.end}{at}{why}", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
