"""Listing run files: which runs folders hold, what each one is, filtered on request.

:func:`list_runs` finds the run files under folders (recursively) or takes files one by one,
brings each folder's index up to date (:mod:`labrig.catalogue.index`: only files whose stamp
changed are read, from their summary or in full, in child processes with time limits,
:mod:`labrig.catalogue.read`), checks that every ``--where`` key is one the runs listed have,
and keeps the runs that satisfy every condition (:mod:`labrig.catalogue.where`). A file the
reader refuses is listed as ``unreadable`` with the reader's reason; it never stops the
listing.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from labrig.catalogue.index import INDEX_NAME, FolderIndex, Stamp
from labrig.catalogue.where import Condition, check_keys, matches, metadata_values, parse_all
from labrig.core.errors import InputFileError, InputIssue

#: file names the catalogue takes for run files when it searches a folder
RUN_SUFFIXES = (".h5", ".hdf5")
#: ``progress(files_read, files_to_read)`` while the index is brought up to date
ScanProgress = Callable[[int, int], None]

__all__ = [
    "INDEX_NAME",
    "RUN_SUFFIXES",
    "ListedRun",
    "Listing",
    "entry_summary",
    "find_run_files",
    "list_runs",
]


@dataclass
class ListedRun:
    """One run file of a listing: its path (as the folder argument spells it), its record
    (:mod:`labrig.catalogue.read`) and the entries that satisfied the entry conditions."""

    path: Path
    record: dict[str, Any]
    entries: list[str] = field(default_factory=list)

    @property
    def readable(self) -> bool:
        return bool(self.record.get("readable"))

    def to_json(self) -> dict[str, Any]:
        """What ``labrig runs --json`` prints for the run."""
        r = self.record
        return {
            "path": str(self.path),
            **{k: v for k, v in r.items() if k not in ("entries", "metadata", "units")},
            "summary": entry_summary(r),
            "matching_entries": self.entries,
            "entries": r.get("entries", []),
            "metadata": r.get("metadata", {}),
            "units": r.get("units", {}),
        }


@dataclass
class Listing:
    """The result of :func:`list_runs`."""

    runs: list[ListedRun]
    #: run files looked at (before filtering)
    files: int
    #: files read now (the others came from an index)
    read: int
    #: every unreadable file among those looked at, whether it matched or not
    unreadable: list[ListedRun]
    #: the index files used
    indexes: list[Path]
    notes: list[str]
    elapsed_s: float


def _numbers(values: Sequence[Any]) -> list[float]:
    return sorted({float(v) for v in values if isinstance(v, int | float) and v == v})


def entry_summary(record: dict[str, Any]) -> dict[str, Any]:
    """A run's entries in a few numbers: count, kinds, amplitudes (V), frequencies (Hz),
    recorded time (s) and samples."""
    entries = record.get("entries", [])
    steps = [e.get("step", {}) for e in entries]
    return {
        "entries": len(entries),
        "kinds": sorted({str(e.get("kind")) for e in entries if e.get("kind")}),
        "amplitudes_V": _numbers([s.get("amplitude_V") for s in steps]),
        "frequencies_hz": _numbers([s.get("frequency_hz") for s in steps]),
        "duration_s": float(sum(e.get("duration_s") or 0.0 for e in entries)),
        "samples": int(sum(e.get("samples") or 0 for e in entries)),
    }


def _walk(folder: Path, rel: str = "") -> Iterator[tuple[str, Path, os.stat_result]]:
    """Run files below ``folder`` (hidden names and symbolic links to folders skipped)."""
    try:
        items = list(os.scandir(folder / rel if rel else folder))
    except OSError:
        return
    for item in items:
        if item.name.startswith("."):
            continue
        name = f"{rel}/{item.name}" if rel else item.name
        try:
            if item.is_dir(follow_symlinks=False):
                yield from _walk(folder, name)
            elif item.name.lower().endswith(RUN_SUFFIXES) and item.is_file():
                yield name, Path(item.path), item.stat()
        except OSError:
            continue


def _drop_undecodable(targets: dict[Path, _Wanted]) -> list[str]:
    """Take out of ``targets`` the files whose names are not UTF-8 (the index keeps names as
    UTF-8 text); a note naming them."""
    dropped = []
    for folder, wanted in targets.items():
        for rel in list(wanted.files):
            try:
                rel.encode("utf-8")
            except UnicodeEncodeError:
                del wanted.files[rel]
                dropped.append(os.fsencode(folder / rel).decode("utf-8", "backslashreplace"))
    if not dropped:
        return []
    return [
        f"not listed: {len(dropped)} file(s) whose name is not UTF-8 text ({dropped[0]}"
        f"{', ...' if len(dropped) > 1 else ''}): rename them to list them"
    ]


def find_run_files(folder: Path) -> dict[str, tuple[Path, Stamp]]:
    """The run files below ``folder``: path relative to it -> (path, stamp)."""
    return {rel: (path, Stamp.of(st)) for rel, path, st in _walk(folder)}


@dataclass
class _Wanted:
    """The files one folder's index answers for, and whether the folder was listed whole
    (then rows of files that are gone are deleted)."""

    files: dict[str, tuple[Path, Stamp]] = field(default_factory=dict)
    whole: bool = False


def _targets(paths: Sequence[Path]) -> dict[Path, _Wanted]:
    """Folder -> the files its index answers for; a path that is neither a folder nor a file
    is an :class:`InputFileError`."""
    wanted: dict[Path, _Wanted] = {}
    missing = []
    for p in paths:
        if p.is_dir():
            w = wanted.setdefault(p, _Wanted())
            w.files.update(find_run_files(p))
            w.whole = True
        elif p.is_file():
            st = p.stat()
            w = wanted.setdefault(p.parent, _Wanted())
            w.files.setdefault(p.name, (p, Stamp.of(st)))
        else:
            missing.append(p)
    if missing:
        raise InputFileError(
            [
                InputIssue(
                    str(p),
                    None,
                    "",
                    (
                        "not found"
                        if not p.exists()
                        else "not a file nor a folder (a pipe, socket or device)"
                    )
                    + ": give folders of run files or run files",
                )
                for p in missing
            ]
        )
    return wanted


def _update(
    index: FolderIndex,
    wanted: _Wanted,
    reindex: bool,
    progress: ScanProgress | None,
    done_before: int,
    total: int,
) -> int:
    """Read the files whose stamp changed into ``index``; returns how many were read."""
    from labrig.catalogue.read import BATCH_FILES, read_records

    have = index.stamps()
    stale = [rel for rel, (_, s) in wanted.files.items() if reindex or have.get(rel) != s]
    if wanted.whole:
        index.remove(rel for rel in have if rel not in wanted.files)
    batch: list[tuple[str, Stamp, dict[str, Any]]] = []
    files = [(wanted.files[rel][0], wanted.files[rel][1].size) for rel in stale]
    by_path = {str(wanted.files[rel][0]): rel for rel in stale}

    def done(n: int) -> None:
        if progress is not None:
            progress(done_before + n, total)

    for path, record in read_records(files, done, full=reindex):
        rel = by_path[str(path)]
        batch.append((rel, wanted.files[rel][1], record))
        if len(batch) >= BATCH_FILES:
            index.put(batch)
            batch = []
    index.put(batch)
    return len(stale)


def _stale_count(folder: Path, wanted: _Wanted, reindex: bool) -> int:
    if reindex:
        return len(wanted.files)
    with FolderIndex(folder) as index:
        have = index.stamps()
    return sum(1 for rel, (_, s) in wanted.files.items() if have.get(rel) != s)


def _sort_key(run: ListedRun) -> tuple:
    return (not run.readable, str(run.record.get("start_time") or ""), str(run.path))


def _needs_detail(index: FolderIndex, conditions: Sequence[Condition]) -> bool:
    """Whether a condition names a metadata key kept in the records' second part."""
    keys = dict.fromkeys(index.detail_keys())
    return any(c.scope == "entry-or-metadata" and metadata_values(keys, c.key) for c in conditions)


def list_runs(
    paths: Sequence[Path],
    where: Sequence[str | Condition] = (),
    *,
    detail: bool = False,
    reindex: bool = False,
    progress: ScanProgress | None = None,
) -> Listing:
    """The runs under ``paths`` (folders, searched recursively, or run files) that satisfy
    every ``where`` condition (texts are parsed first: a bad one raises
    :class:`~labrig.catalogue.where.WhereError` before any file is read), oldest first,
    unreadable files last. ``detail``: the records hold the instrument's metadata and the
    units too (``--json``); ``reindex`` reads every file again."""
    t0 = time.perf_counter()
    conditions = [c if isinstance(c, Condition) else parse_all([c])[0] for c in where]
    targets = _targets(paths)
    notes: list[str] = _drop_undecodable(targets)
    total = sum(_stale_count(f, w, reindex) for f, w in targets.items()) if progress else 0
    listed: list[ListedRun] = []
    indexes: list[Path] = []
    read = 0
    seen: set[Path] = set()
    detail_keys: set[str] = set()
    for folder, wanted in targets.items():
        with FolderIndex(folder) as index:
            read += _update(index, wanted, reindex, progress, read, total)
            records = index.records(wanted.files, detail or _needs_detail(index, conditions))
            detail_keys |= index.detail_keys()
            if index.note:
                notes.append(index.note)
            if index.path is not None:
                indexes.append(index.path)
        real = folder.resolve()
        for rel, (path, _) in wanted.files.items():
            key = real / rel
            if key in seen or rel not in records:
                continue
            seen.add(key)
            listed.append(ListedRun(path, records[rel]))
    check_keys(conditions, [r.record for r in listed], detail_keys)
    unreadable = sorted((r for r in listed if not r.readable), key=lambda r: str(r.path))
    runs = []
    for run in listed:
        ok, entries = matches({**run.record, "path": str(run.path)}, conditions)
        if ok:
            run.entries = entries
            runs.append(run)
    runs.sort(key=_sort_key)
    return Listing(
        runs=runs,
        files=len(listed),
        read=read,
        unreadable=unreadable,
        indexes=indexes,
        notes=notes,
        elapsed_s=time.perf_counter() - t0,
    )
