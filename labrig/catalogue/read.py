"""What the catalogue knows of one run file (its *record*), read from the file's summary.

A record is a JSON-able dict: the run file's summary (:mod:`labrig.store.summary`: status,
protocol, times, seed, entries with their steps, metadata, units) and whether it could be read::

    {"readable": true, "error": "",
     "status": "complete", "reason": "", "protocol": "paper sine sweep",
     "protocol_file": "experiments/sweep.yaml", "rig_file": "", "start_time": "2026-...",
     "end_time": "2026-...", "seed": 1, "software_version": "0.1.0", "planned_entries": 10,
     "entries": [{"name", "kind", "status", "samples", "rate_hz", "duration_s",
                  "step": {scalar keys of the step definition}}, ...],
     "metadata": {"instrument/amplifier/identity": "...", "sample/name": "P-888 #3", ...},
     "units": {"instrument/amplifier/gain_V_per_V": "V/V", ...}}

A file labrig closed holds its summary (``/run/summary``): the record is that one dataset,
checked against its own seal (about 1 ms). A file without one (written by an older labrig,
being written, interrupted, or a summary that does not match its seal) is read in full by the
store's reader and the generic metadata walk, which give the same record
(:func:`labrig.store.summary.summary_of`). Either way the listing does not check the rest of
the file's seals nor its samples: that is done when the data is read (``labrig info``,
``export``, ``fit``, ...), not when a folder is listed. An unreadable file gives a record with
``readable: false`` and the reader's message in ``error``.

Reading happens in child processes with CPU and wall-clock limits
(:func:`labrig.store.isolated.call_isolated`), a batch of files per child; a batch whose child
crashes or runs out of time is read again one file per child, so one bad file costs only its own
record.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import h5py

from labrig.core.errors import InputFileError, InputIssue
from labrig.store.isolated import IsolatedReadError, call_isolated
from labrig.store.summary import metadata_of, read_summary_here, summary_of

#: bumped whenever a record's content changes: an index of another version is rebuilt
#: (2: records from the summary, without the seal check)
RECORD_VERSION = 2

#: files read per child process
BATCH_FILES = 32
#: CPU time granted per file of a batch on top of the store's size-based allowance, expressed
#: as bytes of the store's budget (:data:`labrig.store.isolated.CPU_BYTES_PER_S` bytes per
#: second: 5e6 bytes is 0.25 s, several times what a sound file's metadata takes)
PER_FILE_BUDGET_BYTES = 5_000_000

#: metadata kept apart in an index (:func:`split_record`): many keys, rarely asked for
DETAIL_PREFIXES = ("instrument/",)
#: metadata every labrig file has the same (indexed, not shown in listings)
QUIET_KEYS = frozenset({"program_name", "definition"})


def read_metadata_here(path: Path | str) -> tuple[dict[str, Any], dict[str, str]]:
    """The run file's metadata and the units of the values that have one
    (:func:`labrig.store.summary.metadata_of`), read in this process."""
    with h5py.File(path, "r", locking=False) as f:
        return metadata_of(f)


def read_metadata(path: Path | str) -> tuple[dict[str, Any], dict[str, str]]:
    """:func:`read_metadata_here` in a child process with the store's time limits; a file it
    cannot read is an :class:`~labrig.core.errors.InputFileError` naming it."""
    size = Path(path).stat().st_size
    try:
        return call_isolated(read_metadata_here, str(path), size_bytes=_budget([size]))
    except Exception as e:  # a limit, a crash, or h5py's own error raised in the child
        why = (str(e).strip().splitlines() or [type(e).__name__])[0][:200]
        raise InputFileError(
            [InputIssue(str(path), None, "", f"metadata not readable ({why})")]
        ) from None


def unreadable_record(error: str) -> dict[str, Any]:
    """The record of a file the reader refused (``error``: why, for a person)."""
    return {
        "readable": False,
        "error": error,
        "status": "unreadable",
        "entries": [],
        "metadata": {},
    }


def _record(summary: dict[str, Any]) -> dict[str, Any]:
    record = {"readable": True, "error": "", **summary}
    record.pop("summary_version", None)
    return record


def file_record_here(path: Path | str, full: bool = False) -> dict[str, Any]:
    """The record of one file, read in this process (module docstring): from its summary, or
    (none, or ``full``) from the whole file; never raises for a bad file: an unreadable one
    gives :func:`unreadable_record`."""
    try:
        summary = None if full else read_summary_here(path)
        if summary is None:
            with h5py.File(path, "r", locking=False) as f:
                summary = summary_of(path, f, seals=False)
    except InputFileError as e:
        return unreadable_record("; ".join(_issue_text(i) for i in e.issues))
    except OSError as e:  # h5py: not an HDF5 file, or one it cannot open
        return unreadable_record(f"not a readable HDF5 run file ({e})")
    except Exception as e:  # the reader's own failure: still one line in the listing
        return unreadable_record(f"{type(e).__name__}: {str(e)[:200]}")
    return _record(summary)


def shown_metadata(metadata: dict[str, Any]) -> dict[str, Any]:
    """The metadata a person looks for in a listing: not the instrument's (``--json`` has it)
    nor what every labrig file says the same (:data:`QUIET_KEYS`)."""
    return {
        k: v
        for k, v in metadata.items()
        if not k.startswith(DETAIL_PREFIXES) and k not in QUIET_KEYS
    }


def split_record(record: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """A record as what most listings read (``core``: all but the instrument's metadata and
    the units) and the rest (``detail``), so that an index parses the rest only when asked."""
    meta = record.get("metadata", {})
    core = {k: v for k, v in record.items() if k != "units"}
    core["metadata"] = {k: v for k, v in meta.items() if not k.startswith(DETAIL_PREFIXES)}
    detail = {
        "metadata": {k: v for k, v in meta.items() if k.startswith(DETAIL_PREFIXES)},
        "units": record.get("units", {}),
    }
    return core, detail


def join_record(core: dict[str, Any], detail: dict[str, Any]) -> dict[str, Any]:
    """The record :func:`split_record` split."""
    return {
        **core,
        "metadata": {**core.get("metadata", {}), **detail.get("metadata", {})},
        "units": detail.get("units", {}),
    }


def _issue_text(issue: Any) -> str:
    where = f"[{issue.field}] " if issue.field else ""
    return f"{where}{issue.message}"


def records_here(paths: Sequence[str], full: bool = False) -> list[dict[str, Any]]:
    """:func:`file_record_here` of each path (what a child process of :func:`read_records`
    runs)."""
    return [file_record_here(p, full) for p in paths]


def _budget(sizes: Sequence[int]) -> int:
    """The size to declare to :func:`call_isolated` for a batch (its limits grow with it)."""
    return int(sum(sizes)) + PER_FILE_BUDGET_BYTES * len(sizes)


def read_records(
    files: Sequence[tuple[Path, int]],
    done: Callable[[int], None] | None = None,
    full: bool = False,
) -> Iterator[tuple[Path, dict[str, Any]]]:
    """The record of every ``(path, size_bytes)``, in order, read in child processes
    (module docstring); ``done(n)`` is called after each batch with the files read so far;
    ``full``: every file read in full, its summary not used."""
    n_done = 0
    for i in range(0, len(files), BATCH_FILES):
        batch = files[i : i + BATCH_FILES]
        try:
            records = call_isolated(
                records_here,
                [str(p) for p, _ in batch],
                full,
                size_bytes=_budget([s for _, s in batch]),
            )
        except Exception:  # the child died, ran out of time or could not send its records
            records = [_alone(p, s, full) for p, s in batch]
        yield from zip([p for p, _ in batch], records, strict=True)
        n_done += len(batch)
        if done is not None:
            done(n_done)


def _alone(path: Path, size: int, full: bool) -> dict[str, Any]:
    """One file in its own child (after its batch's child failed)."""
    try:
        return call_isolated(file_record_here, str(path), full, size_bytes=_budget([size]))
    except IsolatedReadError as e:
        return unreadable_record(f"{e}: the file is damaged")
    except Exception as e:  # the child could not send its result back
        last = (str(e).strip().splitlines() or [type(e).__name__])[-1][:200]
        return unreadable_record(f"the reader failed: {last}")
