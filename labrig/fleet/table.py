"""The fleet table: one row per run (``fleet.parquet``) and one row per run and entry
(``fleet_entries.parquet``); CSV (``fleet.csv``, ``fleet_entries.csv``) when pyarrow is not
installed. The columns, their types and meanings are listed here once (:data:`RUN_COLUMNS`,
:data:`ENTRY_COLUMNS`); ``docs/fleet.md`` shows them as a table.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from labrig.fleet.cache import write_atomic

PARAMS = (
    ("alpha0_ue_per_V", "ue/V"),
    ("gamma_ue_per_V", "ue/V"),
    ("vc_V", "V"),
    ("lam_t", ""),
    ("tau_t_s", "s"),
    ("lam_d", ""),
    ("tau_d_s", "s"),
)

#: (name, type, meaning); type one of str, float, int, bool
Column = tuple[str, str, str]

RUN_COLUMNS: list[Column] = [
    ("run_file", "str", "the run file's path"),
    ("key", "str", "its folder under DIR/runs/"),
    ("command", "str", "fit, diagnose or report"),
    ("status", "str", "ok or failed"),
    ("error", "str", "why it failed (empty when ok)"),
    ("skipped", "bool", "reused from a previous batch (same content hash, options, version)"),
    ("actuator", "str", "the actuator (sample) the file names (labrig.fleet.identity)"),
    ("rig", "str", "the rig's name"),
    ("protocol", "str", "the protocol's name"),
    ("start_time", "str", "when the run started (ISO 8601)"),
    ("seed", "int", "random seed of a simulated rig"),
    ("run_status", "str", "the run file's status (complete, aborted, failed, running)"),
    ("recorded_by", "str", "labrig version that recorded the run"),
    ("n_entries", "int", "entries in the run file"),
    *[(p, "float", f"fitted {p} ({u or 'dimensionless'})") for p, u in PARAMS],
    *[(f"{p}_sd", "float", f"1-sigma uncertainty of {p}") for p, _ in PARAMS],
    ("nrmse_pct", "float", "NRMSE in-sample (%), mean over entries (labrig fit)"),
    ("heldout_nrmse_pct", "float", "NRMSE held-out, leave-one-entry-out (%) (labrig fit)"),
    ("fit_method", "str", "fit method"),
    ("creep_pct_per_decade", "float", "creep the fitted model describes, 1-100 s after a step"),
    ("effects", "str", "effects diagnose added, comma-separated"),
    ("verdict_class", "str", "consistent_with_noise, explained, partially_explained, unexplained"),
    ("verdict", "str", "diagnose's verdict in words"),
    ("diag_nrmse_before_pct", "float", "diagnose: NRMSE of the base model (%)"),
    ("diag_heldout_before_pct", "float", "diagnose: held-out NRMSE of the base model (%)"),
    ("diag_nrmse_after_pct", "float", "diagnose: NRMSE with the effects added (%)"),
    ("diag_heldout_after_pct", "float", "diagnose: held-out NRMSE with the effects added (%)"),
    ("diag_creep_before_pct_per_decade", "float", "diagnose: creep of the base model"),
    ("diag_creep_after_pct_per_decade", "float", "diagnose: creep of the final model"),
    ("diag_elapsed_s", "float", "diagnose's own time (s)"),
    ("flagged", "bool", "flagged by the fleet rule (labrig.fleet.outliers)"),
    ("flags", "str", "why: outlying quantities with their robust z, effects, verdict"),
    ("named_effect", "str", "what the flag points to (effects added, else the outliers)"),
    ("notes", "str", "notes of the analysis"),
    ("input_sha256", "str", "SHA-256 of the run file's bytes"),
    ("labrig_version", "str", "labrig version of the analysis"),
    ("worker", "str", "host:pid that ran the task"),
    ("elapsed_s", "float", "task time on its worker (s)"),
]

ENTRY_COLUMNS: list[Column] = [
    ("run_file", "str", "the run file's path"),
    ("key", "str", "its folder under DIR/runs/"),
    ("actuator", "str", "the actuator the file names"),
    ("entry", "str", "the entry's name"),
    ("nrmse_pct", "float", "NRMSE in-sample (%) (labrig fit)"),
    ("heldout_nrmse_pct", "float", "NRMSE held-out (%) (labrig fit)"),
    ("diag_nrmse_before_pct", "float", "diagnose: NRMSE of the base model (%)"),
    ("diag_nrmse_after_pct", "float", "diagnose: NRMSE with the effects added (%)"),
]


def report_columns(rows: Sequence[dict[str, Any]]) -> list[Column]:
    """``report_<baseline>_[heldout_]nrmse_pct``: each baseline's NRMSE in ``labrig report``
    (as many as the report compares; added after the declared columns)."""
    names = sorted({k for r in rows for k in r if k.startswith("report_")})
    return [(n, "float", "labrig report: a baseline's NRMSE (%)") for n in names]


def outlier_columns(quantities: Sequence[str]) -> list[Column]:
    """``z_<quantity>``: the robust z-score of each quantity tested for outliers."""
    return [(f"z_{q}", "float", f"robust z-score of {q}") for q in quantities]


def _arrow_type(kind: str):
    import pyarrow as pa

    return {"str": pa.string(), "float": pa.float64(), "int": pa.int64(), "bool": pa.bool_()}[kind]


def _cell(v: Any, kind: str) -> Any:
    if v is None or v == "":
        return "" if kind == "str" else None
    if kind == "float":
        return float(v)
    if kind == "int":
        return int(v)
    if kind == "bool":
        return bool(v)
    return str(v)


def has_pyarrow() -> bool:
    try:
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        return False
    return True


def write_table(path_stem: Path, rows: Sequence[dict[str, Any]], columns: Sequence[Column]) -> Path:
    """``rows`` as ``<stem>.parquet`` (pyarrow) or ``<stem>.csv``; returns the file written.
    Only the declared ``columns`` are written, in their order (a missing key is null)."""
    data = {name: [_cell(r.get(name), kind) for r in rows] for name, kind, _ in columns}
    if has_pyarrow():
        import pyarrow as pa
        import pyarrow.parquet as pq

        schema = pa.schema([(name, _arrow_type(kind)) for name, kind, _ in columns])
        table = pa.table(data, schema=schema)
        out = path_stem.with_suffix(".parquet")
        tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
        pq.write_table(table, tmp)
        os.replace(tmp, out)
        return out
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([c[0] for c in columns])
    for i in range(len(rows)):
        w.writerow(["" if data[c[0]][i] is None else repr_cell(data[c[0]][i]) for c in columns])
    out = path_stem.with_suffix(".csv")
    write_atomic(out, buf.getvalue())
    return out


def repr_cell(v: Any) -> str:
    """A CSV cell: floats with every digit (``repr``), booleans as true/false."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def read_table(path: Path) -> list[dict[str, Any]]:
    """A table written by :func:`write_table` as a list of rows (CSV cells stay text)."""
    if path.suffix == ".parquet":
        import pyarrow.parquet as pq

        return pq.read_table(path).to_pylist()
    with path.open(newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))
