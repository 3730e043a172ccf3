"""`uavtrack export`: a trace or a results folder as tidy tables (the io extra)."""

from __future__ import annotations

import enum
import warnings
from pathlib import Path
from typing import Annotated

import typer

from .._files import check_new_file, check_new_folder, new_folder, replacing, write_bytes
from ..errors import RunError, UsageError
from .app import ForceOpt, app
from .experiments import note


class Format(enum.StrEnum):
    parquet = "parquet"
    csv = "csv"
    netcdf = "netcdf"


@app.command()
def export(
    source: Annotated[
        Path,
        typer.Argument(
            metavar="SOURCE",
            help="a trace file (run --trace FILE.npz) or a results folder (reproduce, "
            "sweep, robustness, trackers, flight, sensing, ...)",
        ),
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            metavar="PATH",
            help="a trace's parquet or csv tables: a new folder (steps, uavs, targets, pairs; "
            "with tracks, tracks and measurements for pairs); its netcdf: a new file; a "
            "results folder's table: a new file",
        ),
    ],
    format_: Annotated[
        Format | None,
        typer.Option(
            "--format",
            help="parquet, csv, or netcdf (traces only) [default: from --out's suffix "
            "(.parquet, .csv, .nc), else parquet]",
        ),
    ] = None,
    force: ForceOpt = False,
) -> None:
    """Write a trace or a results folder as tidy tables for pandas, xarray or a spreadsheet."""
    source = source.expanduser()
    out = out.expanduser()
    if not source.exists():
        raise UsageError(f"SOURCE: {source} does not exist")
    if out.resolve() == source.resolve():
        raise UsageError(f"--out: {out} is SOURCE itself; give another name")
    format_ = _format(out, format_)
    try:
        from ..io import tables
    except ImportError as exc:
        raise UsageError(f"export: {exc}") from None
    if source.is_dir():
        if format_ is Format.netcdf:
            raise UsageError("--format netcdf: a results folder exports as parquet or csv")
        check_new_file(out, "--out", "the table", force)
        frame = tables.results_frame(source)
        left_out = frame.attrs.get("left_out", [])
        if left_out:
            typer.echo(
                f"uavtrack: left out {len(left_out)} job file(s) that fail their checksum "
                f"({', '.join(left_out[:3])}{', ...' if len(left_out) > 3 else ''}); run the "
                "experiment's command again to compute them anew",
                err=True,
            )
        if frame.empty:
            raise UsageError(f"SOURCE: {source} holds no intact finished job")
        with replacing(out) as tmp:
            tables.write_table(frame, tmp, format_.value)
        typer.echo(f"{len(frame)} trials written to {out}")
        return
    if format_ is not Format.netcdf and out.suffix in SUFFIXES:
        raise UsageError(
            f"--out: a trace's {format_.value} tables go in a folder; give a name without "
            f"{out.suffix}"
        )
    if format_ is Format.netcdf:
        check_new_file(out, "--out", "the netCDF file", force)
    else:
        check_new_folder(out, "--out", "the tables", force)
    saved = _read(source)
    if format_ is Format.netcdf:
        # built in memory: HDF5 cannot recover from a failed write (a full disk crashes
        # it), a plain write of the bytes fails cleanly and leaves nothing
        write_bytes(out, tables.to_xarray(saved).to_netcdf(engine="h5netcdf"))
        typer.echo(f"{source} written to {out} (netCDF 4)")
        return
    frames = tables.to_frames(saved)
    try:
        with new_folder(out) as folder:
            folder.mkdir()
            for name, frame in frames.items():
                tables.write_table(frame, folder / f"{name}.{format_.value}", format_.value)
            (folder / "scenario.toml").write_text(_replayed(saved.scenario), encoding="utf-8")
    except OSError as exc:
        raise RunError(f"cannot write the tables {out}: {exc.strerror or exc}") from None
    rows = ", ".join(f"{name} {len(frame)}" for name, frame in frames.items())
    typer.echo(f"{source} written to {out}/ ({format_.value}; rows: {rows})")
    if "measurements" in frames:  # a recording of scans
        seed = "" if saved.seed is None else f" --seed {saved.seed}"
        command = f"uavtrack replay {out} --method {saved.method}{seed}"
        if saved.scenario.faults.position_std > 0:
            typer.echo("its scans do not replay: the tables hold the UAVs' true positions, and "
                       "its UAVs converted their scans from where GPS error put them")  # fmt: skip
        elif saved.scenario.tracker.briefing and "briefing" not in frames:
            typer.echo(f"its scans replay with: {command} (no briefing: the trace lacks the "
                       "seed it was drawn from, so the team starts with no track)")  # fmt: skip
        else:
            typer.echo(f"its scans replay with: {command}")


def _replayed(scenario) -> str:
    """The scenario of an export's replay as TOML: the failures of the fault model left
    out, as the tables' alive column holds them."""
    return scenario.with_overrides({"faults.failure_rate": 0.0, "faults.failures": []}).to_toml()


def _read(source: Path):
    """The trace file, its version note (another uavtrack wrote it) on standard error."""
    from ..io import trace as trace_file

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", trace_file.TraceVersionWarning)
        saved = trace_file.read(source)
    for warning in caught:
        if issubclass(warning.category, trace_file.TraceVersionWarning):
            note(str(warning.message))
        else:
            warnings.warn_explicit(warning.message, warning.category, warning.filename,
                                   warning.lineno)  # fmt: skip
    return saved


SUFFIXES = {".parquet": Format.parquet, ".pq": Format.parquet, ".csv": Format.csv,
            ".nc": Format.netcdf}  # fmt: skip


def _format(out: Path, given: Format | None) -> Format:
    """The format asked for, or the one --out's suffix names; refused if they differ."""
    named = SUFFIXES.get(out.suffix.lower())
    if given is None:
        return named or Format.parquet
    if named is not None and named is not given:
        raise UsageError(f"--out {out} names {named.value}, but --format is {given.value}")
    return given
