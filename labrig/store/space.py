"""Disk space for a run file: what a run needs, what the disk has, and a reserve to close with.

A run that fills the disk must still be able to record how it ended. Three measures:

- before a run: :func:`estimate_run_bytes` (the chunks HDF5 allocates, channel by channel,
  plus metadata) against :func:`free_bytes` of the run file's filesystem;
- before each block: the chunks the block will allocate against the free space, so the run
  stops cleanly (:class:`~labrig.core.errors.StorageError`) before HDF5 ever fails a write;
- a :class:`Reserve` file of ``RESERVE_BYTES`` beside the run file, allocated when the run
  starts and deleted when the run's final records are written, so they fit even when another
  program has taken the last byte.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import math
import os
import shutil
from collections.abc import Iterable
from pathlib import Path

log = logging.getLogger("labrig.store")

#: sample datasets are float64
SAMPLE_BYTES = 8
#: bytes a Fletcher32 checksum adds to every chunk
CHECKSUM_BYTES = 4
#: metadata of one entry (groups, attributes, B-tree nodes), generously
ENTRY_METADATA_BYTES = 64 * 1024
#: metadata of the run (protocol and rig texts are added to this), generously
RUN_METADATA_BYTES = 256 * 1024
#: free space kept beyond what a block needs, for the metadata it updates
BLOCK_MARGIN_BYTES = 64 * 1024
#: the reserve file's size: room for the final records (ramp, statuses, times)
RESERVE_BYTES = 1024 * 1024
#: errno values that mean the disk (or the user's quota) is full
FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)
#: what a run's reason says when the disk or quota is full
DISK_FULL = "disk full (no space left on the device or quota exceeded)"


def chunk_length(rate_hz: float) -> int:
    """Samples per chunk of a sample dataset: the next power of two at or above one second of
    samples, from 1024 to 65536."""
    return int(min(max(1024, 2 ** math.ceil(math.log2(max(rate_hz, 1)))), 65536))


def chunk_bytes(rate_hz: float) -> int:
    """Bytes HDF5 allocates for one chunk of one channel (samples plus checksum)."""
    return chunk_length(rate_hz) * SAMPLE_BYTES + CHECKSUM_BYTES


def estimate_entry_bytes(n_samples: int, rate_hz: float, n_channels: int) -> int:
    """Bytes one entry takes: whole chunks per channel (``time`` included) plus metadata."""
    chunks = max(1, math.ceil(n_samples / chunk_length(rate_hz)))
    return n_channels * chunks * chunk_bytes(rate_hz) + ENTRY_METADATA_BYTES


def estimate_run_bytes(entries: Iterable[tuple[int, float, int]], text_bytes: int = 0) -> int:
    """Bytes a run file will take: ``entries`` are ``(n_samples, rate_hz, n_channels)``;
    ``text_bytes`` the protocol and rig texts stored with it. The reserve is not included."""
    total = RUN_METADATA_BYTES + 2 * text_bytes
    return total + sum(estimate_entry_bytes(n, r, c) for n, r, c in entries)


def free_bytes(path: Path | str) -> int:
    """Bytes free for this user on the filesystem that holds (or will hold) ``path``."""
    p = Path(path).absolute()
    for candidate in (p, *p.parents):
        if candidate.exists():
            return shutil.disk_usage(candidate).free
    return 0


def is_disk_full(exc: BaseException) -> bool:
    """True when ``exc`` says the disk or quota is full (OSError errno, or HDF5's message)."""
    if isinstance(exc, OSError) and exc.errno in FULL_ERRNOS:
        return True
    text = str(exc)
    return any(f"errno = {n}," in text for n in FULL_ERRNOS) or any(
        os.strerror(n) in text for n in FULL_ERRNOS
    )


class Reserve:
    """A file of ``size`` bytes allocated on the run file's filesystem, deleted by
    :meth:`release` to give that room back (idempotent, never raises)."""

    def __init__(self, run_path: Path, size: int = RESERVE_BYTES):
        self.path = run_path.with_name(f".{run_path.name}.reserve")
        self.size = size
        self._held = False
        self._folder: int | None = None
        if size <= 0:
            return
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            try:
                os.posix_fallocate(fd, 0, size)
            except OSError as e:
                if e.errno in FULL_ERRNOS:
                    raise
                # no fallocate here: write incompressible bytes instead
                os.write(fd, os.urandom(size))
            os.fsync(fd)
        except BaseException:
            os.close(fd)
            with contextlib.suppress(OSError):
                os.unlink(self.path)
            raise
        os.close(fd)
        self._held = True
        # the folder held open: the reserve is deleted where it is, even if the folder has
        # been renamed meanwhile
        with contextlib.suppress(OSError, AttributeError):
            self._folder = os.open(self.path.parent, os.O_RDONLY | os.O_DIRECTORY)

    @property
    def held(self) -> bool:
        return self._held

    def release(self) -> None:
        if not self._held:
            return
        self._held = False
        folder, self._folder = self._folder, None
        try:
            if folder is not None and os.unlink in os.supports_dir_fd:
                os.unlink(self.path.name, dir_fd=folder)
            else:
                os.unlink(self.path)
        except OSError as e:
            log.error("cannot delete the reserve file %s: %s", self.path, e)
        finally:
            if folder is not None:
                os.close(folder)
