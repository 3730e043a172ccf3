"""``python -m uavtrack.agents RUN PROGRAM``: one program of a swarm over Zenoh
(`uavtrack agent` is the documented way to start one by hand).

Its spec comes as one JSON line on standard input, read before anything heavy is
imported: the run, the program's number, the endpoints, Zenoh's options, the program's
key (`security.Credential`) and the pid of the process that started it. It ends with
that process: at once if it is already gone, otherwise as soon as it goes (the kernel's
parent-death signal where there is one, and a watch every half second).

``python -m uavtrack.agents --launcher FD PARENT``: the launcher `uavtrack swarm` starts,
which forks its programs (`launcher`); each runs `run_program` with its spec.
"""

import json
import sys

from .._process import die_with


def main() -> int:
    if len(sys.argv) == 4 and sys.argv[1] == "--launcher":
        from .launcher import main as launch

        return launch(int(sys.argv[2]), int(sys.argv[3]))
    try:
        spec = json.loads(sys.stdin.readline())
    except (ValueError, OSError):
        print("uavtrack.agents: expected the program's spec on standard input", file=sys.stderr)
        return 2
    return run_program(spec, int(spec["parent"]))


def run_program(spec: dict, parent: int) -> int:
    """Run one program with `spec` (see the module doc) until its run ends; it ends with
    process `parent`. Its exit code."""
    die_with(parent)
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
