"""What the catalogue knows of one run file (its *record*), read through the store's reader.

A record is a JSON-able dict::

    {"readable": true, "error": "",
     "status": "complete", "reason": "", "protocol": "paper sine sweep",
     "protocol_file": "experiments/sweep.yaml", "rig_file": "", "start_time": "2026-...",
     "end_time": "2026-...", "seed": 1, "software_version": "0.1.0", "planned_entries": 10,
     "entries": [{"name", "kind", "status", "samples", "rate_hz", "duration_s",
                  "step": {scalar keys of the step definition}}, ...],
     "metadata": {"instrument/amplifier/identity": "...", "sample/name": "P-888 #3", ...},
     "units": {"instrument/amplifier/gain_V_per_V": "V/V", ...}}

The run's fixed fields come from :func:`labrig.store.parse.read_run_here` (which checks the
file's seals and refuses a damaged one); *metadata* is read generically afterwards
(:func:`read_metadata_here`), so whatever groups a run file gains later (NXuser, NXsample, a
protocol's ``metadata:``) are indexed without a change here. An unreadable file gives a record
with ``readable: false`` and the reader's message in ``error``.

Reading happens in child processes with CPU and wall-clock limits
(:func:`labrig.store.isolated.call_isolated`), a batch of files per child; a batch whose child
crashes or runs out of time is read again one file per child, so one bad file costs only its own
record.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from labrig.core.errors import InputFileError, InputIssue
from labrig.store.format import SEAL_ATTR
from labrig.store.isolated import IsolatedReadError, call_isolated
from labrig.store.parse import read_run_here

#: bumped whenever a record's content changes: an index of another version is rebuilt
RECORD_VERSION = 1

#: files read per child process
BATCH_FILES = 32
#: CPU time granted per file of a batch on top of the store's size-based allowance, expressed
#: as bytes of the store's budget (:data:`labrig.store.isolated.CPU_BYTES_PER_S` bytes per
#: second: 5e6 bytes is 0.25 s, several times what a sound file's metadata takes)
PER_FILE_BUDGET_BYTES = 5_000_000

#: metadata: at most this many path components below ``/run`` or an entry
MAX_DEPTH = 3
#: metadata: longer texts (notes, JSON documents) are not indexed
MAX_TEXT_CHARS = 200
#: metadata: arrays of up to this many numbers or texts are indexed as lists
MAX_ARRAY_ITEMS = 16
#: groups whose contents are data or documents, not metadata
SKIP_CLASSES = frozenset({"NXdata", "NXnote"})
#: run-level groups that record how the run ended, not what it was
SKIP_RUN_GROUPS = frozenset({"ramp_to_zero"})
#: attributes that describe the file's structure
HOUSEKEEPING_ATTRS = frozenset({"NX_class", SEAL_ATTR, "default", "units", "long_name"})
#: metadata kept apart in an index (:func:`split_record`): many keys, rarely asked for
DETAIL_PREFIXES = ("instrument/",)
#: metadata every labrig file has the same (indexed, not shown in listings)
QUIET_KEYS = frozenset({"program_name", "definition"})
#: fields of ``/run`` and of entries the record holds already
RUN_FIELDS = frozenset(
    {
        "status",
        "status_reason",
        "start_time",
        "end_time",
        "seed",
        "software_version",
        "protocol_name",
        "planned_entries",
        "exit_code",
        "final_amplifier_voltage_V",
        "description_json",
    }
)
ENTRY_FIELDS = frozenset(
    {
        "title",
        "entry_index",
        "start_time",
        "end_time",
        "status",
        "status_reason",
        "sample_rate",
        "step_definition",
        "duration",
    }
)


def _plain(value: Any) -> Any:
    """An HDF5 value as a JSON value, or ``None`` when it is not metadata (too long, an array
    too large, the ``"null"`` older writers stored for unset values, a non-finite number)."""
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if isinstance(value, str):
        return value if value != "null" and len(value) <= MAX_TEXT_CHARS else None
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, np.integer | int):
        return int(value)
    if isinstance(value, np.floating | float):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.ndarray) and value.ndim == 1 and 0 < value.size <= MAX_ARRAY_ITEMS:
        items = [_plain(v) for v in value.tolist()]
        return items if all(v is not None for v in items) else None
    return None


def _collect(
    group: h5py.Group,
    prefix: str,
    skip_fields: frozenset[str],
    skip_objects: Sequence[h5py.HLObject],
    out: dict[str, Any],
    units: dict[str, str],
) -> None:
    """Scalar datasets and attributes of ``group`` and its small subgroups into ``out``, keyed
    by their path below the top group (``sample/name``)."""
    for name, value in group.attrs.items():
        if name not in HOUSEKEEPING_ATTRS and (v := _plain(value)) is not None:
            out[f"{prefix}{name}"] = v
    depth = prefix.count("/") + 1
    for name in group:
        if not prefix and name in skip_fields:
            continue
        obj = group.get(name)
        if obj is None or any(obj == other for other in skip_objects):
            continue
        key = f"{prefix}{name}"
        if isinstance(obj, h5py.Group):
            if depth < MAX_DEPTH and obj.attrs.get("NX_class") not in SKIP_CLASSES:
                _collect(obj, key + "/", skip_fields, skip_objects, out, units)
        elif isinstance(obj, h5py.Dataset) and obj.size <= MAX_ARRAY_ITEMS and obj.ndim <= 1:
            if obj.dtype.kind not in "iufbOSU":
                continue
            v = _plain(obj[()])
            if v is None:
                continue
            out[key] = v
            u = obj.attrs.get("units")
            if isinstance(u, bytes | str) and u:
                units[key] = u.decode() if isinstance(u, bytes) else u


def _merge(into: dict[str, Any], key: str, value: Any) -> None:
    """Entry-level values: one value when every entry agrees, else the distinct values."""
    if key not in into:
        into[key] = value
        return
    have = into[key]
    values = have if isinstance(have, _Distinct) else _Distinct([have])
    if value not in values:
        values.append(value)
    into[key] = values if len(values) > 1 else values[0]


class _Distinct(list):
    """Several entries' differing values of one key (a list the merge can tell from a value)."""


def read_metadata_here(path: Path | str) -> tuple[dict[str, Any], dict[str, str]]:
    """The run file's metadata (module docstring) and the units of the values that have one.

    Run-level values are keyed by their path below ``/run`` (``instrument/amplifier/identity``,
    ``metadata/operator``); entry-level values by their path below the entry (``sample/name``,
    ``user/name``), merged across entries. The groups entries share with ``/run`` (hard links),
    data groups (NXdata) and notes (NXnote: the protocol and rig texts) are skipped."""
    meta: dict[str, Any] = {}
    units: dict[str, str] = {}
    with h5py.File(path, "r", locking=False) as f:
        run = f.get("run")
        shared: list[h5py.HLObject] = []
        if isinstance(run, h5py.Group):
            skip = [run[k] for k in SKIP_RUN_GROUPS if k in run]
            _collect(run, "", RUN_FIELDS, skip, meta, units)
            shared = [run[k] for k in run if isinstance(run[k], h5py.Group)]
        entry_meta: dict[str, Any] = {}
        for name, g in f.items():
            if name == "run" or not isinstance(g, h5py.Group):
                continue
            if g.attrs.get("NX_class") not in ("NXentry", b"NXentry"):
                continue
            one: dict[str, Any] = {}
            _collect(g, "", ENTRY_FIELDS, shared, one, units)
            for k, v in one.items():
                _merge(entry_meta, k, v)
    for k, v in entry_meta.items():
        meta.setdefault(k, list(v) if isinstance(v, _Distinct) else v)
    return meta, units


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


def _step_scalars(step: dict[str, Any]) -> dict[str, Any]:
    """The step definition's scalar values (numbers, texts, booleans)."""
    return {
        k: v
        for k, v in step.items()
        if isinstance(v, str | int | float | bool)
        and not (isinstance(v, float) and not math.isfinite(v))
    }


def unreadable_record(error: str) -> dict[str, Any]:
    """The record of a file the reader refused (``error``: why, for a person)."""
    return {
        "readable": False,
        "error": error,
        "status": "unreadable",
        "entries": [],
        "metadata": {},
    }


def file_record_here(path: Path | str) -> dict[str, Any]:
    """The record of one file, read in this process (module docstring); never raises for a
    bad file: an unreadable one gives :func:`unreadable_record`."""
    try:
        run, shapes = read_run_here(path, load_data=False)
    except InputFileError as e:
        return unreadable_record("; ".join(_issue_text(i) for i in e.issues))
    except Exception as e:  # the reader's own failure: still one line in the listing
        return unreadable_record(f"{type(e).__name__}: {str(e)[:200]}")
    entries = []
    for e in run:
        n = max((s[0] for s in shapes.get(e.name, {}).values() if s), default=0)
        rate = e.rate_hz if math.isfinite(e.rate_hz) else None
        entries.append(
            {
                "name": e.name,
                "kind": str(e.step.get("kind", "")),
                "status": e.status,
                "samples": int(n),
                "rate_hz": rate,
                "duration_s": (n - 1) / rate if rate and n > 1 else 0.0,
                "step": _step_scalars(e.step),
            }
        )
    record: dict[str, Any] = {
        "readable": True,
        "error": "",
        "status": run.status,
        "reason": run.reason,
        "protocol": run.protocol_name,
        "protocol_file": run.protocol_file,
        "rig_file": run.rig_file,
        "start_time": run.start_time or run.file_time,
        "end_time": run.end_time,
        "seed": run.seed,
        "software_version": run.software_version,
        "planned_entries": len(run.planned_entries),
        "entries": entries,
    }
    try:
        record["metadata"], record["units"] = read_metadata_here(path)
    except Exception as e:  # the checked file read above; its metadata walk failed
        record["metadata"], record["units"] = {}, {}
        record["error"] = f"metadata not read ({type(e).__name__}: {str(e)[:160]})"
    return record


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


def records_here(paths: Sequence[str]) -> list[dict[str, Any]]:
    """:func:`file_record_here` of each path (what a child process of :func:`read_records`
    runs)."""
    return [file_record_here(p) for p in paths]


def _budget(sizes: Sequence[int]) -> int:
    """The size to declare to :func:`call_isolated` for a batch (its limits grow with it)."""
    return int(sum(sizes)) + PER_FILE_BUDGET_BYTES * len(sizes)


def read_records(
    files: Sequence[tuple[Path, int]],
    done: Callable[[int], None] | None = None,
) -> Iterator[tuple[Path, dict[str, Any]]]:
    """The record of every ``(path, size_bytes)``, in order, read in child processes
    (module docstring); ``done(n)`` is called after each batch with the files read so far."""
    n_done = 0
    for i in range(0, len(files), BATCH_FILES):
        batch = files[i : i + BATCH_FILES]
        try:
            records = call_isolated(
                records_here, [str(p) for p, _ in batch], size_bytes=_budget([s for _, s in batch])
            )
        except Exception:  # the child died, ran out of time or could not send its records
            records = [_alone(p, s) for p, s in batch]
        yield from zip([p for p, _ in batch], records, strict=True)
        n_done += len(batch)
        if done is not None:
            done(n_done)


def _alone(path: Path, size: int) -> dict[str, Any]:
    """One file in its own child (after its batch's child failed)."""
    try:
        return call_isolated(file_record_here, str(path), size_bytes=_budget([size]))
    except IsolatedReadError as e:
        return unreadable_record(f"{e}: the file is damaged")
    except Exception as e:  # the child could not send its result back
        last = (str(e).strip().splitlines() or [type(e).__name__])[-1][:200]
        return unreadable_record(f"the reader failed: {last}")
