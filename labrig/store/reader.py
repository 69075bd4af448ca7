"""Reading a run file back: metadata and arrays, summaries, CSV export (layout:
:mod:`labrig.store`).

Files from older labrig versions (without checksums, seals or the records of how a run ended)
read the same. Every read happens in a child process with limits on its time
(:mod:`labrig.store.isolated`), and every check is made there (:mod:`labrig.store.parse`): a
damaged file, or one libhdf5 loops or crashes on, is an input error (exit 2) naming the file
and, where known, the object.
"""

from __future__ import annotations

import copy
import os
import re
import time
from collections import OrderedDict
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from labrig.core.errors import InputFileError, InputIssue
from labrig.core.words import shown
from labrig.store.isolated import IsolatedReadError, call_isolated
from labrig.store.parse import RunEntry, RunFile, read_run_here
from labrig.store.writing import writer_of

if TYPE_CHECKING:
    from rich.console import RenderableType

__all__ = [
    "RunEntry",
    "RunFile",
    "being_written",
    "export_csv",
    "read_run",
    "run_info",
    "run_summary",
]


#: a file being written may be caught between two of its writer's writes: it is read again
#: this many times, this long apart, before it is reported as damaged
RETRIES_WHILE_WRITTEN = 5
RETRY_PAUSE_S = 0.15

#: the files read last, newest at the end: key -> (whether its samples were read, the run, the
#: channels' shapes), the key being the path and the file's identity, size and change times
#: (any write changes them); a command or a session that reads a file again (its metadata,
#: then its records; a report after a fit) reads it once
_recent: OrderedDict[tuple, tuple[bool, RunFile, dict]] = OrderedDict()
#: at most this many files are kept, holding at most this many bytes of samples in all
RECENT_FILES = 8
RECENT_BYTES = 64 * 2**20


def _not_a_file(p: Path) -> str:
    """Why ``p`` cannot be read as a run file, for the exit-2 message."""
    if p.is_dir():
        return (
            "is a folder, not a run file: give one .h5 run file (`labrig runs FOLDER` lists the"
            " runs in a folder)"
        )
    return "run file not found" if not p.exists() else "not a regular file: give one .h5 run file"


def read_run(path: Path | str, load_data: bool = True) -> RunFile:
    """Read a run file: metadata, and every entry's arrays (in run order).

    ``load_data=False`` reads metadata only (arrays are left empty of the right shape).
    The file is read in a child process with a time limit (:mod:`labrig.store.isolated`):
    a file that is not a labrig run file, is damaged, or makes libhdf5 loop or crash raises
    :class:`InputFileError` naming the file and, where known, the object.
    """
    p = Path(path)
    if not p.is_file():
        raise InputFileError([InputIssue(str(path), None, "", _not_a_file(p))])
    for attempt in range(RETRIES_WHILE_WRITTEN + 1):
        st = p.stat()
        key = (str(p.resolve()), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
        kept = _recent.get(key)
        if kept is not None and (kept[0] or not load_data):
            _recent.move_to_end(key)
            break
        try:
            read, shapes = _read_isolated(p, load_data, st.st_size)
        except InputFileError:
            if attempt == RETRIES_WHILE_WRITTEN or not _changing(p, st):
                raise
            continue  # caught between two writes of a live writer: read it again
        kept = (load_data, read, shapes)
        _keep(key, kept)
        break
    assert kept is not None  # read above, or a kept read matched
    run, shapes = copy.deepcopy(kept[1:])
    run.path = Path(path)
    if run.status == "running":
        w = writer_of(p, run.writer_pid, run.writer_host)
        run.being_written, run.writer = w.alive, w.describe()
    if not load_data:
        for e in run:
            e.data = {c: np.empty(shapes[e.name][c]) for c in e.data}
    return run


def _keep(key: tuple, kept: tuple[bool, RunFile, dict]) -> None:
    """Keep a read among the recent ones, dropping the oldest beyond :data:`RECENT_FILES` files
    or :data:`RECENT_BYTES` of samples (a read larger than that alone is not kept)."""
    _recent.pop(key, None)
    _recent[key] = kept
    while len(_recent) > RECENT_FILES or sum(map(_sample_bytes, _recent.values())) > RECENT_BYTES:
        _recent.popitem(last=False)


def _sample_bytes(kept: tuple[bool, RunFile, dict]) -> int:
    return sum(a.nbytes for e in kept[1] for a in e.data.values())


#: the first bytes of an HDF5 file (without a user block, as labrig writes them)
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def being_written(path: Path | str) -> str | None:
    """Who writes the run file ``path`` now (:mod:`labrig.store.writing`: its writer's process,
    host and last write), or ``None`` when it is not a run file being written (another kind of
    file, a finished or abandoned run, a file that cannot be read). The output check's probe
    (:func:`labrig.core.outputs.check_outputs`)."""
    try:
        with open(path, "rb") as fh:
            if fh.read(len(HDF5_SIGNATURE)) != HDF5_SIGNATURE:
                return None
        run = read_run(path, load_data=False)
    except (OSError, InputFileError):
        return None
    return run.writer if run.being_written else None


def _read_isolated(p: Path, load_data: bool, size: int) -> tuple[RunFile, dict]:
    try:
        return call_isolated(read_run_here, p, load_data, size_bytes=size)
    except IsolatedReadError as e:
        raise InputFileError([InputIssue(str(p), None, "", f"{e}: the file is damaged")]) from None


def _changing(p: Path, before: os.stat_result) -> bool:
    """The file is being changed (by a writer at work on it): modified within the last
    seconds, and again within :data:`RETRY_PAUSE_S` of ``before`` (a writer flushes a block
    or touches the file every 0.1 s). A file that does not change is not read again."""
    try:
        if not writer_of(p, None, "").alive:
            return False
        time.sleep(RETRY_PAUSE_S)
        now = p.stat()
    except OSError:
        return False
    return (now.st_size, now.st_mtime_ns) != (before.st_size, before.st_mtime_ns)


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
        "being_written": run.being_written,
        "writer": run.writer,
        "metadata": dict(run.metadata),
        "resumes": [dict(r) for r in run.resumes],
        "additions": list(run.additions),
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
                "strain_units": e.units.get("strain") or "ue",
                "channels": e.channels,
            }
            for e in run
        ],
    }


def run_info(path: Path | str) -> RenderableType:
    """A rich renderable summarising a run file (for ``labrig info RUN``)."""
    from rich.console import Group
    from rich.table import Table
    from rich.text import Text

    s = run_summary(path)
    status = s["status"]
    if s["being_written"]:
        status += f" (being written now by {s['writer']})"
    elif s["incomplete"]:
        status += " (incomplete: the writer stopped without finishing the run)"
    elif s["reason"]:
        status += f" ({s['reason']})"
    planned = s["planned_entries"]
    n = len(s["entries"])
    complete = sum(1 for e in s["entries"] if e["status"] == "complete")
    counts = f"\nentries: {n}" + (f" of {planned} planned" if planned else "")
    if complete != n:
        counts += f" ({complete} complete)"
    head = Text.assemble(
        ("run file ", "bold"),
        shown(s["path"]),
        "\nprotocol: ",
        shown(s["protocol"] or "-"),
        "\nstatus: ",
        (shown(status), "green" if s["status"] == "complete" else "red"),
        counts,
        f"\nstarted {shown(s['start_time'] or '-')}, ended {shown(s['end_time'] or '-')}",
        f"\nseed {s['seed'] if s['seed'] is not None else '-'}, "
        f"labrig {shown(s['software_version'] or '-')}",
        *_metadata_lines(s),
        *_resume_lines(s),
        *_addition_lines(s),
    )
    # the strain's unit as the file states it: an import keeps a sensor's numbers as `raw`
    units = {e["strain_units"] for e in s["entries"]}
    strain_col = f"max {shown(units.pop())}" if len(units) == 1 else "max strain"
    t = Table(  # Text: a unit from the file is not read as rich markup
        caption=Text(
            "s: duration; Hz: sample rate; max V: largest command voltage; "
            f"{strain_col}: largest strain"
        )
    )
    t.add_column("entry", no_wrap=True)
    t.add_column("status")
    for col in ("samples", "s", "Hz", "max V"):
        t.add_column(col, justify="right")
    t.add_column(Text(strain_col), justify="right")

    def g(x: float | None, spec: str = ".1f") -> str:
        if x is None:
            return "-"
        if x != 0 and not 1e-3 <= abs(x) < 1e9:  # no 300-digit cells (nan, inf stay short)
            return format(x, ".4g")
        return format(x, spec)

    for e in s["entries"]:
        st = e["status"] + (f": {e['reason']}" if e["reason"] else "")
        t.add_row(  # Text: a name is not read as rich markup
            Text(shown(e["name"])),
            Text(shown(st)),
            str(e["samples"]),
            g(e["duration_s"], ".3f"),
            g(e["rate_hz"], "g"),
            g(e["max_command_voltage_V"]),
            Text(
                g(e["max_strain_ue"])
                + ("" if strain_col != "max strain" else f" {shown(e['strain_units'])}")
            ),
        )
    return Group(head, t)


def _metadata_lines(s: dict) -> list[str]:
    """``metadata: operator=alice sample=P-888 #3 ...`` (none when the run has none)."""
    meta = s.get("metadata") or {}
    pairs = " ".join(f"{shown(k)}={shown(v)}" for k, v in meta.items())
    return [f"\nmetadata: {pairs}"] if meta else []


#: the most additions ``labrig info`` names one by one
SHOWN_ADDITIONS = 8


def _addition_lines(s: dict) -> list[str]:
    """What other programs added to the file (not covered by labrig's seals, not checked)."""
    added = s.get("additions") or []
    if not added:
        return []
    names = ", ".join(shown(a) for a in added[:SHOWN_ADDITIONS])
    more = f" and {len(added) - SHOWN_ADDITIONS} more" if len(added) > SHOWN_ADDITIONS else ""
    return [f"\nadded by another program (not labrig's, not checked): {names}{more}"]


def _resume_lines(s: dict) -> list[str]:
    """One line per resume: when, which entries, the seed, how the run had ended."""
    lines = []
    for r in s.get("resumes") or []:
        seed = r.get("seed", -1)
        before = r.get("previous_status", "?")
        if r.get("previous_reason"):
            before += f": {r['previous_reason']}"
        lines.append(
            f"\nresumed {r.get('time', '?')} (resume {r.get('number', '?')}): "
            f"{shown(', '.join(r.get('entries') or []))}; seed {seed if seed >= 0 else '-'}; "
            f"the run had ended {shown(before)}"
        )
    return lines


def _col_header(name: str, units: str) -> str:
    u = re.sub(r"[^A-Za-z0-9]+", "", units or "")
    return f"{name}_{u}" if u else name


def export_csv(
    path: Path | str, out_dir: Path | str, overwrite: bool = False, option: str = "--csv"
) -> list[Path]:
    """Write one CSV per entry (``<out_dir>/<entry>.csv``); returns the paths written.

    The header line names the columns with their units, e.g. ``time_s,command_voltage_V,
    amplifier_voltage_V,gauge_raw_V,strain_ue``; values use up to 10 significant digits.
    Existing CSVs are refused unless ``overwrite`` (an :class:`InputFileError` naming them,
    before anything is written); the files are written beside their targets and renamed into
    place together (:mod:`labrig.core.outputs`).
    """
    from labrig.core.outputs import staged_outputs

    run = read_run(path)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputFileError([InputIssue(str(out), None, option, "is a file, not a directory")])
    targets = [out / f"{e.name}.csv" for e in run]
    with staged_outputs(targets, inputs=[Path(path)], overwrite=overwrite, option=option) as st:
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
