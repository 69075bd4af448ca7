"""``labrig report``: model versus measurement as one HTML file, baselines fitted on the same data
(:func:`labrig.report.build.build_run_report`)."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.markup import escape

from labrig.cli.common import (
    ENTRIES_HELP,
    HELDOUT_OPTION,
    OFFSET_OPTION,
    WARMUP_OPTION,
    Method,
    choice,
    flag,
    friendly,
    one_of,
)


@friendly
def report(
    run_file: Path = typer.Argument(..., help="Run file (HDF5), recorded or imported."),
    out: Path = typer.Option(..., "--out", help="HTML file to write (self-contained)."),
    params: Path | None = typer.Option(
        None, "--params", help="Parameters from `labrig fit --out` (default: fit now)."
    ),
    as_json: bool = flag(False, "--json", help="Print the metrics table as JSON."),
    entries: str | None = typer.Option(
        None, "--entries", help=ENTRIES_HELP.format("Entries to report")
    ),
    method: Method = typer.Option(
        Method.GLOBAL,
        "--method",
        parser=choice(Method, "a fit method"),
        metavar="<method>",
        help=f"Fit method when fitting: {one_of(Method)}.",
    ),
    warmup_s: float | None = WARMUP_OPTION,
    heldout: bool = HELDOUT_OPTION,
    offset: bool | None = OFFSET_OPTION,
    overwrite: bool = flag(False, "--overwrite", help="Replace an existing --out file."),
) -> None:
    """Model versus measurement as one HTML file; baselines fitted on the same data."""
    from labrig.analysis.prepare import parse_entries
    from labrig.cli.progress import RichUI
    from labrig.outputs import check_writable, write_text_output
    from labrig.report.build import build_run_report

    # before the work: --out an input, a folder, an existing file, or no place to write
    check_writable([out], inputs=[run_file, params], overwrite=overwrite)
    ui = RichUI()
    built = build_run_report(
        run_file,
        params,
        entries=parse_entries(entries),
        warmup_s=warmup_s,
        offset=offset,
        method=method.value,
        heldout=heldout,
        ui=ui,
    )
    write_text_output(out, built.page, overwrite=overwrite)
    ui.err.print(f"wrote {escape(str(out))} ({len(built.page) / 1e6:.1f} MB)")
    if as_json:
        typer.echo(json.dumps(built.metrics, indent=2, allow_nan=False))
    else:
        typer.echo(str(out))
