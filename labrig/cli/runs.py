"""``labrig runs [DIR|FILES...] [--where EXPR]... [--json] [--out FILE] [--reindex]``: the
catalogue of run files (:func:`labrig.catalogue.list_runs`; the filter language:
docs/catalogue.md). ``labrig info`` of several files or of a folder lists them here too.

Exit codes: 0 listed (unreadable files are listed as such, with a note on stderr), 2 a bad
``--where`` or a path that does not exist, 64 a usage error, 130 Ctrl-C (the index keeps what
was read).
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from labrig.cli.common import (
    OVERWRITE_OPTION,
    check_out,
    deliver_json,
    flag,
    friendly,
    json_option,
    out_file_option,
    plural,
)

if TYPE_CHECKING:
    from labrig.catalogue import ListedRun, Listing, ScanProgress

#: the folder listed when no path is given (where ``labrig run`` writes by default)
DEFAULT_FOLDER = Path("runs")
#: the text table's column widths (characters; ``None``: as wide as the widest cell, never cut:
#: a file name is shown whole so that it can be copied)
WIDTHS: dict[str, int | None] = {
    "file": None,
    "status": 10,
    "started": 16,
    "protocol": 24,
    "entries": 34,
}

WHERE_HELP = (
    "Keep runs where KEY OP VALUE holds (repeatable; all must hold). OP: = != ~ (contains) "
    "!~ < <= > >=. Keys: status, protocol, rig, file, seed, entries; since=DATE, until=DATE, "
    "date>=DATE; entry keys kind, amplitude_V, frequency_hz (or any step key: all on one "
    "entry); any other key is metadata (sample, operator, ...). Text ignores case and spaces. "
    "docs/catalogue.md."
)


@friendly
def runs(
    paths: list[Path] = typer.Argument(
        None,
        help="Folders (searched recursively) or run files (default: runs/).",
        show_default=False,
    ),
    where: list[str] = typer.Option([], "--where", metavar="EXPR", help=WHERE_HELP),
    as_json: bool = json_option("the runs"),
    out: Path | None = out_file_option("the runs as JSON (what --json prints)"),
    overwrite: bool = OVERWRITE_OPTION,
    reindex: bool = flag(False, "--reindex", help="Read every file again, in full."),
) -> None:
    """List run files with status, protocol, date, metadata and entries; filter with --where."""
    list_runs_command(paths or [], where, as_json, reindex, out, overwrite)


def list_runs_command(
    paths: list[Path],
    where: list[str],
    as_json: bool,
    reindex: bool,
    out: Path | None = None,
    overwrite: bool = False,
) -> None:
    """The listing of ``paths`` (default ``runs/``) filtered by ``where``, as a table on stdout
    or as JSON (``as_json``, ``out``); counts and notes on stderr."""
    from labrig.catalogue import list_runs
    from labrig.catalogue.where import parse_all
    from labrig.core.errors import InputFileError, InputIssue

    conditions = parse_all(where)  # a bad expression: exit 2 before any file is read
    targets = list(paths or [DEFAULT_FOLDER])
    if not paths and not DEFAULT_FOLDER.is_dir():
        raise InputFileError(
            [InputIssue(str(DEFAULT_FOLDER), None, "", "no runs/ folder here: give a folder")]
        )
    from labrig.catalogue.listing import RUN_SUFFIXES
    from labrig.core.outputs import ReadFolder

    folders = [ReadFolder(p, RUN_SUFFIXES) for p in targets if p.is_dir()]
    check_out(out, targets, overwrite, folders)
    detail = as_json or out is not None
    with _progress_bar() as progress:
        listing = list_runs(targets, conditions, detail=detail, reindex=reindex, progress=progress)
    if not detail or deliver_json(
        listing_json(listing), as_json=as_json, out=out, overwrite=overwrite
    ):
        for line in table_lines(listing.runs):
            typer.echo(line)
    _notes(listing, bool(conditions))


def listing_json(listing: Listing) -> dict[str, Any]:
    """The listing as ``labrig runs --json`` prints it: runs, files, unreadable, indexes."""
    return {
        "runs": [r.to_json() for r in listing.runs],
        "files": listing.files,
        "unreadable": [str(r.path) for r in listing.unreadable],
        "indexes": [str(p) for p in listing.indexes],
    }


@contextmanager
def _progress_bar() -> Iterator[ScanProgress | None]:
    """A bar on stderr while files are read (only on a terminal)."""
    if not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    bar = Progress(
        "reading run files",
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
    )
    task = None

    def progress(done: int, total: int) -> None:
        nonlocal task
        if task is None:
            task = bar.add_task("", total=total)
        bar.update(task, completed=done, total=total)

    with bar:
        yield progress


def _notes(listing: Listing, filtered: bool) -> None:
    """The listing's counts and notes on stderr."""
    err = typer.get_text_stream("stderr")
    shown = plural(len(listing.runs), "run")
    of = f" of {plural(listing.files, 'file')}" if filtered else ""
    index = ", ".join(str(p) for p in listing.indexes) or "none"
    print(
        f"{shown}{of}; {listing.read} read now, the others from the index ({index}); "
        f"{listing.elapsed_s:.2f} s",
        file=err,
    )
    for note in listing.notes:
        print(f"note: {note}", file=err)
    if listing.unreadable:
        print(f"note: {plural(len(listing.unreadable), 'file')} unreadable:", file=err)
        for r in listing.unreadable[:20]:
            print(f"  {r.path}: {r.record.get('error', '')}", file=err)
        if len(listing.unreadable) > 20:
            print(f"  ... and {len(listing.unreadable) - 20} more (--json lists all)", file=err)


def _cut(text: str, width: int) -> str:
    """``text`` in at most ``width`` characters (``...`` where it was cut)."""
    return text if len(text) <= width else text[: width - 3] + "..."


def _values(xs: list[float], unit: str) -> str:
    if not xs:
        return ""
    if len(xs) <= 3:
        return ", ".join(f"{x:g}" for x in xs) + f" {unit}"
    return f"{xs[0]:g}-{xs[-1]:g} {unit}"


def entries_text(record: dict[str, Any]) -> str:
    """``10 sine, 50, 100 V, 1-40 Hz``: count, kinds, amplitudes and frequencies."""
    from labrig.catalogue import entry_summary

    s = entry_summary(record)
    parts = [f"{s['entries']} {'+'.join(s['kinds'])}".strip()]
    parts += [_values(s["amplitudes_V"], "V"), _values(s["frequencies_hz"], "Hz")]
    return ", ".join(p for p in parts if p)


def metadata_text(record: dict[str, Any]) -> str:
    """The metadata a person looks for (instrument details are in ``--json``), as
    ``key=value`` pairs; ``sample/name`` shows as ``sample``, ``metadata/x`` as ``x``."""
    from labrig.catalogue.read import shown_metadata
    from labrig.catalogue.where import METADATA_ALIASES

    # a key with an alias shows under its canonical name (NXuser's name is the operator)
    same_as = {a: key for key, aliases in METADATA_ALIASES.items() for a in aliases}
    pairs: list[str] = []
    for k, v in shown_metadata(record.get("metadata", {})).items():
        name = k.removeprefix("metadata/").removesuffix("/name")
        name = same_as.get(name, name)
        value = ", ".join(map(str, v)) if isinstance(v, list) else str(v)
        if f"{name}={value}" not in pairs:
            pairs.append(f"{name}={value}")
    return " ".join(pairs)


def _row(run: ListedRun) -> list[str]:
    r = run.record
    if not run.readable:
        return [str(run.path), "unreadable", "", "", "", r.get("error", "")]
    status = str(r.get("status", ""))
    return [
        str(run.path),
        "incomplete" if status == "running" else status,
        str(r.get("start_time") or "")[:16].replace("T", " "),
        str(r.get("protocol") or ""),
        entries_text(r),
        metadata_text(r),
    ]


def table_lines(runs: list[ListedRun]) -> list[str]:
    """The listing as aligned text: a header and one line per run."""
    rows = [_row(r) for r in runs]
    widths = []
    for i, (name, limit) in enumerate(WIDTHS.items()):
        widest = max([len(name)] + [len(row[i]) for row in rows])
        widths.append(widest if limit is None else min(limit, widest))
    lines = ["  ".join(n.ljust(w) for n, w in zip(WIDTHS, widths, strict=True)) + "  metadata"]
    for row in rows:
        cells = [_cut(c, w).ljust(w) for c, w in zip(row, widths, strict=False)]
        lines.append(("  ".join(cells) + "  " + _cut(row[-1], 80)).rstrip())
    return lines
