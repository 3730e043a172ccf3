"""`uavtrack swarm` and `uavtrack agent`: the cycle as separate programs exchanging messages."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from ..errors import UsageError
from ..files import check_output
from . import ConfigOpt, MethodName, MethodOpt, SeedOpt, SetOpt, app, load_scenario, show, steps_bar


class TransportName(StrEnum):
    memory = "memory"
    zenoh = "zenoh"


@app.command()
def swarm(
    config: ConfigOpt = None,
    method: MethodOpt = MethodName.distributed,
    seed: SeedOpt = 0,
    set_: SetOpt = None,
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

    scenario = load_scenario(config, set_)
    if trace is not None:
        check_output(trace, "--trace")
    if transport == TransportName.memory and (listen or connect or not spawn):
        raise UsageError("--listen, --connect and --no-spawn need --transport zenoh")
    if not spawn:
        typer.echo(
            f"waiting for {scenario.n_uavs} UAV programs: start each with uavtrack agent "
            "(the run id and endpoint follow)",
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
            announce=None if spawn else _announce,
        )
    traffic = out.traffic
    cycles = max(len(traffic.cycle_seconds), 1)
    uavs = scenario.n_uavs
    seconds = sorted(traffic.cycle_seconds) or [0.0]
    swarm_info = {
        "transport": out.transport,
        "run": out.run,
        "cycle_ms_median": 1e3 * seconds[len(seconds) // 2],
        "cycle_ms_max": 1e3 * seconds[-1],
        "published_per_uav_cycle": traffic.published / (uavs * cycles),
        "bytes_per_uav_cycle": traffic.bytes / (uavs * cycles),
        "overruns": traffic.overruns if realtime else None,
        "failed": {str(k): v for k, v in traffic.failed.items()},
        "dropped_messages": traffic.dropped,
    }
    rows = [
        ("transport", out.transport),
        (
            "cycle wall time, median / max [ms]",
            f"{swarm_info['cycle_ms_median']:.1f} / {swarm_info['cycle_ms_max']:.1f}",
        ),
        (
            "radio messages published per UAV and cycle",
            f"{swarm_info['published_per_uav_cycle']:.1f}",
        ),
        ("bytes published per UAV and cycle", f"{swarm_info['bytes_per_uav_cycle']:.0f}"),
    ]
    if realtime:
        rows.append(("cycles over dt (--realtime)", f"{len(traffic.overruns)} of {cycles}"))
    if traffic.failed:
        rows.append(
            (
                "UAV programs lost (uav: step)",
                ", ".join(f"{k}: {v}" for k, v in traffic.failed.items()),
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
    )


def _announce(run: str, endpoint: str) -> None:
    typer.echo(f"run {run}; world at {endpoint}", err=True)
    typer.echo(
        f"  uavtrack agent --run {run} --uav I --connect {endpoint}   (I = 0, 1, ...)", err=True
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
        ran = serve(transport, run, uav)
    finally:
        transport.close()
    typer.echo(f"UAV program {uav} ran {ran} cycles of run {run}")
