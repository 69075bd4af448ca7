"""The catalogue's index of a folder: one SQLite file, ``FOLDER/.labrig-index.sqlite``.

One row per run file, keyed by its path below the folder, with the file's *stamp* when it was
read (:class:`Stamp`: size, modification time, inode and inode change time) and its record
(:mod:`labrig.catalogue.read`) as JSON, in two parts
(:func:`~labrig.catalogue.read.split_record`): the part every listing reads and the instrument's
metadata with the units, read only when asked (``--json``, or a ``--where`` key that names a
key of that part: the table ``detail_keys`` lists them). A row whose
stamp differs from the file's is stale and the file is read again; rows of files that
are gone are deleted. The HDF5 files stay the source of truth: deleting the index costs one
rebuild, nothing else. An index of another record or schema version is emptied on opening.

A folder that cannot hold the index (read-only, a full disk) gets an index in memory for the
one listing, said in :attr:`FolderIndex.note`. Writes are committed every batch, so a listing
stopped half way keeps what it read.
"""

from __future__ import annotations

import contextlib
import json
import os
import sqlite3
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from labrig.catalogue.read import RECORD_VERSION, join_record, split_record

INDEX_NAME = ".labrig-index.sqlite"
#: 2: the stamp holds the inode and its change time (a file replaced by another of the same size
#: with its modification time put back was taken for the one read before)
SCHEMA_VERSION = 2
#: seconds a listing waits for another process writing the same index
BUSY_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class Stamp:
    """What says a file changed: its size (bytes), modification time (ns), inode number and
    inode change time (ns). A program can set the modification time back (``touch -d``,
    ``os.utime``, ``cp -p``), but not the change time: writing the file, or replacing it by
    another (a new inode, or the same one rewritten), moves it. Costs nothing: the listing's
    ``stat`` of each file gives all four."""

    size: int
    mtime_ns: int
    ino: int = 0
    ctime_ns: int = 0

    @classmethod
    def of(cls, st: os.stat_result) -> Stamp:
        # SQLite integers are signed 64-bit; some file systems number inodes up to 2**64 - 1
        ino = st.st_ino - 2**64 if st.st_ino >= 2**63 else st.st_ino
        return cls(st.st_size, st.st_mtime_ns, ino, st.st_ctime_ns)


def _connect(path: Path | str) -> sqlite3.Connection:
    db = sqlite3.connect(str(path), timeout=BUSY_TIMEOUT_S, isolation_level=None)
    _connect_tables(db)
    return db


def _connect_tables(db: sqlite3.Connection) -> None:
    """The index's tables, created when missing."""
    db.execute("CREATE TABLE IF NOT EXISTS info (key TEXT PRIMARY KEY, value TEXT NOT NULL)")
    db.execute(
        "CREATE TABLE IF NOT EXISTS files (path TEXT PRIMARY KEY, size INTEGER NOT NULL, "
        "mtime_ns INTEGER NOT NULL, ino INTEGER NOT NULL, ctime_ns INTEGER NOT NULL, "
        "record TEXT NOT NULL, detail TEXT NOT NULL)"
    )
    db.execute("CREATE TABLE IF NOT EXISTS detail_keys (key TEXT PRIMARY KEY)")


def _version_text() -> str:
    return f"{SCHEMA_VERSION}.{RECORD_VERSION}"


class FolderIndex:
    """The index of one folder (module docstring); a context manager closing the database."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.path: Path | None = folder / INDEX_NAME
        self.note = ""
        try:
            if self.path.is_symlink() or (self.path.exists() and not self.path.is_file()):
                # never written through: a link could lead out of the folder, to a database
                # whose tables this index would drop
                raise sqlite3.OperationalError("a symbolic link or not a file: not followed")
            self.db = self._open_file(self.path)
        except sqlite3.Error as e:
            self.note = f"index kept in memory ({self.path}: {e})"
            self.path = None
            self.db = _connect(":memory:")
            self._check_version()

    def _open_file(self, path: Path) -> sqlite3.Connection:
        """The index file, replaced when it is not a database (a damaged cache is rebuilt)."""
        try:
            self.db = _connect(path)
            self._check_version()
        except sqlite3.DatabaseError as e:
            if isinstance(e, sqlite3.OperationalError) or not path.is_file():
                raise
            if hasattr(self, "db"):
                self.close()
            path.unlink()
            self.note = f"{path} was damaged ({e}): rebuilt"
            self.db = _connect(path)
            self._check_version()
        return self.db

    def _check_version(self) -> None:
        row = self.db.execute("SELECT value FROM info WHERE key = 'version'").fetchone()
        if row is None or row[0] != _version_text():
            with self.db:
                self.db.execute("BEGIN IMMEDIATE")
                self.db.execute("DROP TABLE IF EXISTS files")
                self.db.execute("DROP TABLE IF EXISTS detail_keys")
                self.db.execute(
                    "INSERT OR REPLACE INTO info (key, value) VALUES ('version', ?)",
                    (_version_text(),),
                )
            _connect_tables(self.db)

    def __enter__(self) -> FolderIndex:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        with contextlib.suppress(sqlite3.Error):
            self.db.close()

    def stamps(self) -> dict[str, Stamp]:
        """Every indexed path and the stamp it was read with."""
        rows = self.db.execute("SELECT path, size, mtime_ns, ino, ctime_ns FROM files")
        return {p: Stamp(s, m, i, c) for p, s, m, i, c in rows}

    def records(self, paths: Iterable[str], detail: bool = False) -> dict[str, dict[str, Any]]:
        """The records of ``paths`` the index holds; without ``detail``, the part every
        listing reads (:func:`~labrig.catalogue.read.split_record`)."""
        wanted = set(paths)
        column = "record, detail" if detail else "record, ''"
        rows = self.db.execute(f"SELECT path, {column} FROM files")
        out = {}
        for p, core, rest in rows:
            if p in wanted:
                record = json.loads(core)
                out[p] = join_record(record, json.loads(rest)) if detail else record
        return out

    def detail_keys(self) -> set[str]:
        """The metadata keys kept in the records' second part (any file, now or before)."""
        return {k for (k,) in self.db.execute("SELECT key FROM detail_keys")}

    def put(self, rows: Iterable[tuple[str, Stamp, dict[str, Any]]]) -> None:
        """Store records (one transaction); a folder that refuses the write moves the index to
        memory (:attr:`note`) and keeps going."""
        data, keys = [], set()
        for p, s, r in rows:
            core, rest = split_record(r)
            keys.update(rest["metadata"])
            data.append(
                (p, s.size, s.mtime_ns, s.ino, s.ctime_ns, json.dumps(core), json.dumps(rest))
            )
        for attempt in (1, 2):
            try:
                with self.db:
                    self.db.execute("BEGIN IMMEDIATE")
                    self.db.executemany(
                        "INSERT OR REPLACE INTO files VALUES (?, ?, ?, ?, ?, ?, ?)", data
                    )
                    self.db.executemany(
                        "INSERT OR IGNORE INTO detail_keys VALUES (?)", [(k,) for k in keys]
                    )
                return
            except sqlite3.Error as e:
                if attempt == 2:
                    raise
                self._to_memory(e)

    def remove(self, paths: Iterable[str]) -> None:
        """Forget files that are gone."""
        data = [(p,) for p in paths]
        if not data:
            return
        try:
            with self.db:
                self.db.execute("BEGIN IMMEDIATE")
                self.db.executemany("DELETE FROM files WHERE path = ?", data)
        except sqlite3.Error as e:
            self._to_memory(e)

    def _to_memory(self, error: sqlite3.Error) -> None:
        """Continue with a copy of the index in memory (the folder refused a write)."""
        memory = _connect(":memory:")
        with contextlib.suppress(sqlite3.Error):
            self.db.backup(memory)
        self.close()
        self.db = memory
        self.note = f"index kept in memory ({self.path}: {error})"
        self.path = None
