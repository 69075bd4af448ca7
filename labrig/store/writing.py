"""Is a run file being written now? The writer marks the file with its process id and host
(root attributes ``writer_pid``, ``writer_host``, set when it opens the file; ``writer_pid`` -1
once it closed the file without finishing the run) and keeps its
modification time fresh: every block is flushed (about 10 times a second) and a rest between
entries touches the file (:meth:`labrig.store.writer.RunWriter.heartbeat`).

A file whose run status is ``running`` is **being written** when its modification time is
less than :data:`STALE_S` old and, if it was written on this host, its writer's process is
alive; otherwise the writer stopped without finishing it (**incomplete**: a crash, a kill).
"""

from __future__ import annotations

import os
import socket
import time
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

#: a file not modified for this long (s) is no longer being written: the writer touches it at
#: least every block (0.1 s) and every rest block; a real DAQ may stall a few seconds at most
STALE_S = 10.0


def this_host() -> str:
    return socket.gethostname()


#: a file's identity: (device, inode) of the file opened, whatever name it has now
FileId = tuple[int, int]


def file_identity(f: h5py.File) -> FileId:
    """The identity of the file ``f`` has open (not of whatever its path names now: a file
    replaced at its path, a run rewritten with ``--overwrite``, is another file)."""
    st = os.fstat(f.id.get_vfd_handle())
    return st.st_dev, st.st_ino


def path_identity(path: Path | str) -> FileId | None:
    """The identity of the file at ``path`` now; None when there is none (raises the other
    errors of ``stat``: a folder made unreadable says nothing about the file)."""
    try:
        st = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None
    return st.st_dev, st.st_ino


def mark_writer(f: h5py.File) -> None:
    """Record this process as the file's writer (root attributes; sealed with the root)."""
    f.attrs["writer_pid"] = os.getpid()
    f.attrs["writer_host"] = this_host()


def unmark_writer(f: h5py.File) -> None:
    """The writer closed the file without finishing the run: no process writes it now
    (``writer_pid`` -1)."""
    f.attrs["writer_pid"] = -1


@dataclass(frozen=True)
class Writer:
    """Who writes a run file and how recently it wrote (``age_s``: since its modification)."""

    pid: int | None
    host: str
    age_s: float
    alive: bool

    def describe(self) -> str:
        who = f"process {self.pid}" if self.pid is not None and self.pid >= 0 else "a process"
        where = "" if self.host in ("", this_host()) else f" on {self.host}"
        return f"{who}{where}, last written {self.age_s:.1f} s ago"


def pid_alive(pid: int) -> bool:
    """True when a process of that id exists (a zombie counts as gone)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:  # a zombie (a killed child not yet reaped) holds its id but writes nothing
        with open(f"/proc/{pid}/stat", "rb") as fh:
            return fh.read().rsplit(b")", 1)[-1].split()[0] != b"Z"
    except OSError:
        return True


def writer_of(path: Path | str, pid: object, host: object, now: float | None = None) -> Writer:
    """The writer recorded in a file (``pid``, ``host``: its root attributes, or ``None``) and
    whether it is still writing it (module docstring)."""
    age = (time.time() if now is None else now) - Path(path).stat().st_mtime
    pid_i = int(pid) if isinstance(pid, int | np.integer) else None
    host_s = host.decode() if isinstance(host, bytes) else str(host or "")
    alive = age < STALE_S and (pid_i is None or pid_i >= 0)
    if alive and pid_i is not None and host_s in ("", this_host()):
        alive = pid_alive(pid_i)
    return Writer(pid_i, host_s, max(age, 0.0), alive)
