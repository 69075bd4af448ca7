"""``labrig info``, ``labrig export`` and ``labrig import``: run files in and out
(:mod:`labrig.store`, :mod:`labrig.importers`). ``info`` of several files or of a folder is the
catalogue's listing (``labrig runs``, :mod:`labrig.cli.runs`)."""

from __future__ import annotations

from pathlib import Path

import typer

from labrig.cli.common import (
    OVERWRITE_OPTION,
    check_out,
    deliver_json,
    flag,
    friendly,
    json_option,
    json_text,
    one_option,
    out_file_option,
)
from labrig.cli.run import META_OPTION, OPERATOR_OPTION, SAMPLE_OPTION, metadata_of


@friendly
def info(
    paths: list[Path] = typer.Argument(
        ..., metavar="RUN_FILES", help="Run file (HDF5); several files or a folder: a listing."
    ),
    as_json: bool = json_option("the summary (several files: the listing of `labrig runs`)"),
    out: Path | None = out_file_option("the summary as JSON (what --json prints)"),
    overwrite: bool = OVERWRITE_OPTION,
) -> None:
    """Summarise a run file: entries, status, durations, ranges (several: list them)."""
    if len(paths) > 1 or paths[0].is_dir():
        from labrig.cli.runs import list_runs_command

        list_runs_command(paths, [], as_json, False, out, overwrite)
        return
    from labrig.store import run_info, run_summary

    check_out(out, paths, overwrite)
    doc_wanted = as_json or out is not None
    if doc_wanted and not deliver_json(
        run_summary(paths[0]), as_json=as_json, out=out, overwrite=overwrite
    ):
        return
    from rich.console import Console

    Console().print(run_info(paths[0]))


@friendly
def export(
    run_file: Path = typer.Argument(..., help="Run file (HDF5)."),
    out: Path | None = typer.Option(
        None, "--out", metavar="DIR", help="Folder for one CSV file per entry (required)."
    ),
    csv: Path | None = typer.Option(
        None, "--csv", metavar="DIR", help="The older name of --out (give one of them)."
    ),
    as_json: bool = json_option("the files written"),
    overwrite: bool = flag(False, "--overwrite", help="Replace CSV files of the same names."),
) -> None:
    """Export every entry of a run file to CSV (header: column names with units)."""
    from labrig.store import export_csv

    folder = one_option("--out", {"--out": out, "--csv": csv})
    if folder is None:
        raise typer.BadParameter(
            "Missing option '--out': give the folder for the CSV files", param_hint="--out"
        )
    from labrig.store.reader import being_written

    writer = being_written(run_file)
    written = export_csv(run_file, folder, overwrite, option="--csv" if csv else "--out")
    if writer is not None:  # a run in progress: the CSVs end where the file did
        typer.echo(
            f"note: {run_file} is being written ({writer}): the CSV files hold what it held "
            "when read; export again when the run has ended",
            err=True,
        )
    if as_json:
        typer.echo(json_text({"files": [str(p) for p in written]}))
        return
    for p in written:
        typer.echo(str(p))


@friendly
def import_(
    files: list[Path] = typer.Argument(..., help="Data files: delimited text or MATLAB .mat."),
    out: Path | None = typer.Option(
        None, "--out", help="Run file to write (HDF5).", metavar="FILE"
    ),
    list_: bool = flag(
        False, "--list", help="Print each file's columns or channels; write nothing."
    ),
    time: str | None = typer.Option(None, "--time", help="Time column: name or 1-based number."),
    voltage: str | None = typer.Option(None, "--voltage", help="Voltage column: name or number."),
    strain: str | None = typer.Option(None, "--strain", help="Strain column: name or number."),
    rate_hz: float | None = typer.Option(None, "--rate-hz", help="Sample rate if no time column."),
    window: str | None = typer.Option(None, "--window", help="Keep T0:T1 (s of the file's time)."),
    capture: list[str] = typer.Option(
        [], "--capture", help="ControlDesk capture to import: name or number (default: all)."
    ),
    voltage_scale: float | None = typer.Option(
        None, help="Multiply the voltage (e.g. amplifier gain; 1: raw numbers are volts)."
    ),
    voltage_offset: float = typer.Option(0.0, help="Then add this (V)."),
    strain_scale: float = typer.Option(1.0, help="Multiply the strain (-1: flip its sign)."),
    strain_offset: float = typer.Option(0.0, help="Then add this (ue)."),
    strain_units: str | None = typer.Option(
        None,
        help="Unit of the strain column (default: from the header; a strain stating no unit is"
        " refused): ue, %, mm/m, um with --stack-length-mm, or raw to keep the numbers.",
    ),
    stack_length_mm: float | None = typer.Option(
        None, help="Stack length: a displacement column (um...) becomes strain = d / L."
    ),
    scale: list[str] = typer.Option(
        [], "--scale", help="CHANNEL=FACTOR: multiply a channel (voltage, strain or auxiliary)."
    ),
    aux: list[str] = typer.Option(
        [],
        "--aux",
        help="Keep a column as a channel: COLUMN or NAME=COLUMN (NAME like "
        "temperature_C gives name and unit). Named columns are kept without it.",
    ),
    delimiter: str | None = typer.Option(None, help="Column separator (default: detect; tab)."),
    decimal: str | None = typer.Option(None, help="Decimal mark . or , (default: detect)."),
    encoding: str | None = typer.Option(None, help="Text encoding (default: detect)."),
    overwrite: bool = flag(False, "--overwrite", help="Replace an existing --out file."),
    meta: list[str] = META_OPTION,
    operator: str | None = OPERATOR_OPTION,
    sample: str | None = SAMPLE_OPTION,
) -> None:
    """Bring measured data into a run file, one entry per input file or ControlDesk capture
    (named after the file's stem). docs/import.md describes the formats and options."""
    from labrig.core.errors import option_error
    from labrig.importers import ImportOptions, check_options, import_files, list_table, read_tables
    from labrig.importers.entry import conversion_notes

    opt = ImportOptions(
        time=time, voltage=voltage, strain=strain, rate_hz=rate_hz, window=window,
        captures=list(capture), voltage_scale=voltage_scale, voltage_offset=voltage_offset,
        strain_scale=strain_scale, strain_offset=strain_offset, strain_units=strain_units,
        stack_length_mm=stack_length_mm, scale=list(scale), aux=list(aux),
        delimiter=delimiter, decimal=decimal, encoding=encoding,
    )  # fmt: skip
    if list_:
        checked = check_options(opt)
        for f in files:
            for table in read_tables(f, checked):
                typer.echo("\n".join(list_table(table, checked)))
        return
    if out is None:
        raise option_error("--out", "missing: give the run file to write (or --list)")
    metadata = metadata_of(meta, operator, sample)
    for e in import_files(list(files), out, opt, overwrite, metadata):
        cols = ", ".join(f"{k}={v}" for k, v in e.meta["columns"].items() if v)
        aux_text = (
            "; aux " + ", ".join(f"{k} [{u}]" for k, (_, u) in e.aux.items()) if e.aux else ""
        )
        typer.echo(f"{e.name}: {e.voltage_V.size} samples at {e.rate_hz:g} Hz ({cols}{aux_text})")
        for note in conversion_notes(e.meta):
            typer.echo(f"  {note}")
        for what in e.meta.get("skipped", []):  # e.g. a temperature column with a gap
            typer.echo(f"  left out: {what}")
    typer.echo(str(out))
