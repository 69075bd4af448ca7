"""One run file's task, as a worker runs it: the same library calls as the one-by-one commands.

- ``fit``: :func:`labrig.commands.fit.fit_run_file` (``labrig fit RUN --json``);
- ``diagnose``: the fit, then :func:`labrig.commands.diagnose.diagnose_run_file`
  (``labrig diagnose RUN --json --out D``);
- ``report``: the fit, then :func:`labrig.commands.report.build_run_report` (``labrig report RUN
  --out report.html --json``).

**One snapshot per result.** A task reads its run file once (:func:`read_snapshot`) and gives
the same records to every part (the fit and the diagnosis, the fit and the report), and the
SHA-256 it records is of the bytes it read: a file that changed while it was read is a failed
task ("changed while it was read"), never a row mixing two versions. A run file still being
written (:mod:`labrig.store.writing`) is not analysed: its row has the status
``being written`` and counts as failed (exit 4); a later batch analyses it once the run ended.
``report`` takes the fit the task made (our model is fitted once per run, not twice).

A task never raises: any failure (a file that is not a run file, a truncated one, a fit that
fails) becomes a :class:`TaskResult` with ``ok=False`` and the error's text, so one bad run
never stops the others. The documents the commands would write (``fit.json``,
``diagnosis.json``, ``diagnosis.html``, ``report.html``, ``report.json``) come back as text and
the client writes them (workers need not see the output directory).
"""

from __future__ import annotations

import json
import os
import socket
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from labrig.core.errors import LabrigError
from labrig.core.version import __version__

if TYPE_CHECKING:
    from labrig.analysis.fit import FitResult
    from labrig.commands.fit import FitOutcome
    from labrig.store import RunFile

#: the three batch commands
COMMANDS = ("fit", "diagnose", "report")


@dataclass(frozen=True)
class TaskOptions:
    """The analysis options of a batch (the same meaning as the one-by-one commands')."""

    method: str = "global"
    memory: str = "return_point"
    heldout: bool = True
    also: tuple[str, ...] = ()
    max_effects: int = 2
    mains_hz: float | None = None
    #: the baselines a report fits (``None``: all of them)
    peers: tuple[str, ...] | None = None

    def to_json(self) -> dict[str, Any]:
        doc = {**asdict(self), "also": list(self.also)}
        if self.peers is None:  # every peer: the options as before there was a choice, so
            del doc["peers"]  # batches made then are still recognised (the cache's identity)
        else:
            doc["peers"] = list(self.peers)
        return doc


@dataclass(frozen=True)
class TaskSpec:
    """One task: the command, the run file (by path: workers read it from a filesystem they
    share with the client) and its key (the folder of its outputs)."""

    command: str
    path: str
    key: str
    options: TaskOptions


@dataclass
class TaskResult:
    """What a task sends back: the run's row of the table, its per-entry rows, the documents
    the one-by-one commands write, and where and how long it ran."""

    command: str
    path: str
    key: str
    ok: bool
    error: str = ""
    #: why a task that did not run is not ``failed`` (``being written``); ``""`` otherwise
    status: str = ""
    input_sha256: str = ""
    row: dict[str, Any] = field(default_factory=dict)
    entries: list[dict[str, Any]] = field(default_factory=list)
    documents: dict[str, str] = field(default_factory=dict)
    elapsed_s: float = 0.0
    worker: str = ""
    labrig_version: str = __version__

    def to_json(self) -> dict[str, Any]:
        """Everything but the documents (stored beside them)."""
        d = asdict(self)
        d.pop("documents")
        return d


def file_sha256(path: Path | str, block: int = 1 << 20) -> str:
    """SHA-256 of the file's bytes (hex)."""
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(block):
            h.update(chunk)
    return h.hexdigest()


def error_text(e: BaseException) -> str:
    """A one-paragraph error for the table: the message of an expected failure, else the
    exception's type, message and the innermost frame."""
    if isinstance(e, LabrigError):
        return str(e)
    tb = traceback.extract_tb(e.__traceback__)
    where = f" (at {Path(tb[-1].filename).name}:{tb[-1].lineno})" if tb else ""
    return f"{type(e).__name__}: {e}{where}"


def dumps(doc: Any) -> str:
    """A document as the commands write it (indented, strict JSON, final newline)."""
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


#: the row status of a run file still being written (not analysed; counts as failed)
BEING_WRITTEN = "being written"


class NotAnalysedError(Exception):
    """The run file is not analysed now (``status``: the row's status; message: why)."""

    def __init__(self, status: str, message: str):
        self.status = status
        super().__init__(message)


@dataclass
class Snapshot:
    """A run file as the task read it: the file, its SHA-256, and the fit once made
    (``run`` ``None``: not read yet; each part then reads it itself)."""

    path: Path
    run: RunFile | None
    sha256: str = ""
    fit: FitOutcome | None = None


def _snapshot(source: Snapshot | Path) -> Snapshot:
    """A part's input: the task's snapshot, or a path (a part called on its own)."""
    return source if isinstance(source, Snapshot) else Snapshot(Path(source), None)


def _stamp(path: Path) -> tuple[int, int, int, int]:
    st = path.stat()
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


def read_snapshot(path: Path) -> Snapshot:
    """Read ``path`` once (every sample), with the SHA-256 of the same bytes: a file changed
    between the read and the hash is :class:`NotAnalysedError`, as is a file being written."""
    from labrig.store import read_run

    before = _stamp(path)
    run = read_run(path)
    if run.being_written:
        raise NotAnalysedError(
            BEING_WRITTEN,
            f"is being written now ({run.writer}); analyse it once the run has ended",
        )
    sha = file_sha256(path)
    if _stamp(path) != before:
        raise NotAnalysedError("failed", "changed while it was read; run the batch again")
    return Snapshot(path, run, sha)


# -- the three commands ---------------------------------------------------------------------


def fit_part(source: Snapshot | Path, opt: TaskOptions, out: TaskResult) -> None:
    """``labrig fit RUN --json``: ``fit.json``, the parameters with uncertainties, NRMSE, and the
    creep the fitted model describes (:func:`~labrig.analysis.diagnose.modelled_creep_per_decade`
    after a step to the run's largest voltage)."""
    from labrig.analysis.diagnose import modelled_creep_per_decade
    from labrig.analysis.fit import PARAM_NAMES
    from labrig.commands.fit import fit_run_file
    from labrig.core.jsonsafe import json_safe
    from labrig.model import ModelParams

    snap = _snapshot(source)
    outcome = fit_run_file(
        snap.path, method=opt.method, memory=opt.memory, heldout=opt.heldout, run=snap.run
    )
    snap.fit = outcome
    doc = json_safe(outcome.result.to_json())
    out.documents["fit.json"] = dumps(doc)
    for name in PARAM_NAMES:
        out.row[name] = doc["params"].get(name)
        out.row[f"{name}_sd"] = doc["uncertainty"].get(name)
    out.row["nrmse_pct"] = doc["nrmse_pct"]
    out.row["heldout_nrmse_pct"] = doc["heldout_nrmse_pct"]
    out.row["fit_method"] = doc["method"]
    v_ref = max(float(np.max(np.abs(r.voltage_V))) for r in outcome.setup.scored_records)
    creep = modelled_creep_per_decade(ModelParams(**doc["params"]), v_ref)
    out.row["creep_pct_per_decade"] = 100 * creep if creep == creep else None
    held = getattr(outcome.result, "heldout_per_entry", None)
    for entry, v in doc["per_entry"].items():
        out.entries.append(
            {
                "entry": entry,
                "nrmse_pct": v,
                "heldout_nrmse_pct": (held or {}).get(entry),
            }
        )


def task_base_fit(snap: Snapshot) -> FitResult | None:
    """The fit :func:`fit_part` made of this snapshot, for the diagnosis to use as its base
    fit (it checks that the fit is the one it would make:
    :func:`~labrig.analysis.diagnose.procedure.base_fit_reusable`): our model, every entry
    scored, nothing but scored entries simulated. ``None`` otherwise (the diagnosis fits)."""
    from labrig.analysis.fit import FitResult

    if snap.fit is None or not isinstance(snap.fit.result, FitResult):
        return None
    setup = snap.fit.setup
    if [r.name for r in setup.records] != list(setup.scored):
        return None  # history entries in the chain: not the diagnosis' records
    return snap.fit.result


def diagnose_part(source: Snapshot | Path, opt: TaskOptions, out: TaskResult) -> None:
    """``labrig diagnose RUN --json --out D``: ``diagnosis.json`` and ``diagnosis.html``, the
    effects added, the verdict and its class."""
    from labrig.commands.diagnose import diagnose_run_file

    snap = _snapshot(source)
    notes: list[str] = []
    result = diagnose_run_file(
        snap.path,
        also=opt.also,
        max_effects=opt.max_effects,
        mains_hz=opt.mains_hz,
        say=notes.append,
        snapshot=snap.run,
        base_fit=task_base_fit(snap),
    )
    d, doc = result.diagnosis, result.document
    out.documents.update(result.documents())
    r = out.row
    r["effects"] = ",".join(e["effect"] for e in doc["effects_added"])
    r["verdict_class"] = d.classification
    r["verdict"] = doc["verdict"]
    r["diag_nrmse_before_pct"] = doc["before"]["nrmse_pct"]
    r["diag_heldout_before_pct"] = doc["before"]["heldout_nrmse_pct"]
    r["diag_nrmse_after_pct"] = doc["after"]["nrmse_pct"]
    r["diag_heldout_after_pct"] = doc["after"]["heldout_nrmse_pct"]
    for key, attr in (("creep_before", "base"), ("creep_after", "after")):
        v = getattr(d, f"{attr}_creep_pct_per_decade", None)
        r[f"diag_{key}_pct_per_decade"] = None if v is None or v != v else float(v)
    r["diag_elapsed_s"] = d.elapsed_s
    before = doc["before"].get("per_entry") or {}
    after = doc["after"].get("per_entry") or {}
    by_entry = {e["entry"]: e for e in out.entries}
    for entry in before:
        row = by_entry.setdefault(entry, {"entry": entry})
        row["diag_nrmse_before_pct"] = before.get(entry)
        row["diag_nrmse_after_pct"] = after.get(entry)
    out.entries[:] = list(by_entry.values())
    if notes:
        r["notes"] = "; ".join(notes)


def report_part(source: Snapshot | Path, opt: TaskOptions, out: TaskResult) -> None:
    """``labrig report RUN --out report.html --json``: the page, its metrics table, and each
    model's mean NRMSE; our model is the fit :func:`fit_part` made."""
    from labrig.commands.report import build_run_report

    snap = _snapshot(source)
    built = build_run_report(
        snap.path, None, method=opt.method, heldout=opt.heldout, fit=snap.fit, peers=opt.peers
    )
    out.documents["report.html"] = built.page
    out.documents["report.json"] = dumps(built.metrics)
    by_entry = {e["entry"]: e for e in out.entries}
    sums: dict[str, list[float]] = {}
    for entry, metrics in built.metrics.items():
        row = by_entry.setdefault(entry, {"entry": entry})
        for k, v in metrics.items():
            if k.endswith("nrmse_pct") and not k.startswith("dynamic."):
                col = "report_" + k.replace(".", "_")
                row[col] = v
                if v is not None:
                    sums.setdefault(col, []).append(float(v))
    out.entries[:] = list(by_entry.values())
    for col, vals in sums.items():
        out.row[col] = sum(vals) / len(vals)


PARTS = {
    "fit": (fit_part,),
    "diagnose": (fit_part, diagnose_part),
    "report": (fit_part, report_part),
}


def run_task(spec: TaskSpec) -> TaskResult:
    """Run one task (module docstring); never raises."""
    from labrig.fleet.identity import run_identity

    t0 = time.perf_counter()
    out = TaskResult(spec.command, spec.path, spec.key, ok=False)
    out.worker = f"{socket.gethostname()}:{os.getpid()}"
    path = Path(spec.path)
    try:
        snap = read_snapshot(path)
        out.input_sha256 = snap.sha256
        out.row.update(run_identity(path, snap.run))
        for part in PARTS[spec.command]:
            part(snap, spec.options, out)
        out.ok = True
    except NotAnalysedError as e:
        out.status, out.error = e.status, f"{path}: {e}"
    except Exception as e:
        out.error = error_text(e)
        out.documents.clear()
    out.elapsed_s = time.perf_counter() - t0
    return out
