"""``labrig report``: model versus measurement as one HTML file, baselines fitted on the same data
(:func:`labrig.commands.report.build_run_report`).

``--out FILE`` writes the page; ``--json`` prints the metrics table (with or without
``--out``); with neither, the mean NRMSE per entry and model is printed as a table and no page is
drawn.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer
from rich.markup import escape

from labrig.cli.common import (
    HELDOUT_OPTION,
    OFFSET_OPTION,
    OVERWRITE_OPTION,
    PEERS_OPTION,
    WARMUP_OPTION,
    Method,
    check_out,
    choice,
    entries_option,
    friendly,
    json_option,
    json_text,
    one_of,
    out_file_option,
    peer_list,
)


@friendly
def report(
    run_file: Path = typer.Argument(..., help="Run file (HDF5), recorded or imported."),
    out: Path | None = out_file_option("the report as one self-contained HTML page"),
    params: Path | None = typer.Option(
        None,
        "--params",
        metavar="FILE",
        help="Parameters from `labrig fit --out` (default: fit now).",
    ),
    as_json: bool = json_option("the metrics table"),
    entries: str | None = entries_option("Entries to report"),
    method: Method = typer.Option(
        Method.GLOBAL,
        "--method",
        parser=choice(Method, "a fit method"),
        metavar="METHOD",
        help=f"Fit method when fitting: {one_of(Method)}.",
    ),
    warmup_s: float | None = WARMUP_OPTION,
    heldout: bool = HELDOUT_OPTION,
    offset: bool | None = OFFSET_OPTION,
    peers: str = PEERS_OPTION,
    overwrite: bool = OVERWRITE_OPTION,
) -> None:
    """Model versus measurement as one HTML file; baselines fitted on the same data."""
    from labrig.commands.prepare import parse_entries
    from labrig.commands.progress import RichUI
    from labrig.commands.report import build_run_report, named_training_files
    from labrig.core.outputs import write_text_output
    from labrig.store.reader import being_written

    # before the work; the training files a parameter file names are inputs too
    check_out(out, [run_file, params, *named_training_files(params)], overwrite)
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
        page=out is not None,
        peers=peer_list(peers),
    )
    if out is not None:
        write_text_output(out, built.page, overwrite=overwrite, being_written=being_written)
        ui.err.print(f"wrote {escape(str(out))} ({len(built.page) / 1e6:.1f} MB)")
    if as_json:
        typer.echo(json_text(built.metrics))
    elif out is not None:
        typer.echo(str(out))
    else:
        print_metrics(built.metrics, built.caveat)
        ui.err.print("no page drawn: --out FILE writes the report")
    if built.caveat and (as_json or out is not None):
        ui.err.print(f"[yellow]note:[/] {escape(built.caveat)}")


def print_metrics(metrics: dict[str, dict[str, Any]], caveat: str | None = None) -> None:
    """NRMSE (%) per entry and model, held-out in brackets, as a table on stdout; ``caveat``
    (what the comparison is not) as its caption."""
    from rich.console import Console
    from rich.table import Table

    models = list(
        dict.fromkeys(
            k.removesuffix(".nrmse_pct")
            for row in metrics.values()
            for k in row
            if k.endswith(".nrmse_pct") and not k.endswith("heldout_nrmse_pct")
        )
    )
    t = Table(title="NRMSE (%) per entry and model, held-out in brackets")
    t.add_column("entry")
    for m in models:
        t.add_column(m, justify="right")
    for entry, row in metrics.items():
        cells = []
        for m in models:
            v, h = row.get(f"{m}.nrmse_pct"), row.get(f"{m}.heldout_nrmse_pct")
            cell = "—" if v is None else f"{v:.3g}"
            cells.append(cell + ("" if h is None else f" ({h:.3g})"))
        t.add_row(escape(entry), *cells)
    if caveat:
        t.caption = escape(caveat)
    Console().print(t)
