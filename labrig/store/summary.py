"""A run file's *summary*: what a listing shows of it, written into the file by the writer when it
closes the file, so that ``labrig runs`` reads one dataset instead of the whole file
(docs/runfile.md, "Summary"; docs/catalogue.md).

``/run/summary`` is a JSON text (sealed like every object labrig writes)::

    {"summary_version": 1, "status": "complete", "reason": "", "protocol": "paper sweep",
     "protocol_file": "experiments/sweep.yaml", "rig_file": "", "start_time": "2026-...",
     "end_time": "2026-...", "seed": 5400616385192348103, "software_version": "0.1.0",
     "planned_entries": 11,
     "entries": [{"name", "kind", "status", "samples", "rate_hz", "duration_s",
                  "step": {the step definition's scalar values}}, ...],
     "metadata": {"sample/name": "P-888 #3", "instrument/amplifier/identity": "...", ...},
     "units": {"instrument/amplifier/gain_V_per_V": "V/V", ...}}

It is made by :func:`summary_of` from the open file with the same reader as a full read
(:mod:`labrig.store.parse`, seals not checked: the writer wrote them) and the generic metadata
walk :func:`metadata_of`, so a summary and a full read of the same file give the same record
(a test compares them). Integers stay integers (JSON has no size limit; a 63-bit seed keeps
every digit).

A file has no summary while it is written, after a crash or ``kill -9`` (the writer never
closed it), when a resume reopens it (until it closes it again), or when an older labrig or
another program wrote it: readers then read the whole file. Another program that adds metadata
after labrig closed the file leaves the summary as labrig wrote it (``labrig runs --reindex``
reads the files in full); :func:`labrig.store.writer.seal_all` (an edit made on purpose)
writes it again.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from labrig.store.format import SEAL_ATTRS, STRING_DTYPE, check_seal
from labrig.store.isolated import allow_cpu
from labrig.store.parse import read_open

#: where the summary lives
SUMMARY_NAME = "summary"
#: bumped when a summary's content changes: a summary of another version is not used
SUMMARY_VERSION = 1
#: the longest summary a reader parses (bytes of JSON): a 1000-entry run's is about 1 MB
MAX_SUMMARY_BYTES = 20_000_000

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
HOUSEKEEPING_ATTRS = frozenset({"NX_class", "default", "units", "long_name", *SEAL_ATTRS})
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
        SUMMARY_NAME,
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
    too large, the ``"null"`` older writers stored for unset values, a non-finite number).
    Whole numbers stay whole (``int``, never through a float)."""
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
    allow_cpu()
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


def metadata_of(f: h5py.File) -> tuple[dict[str, Any], dict[str, str]]:
    """An open run file's metadata and the units of the values that have one: every scalar
    dataset (text up to :data:`MAX_TEXT_CHARS`, number, boolean; arrays of up to
    :data:`MAX_ARRAY_ITEMS`) and attribute in ``/run`` and in each entry, down to
    :data:`MAX_DEPTH` levels, but the fields the summary holds already.

    Run-level values are keyed by their path below ``/run`` (``instrument/amplifier/identity``,
    ``metadata/operator``); entry-level values by their path below the entry (``sample/name``,
    ``user/name``), merged across entries (one value when they agree, else the distinct
    values). The groups entries share with ``/run`` (hard links), data groups (NXdata) and notes
    (NXnote: the protocol and rig texts) are skipped."""
    meta: dict[str, Any] = {}
    units: dict[str, str] = {}
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


def step_scalars(step: dict[str, Any]) -> dict[str, Any]:
    """The step definition's scalar values (numbers, texts, booleans)."""
    return {
        k: v
        for k, v in step.items()
        if isinstance(v, str | int | float | bool)
        and not (isinstance(v, float) and not math.isfinite(v))
    }


def summary_of(path: Path | str, f: h5py.File, seals: bool = False) -> dict[str, Any]:
    """The summary (module docstring) of the run file ``path`` open as ``f``; raises
    :class:`~labrig.core.errors.InputFileError` as :func:`labrig.store.parse.read_run_here` does.
    ``seals``: check the seals first (a reader that has not checked them)."""
    run, shapes = read_open(path, f, load_data=False, seals=seals)
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
                "step": step_scalars(e.step),
            }
        )
    metadata, units = metadata_of(f)
    return {
        "summary_version": SUMMARY_VERSION,
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
        "metadata": metadata,
        "units": units,
    }


def summary_text(summary: dict[str, Any]) -> str:
    """The summary as stored: strict JSON (non-finite numbers as ``null``), integers exact."""
    from labrig.core.jsonsafe import json_safe

    return json.dumps(json_safe(summary), allow_nan=False, separators=(",", ":"))


def write_summary(path: Path | str, f: h5py.File) -> h5py.Dataset:
    """Write (or replace) ``/run/summary`` of the open run file ``f`` at ``path`` from what it
    holds now; the caller seals ``/run`` and the summary. Raises what :func:`summary_of`
    raises."""
    text = summary_text(summary_of(path, f))
    run = f["run"]
    if SUMMARY_NAME in run:
        del run[SUMMARY_NAME]
    ds = run.create_dataset(SUMMARY_NAME, data=text, dtype=STRING_DTYPE)
    ds.attrs["long_name"] = "what a listing of run files shows (JSON), as labrig closed the file"
    return ds


def read_summary_here(path: Path | str) -> dict[str, Any] | None:
    """The summary of the run file ``path`` (read in this process), or ``None`` when it has
    none that can be used: none written, of another version, or not matching its seal. Reads
    one dataset; the rest of the file is neither read nor checked. Raises what opening the
    file raises (``OSError``: not HDF5)."""
    with h5py.File(path, "r", locking=False) as f:
        allow_cpu()
        run = f.get("run")
        ds = run.get(SUMMARY_NAME) if isinstance(run, h5py.Group) else None
        if not isinstance(ds, h5py.Dataset) or ds.shape != () or ds.dtype.kind != "O":
            return None
        found = check_seal(ds)
        if found.problem or not found.sealed:
            return None
        text = ds[()]
    text = text.decode("utf-8", "replace") if isinstance(text, bytes) else str(text)
    if len(text) > MAX_SUMMARY_BYTES:
        return None
    try:  # sealed: as labrig wrote it (a nesting too deep raises RecursionError, caught)
        summary = json.loads(text)
    except (ValueError, RecursionError):
        return None
    if not isinstance(summary, dict) or summary.get("summary_version") != SUMMARY_VERSION:
        return None
    return summary
