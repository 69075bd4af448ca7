"""Reading a run file back: metadata and arrays, summaries, CSV export (layout:
:mod:`labrig.store`).

Files from older labrig versions (without checksums, seals or the records of how a run ended)
read the same. Every read happens in a child process with limits on its time
(:mod:`labrig.store_isolated`), and every check is made there (:mod:`labrig.store_parse`): a
damaged file, or one libhdf5 loops or crashes on, is an input error (exit 2) naming the file
and, where known, the object.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path

import numpy as np

from labrig.errors import InputFileError, InputIssue
from labrig.store_isolated import IsolatedReadError, call_isolated
from labrig.store_parse import RunEntry, RunFile, read_run_here

__all__ = ["RunEntry", "RunFile", "export_csv", "read_run", "run_info", "run_summary"]


#: the last file read: (key, whether its samples were read, the run, the channels' shapes), the
#: key being the path and the file's identity and change times; a command that reads one file
#: twice (e.g. its metadata, then its records) reads it once
_last: tuple[tuple, bool, RunFile, dict] | None = None


def read_run(path: Path | str, load_data: bool = True) -> RunFile:
    """Read a run file: metadata, and every entry's arrays (in run order).

    ``load_data=False`` reads metadata only (arrays are left empty of the right shape).
    The file is read in a child process with a time limit (:mod:`labrig.store_isolated`):
    a file that is not a labrig run file, is damaged, or makes libhdf5 loop or crash raises
    :class:`InputFileError` naming the file and, where known, the object.
    """
    global _last
    p = Path(path)
    if not p.is_file():
        raise InputFileError([InputIssue(str(path), None, "", "run file not found")])
    st = p.stat()
    key = (str(p.resolve()), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    if _last is None or _last[0] != key or (load_data and not _last[1]):
        try:
            run, shapes = call_isolated(read_run_here, p, load_data, size_bytes=st.st_size)
        except IsolatedReadError as e:
            raise InputFileError(
                [InputIssue(str(path), None, "", f"{e}: the file is damaged")]
            ) from None
        _last = (key, load_data, run, shapes)
    run, shapes = copy.deepcopy(_last[2:])
    run.path = Path(path)
    if not load_data:
        for e in run:
            e.data = {c: np.empty(shapes[e.name][c]) for c in e.data}
    return run


def run_summary(path: Path | str) -> dict:
    """JSON-able summary of a run: status, seed, and per entry status, samples, duration,
    rate and the largest command voltage, amplifier voltage and strain."""
    run = read_run(path)

    def mx(e: RunEntry, k: str) -> float | None:
        v = e.data.get(k)
        return float(np.max(v)) if v is not None and len(v) else None

    return {
        "path": str(run.path),
        "protocol": run.protocol_name,
        "status": run.status,
        "reason": run.reason,
        "incomplete": run.incomplete,
        "start_time": run.start_time,
        "end_time": run.end_time,
        "seed": run.seed,
        "software_version": run.software_version,
        "planned_entries": len(run.planned_entries),
        "entries": [
            {
                "name": e.name,
                "status": e.status,
                "reason": e.reason,
                "samples": e.n_samples,
                "duration_s": e.duration_s,
                "rate_hz": e.rate_hz,
                "max_command_voltage_V": mx(e, "command_voltage"),
                "max_amplifier_voltage_V": mx(e, "amplifier_voltage"),
                "max_strain_ue": mx(e, "strain"),
                "channels": e.channels,
            }
            for e in run
        ],
    }


def run_info(path: Path | str):
    """A rich renderable summarising a run file (for ``labrig info RUN``)."""
    from rich.console import Group
    from rich.table import Table
    from rich.text import Text

    s = run_summary(path)
    status = s["status"]
    if s["incomplete"]:
        status += " (incomplete: the writer stopped without finishing the run)"
    elif s["reason"]:
        status += f" ({s['reason']})"
    planned = s["planned_entries"]
    n = len(s["entries"])
    head = Text.assemble(
        ("run file ", "bold"),
        s["path"],
        "\nprotocol: ",
        s["protocol"] or "-",
        "\nstatus: ",
        (status, "green" if s["status"] == "complete" else "red"),
        f"\nentries: {n}" + (f" of {planned} planned" if planned else ""),
        f"\nstarted {s['start_time'] or '-'}, ended {s['end_time'] or '-'}",
        f"\nseed {s['seed'] if s['seed'] is not None else '-'}, "
        f"labrig {s['software_version'] or '-'}",
    )
    t = Table(
        caption="s: duration; Hz: sample rate; max V: largest command voltage; "
        "max ue: largest strain"
    )
    t.add_column("entry", no_wrap=True)
    t.add_column("status")
    for col in ("samples", "s", "Hz", "max V", "max ue"):
        t.add_column(col, justify="right")

    def g(x: float | None, spec: str = ".1f") -> str:
        if x is None:
            return "-"
        if x != 0 and not 1e-3 <= abs(x) < 1e9:  # no 300-digit cells (nan, inf stay short)
            return format(x, ".4g")
        return format(x, spec)

    for e in s["entries"]:
        st = e["status"] + (f": {e['reason']}" if e["reason"] else "")
        t.add_row(
            e["name"],
            st,
            str(e["samples"]),
            g(e["duration_s"], ".3f"),
            g(e["rate_hz"], "g"),
            g(e["max_command_voltage_V"]),
            g(e["max_strain_ue"]),
        )
    return Group(head, t)


def _col_header(name: str, units: str) -> str:
    u = re.sub(r"[^A-Za-z0-9]+", "", units or "")
    return f"{name}_{u}" if u else name


def export_csv(path: Path | str, out_dir: Path | str, overwrite: bool = False) -> list[Path]:
    """Write one CSV per entry (``<out_dir>/<entry>.csv``); returns the paths written.

    The header line names the columns with their units, e.g. ``time_s,command_voltage_V,
    amplifier_voltage_V,gauge_raw_V,strain_ue``; values use up to 10 significant digits.
    Existing CSVs are refused unless ``overwrite`` (an :class:`InputFileError` naming them,
    before anything is written); the files are written beside their targets and renamed into
    place together (:mod:`labrig.outputs`).
    """
    from labrig.outputs import staged_outputs

    run = read_run(path)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputFileError([InputIssue(str(out), None, "--csv", "is a file, not a directory")])
    targets = [out / f"{e.name}.csv" for e in run]
    with staged_outputs(targets, inputs=[Path(path)], overwrite=overwrite, option="--csv") as st:
        for e, target in zip(run, targets, strict=True):
            cols = e.channels
            header = [_col_header(c, e.units.get(c, "")) for c in cols]
            table = np.column_stack([e.data[c] for c in cols]) if cols else np.empty((0, 0))
            try:
                np.savetxt(
                    st.path(target), table, fmt="%.10g", delimiter=",",
                    header=",".join(header), comments="",
                )  # fmt: skip
            except OSError as err:
                raise st.error(target, f"cannot write it: {err.strerror or err}") from None
    return targets
