"""`uavtrack swarm` and `uavtrack agent`: the cycle as separate programs exchanging messages."""

from __future__ import annotations

from enum import StrEnum
from functools import partial
from pathlib import Path
from typing import Annotated

import typer

from ..errors import Interrupted, RunError, UsageError
from ..files import check_output
from . import (
    ConfigOpt,
    MethodName,
    MethodOpt,
    SeedOpt,
    SetOpt,
    TeamOpt,
    app,
    load_scenario,
    show,
    steps_bar,
)


class TransportName(StrEnum):
    memory = "memory"
    zenoh = "zenoh"


@app.command()
def swarm(
    config: ConfigOpt = None,
    method: MethodOpt = MethodName.distributed,
    seed: SeedOpt = 0,
    set_: SetOpt = None,
    team: TeamOpt = None,
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
    listen: Annotated[
        str | None,
        typer.Option(
            metavar="ENDPOINT",
            help="zenoh: the world's endpoint [tcp/127.0.0.1 and a free port]",
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
    deadline: Annotated[
        float,
        typer.Option(min=0.05, max=60, metavar="S", help="seconds a round waits for messages"),
    ] = 2.0,
) -> None:
    """Run one trial as a swarm: a world program and one program per UAV exchanging
    messages; prints and writes what `uavtrack run` does."""
    from ..agents import run_swarm
    from ..methods import get

    scenario = load_scenario(config, set_, team)
    if trace is not None:
        check_output(trace, "--trace")
    if transport == TransportName.memory and (listen is not None or connect or not spawn):
        raise UsageError("--listen, --connect and --no-spawn need --transport zenoh")
    n = scenario.n_uavs
    central = get(method.value).central
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
    with steps_bar(scenario, label="cycles") as advance:
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
            trace=trace is not None,
            progress=lambda _: advance(1),
            announce=None if spawn else partial(_announce, n + central),
        )
    import numpy as np  # not at import: `uavtrack bench` pins BLAS threads first

    traffic = out.traffic
    cycles = max(len(traffic.cycle_seconds), 1)
    uavs = scenario.n_uavs
    seconds = np.array(traffic.cycle_seconds or [0.0])
    swarm_info = {
        "transport": out.transport,
        "run": out.run,
        "cycle_ms_median": 1e3 * float(np.median(seconds)),
        "cycle_ms_p90": 1e3 * float(np.percentile(seconds, 90)),
        "cycle_ms_max": 1e3 * float(seconds.max()),
        "published_per_uav_cycle": traffic.published / (uavs * cycles),
        "bytes_per_uav_cycle": traffic.bytes / (uavs * cycles),
        "overruns": traffic.overruns if realtime else None,
        "failed": {str(k): v for k, v in traffic.failed.items()},
        "lost": {str(k): v for k, v in traffic.lost.items()},
        "dropped_messages": traffic.dropped,
    }
    rows = [
        ("transport", out.transport),
        (
            "cycle wall time, median / 90th percentile / max [ms]",
            f"{swarm_info['cycle_ms_median']:.1f} / {swarm_info['cycle_ms_p90']:.1f} / "
            f"{swarm_info['cycle_ms_max']:.1f}",
        ),
        (
            "radio messages published per UAV and cycle",
            f"{swarm_info['published_per_uav_cycle']:.1f}",
        ),
        ("bytes published per UAV and cycle", f"{swarm_info['bytes_per_uav_cycle']:.0f}"),
    ]
    if realtime:
        rows.append(("cycles longer than dt (--realtime)", f"{len(traffic.overruns)} of {cycles}"))
    for name, found in (
        ("UAVs failed by the fault model (uav: step)", traffic.failed),
        ("UAV programs lost (uav: step)", traffic.lost),
    ):
        if found:
            rows.append((name, ", ".join(f"{k}: {v}" for k, v in found.items())))
    if traffic.dropped:
        rows.append(("malformed or foreign messages dropped", str(traffic.dropped)))
    show(
        out.result,
        scenario,
        seed,
        as_json,
        trace,
        extra={"swarm": swarm_info},
        title="uavtrack swarm",
        rows=rows,
    )


def _announce(programs: int, run: str, endpoint: str) -> None:
    typer.echo(f"run {run}; world at {endpoint}", err=True)
    typer.echo(
        f"  uavtrack agent --run {run} --uav I --connect {endpoint}   (I = 0 .. {programs - 1})",
        err=True,
    )


@app.command()
def agent(
    run: Annotated[str, typer.Option("--run", metavar="ID", help="the swarm's run id")],
    uav: Annotated[
        int, typer.Option("--uav", min=0, metavar="I", help="which UAV (N: the central node)")
    ],
    connect: Annotated[
        str, typer.Option("--connect", metavar="ENDPOINT", help="the world's endpoint")
    ],
    listen: Annotated[
        str,
        typer.Option(metavar="ENDPOINT", help="this program's own endpoint"),
    ] = "tcp/127.0.0.1:0",
) -> None:
    """Run one UAV's program and join a swarm started with `uavtrack swarm --no-spawn`
    (on this machine or another: give the world's reachable endpoint)."""
    from ..agents.program import serve
    from ..agents.transport import ZenohTransport, zenoh_reason

    try:
        transport = ZenohTransport([listen], [connect])
    except ImportError:
        raise UsageError(
            'uavtrack agent needs eclipse-zenoh: pip install "uavtrack[agents]"'
        ) from None
    except Exception as exc:
        raise UsageError(
            f"cannot listen on {listen} and connect to {connect}: {zenoh_reason(exc)}"
        ) from None
    try:
        served = serve(transport, run, uav, first=AGENT_WAIT)
    except KeyboardInterrupt:
        raise Interrupted("the program left the swarm") from None
    finally:
        transport.close()
    if served.end == "no world":
        raise RunError(
            f"no world of run {run} answered at {connect} within {AGENT_WAIT:g} s; check the "
            "run id and that uavtrack swarm --no-spawn is waiting"
        )
    if served.end == "not in run":
        raise UsageError(f"--uav {uav}: run {run} has programs 0 to {served.programs - 1} only")
    if served.end == "taken":
        raise UsageError(f"--uav {uav}: program {uav} of run {run} is already running")
    name = f"{served.name(uav)} {uav} of run {run}"
    if served.end == "world gone":
        raise RunError(
            f"{name}: the world ended or went silent at step {served.at}, after {served.ran} "
            f"of {served.steps} cycles"
        )
    ended = f" (the fault model failed it at step {served.at})" if served.end == "failed" else ""
    typer.echo(f"{name} ran {served.ran} of {served.steps} cycles{ended}")


AGENT_WAIT = 30.0
"""Seconds `uavtrack agent` waits for its world to answer."""
