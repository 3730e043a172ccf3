"""`uavtrack bench`: BLAS threads are pinned before numpy loads."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from .._files import check_output, write_json
from .app import ForceOpt, app, console


@app.command()
def bench(
    quick: Annotated[bool, typer.Option("--quick", help="small profile (under a minute)")] = False,
    json_out: Annotated[
        Path | None, typer.Option("--json", metavar="FILE", help="write the results as JSON")
    ] = None,
    figure: Annotated[
        Path | None,
        typer.Option(
            "--figure",
            metavar="FILE",
            help="draw time per cycle against team size (.png, .pdf or .svg, by its suffix)",
        ),
    ] = None,
    force: ForceOpt = False,
) -> None:
    """Speed of the building blocks and whole runs, each beside its reference."""
    if json_out is not None:
        check_output(json_out, "--json", force)
    if figure is not None:
        check_output(figure, "--figure", force)
    from ..experiments.bench import bench as run_bench

    results = run_bench(quick, progress=lambda what: print(f"bench: {what}", file=sys.stderr))
    if json_out is not None:
        write_json(json_out, results)
    from rich.markup import escape
    from rich.table import Table

    table = Table(
        title=f"uavtrack bench{' --quick' if quick else ''} "
        f"({results['machine']['cores']} cores, BLAS threads: "
        f"{results['machine']['blas_threads']})"
    )
    for col in ("case", "ours", "reference", "speedup", "memory peak"):
        table.add_column(col, justify="left" if col == "case" else "right")
    for c in results["cases"]:
        if "skipped" in c:
            table.add_row(escape(c["name"]), "skipped", escape(c["skipped"]), "", "")
            continue
        ref = c.get("reference_median_s")
        table.add_row(
            escape(c["name"]),
            f"{_si(c['median_s'])} / {c['unit']}",
            "" if ref is None else f"{_si(ref)} / {c['unit']}",
            "" if ref is None else f"{c['speedup']:.1f}x",
            f"{c['peak_bytes'] / 2**20:.0f} MiB" if "peak_bytes" in c else "",
        )
    console(160).print(table)
    if json_out is not None:
        typer.echo(f"wrote {json_out}")
    if figure is not None:
        from ..experiments.figures import scaling_figure

        scaling_figure(results["cases"], figure)
        typer.echo(f"wrote {figure}")


def _si(seconds: float) -> str:
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9)):
        if seconds >= scale:
            return f"{seconds / scale:.3g} {unit}"
    return f"{seconds / 1e-9:.3g} ns"
