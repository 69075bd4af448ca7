"""``labrig info``, ``labrig export`` and ``labrig import``: run files in and out
(:mod:`labrig.store`, :mod:`labrig.importer`)."""

from __future__ import annotations

from pathlib import Path

import typer

from labrig.cli.common import flag, friendly


@friendly
def info(run_file: Path = typer.Argument(..., help="Run file (HDF5).")) -> None:
    """Summarise a run file: entries, status, durations, ranges."""
    from rich.console import Console

    from labrig.store import run_info

    Console().print(run_info(run_file))


@friendly
def export(
    run_file: Path = typer.Argument(..., help="Run file (HDF5)."),
    csv: Path = typer.Option(..., "--csv", help="Directory for one CSV file per entry."),
) -> None:
    """Export every entry of a run file to CSV (header: column names with units)."""
    from labrig.store import export_csv

    for p in export_csv(run_file, csv):
        typer.echo(str(p))


@friendly
def import_(
    files: list[Path] = typer.Argument(..., help="Data files: delimited text or MATLAB .mat."),
    out: Path = typer.Option(..., "--out", help="Run file to write (HDF5)."),
    time: str | None = typer.Option(None, "--time", help="Time column: name or 1-based index."),
    voltage: str | None = typer.Option(None, "--voltage", help="Voltage column (name/index)."),
    strain: str | None = typer.Option(None, "--strain", help="Strain column (name/index)."),
    rate_hz: float | None = typer.Option(None, "--rate-hz", help="Sample rate if no time column."),
    voltage_scale: float = typer.Option(1.0, help="Multiply the voltage column (e.g. amp gain)."),
    voltage_offset: float = typer.Option(0.0, help="Then add this (V)."),
    strain_scale: float = typer.Option(1.0, help="Multiply the strain column (to ue)."),
    strain_offset: float = typer.Option(0.0, help="Then add this."),
    strain_units: str = typer.Option("ue", help="Units of the scaled strain column."),
    aux: list[str] = typer.Option(
        [],
        "--aux",
        help="Extra channel to keep: NAME or NAME=COLUMN "
        "(NAME like temperature_C gives name and unit).",
    ),
    delimiter: str | None = typer.Option(None, help="Column delimiter (default: detect)."),
    overwrite: bool = flag(False, "--overwrite", help="Replace an existing --out file."),
) -> None:
    """Bring measured data into a run file, one entry per input file (named after its stem)."""
    from labrig.importer import ImportOptions, import_files

    opt = ImportOptions(
        time=time, voltage=voltage, strain=strain, rate_hz=rate_hz,
        voltage_scale=voltage_scale, voltage_offset=voltage_offset,
        strain_scale=strain_scale, strain_offset=strain_offset, strain_units=strain_units,
        aux=list(aux), delimiter=delimiter,
    )  # fmt: skip
    for e in import_files(list(files), out, opt, overwrite):
        cols = ", ".join(f"{k}={v}" for k, v in e.columns.items())
        typer.echo(f"{e.name}: {e.voltage_V.size} samples at {e.rate_hz:g} Hz ({cols})")
    typer.echo(str(out))
