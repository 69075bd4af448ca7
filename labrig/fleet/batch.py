"""``labrig batch fit|diagnose|report`` as a library call (:func:`run_batch`).

The output folder ``DIR`` holds ``fleet.parquet`` (or ``fleet.csv``), ``fleet_entries.parquet``,
``fleet.html``, ``fleet-manifest.json`` and one folder per run (``runs/<key>/``) with the
documents the one-by-one commands write and the task's result (:mod:`labrig.fleet.cache`). A
batch writes only into a new or empty folder or one a batch wrote before (it has the manifest);
there it replaces the outputs of the runs it computes again and the fleet files.

Exit codes: 0 every run succeeded; :data:`SOME_FAILED` (4) some runs failed (each is a row with
its error); 2 bad input (no run file matches, an unusable ``--out``, an unreachable scheduler);
130 interrupted (the runs finished so far are kept and a rerun skips them).
"""

from __future__ import annotations

import glob
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rich.console import Console

from labrig.core.errors import InputFileError, InputIssue
from labrig.core.outputs import never_an_output
from labrig.core.version import __version__
from labrig.core.words import plural
from labrig.fleet.cache import MANIFEST, cached_result, run_keys, store_result, write_atomic
from labrig.fleet.outliers import flag_runs
from labrig.fleet.schedule import ScheduleInfo, Where, run_tasks
from labrig.fleet.table import (
    ENTRY_COLUMNS,
    RUN_COLUMNS,
    outlier_columns,
    report_columns,
    write_table,
)
from labrig.fleet.tasks import COMMANDS, TaskOptions, TaskResult, TaskSpec

#: exit code of a batch in which some runs failed
SOME_FAILED = 4
GLOB_CHARS = set("*?[")


@dataclass
class BatchOutcome:
    """What a batch did: the rows of the table, where it wrote, and its exit code."""

    rows: list[dict[str, Any]]
    entry_rows: list[dict[str, Any]]
    table: Path
    entries_table: Path
    report: Path
    schedule: ScheduleInfo
    n_skipped: int = 0
    quantities: list[str] = field(default_factory=list)

    @property
    def failed(self) -> list[dict[str, Any]]:
        return [r for r in self.rows if r["status"] != "ok"]

    @property
    def exit_code(self) -> int:
        return SOME_FAILED if self.failed else 0

    def summary(self) -> dict[str, Any]:
        """``labrig batch --json``: where the outputs are, the counts, the failures."""
        return {
            "table": str(self.table),
            "entries_table": str(self.entries_table),
            "report": str(self.report),
            "runs": len(self.rows),
            "succeeded": len(self.rows) - len(self.failed),
            "failed": [{"run_file": r["run_file"], "error": r["error"]} for r in self.failed],
            "skipped": self.n_skipped,
            "flagged": [r["run_file"] for r in self.rows if r.get("flagged")],
            "scheduler": self.schedule.kind,
            "workers": self.schedule.n_workers,
            "wall_s": round(self.schedule.wall_s, 3),
            "exit_code": self.exit_code,
        }


def _issue(what: str, message: str, fld: str = "") -> InputFileError:
    return InputFileError([InputIssue(what, None, fld, message)])


def expand_inputs(patterns: list[str]) -> list[Path]:
    """Run files from paths, globs (``**`` included) and folders (their ``*.h5``), each once,
    in the order given (a glob's matches sorted)."""
    out: list[Path] = []
    for pat in patterns:
        p = Path(pat)
        if GLOB_CHARS & set(pat):
            found = sorted(Path(m) for m in glob.glob(pat, recursive=True) if Path(m).is_file())
            if not found:
                raise _issue(pat, "no file matches this pattern")
        elif p.is_dir():
            found = sorted(x for x in p.glob("*.h5") if x.is_file())
            if not found:
                raise _issue(pat, "the folder has no *.h5 run file")
        elif p.is_file():
            found = [p]
        else:
            raise _issue(pat, "no such file")
        out.extend(found)
    seen: set[Path] = set()
    unique = []
    for p in out:
        r = p.resolve()
        if r not in seen:
            seen.add(r)
            unique.append(r)
    return unique


def check_out_dir(out: Path) -> None:
    """``--out`` must be a new or empty folder, or one a batch wrote (it has the manifest); not
    a device, a name that is not UTF-8 or a symbolic link but to a folder
    (:func:`labrig.core.outputs.never_an_output`)."""
    why = never_an_output(out, folder=True)
    if why:
        raise _issue(str(out), why, "--out")
    if out.exists() and not out.is_dir():
        raise _issue(str(out), "is a file; give a folder for the batch's outputs", "--out")
    if out.is_dir() and any(out.iterdir()) and not (out / MANIFEST).is_file():
        raise _issue(
            str(out),
            f"holds other files (no {MANIFEST}); give a new or empty folder, or the folder of "
            "an earlier batch",
            "--out",
        )


def row_of(res: TaskResult, skipped: bool) -> dict[str, Any]:
    """The table's row of a task's result."""
    return {
        **res.row,
        "run_file": res.path,
        "key": res.key,
        "command": res.command,
        "status": "ok" if res.ok else (res.status or "failed"),
        "error": res.error,
        "skipped": skipped,
        "input_sha256": res.input_sha256,
        "labrig_version": res.labrig_version,
        "worker": res.worker,
        "elapsed_s": res.elapsed_s,
    }


def entry_rows_of(res: TaskResult) -> list[dict[str, Any]]:
    ident = {"run_file": res.path, "key": res.key, "actuator": res.row.get("actuator", "")}
    return [{**ident, **e} for e in res.entries]


def run_batch(
    command: str,
    patterns: list[str],
    out: Path,
    where: Where,
    options: TaskOptions | None = None,
    *,
    force: bool = False,
    console: Console | None = None,
) -> BatchOutcome:
    """Run ``command`` (one of :data:`~labrig.fleet.tasks.COMMANDS`) on every run file of
    ``patterns`` and write the outputs into ``out`` (module docstring). ``force``: compute
    every run again (no skip)."""
    if command not in COMMANDS:
        raise ValueError(f"command must be one of {COMMANDS}, got {command!r}")
    console = console or Console(stderr=True)
    options = options or TaskOptions()
    paths = expand_inputs(patterns)
    check_out_dir(out)
    out.mkdir(parents=True, exist_ok=True)
    manifest = {"labrig_version": __version__, "command": command, "runs": len(paths)}
    write_atomic(out / MANIFEST, json.dumps({**manifest, "started": time.time()}, indent=2))
    specs = [
        TaskSpec(command, str(p), k, options) for p, k in zip(paths, run_keys(paths), strict=True)
    ]
    results: dict[str, tuple[TaskResult, bool]] = {}
    for spec in specs:
        cached = None if force else cached_result(out, spec)
        if cached is not None:
            results[spec.key] = (cached, True)
    todo = [s for s in specs if s.key not in results]
    if len(todo) < len(specs):
        console.print(
            f"{len(specs) - len(todo)} of {plural(len(specs), 'run')} unchanged since the last "
            "batch (content hash, options, labrig version): skipped"
        )
    by_key = {s.key: s for s in specs}

    def on_result(res: TaskResult) -> None:
        store_result(out, by_key[res.key], res)
        results[res.key] = (res, False)

    info = run_tasks(todo, where, on_result, console)
    rows = [row_of(*results[s.key]) for s in specs]
    entry_rows = [e for s in specs for e in entry_rows_of(results[s.key][0])]
    quantities = flag_runs(rows)
    columns = RUN_COLUMNS + report_columns(rows) + outlier_columns(quantities)
    table = write_table(out / "fleet", rows, columns)
    entries_table = write_table(
        out / "fleet_entries", entry_rows, ENTRY_COLUMNS + report_columns(entry_rows)
    )
    from labrig.fleet.fleet_report import write_fleet_report

    report = write_fleet_report(out / "fleet.html", rows, quantities, info)
    return BatchOutcome(
        rows,
        entry_rows,
        table,
        entries_table,
        report,
        info,
        n_skipped=len(specs) - len(todo),
        quantities=quantities,
    )
