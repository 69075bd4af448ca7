"""``labrig import``: every input read and checked, then one run file written (beside the target,
renamed over it when complete), one entry per input file or ControlDesk capture.

Formats (docs/import.md shows each with a file under tests/data/import/): delimited text
(:mod:`~labrig.importers.text`), plain MATLAB variables (:mod:`~labrig.importers.mat_tables`)
and dSPACE ControlDesk captures (:mod:`~labrig.importers.dspace`) from v4-v7.3 ``.mat`` files
(:mod:`~labrig.importers.mat_read`).
"""

from __future__ import annotations

import hashlib
import stat
from dataclasses import asdict
from pathlib import Path

from labrig.core.errors import InputFileError, InputIssue
from labrig.core.metadata import RunMetadata
from labrig.core.samples import samples_digest
from labrig.importers.dspace import capture_table, find_captures
from labrig.importers.entry import ImportedEntry, build_entry
from labrig.importers.labels import entry_name
from labrig.importers.limits import MAX_FILE_BYTES
from labrig.importers.mat_read import V5_MAGIC, V73_MAGIC, mat_version, read_tree
from labrig.importers.mat_tables import plain_table
from labrig.importers.options import Checked, ImportOptions, check_options
from labrig.importers.table import Table, bad
from labrig.importers.text import read_text
from labrig.importers.writer import import_description, write_run


def _looks_like_mat(path: Path) -> bool:
    """A MAT-file header, or a ``.mat`` name on binary content (v4 has no header); a ``.mat``
    file of text (``save -ascii``) is text."""
    with path.open("rb") as f:
        head = f.read(512)
    if head.startswith((V5_MAGIC, V73_MAGIC)):
        return True
    return path.suffix.lower() == ".mat" and (mat_version(path) != "4" or b"\x00" in head)


def _pick_captures(path: Path, tables: list[Table], wanted: list[str]) -> list[Table]:
    if not wanted:
        return tables
    names = [t.capture for t in tables]
    picked = []
    for spec in wanted:
        hits = [t for i, t in enumerate(tables, start=1)
                if spec.lower() == t.capture.lower() or spec == str(i)]  # fmt: skip
        if not hits:
            raise bad(path, f"--capture {spec}: no such capture (captures: {', '.join(names)})")
        picked += [t for t in hits if t not in picked]
    return picked


def read_tables(path: Path, checked: Checked) -> list[Table]:
    """The tables of one input file (one, or one per picked ControlDesk capture)."""
    if not path.is_file():
        raise bad(path, "file not found" if not path.exists() else "not a file")
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        raise bad(
            path, f"{size / 2**20:.0f} MiB: at most {MAX_FILE_BYTES / 2**20:.0f} MiB are read"
        )
    try:
        is_mat = _looks_like_mat(path)
    except OSError as e:
        raise bad(path, f"cannot read: {e.strerror}") from None
    if not is_mat:
        if checked.opt.captures:
            raise bad(path, "--capture: a text file holds no ControlDesk captures")
        return [read_text(path, checked.separator, checked.decimal, checked.encoding)]
    tree, version = read_tree(path)
    captures = find_captures(tree)
    if not captures:
        if checked.opt.captures:
            raise bad(path, "--capture: the file holds no ControlDesk capture (a struct with X, Y)")
        return [plain_table(path, tree, version)]
    tables = [capture_table(path, n, c, len(captures), version) for n, c in captures]
    return _pick_captures(path, tables, checked.opt.captures)


def _check_out(files: list[Path], out: Path, overwrite: bool) -> None:
    """The one output check (:func:`labrig.core.outputs.check_outputs`): ``--out`` is not an
    input (any spelling, a link), not a run file being written, not a folder, not an existing
    file without ``--overwrite``."""
    from labrig.core.outputs import check_outputs
    from labrig.store.reader import being_written

    check_outputs([out], inputs=files, overwrite=overwrite, being_written=being_written)


def _digest(path: Path) -> bytes:
    with path.open("rb") as fh:
        return hashlib.file_digest(fh, "sha256").digest()


def check_distinct(files: list[Path]) -> None:
    """Each input once: the same path twice, two paths to one file (a link, ``./a.csv`` and
    ``a.csv``) or two files of the same content would make two entries of the same data (and a
    leave-one-entry-out score that has seen the entry it scores). An
    :class:`~labrig.core.errors.InputFileError` names every repeat and the input it repeats.
    Contents are compared (SHA-256) only between files of the same size."""
    issues: list[InputIssue] = []
    first: dict[tuple[int, int], Path] = {}
    by_size: dict[int, list[Path]] = {}
    for f in files:
        try:
            st = f.stat()
        except OSError:
            continue  # not there: reading it says so
        if not stat.S_ISREG(st.st_mode):
            continue
        key = (st.st_dev, st.st_ino)
        if key in first:
            same = "the same path" if f == first[key] else f"the same file as {first[key]}"
            issues.append(InputIssue(str(f), None, "", f"given twice ({same}): give each once"))
            continue
        first[key] = f
        by_size.setdefault(st.st_size, []).append(f)
    for group in by_size.values():
        seen: dict[bytes, Path] = {}
        for f in group if len(group) > 1 else ():
            try:
                digest = _digest(f)
            except OSError:
                continue
            if digest in seen:
                issues.append(
                    InputIssue(
                        str(f),
                        None,
                        "",
                        f"the same content as {seen[digest]}: the same data would be two "
                        "entries; give each record once",
                    )
                )
            else:
                seen[digest] = f
    if issues:
        raise InputFileError(issues)


def read_entries(files: list[Path], checked: Checked) -> list[ImportedEntry]:
    """Every input read and checked, in the order given (nothing is written)."""
    entries: list[ImportedEntry] = []
    taken: set[str] = set()
    seen: dict[bytes, ImportedEntry] = {}
    issues: list[InputIssue] = []
    for f in files:
        for table in read_tables(Path(f), checked):
            name = entry_name(table.source, table.capture, table.n_captures, taken)
            e = build_entry(table, checked, name)
            # the same samples from files that differ in bytes (line ends, a BOM, a header):
            # two entries of one record would let a leave-one-out score see what it scores
            first = seen.setdefault(samples_digest(e.voltage_V, e.strain), e)
            if first is not e:
                issues.append(
                    InputIssue(
                        str(e.source),
                        None,
                        e.meta.get("capture", ""),
                        f"holds the same voltage and strain samples as {first.source}"
                        + (f" ({first.meta['capture']})" if first.meta.get("capture") else "")
                        + ": give each record once",
                    )
                )
            entries.append(e)
            taken.add(name)
    if issues:
        raise InputFileError(issues)
    return entries


def import_files(
    files: list[Path],
    out: Path,
    opt: ImportOptions,
    overwrite: bool = False,
    metadata: RunMetadata | None = None,
) -> list[ImportedEntry]:
    """Read every file, then write the run file ``out`` (beside it, renamed over it when
    complete: a bad input or a failed write leaves an existing ``out`` as it was), with
    ``metadata`` (``--meta``, ``--operator``, ``--sample``: :mod:`labrig.core.metadata`)."""
    if not files:
        raise InputFileError([InputIssue("", None, "", "no input files given")])
    checked = check_options(opt)
    files = [Path(f) for f in files]
    _check_out(files, out, overwrite)
    check_distinct(files)
    entries = read_entries(files, checked)
    write_run(out, entries, import_description(files, asdict(opt)), metadata, overwrite)
    return entries
