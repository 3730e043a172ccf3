"""`uavtrack swarm` and `uavtrack agent`: the cycle as separate programs exchanging messages."""

from __future__ import annotations

import os
import re
import sys
from contextlib import contextmanager, nullcontext
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from .._files import check_distinct, check_output
from ..errors import Interrupted, RunError, UsageError, install_hint
from .app import (
    DISTRIBUTED,
    BagOpt,
    ConfigOpt,
    ForceOpt,
    MethodOpt,
    Ros2Opt,
    SeedOpt,
    SetOpt,
    TeamOpt,
    TrialStepsOpt,
    app,
    check_bag,
    load_scenario,
    show,
    source_of,
    steps_bar,
    with_steps,
)


class TransportName(StrEnum):
    memory = "memory"
    zenoh = "zenoh"


ZenohConfigOpt = Annotated[
    Path | None,
    typer.Option(
        "--zenoh-config",
        metavar="FILE",
        help="zenoh: a Zenoh configuration file (JSON5, Zenoh's own format) to start from",
    ),
]
TlsCaOpt = Annotated[
    Path | None,
    typer.Option(
        "--tls-ca", metavar="FILE", help="zenoh: the CA certificate (PEM) of the swarm's TLS"
    ),
]
TlsCertOpt = Annotated[
    Path | None,
    typer.Option("--tls-cert", metavar="FILE", help="zenoh: this host's TLS certificate (PEM)"),
]
TlsKeyOpt = Annotated[
    Path | None,
    typer.Option("--tls-key", metavar="FILE", help="zenoh: this host's TLS private key (PEM)"),
]


def zenoh_options(config, ca, cert, key, endpoints: list[str]):
    """The Zenoh options of the command line, checked: readable files, the three TLS
    files together, a tls/ endpoint only with them (or a configuration file), no clear
    endpoint with them, and TLS files this host's peers would accept (in date, the
    certificate the CA's, the key the certificate's and private: `agents.tls`)."""
    from ..agents.transport import ZenohOptions

    for option, path in (
        ("--zenoh-config", config),
        ("--tls-ca", ca),
        ("--tls-cert", cert),
        ("--tls-key", key),
    ):
        if path is not None and not path.is_file():
            raise UsageError(f"{option}: {path} is not a file")
        if path is not None and not os.access(path, os.R_OK):
            raise UsageError(f"{option}: {path} cannot be read")
    tls = [p for p in (ca, cert, key) if p is not None]
    if tls and len(tls) < 3:
        raise UsageError("TLS needs all three of --tls-ca, --tls-cert and --tls-key")
    if not tls and config is None and any(e.strip().startswith("tls/") for e in endpoints):
        raise UsageError(
            "a tls/ endpoint needs --tls-ca, --tls-cert and --tls-key (or a --zenoh-config "
            "that sets Zenoh's TLS files)"
        )
    absolute = lambda p: None if p is None else str(p.expanduser().resolve())  # noqa: E731
    options = ZenohOptions(absolute(config), absolute(ca), absolute(cert), absolute(key))
    try:
        options.check(endpoints)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if options.config is not None:
        try:
            import zenoh

            zenoh.Config.from_file(options.config)
        except ImportError:
            pass  # said by the transport
        except Exception as exc:
            from ..agents.transport import zenoh_reason

            raise UsageError(f"--zenoh-config: {config}: {zenoh_reason(exc)}") from None
    return options


@contextmanager
def results_only_on_stdout():
    """Keep this process's standard output for its result while Zenoh runs: what native
    code (Zenoh's log) writes to file descriptor 1 goes to standard error instead.
    (Nothing to do when Python's stdout is not file descriptor 1, as under a test's
    capture.)"""
    if sys.stdout is not sys.__stdout__:
        yield
        return
    try:
        sys.stdout.flush()
        saved = os.dup(1)
        os.dup2(2, 1)
    except (OSError, ValueError):
        yield
        return
    original = sys.stdout
    sys.stdout = os.fdopen(saved, "w", encoding=original.encoding or "utf-8", closefd=False)
    try:
        yield
    finally:
        try:
            sys.stdout.flush()
        finally:
            sys.stdout = original
            os.dup2(saved, 1)
            os.close(saved)


@app.command()
def swarm(
    config: ConfigOpt = None,
    method: MethodOpt = DISTRIBUTED,
    seed: SeedOpt = 0,
    set_: SetOpt = None,
    team: TeamOpt = None,
    steps: TrialStepsOpt = None,
    transport: Annotated[
        TransportName,
        typer.Option(
            metavar="TRANSPORT",
            help="memory (threads of this process) or zenoh (one process per UAV)",
        ),
    ] = TransportName.memory,
    realtime: Annotated[
        bool, typer.Option("--realtime", help="pace cycles at the time step dt; report overruns")
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="print one JSON object")] = False,
    trace: Annotated[
        Path | None,
        typer.Option("--trace", metavar="FILE", help="write the per-step trace to FILE (.npz)"),
    ] = None,
    bag: BagOpt = None,
    force: ForceOpt = False,
    ros2: Ros2Opt = None,
    listen: Annotated[
        str | None,
        typer.Option(
            metavar="ENDPOINT",
            help="zenoh: the world's endpoint [tcp/127.0.0.1 and a free port; tls/ with TLS]",
        ),
    ] = None,
    connect: Annotated[
        list[str] | None,
        typer.Option(metavar="ENDPOINT", help="zenoh: also connect to this endpoint (repeatable)"),
    ] = None,
    spawn: Annotated[
        bool,
        typer.Option(
            "--spawn/--no-spawn",
            help="zenoh: start the UAV programs here, or wait for them (uavtrack agent)",
        ),
    ] = True,
    sign: Annotated[
        bool,
        typer.Option(
            "--sign/--no-sign",
            help="authenticate every message: only the run's programs can speak in it",
        ),
    ] = True,
    keys: Annotated[
        Path | None,
        typer.Option(
            "--keys",
            metavar="DIR",
            help="with --no-spawn: write each program's key file here (removed at the end)",
        ),
    ] = None,
    zenoh_config: ZenohConfigOpt = None,
    tls_ca: TlsCaOpt = None,
    tls_cert: TlsCertOpt = None,
    tls_key: TlsKeyOpt = None,
    deadline: Annotated[
        float,
        typer.Option(min=0.05, max=60, metavar="S", help="seconds a round waits for messages"),
    ] = 2.0,
    recording: Annotated[
        Path | None,
        typer.Option(
            "--recording",
            metavar="FOLDER",
            help="tell each UAV program its scans and pose from a recording (as uavtrack "
            "replay reads it) in place of the world's truth; the trace equals the replay's",
        ),
    ] = None,
) -> None:
    """Run one trial as a swarm: a world program and one program per UAV exchanging
    messages; prints and writes what `uavtrack run` does."""
    from ..methods import get

    record = None
    source = source_of(config, set_, team)
    if recording is not None:
        if team is not None or steps is not None:
            raise UsageError("--team and --steps: the recording sets them; leave them out")
        from .replay import recorded

        record, scenario, given = recorded(recording, config, set_, "--recording")
        source = source_of(given, set_, None)
    else:
        scenario = with_steps(load_scenario(config, set_, team), steps, set_)
    if trace is not None:
        check_output(trace, "--trace", force)
    check_distinct({"--trace": trace, "--bag": bag})
    check_bag(bag, force)
    zenoh_given = [zenoh_config, tls_ca, tls_cert, tls_key, keys]
    if transport == TransportName.memory and (
        listen is not None or connect or not spawn or any(x is not None for x in zenoh_given)
    ):
        raise UsageError(
            "--listen, --connect, --no-spawn, --keys, --zenoh-config and --tls-* need "
            "--transport zenoh"
        )
    if not spawn and sign and keys is None:
        raise UsageError(
            "--no-spawn with signed messages needs --keys DIR, a folder for the programs' "
            "key files (or --no-sign)"
        )
    if keys is not None and (spawn or not sign):
        raise UsageError("--keys is for --no-spawn with signed messages")
    if keys is not None and not keys.is_dir():
        raise UsageError(f"--keys: {keys} is not a directory")
    options = zenoh_options(
        zenoh_config, tls_ca, tls_cert, tls_key, [listen or "", *(connect or [])]
    )
    n = scenario.n_uavs
    central = get(method.value).central
    from ..agents import run_swarm

    if not spawn:
        programs = f"{n} UAV programs (0 to {n - 1})" + (
            f" and the central node (program {n})" if central else ""
        )
        typer.echo(
            f"waiting for {programs}: start each with uavtrack agent (the run id and "
            f"endpoint follow); the run starts when all have joined, within "
            f"{30 + 4 * (n + central)} s",
            err=True,
        )
    quiet = results_only_on_stdout() if transport == TransportName.zenoh else nullcontext()
    with quiet, steps_bar(scenario, label="cycles") as advance:
        out = run_swarm(
            scenario,
            method.value,
            seed,
            transport.value,
            deadline=deadline,
            listen=listen,
            connect=tuple(connect or ()),
            spawn=spawn,
            realtime=realtime,
            trace=trace is not None or bag is not None,
            progress=lambda _: advance(1),
            announce=_ros2_announcer(ros2, n, scenario.n_targets, scenario.tracker.unlabelled)
            if spawn
            else _announcer(n + central, sign, options.tls, ros2),
            sign=sign,
            keys=keys,
            zenoh=options,
            ros2=ros2,
            recording=record,
        )
    import numpy as np  # not at import: `uavtrack bench` pins BLAS threads first

    traffic = out.traffic
    check_not_all_lost(traffic, n + central)
    cycles = max(len(traffic.cycle_seconds), 1)
    uavs = scenario.n_uavs
    seconds = np.array(traffic.cycle_seconds or [0.0])
    swarm_info = {
        "transport": out.transport,
        "run": out.run,
        "signed": sign,
        "cycle_ms_median": 1e3 * float(np.median(seconds)),
        "cycle_ms_p90": 1e3 * float(np.percentile(seconds, 90)),
        "cycle_ms_max": 1e3 * float(seconds.max()),
        "published_per_uav_cycle": traffic.published / (uavs * cycles),
        "received_per_uav_cycle": traffic.received / (uavs * cycles),
        "bytes_per_uav_cycle": traffic.bytes / (uavs * cycles),
        "overruns": traffic.overruns if realtime else None,
        "failed": {str(k): v for k, v in traffic.failed.items()},
        "lost": {str(k): v for k, v in traffic.lost.items()},
        "lost_why": {str(k): v for k, v in traffic.why.items()},
        "dropped_messages": traffic.dropped,
        "dropped_by_reason": dict(sorted(traffic.drops.items())),
        "late_messages": sum(traffic.late.values()),
        "late_by_protocol": dict(sorted(traffic.late.items())),
        "late_from_step": traffic.late_from if traffic.late else None,
    }
    rows = [
        ("transport", out.transport + ("" if sign else ", messages not signed")),
        (
            "cycle wall time, median / 90th percentile / max [ms]",
            f"{swarm_info['cycle_ms_median']:.1f} / {swarm_info['cycle_ms_p90']:.1f} / "
            f"{swarm_info['cycle_ms_max']:.1f}",
        ),
        (
            "messages published / received per UAV and cycle",
            f"{swarm_info['published_per_uav_cycle']:.1f} / "
            f"{swarm_info['received_per_uav_cycle']:.1f}",
        ),
        ("bytes published per UAV and cycle", f"{swarm_info['bytes_per_uav_cycle']:.0f}"),
    ]
    if realtime:
        rows.append(("cycles longer than dt (--realtime)", f"{len(traffic.overruns)} of {cycles}"))
    lost = {
        (f"{k} (central node)" if central and k == n else str(k)): v
        for k, v in traffic.lost.items()
    }
    if traffic.failed:
        found = ", ".join(f"{k}: {v}" for k, v in traffic.failed.items())
        rows.append(("UAVs failed by the fault model (uav: step)", found))
    for (name, k), program in zip(lost.items(), traffic.lost, strict=True):
        rows.append((f"program {name} lost at step {k}", traffic.why.get(program, "")))
    if traffic.dropped:
        reasons = ", ".join(f"{r}: {c}" for r, c in sorted(traffic.drops.items()))
        rows.append(("messages dropped", f"{traffic.dropped} ({reasons})"))
    if traffic.late:
        kinds = ", ".join(f"{p}: {c}" for p, c in sorted(traffic.late.items()))
        rows.append(
            (
                "radio messages late (missed their cycle)",
                f"{swarm_info['late_messages']} ({kinds}), from step {traffic.late_from}",
            )
        )
    show(
        out.result,
        scenario,
        seed,
        as_json,
        trace,
        extra={"swarm": swarm_info},
        title="uavtrack swarm",
        rows=rows,
        source=source,
        bag=bag,
        truth=record is None or record.targets is not None,
    )
    for line in swarm_notes(traffic, lost):
        typer.echo(f"uavtrack: note: {line}", err=True)


def check_not_all_lost(traffic, programs: int) -> None:
    """A run whose every program was lost (but those the fault model failed) measured
    nothing of the method: it ends with exit code 1 and why, and writes nothing."""
    left = set(range(programs)) - set(traffic.failed)
    if not left or not left <= set(traffic.lost):
        return
    whys: dict[str, list[int]] = {}
    for program in sorted(left):
        whys.setdefault(traffic.why.get(program, "no reason recorded"), []).append(program)
    why, who = max(whys.items(), key=lambda item: len(item[1]))
    others = f" (and {len(left) - len(who)} for other reasons)" if len(who) < len(left) else ""
    raise RunError(
        f"every program was lost, the first at step {min(traffic.lost.values())}, so the run "
        f"measured nothing and wrote nothing: programs {', '.join(map(str, who))}: {why}{others}"
    )


def swarm_notes(traffic, names: dict[str, int]) -> list[str]:
    """One line per program the world lost, saying why, and one if radio messages were
    late: each is a reason why the run's numbers may differ from `uavtrack run`'s."""
    lines = [
        f"program {name} lost at step {k}: {traffic.why.get(program, 'no reason recorded')}"
        for (name, k), program in zip(names.items(), traffic.lost, strict=True)
    ]
    if traffic.late:
        count = sum(traffic.late.values())
        which = "message" if count == 1 else "messages"
        lines.append(
            f"{count} radio {which} missed their cycle from step {traffic.late_from} (late, "
            "or their sender stopped): this run may differ from the simulator's from that step"
        )
    return lines


def reachable(endpoint: str) -> list[str]:
    """The endpoint as other machines can reach it: for an unspecified address (0.0.0.0,
    [::]) one endpoint per address of this host's interfaces, loopback last."""
    found = re.fullmatch(r"(tcp|tls)/(0\.0\.0\.0|\[::\]):(\d+)", endpoint)
    if found is None:
        return [endpoint]
    import socket

    import psutil

    scheme, any_, port = found.groups()
    family = socket.AF_INET if any_ == "0.0.0.0" else socket.AF_INET6
    addresses = []
    for entries in psutil.net_if_addrs().values():
        for entry in entries:
            if entry.family == family and not entry.address.startswith("fe80"):
                host = entry.address if family == socket.AF_INET else f"[{entry.address}]"
                addresses.append(f"{scheme}/{host}:{port}")
    loopback = [a for a in addresses if "/127." in a or "[::1]" in a]
    return [a for a in addresses if a not in loopback] + loopback or [endpoint]


def _ros2_announcer(domain: int | None, n_uavs: int, n_targets: int, tracks: bool = False):
    """What a ROS 2 user needs to hear a swarm with --ros2: the domain, the endpoint."""
    if domain is None:
        return None
    estimates = (
        f"/uav_I/tracks (I < {n_uavs}; MarkerArray, ids the team labels)"
        if tracks
        else f"/uav_I/target_J/estimate (I < {n_uavs}, J < {n_targets})"
    )

    def announce(run: str, endpoint: str, written: list[Path]) -> None:
        typer.echo(
            f"ROS 2 (rmw_zenoh): domain {domain}, Zenoh endpoint {endpoint}; topics "
            f"/clock (simulated time: use_sim_time), /tf, /uav_I/pose and {estimates}",
            err=True,
        )

    return announce


def _announcer(programs: int, sign: bool, tls: bool, ros2: int | None = None):
    tail = " --tls-ca CA --tls-cert CERT --tls-key KEY" if tls else ""
    ros2_tail = f" --ros2 {ros2}" if ros2 is not None else ""

    def announce(run: str, endpoint: str, written: list[Path]) -> None:
        where = reachable(endpoint)
        typer.echo(f"run {run}; world at {', '.join(where)}", err=True)
        tail_ = tail + ros2_tail
        if sign:
            folder = written[0].parent if written else Path(".")
            typer.echo(
                f"key files {run}-0.key .. {run}-{programs - 1}.key in {folder}: copy each to "
                "the machine of its program (they are secret; removed here when the run ends)",
                err=True,
            )
            typer.echo(
                f"  uavtrack agent --key {run}-I.key --connect {where[0]}{tail_}   (I = 0 .. "
                f"{programs - 1})",
                err=True,
            )
        else:
            typer.echo(
                f"  uavtrack agent --run {run} --uav I --connect {where[0]}{tail_}   (I = 0 .. "
                f"{programs - 1})",
                err=True,
            )

    return announce


RUN_ID = re.compile(r"[0-9a-f]{12}")
"""A run id as `uavtrack swarm` makes it."""


@app.command()
def agent(
    connect: Annotated[
        str, typer.Option("--connect", metavar="ENDPOINT", help="the world's endpoint")
    ],
    key: Annotated[
        Path | None,
        typer.Option(
            "--key",
            metavar="FILE",
            help="this program's key file, written by uavtrack swarm --no-spawn --keys "
            "(it names the run and the program)",
        ),
    ] = None,
    run: Annotated[
        str | None,
        typer.Option("--run", metavar="ID", help="the swarm's run id (without --key)"),
    ] = None,
    uav: Annotated[
        int | None,
        typer.Option(
            "--uav", min=0, metavar="I", help="which UAV, N: the central node (without --key)"
        ),
    ] = None,
    zenoh_config: ZenohConfigOpt = None,
    tls_ca: TlsCaOpt = None,
    tls_cert: TlsCertOpt = None,
    tls_key: TlsKeyOpt = None,
    ros2: Ros2Opt = None,
) -> None:
    """Run one UAV's program and join a swarm started with `uavtrack swarm --no-spawn`
    (on this machine or another: give the world's reachable endpoint)."""
    from ..agents.program import serve
    from ..agents.security import Credential

    credential = None
    if key is not None:
        try:
            credential = Credential.read(key.expanduser())
        except ValueError as exc:
            raise UsageError(f"--key: {exc}") from None
        if run is not None and run != credential.run:
            raise UsageError(f"--run {run}: the key file {key} is of run {credential.run}")
        if uav is not None and uav != credential.program:
            raise UsageError(f"--uav {uav}: the key file {key} is program {credential.program}'s")
        run, uav = credential.run, credential.program
    if run is None or uav is None:
        raise UsageError("give --key FILE, or --run ID and --uav I for a swarm run with --no-sign")
    if not RUN_ID.fullmatch(run):
        raise UsageError(
            f"--run {run!r}: a run id is 12 hexadecimal digits, as uavtrack swarm prints it"
        )
    if not connect.strip():
        raise UsageError("--connect is empty; give the world's endpoint, such as tcp/HOST:7447")
    options = zenoh_options(zenoh_config, tls_ca, tls_cert, tls_key, [connect])
    if ros2 is not None:
        try:
            from ..io import ros2 as _  # noqa: F401
        except ImportError as exc:
            raise UsageError(f"--ros2: {exc}") from None
    with results_only_on_stdout():
        transport = _join(connect, options)
        try:
            served = serve(transport, run, uav, first=AGENT_WAIT, credential=credential, ros2=ros2)
        except KeyboardInterrupt:
            raise Interrupted("the program left the swarm") from None
        finally:
            transport.close()
        _ended(served, run, uav, connect, key)


def _join(connect: str, options):
    """A Zenoh client session of the world at `connect` (it listens on nothing)."""
    from ..agents import transport as transports

    try:
        return transports.ZenohTransport([], [connect], options)
    except ImportError:
        raise UsageError(f"uavtrack agent needs eclipse-zenoh: {install_hint('agents')}") from None
    except Exception as exc:
        raise UsageError(f"cannot connect to {connect}: {transports.zenoh_reason(exc)}") from None


def _ended(served, run: str, uav: int, connect: str, key: Path | None = None) -> None:
    """Say how the program ended; bad input (a run it cannot join) exits 2."""
    usage = {
        "not in run": f"--uav {uav}: run {run} has programs 0 to {served.programs - 1} only",
        "taken": f"--uav {uav}: program {uav} of run {run} is already running",
        "under way": f"run {run} is under way (step {served.at}); a program joins only "
        "before the first cycle",
        "needs key": f"run {run} authenticates its programs: give this program's key file "
        "with --key (uavtrack swarm --no-spawn --keys DIR writes them)",
        "wrong key": f"--key: {key} does not hold program {uav}'s key of run {run} (the "
        "world's Hello names another public key): a damaged or forged key file",
        "not authentic": f"the world of run {run} at {connect} did not prove it holds the "
        "run's key: check that --key is this run's key file",
        "other run": f"the world at {connect} runs {', '.join(served.others)}, not run {run}"
        " (a key file or run id of another run; use those the world printed)",
    }
    if served.end in usage:
        raise UsageError(usage[served.end])
    if served.end == "no world":
        raise RunError(
            f"no world of run {run} answered at {connect} within {AGENT_WAIT:g} s; check the "
            "run id and that uavtrack swarm --no-spawn is waiting"
        )
    name = f"{served.name(uav)} {uav} of run {run}"
    if served.end == "lost":
        raise RunError(
            f"{name}: the world lost it at step {served.at} ({served.why}), after "
            f"{served.ran} of {served.steps} cycles"
        )
    if served.end == "world gone":
        raise RunError(
            f"{name}: the world ended or went silent at step {served.at}, after {served.ran} "
            f"of {served.steps} cycles"
        )
    ended = f" (the fault model failed it at step {served.at})" if served.end == "failed" else ""
    typer.echo(f"{name} ran {served.ran} of {served.steps} cycles{ended}")


AGENT_WAIT = 30.0
"""Seconds `uavtrack agent` waits for its world to answer."""
