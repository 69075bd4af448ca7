"""Writing a run file incrementally while a protocol runs (layout: :mod:`labrig.store`).

Crash safety: :meth:`EntryWriter.append` extends every channel, writes the block and flushes the
file (``H5Fflush``) before returning, so after a ``kill -9`` the file opens and holds every block
whose ``append`` returned. Sample datasets carry Fletcher32 checksums (a damaged chunk is
reported on reading, not read back as numbers).

Disk full (:mod:`labrig.store.space`): before each block the free space is checked against the
chunks the block allocates; a block that does not fit, or a write HDF5 refuses, raises
:class:`~labrig.core.errors.StorageError` with the file as it was before the block (the channels are
cut back to the last complete block). The final records (:meth:`RunWriter.set_run_value`,
:meth:`RunWriter.add_run_collection`, :meth:`RunWriter.finish`) first release the writer's
reserve file, so they fit on a disk another program filled.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from datetime import datetime, timedelta
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from labrig.core.errors import InputFileError, StorageError
from labrig.core.interrupts import reason_for, signum_of
from labrig.core.metadata import RunMetadata
from labrig.core.version import __version__
from labrig.store.format import (
    FINAL_STATUSES,
    FORMAT_VERSION,
    LEGACY_SEAL_ATTR,
    SEAL_ATTR,
    STRING_DTYPE,
    Channel,
    channel,
    data_crc,
    now_iso,
    seal_of,
    sealed_data,
    stored_long_name,
    stored_units,
)
from labrig.store.nexus import (
    set_str,
    write_entry_identity,
    write_metadata_collection,
    write_note,
    write_tree,
)
from labrig.store.space import (
    BLOCK_MARGIN_BYTES,
    DISK_FULL,
    Reserve,
    chunk_bytes,
    chunk_length,
    free_bytes,
    is_disk_full,
)
from labrig.store.summary import SUMMARY_NAME, write_summary
from labrig.store.writing import file_identity, mark_writer, path_identity, unmark_writer

log = logging.getLogger("labrig.store")
_STR = STRING_DTYPE
#: the HDF5 filter every sample dataset of a new run file carries
CHECKSUM = "fletcher32"
#: free bytes the summary needs besides its metadata's size (it is written only then)
SUMMARY_ROOM_BYTES = 256 * 1024


def _check_name(name: str, what: str) -> None:
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,62}", name):
        raise ValueError(f"{what} {name!r}: use a letter, then letters, digits or underscores")


def _renew_seal(obj: h5py.Group | h5py.Dataset, data: tuple[int, int] | None = None) -> None:
    """Seal ``obj`` as it is now (:func:`labrig.store.format.seal_of`); a chunked dataset keeps
    the samples' CRC its seal records unless ``data`` gives a new one. A legacy seal goes."""
    if data is None and isinstance(obj, h5py.Dataset) and obj.chunks is not None:
        data = sealed_data(obj)
    seal = seal_of(obj, data)
    attrs = obj.attrs  # one AttributeManager: h5py makes a new one at each ``.attrs``
    if attrs.get(SEAL_ATTR) != seal:
        attrs[SEAL_ATTR] = seal
    if LEGACY_SEAL_ATTR in attrs:
        del attrs[LEGACY_SEAL_ATTR]


#: samples read at a time to compute a stored channel's CRC-32 (:func:`samples_crc`): 8 MiB
#: of float64, a whole number of chunks (:func:`labrig.store.space.chunk_length`)
CRC_BLOCK_SAMPLES = 2**20


def samples_crc(ds: h5py.Dataset, block: int = CRC_BLOCK_SAMPLES) -> tuple[int, int]:
    """The CRC-32 (:func:`labrig.store.format.data_crc`, the value a seal records) and number
    of the samples the 1-D dataset ``ds`` holds now, read ``block`` samples at a time: the
    same CRC as ``data_crc(ds[()])`` without holding the channel in memory (a 499 s entry at
    100 kHz is 400 MB of float64)."""
    if block < 1:
        raise ValueError(f"block must be at least 1 sample, not {block}")
    n = len(ds)
    buf = np.empty(min(block, n), dtype=ds.dtype)
    crc = 0
    for i in range(0, n, block):
        m = min(block, n - i)
        ds.read_direct(buf, np.s_[i : i + m], np.s_[0:m])
        crc = data_crc(buf[:m], crc)
    return crc, n


def _renew_all(obj: h5py.Group | h5py.Dataset) -> None:
    data = None
    chunked = isinstance(obj, h5py.Dataset) and obj.chunks is not None
    if chunked and sealed_data(obj) is not None:  # sealed samples: sealed again as they are now
        data = samples_crc(obj)
    _renew_seal(obj, data)


#: what an entry's ``end_time`` and ``duration`` carry (``@reconstructed``) when a resume
#: derived them from the samples kept instead of the writer recording them at the end
#: (:func:`end_abandoned_entry`)
RECONSTRUCTED_ATTR = "reconstructed"


def _record_end(g: h5py.Group, end_time: str | None, n_samples: int, rate_hz: float) -> None:
    """An entry's ``end_time`` (absent when ``None``) and ``duration``, the time from the first
    to the last of its ``n_samples`` samples at ``rate_hz`` (s), as every ended entry has
    them."""
    if end_time is not None:
        set_str(g, "end_time", end_time)
    if "duration" not in g:
        ds = g.create_dataset("duration", data=max(n_samples - 1, 0) / rate_hz)
        ds.attrs["units"] = "s"
        ds.attrs["long_name"] = "time from the first to the last sample"


def _iso_plus(start: str, seconds: float) -> str | None:
    """The ISO 8601 time ``seconds`` after ``start`` (as :func:`labrig.store.format.now_iso`
    writes it: millisecond resolution, the offset of ``start``); ``None`` when ``start`` is
    not such a time."""
    try:
        t = datetime.fromisoformat(start) + timedelta(milliseconds=round(seconds * 1000))
    except (ValueError, OverflowError):
        return None
    return t.isoformat(timespec="milliseconds")


def end_abandoned_entry(g: h5py.Group, reason: str) -> None:
    """Record the end of the entry ``g`` that its writer left ``running`` (its process was
    killed or crashed, or could not record the end), as :meth:`EntryWriter.finish` records an
    entry's end, from what the file holds: ``aborted`` with ``reason``; ``duration`` from the
    samples kept (the shortest channel's ``n``: ``(n - 1) / sample_rate``, as the reader trims
    the channels to their common length); ``end_time`` = ``start_time`` + ``duration`` (none
    without a readable ``start_time``), both with ``@reconstructed`` saying so; the file's
    ``@file_update_time``; and each channel's samples, kept as they are, sealed as final (their
    CRC-32 in the seal, :func:`samples_crc`). Only for a file no process writes: a resume's
    copy (:func:`labrig.store.resume.record_resume`); the caller seals and flushes."""
    data = g.get("data")
    channels = [
        ds
        for ds in (data.values() if isinstance(data, h5py.Group) else ())
        if isinstance(ds, h5py.Dataset) and ds.chunks is not None
    ]
    n = min((len(ds) for ds in channels), default=0)
    try:
        rate = float(g["sample_rate"][()]) if "sample_rate" in g else math.nan
    except (TypeError, ValueError):
        rate = math.nan
    start = g["start_time"][()] if "start_time" in g else b""
    start = start.decode("utf-8", "replace") if isinstance(start, bytes) else str(start)
    for name in ("end_time", "duration"):  # nothing the writer recorded of an end it never had
        if name in g:
            del g[name]
    made: list[str] = []
    if math.isfinite(rate) and rate > 0:
        end = _iso_plus(start, max(n - 1, 0) / rate)
        _record_end(g, end, n, rate)
        why = f"by a resume: (n - 1) / sample_rate, n = {n} samples kept (the shortest channel)"
        g["duration"].attrs[RECONSTRUCTED_ATTR] = why
        made.append("duration")
        if end is not None:
            g["end_time"].attrs[RECONSTRUCTED_ATTR] = "by a resume: start_time + duration"
            made.insert(0, "end_time")
    if made:
        reason += (
            f"; its {' and '.join(made)} {'are' if len(made) > 1 else 'is'} reconstructed from "
            "the samples kept, not recorded at its end"
        )
    set_str(g, "status_reason", reason)
    set_str(g, "status", "aborted")
    g.file.attrs["file_update_time"] = now_iso()
    for ds in channels:
        _renew_seal(ds, samples_crc(ds))


def seal_all(f: h5py.File) -> None:
    """Renew the seal (:func:`labrig.store.format.seal_of`) of every object in ``f``: new
    objects, changed metadata, and samples whose seal records their CRC (read again); and
    the summary (:mod:`labrig.store.summary`) when the file has one, so that a file edited on
    purpose reads and lists as if labrig had written it so (a file the reader refuses loses
    its summary)."""
    run = f.get("run")
    if isinstance(run, h5py.Group) and SUMMARY_NAME in run:
        del run[SUMMARY_NAME]
        with contextlib.suppress(InputFileError, OSError, ValueError, KeyError, TypeError):
            write_summary(f.filename, f)
    _renew_all(f)
    f.visititems(lambda _name, obj: _renew_all(obj))


def seal_groups(groups: Iterable[h5py.Group]) -> None:
    """Renew the seals of ``groups`` and of the datasets directly in them (what the writer
    changes when it begins or finishes an entry or the run)."""
    for g in groups:
        _renew_seal(g)
        for obj in g.values():
            if isinstance(obj, h5py.Dataset):
                _renew_seal(obj)


def extend(ds: h5py.Dataset, n0: int, values: np.ndarray) -> None:
    """Write the 1-D float ``values`` at index ``n0`` of the resizable 1-D dataset ``ds``,
    growing it to ``n0 + len(values)`` samples. The same HDF5 calls as ``ds.resize`` and a
    slice assignment, through h5py's low-level interface: its high-level one spends about
    0.3 ms of Python per block and channel on selections and dtype checks, as much as a
    simulated run's physics."""
    m = len(values)
    ds.id.set_extent((n0 + m,))
    file_space = ds.id.get_space()
    file_space.select_hyperslab((n0,), (m,))
    block = np.ascontiguousarray(values, dtype=np.float64)
    ds.id.write(h5py.h5s.create_simple((m,)), file_space, block)


#: why a run stops when its file is deleted or replaced at its path by another program
GONE = (
    "the file was deleted, moved or replaced at its path by another program during the run; "
    "the samples written are not in the file now at that path"
)
#: why a run stops when another program truncates its file or writes over it in place
CHANGED = (
    "the file was truncated or written over by another program during the run; the file at "
    "that path does not hold the samples written"
)
#: the bytes of the file's start kept after each flush (the HDF5 superblock: it records the
#: end of the file, so a truncation or another file copied over this one changes them)
MARK_BYTES = 128


class EntryWriter:
    """Writes one NXentry; get it from :meth:`RunWriter.begin_entry`."""

    def __init__(self, run: RunWriter, group: h5py.Group, rate_hz: float, channels: list[Channel]):
        self._run = run
        self.group = group
        self.name = group.name.lstrip("/")
        self.rate_hz = float(rate_hz)
        self.channels = channels
        self._data = group["data"]
        #: each channel's dataset, looked up once (a look-up by name costs h5py ~0.1 ms)
        self._datasets = {c.name: self._data[c.name] for c in channels}
        self._n = 0
        #: CRC-32 of each channel's samples written so far (sealed when the entry finishes)
        self._crcs = {c.name: 0 for c in channels}
        self.status = "running"

    @property
    def n_samples(self) -> int:
        """Samples written so far."""
        return self._n

    def append(self, block: Mapping[str, np.ndarray | Sequence[float]]) -> int:
        """Append one block (channel name -> 1-D array, all the same length) and flush.

        ``time`` may be omitted: it is then ``k / rate_hz`` continuing from the previous
        block. Every other channel given to :meth:`RunWriter.begin_entry` must be present.
        When this returns, the block is on disk (flushed). Returns the total sample count.
        Raises :class:`~labrig.core.errors.StorageError` if the block does not fit on the disk or
        cannot be written; the entry then holds the blocks before it.
        """
        if self.status != "running":
            raise RuntimeError(f"entry {self.name} is {self.status}; cannot append")
        arrays = {k: np.asarray(v, dtype=float).reshape(-1) for k, v in block.items()}
        names = {c.name for c in self.channels}
        unknown = set(arrays) - names
        missing = names - set(arrays) - {"time"}
        if unknown or missing:
            raise ValueError(
                f"block for {self.name}: unknown channels {sorted(unknown)}, "
                f"missing {sorted(missing)}"
            )
        lengths = {len(v) for v in arrays.values()}
        if len(lengths) != 1:
            raise ValueError(f"block for {self.name}: channels differ in length {sorted(lengths)}")
        m = lengths.pop()
        if m == 0:
            return self._n
        if "time" not in arrays:
            arrays["time"] = np.arange(self._n, self._n + m, dtype=float) / self.rate_hz
        n0, n1 = self._n, self._n + m
        operation = f"writing samples {n0}-{n1 - 1} of entry {self.name}"
        self._run.check_space(self._bytes_for(n0, n1), operation)
        try:
            for c in self.channels:
                extend(self._datasets[c.name], n0, arrays[c.name])
            self._run.flush()
        except Exception as e:
            self._cut_back(n0)
            raise self._run.storage_error(operation, e) from None
        for c in self.channels:
            self._crcs[c.name] = data_crc(arrays[c.name], self._crcs[c.name])
        self._n = n1
        return self._n

    def _bytes_for(self, n0: int, n1: int) -> int:
        """Bytes the file grows by when samples ``n0..n1-1`` are written: new chunks."""
        per = chunk_length(self.rate_hz)
        new_chunks = math.ceil(n1 / per) - math.ceil(n0 / per)
        return len(self.channels) * new_chunks * chunk_bytes(self.rate_hz)

    def _cut_back(self, n: int) -> None:
        """After a failed block: every channel back to ``n`` samples (the complete blocks)."""
        for c in self.channels:
            try:
                self._datasets[c.name].resize((n,))
            except Exception as e:
                log.error("cutting %s/%s back to %d samples failed: %s", self.name, c.name, n, e)

    def finish(self, status: str = "complete", reason: str | None = None) -> None:
        """Close the entry with ``status`` (complete / aborted / failed) and flush; raises
        :class:`~labrig.core.errors.StorageError` if that cannot be written."""
        if status not in FINAL_STATUSES:
            raise ValueError(f"entry status must be one of {FINAL_STATUSES}, not {status!r}")
        if self.status != "running":
            return
        g = self.group
        try:
            _record_end(g, now_iso(), self._n, self.rate_hz)
            set_str(g, "status_reason", reason or "")
            set_str(g, "status", status)
            self._run.entry_done()
            for c in self.channels:  # the samples are final: their CRC goes into the seal
                _renew_seal(self._data[c.name], (self._crcs[c.name], self._n))
            self._run.seal_and_flush(self._run.root, g)
        except Exception as e:
            raise self._run.storage_error(f"finishing entry {self.name}", e) from None
        self.status = status


class RunWriter:
    """Create a run file and write it incrementally; use as a context manager.

    ``protocol_text`` / ``rig_text`` are the files' texts (``rig_text`` may be empty for the
    built-in rig); ``instrument_description`` is the rig's ``describe()``: a dict of devices,
    each a nested dict (identity, settings). The run starts ``running``; call :meth:`finish`
    (leaving the ``with`` block without it finishes ``complete``, or ``failed`` / ``aborted``
    if an exception / Ctrl-C is propagating). ``reserve_bytes`` > 0 keeps a reserve file of
    that size beside the run file until the final records are written (see the module
    docstring).
    """

    def __init__(
        self,
        path: Path | str,
        protocol_text: str,
        rig_text: str,
        instrument_description: Mapping,
        seed: int | None,
        software_version: str | None = None,
        *,
        protocol_name: str = "",
        protocol_file: str = "",
        rig_file: str = "",
        planned_entries: Sequence[str] | None = None,
        overwrite: bool = False,
        reserve_bytes: int = 0,
        metadata: RunMetadata | None = None,
    ):
        self.path = Path(path)
        if self.path.exists() and not overwrite:
            raise FileExistsError(f"run file {self.path} exists; refusing to overwrite it")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # "x" creates the file or fails if another process has made it since the check above:
        # two writers never truncate each other's file
        self._open(reserve_bytes, "w" if overwrite else "x")
        self.version = software_version or __version__
        self.metadata = metadata or RunMetadata()
        f = self._f
        f.attrs["NX_class"] = "NXroot"
        f.attrs["creator"] = "labrig"
        f.attrs["creator_version"] = self.version
        f.attrs["file_name"] = self.path.name
        f.attrs["file_time"] = now_iso()
        f.attrs["file_update_time"] = f.attrs["file_time"]
        f.attrs["HDF5_Version"] = h5py.version.hdf5_version
        f.attrs["h5py_version"] = h5py.version.version
        f.attrs["labrig_format"] = FORMAT_VERSION
        mark_writer(f)
        run = f.create_group("run", track_order=True)
        run.attrs["NX_class"] = "NXcollection"
        self._g = run
        set_str(run, "status", "running")
        set_str(run, "status_reason", "")
        set_str(run, "start_time", now_iso())
        set_str(run, "program_name", "labrig")
        set_str(run, "software_version", self.version)
        set_str(run, "protocol_name", protocol_name)
        ds = run.create_dataset("seed", data=-1 if seed is None else int(seed))
        ds.attrs["long_name"] = "random seed of the simulated rig (-1: none)"
        set_str(run, "planned_entries", json.dumps(list(planned_entries or [])))
        write_note(run, "protocol", protocol_text, protocol_file, "the protocol file as run")
        rig_what = "the rig file as run" if rig_file else "built-in rig (no rig file)"
        write_note(run, "rig", rig_text, rig_file, rig_what)
        inst = run.create_group("instrument", track_order=True)
        write_tree(inst, dict(instrument_description), "NXinstrument")
        set_str(inst, "description_json", json.dumps(instrument_description, default=str))
        if self.metadata:
            write_metadata_collection(run, "metadata", self.metadata)
        self._entries: list[str] = []
        self._current: EntryWriter | None = None
        self.status = "running"
        self.seal_and_flush()

    def _open(self, reserve_bytes: int, mode: str) -> None:
        """Open the HDF5 file in ``mode`` ("w": create, "r+": continue) with the reserve kept."""
        self.close_error = ""
        #: what the file held after this writer's last flush (:meth:`flush`), and the first
        #: problem found with the file at the path (:meth:`problem`; "" while there is none)
        self._mark: tuple[int, bytes] | None = None
        self.lost = ""
        self._reserve = Reserve(self.path, reserve_bytes)
        try:
            # no chunk cache: a block goes to the file in its own write call, so a write the
            # disk refuses fails there and then, and no unwritable chunk waits in a cache (with
            # a cache, cutting a channel back after a refused flush read back zeros)
            self._f = h5py.File(self.path, mode, track_order=True, rdcc_nbytes=0)
        except BaseException:
            self._reserve.release()
            raise
        try:
            self.file_id = file_identity(self._f)
        except BaseException:
            self._f.close()
            self._reserve.release()
            raise

    @classmethod
    def reopen(
        cls, path: Path | str, metadata: RunMetadata | None = None, reserve_bytes: int = 0
    ) -> RunWriter:
        """Continue writing an existing run file (``labrig run --resume``: the caller works on
        a copy, :mod:`labrig.store.resume`): the run is ``running`` again, new entries are
        numbered after the file's, ``metadata`` fills their ``user`` and ``sample`` groups."""
        self = cls.__new__(cls)
        self.path = Path(path)
        self._open(reserve_bytes, "r+")
        f = self._f
        self.version = __version__
        self.metadata = metadata or RunMetadata()
        self._g = f["run"]
        entries = [n for n, g in f.items() if n != "run" and isinstance(g, h5py.Group)]
        self._entries = sorted(entries, key=lambda n: int(f[n]["entry_index"][()]))
        self._current = None
        self.status = "running"
        mark_writer(f)
        set_str(self._g, "status", "running")
        set_str(self._g, "status_reason", "")
        for name in ("end_time", SUMMARY_NAME):  # the summary is written again at the close
            if name in self._g:
                del self._g[name]
        self.seal_and_flush()
        return self

    # -- context manager ------------------------------------------------------------------
    def __enter__(self) -> RunWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        try:
            if self.status == "running" and self._f:
                if exc_type is None:
                    self.finish("complete")
                elif issubclass(exc_type, KeyboardInterrupt):
                    self.finish("aborted", reason_for(signum_of(exc)))
                else:
                    self.finish("failed", f"{exc_type.__name__}: {exc}")
        except StorageError as e:
            log.info("%s", e)
        finally:
            self.close()

    @property
    def root(self) -> h5py.File:
        """The open HDF5 file (its root group)."""
        return self._f

    # -- writing --------------------------------------------------------------------------
    def flush(self) -> None:
        """Write everything to disk (``H5Fflush``), then note what the file holds now
        (:meth:`_marked_now`): until this writer writes again, nobody else should change it."""
        self._f.flush()
        self._mark = self._marked_now()

    def _marked_now(self) -> tuple[int, bytes] | None:
        """The open file's size and first :data:`MARK_BYTES` bytes (the HDF5 superblock, which
        records where the file ends): another program's truncation or rewrite changes them."""
        pread = getattr(os, "pread", None)  # (POSIX: not on Windows, where no mark is kept)
        try:
            fd = self._f.id.get_vfd_handle()
            return (os.fstat(fd).st_size, pread(fd, MARK_BYTES, 0)) if pread else None
        except (OSError, ValueError, TypeError):  # not a plain file descriptor: no mark
            return None

    def heartbeat(self) -> None:
        """Say the run file is still being written when nothing is written to it (a rest
        between entries): its modification time is set to now (:mod:`labrig.store.writing`).
        Raises :class:`StorageError` when the file is no longer at its path
        (:meth:`check_in_place`)."""
        self.check_in_place("keeping the run file")
        with contextlib.suppress(OSError):
            os.utime(self.path)

    def in_place(self) -> bool:
        """Whether the path still names the file being written (not deleted, not replaced by
        another program: what is written then would be lost with the file). A path that
        cannot be looked up now (a folder's permissions changed) counts as in place: the
        open file is still written."""
        try:
            return path_identity(self.path) == self.file_id
        except OSError:
            return True

    def problem(self) -> str:
        """Why the file at the path no longer holds what this writer wrote ("" when it does):
        it was deleted, moved or replaced (:data:`GONE`), or truncated or written over in
        place since this writer's last flush (:data:`CHANGED`). The first problem seen is kept
        in :attr:`lost`."""
        if not self.in_place():
            why = GONE
        elif self._f and self._mark is not None:
            now = self._marked_now()
            changed = now is not None and (now[0] < self._mark[0] or now[1] != self._mark[1])
            why = CHANGED if changed else ""
        else:
            why = ""
        self.lost = self.lost or why
        return why

    def check_in_place(self, operation: str) -> None:
        """Raise :class:`StorageError` when :meth:`problem` finds one."""
        why = self.problem()
        if why:
            raise StorageError(str(self.path), operation, why)

    def seal_and_flush(self, *changed: h5py.Group) -> None:
        """After metadata changed in the groups ``changed`` (and the datasets directly in
        them): renew their seals (:func:`seal_groups`; none given: every seal,
        :func:`seal_all`), then :meth:`flush`."""
        if changed:
            seal_groups(changed)
        else:
            seal_all(self._f)
        self.flush()

    def check_space(self, needed_bytes: int, operation: str) -> None:
        """Raise :class:`StorageError` (disk full) unless ``needed_bytes`` plus a margin are
        free on the run file's filesystem, or the file is no longer at its path
        (:meth:`check_in_place`; checked with every block: a stat, microseconds)."""
        self.check_in_place(operation)
        free = free_bytes(self.path)
        if free < needed_bytes + BLOCK_MARGIN_BYTES:
            raise StorageError(
                str(self.path),
                operation,
                f"disk full: {free / 1024:.0f} kB free on its filesystem, "
                f"{(needed_bytes + BLOCK_MARGIN_BYTES) / 1024:.0f} kB needed; the file keeps "
                "every block written before",
            )

    def storage_error(self, operation: str, exc: BaseException) -> StorageError:
        """A :class:`StorageError` for a write HDF5 refused (disk full named as such)."""
        if is_disk_full(exc):
            detail = DISK_FULL
        else:
            detail = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
        return StorageError(str(self.path), operation, detail)

    def release_reserve(self) -> None:
        """Give the reserve file's room back (before the final records; idempotent)."""
        self._reserve.release()

    def set_run_value(
        self,
        name: str,
        value: float | int | str,
        units: str = "",
        long_name: str = "",
        **attrs: Any,
    ) -> None:
        """Store a run-level scalar as ``/run/<name>`` (replacing one of that name), with
        ``units``, ``long_name`` and any other attributes; flushed. Releases the reserve first;
        raises :class:`StorageError` if it cannot be written."""
        self.release_reserve()
        _check_name(name, "run value")
        try:
            run = self._g
            if name in run:
                del run[name]
            dtype = _STR if isinstance(value, str) else None
            ds = run.create_dataset(name, data=value, dtype=dtype)
            for key, val in {"units": units, "long_name": long_name, **attrs}.items():
                if val != "":
                    ds.attrs[key] = val
            self.seal_and_flush(run)
        except Exception as e:
            raise self.storage_error(f"recording /run/{name}", e) from None

    def add_run_collection(
        self,
        name: str,
        arrays: Mapping[str, tuple[Sequence[float] | NDArray, str, str]],
        **attrs: Any,
    ) -> None:
        """Store ``/run/<name>``, an NXcollection of 1-D float datasets (``arrays``: name ->
        ``(values, units, long_name)``, checksummed) and attributes; flushed. Releases the
        reserve first; raises :class:`StorageError` if it cannot be written."""
        self.release_reserve()
        _check_name(name, "run collection")
        try:
            if name in self._g:
                del self._g[name]
            g = self._g.create_group(name, track_order=True)
            g.attrs["NX_class"] = "NXcollection"
            for key, val in attrs.items():
                g.attrs[key] = val
            for key, (values, units, long_name) in arrays.items():
                data = np.asarray(values, dtype=float).reshape(-1)
                chunk = (max(1, min(data.size, 4096)),)
                ds = g.create_dataset(
                    key, data=data, chunks=chunk, maxshape=(None,), fletcher32=True
                )
                ds.attrs["units"] = units
                ds.attrs["long_name"] = long_name
                _renew_seal(ds, (data_crc(data), data.size))
            self.seal_and_flush(self._g, g)
        except Exception as e:
            raise self.storage_error(f"recording /run/{name}", e) from None

    def begin_entry(
        self,
        name: str,
        step_meta: Mapping,
        rate_hz: float,
        channels: Iterable[Channel | Sequence[str] | str],
        title: str | None = None,
    ) -> EntryWriter:
        """Start the NXentry ``name`` (one concrete step) and return its writer.

        ``step_meta`` is stored as JSON (``step_definition``); ``channels`` lists the recorded
        signals besides ``time`` as :class:`Channel`, ``(name, units, long_name)`` or a
        standard name (see :data:`STANDARD_CHANNELS`). The first entry becomes the file's
        ``@default``. A still-open previous entry is refused.
        """
        if self.status != "running":
            raise RuntimeError(f"run is {self.status}; cannot begin entry {name}")
        if self._current is not None and self._current.status == "running":
            raise RuntimeError(f"entry {self._current.name} is still running; finish it first")
        _check_name(name, "entry name")
        if name in self._f:
            raise ValueError(f"entry {name!r} exists already")
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz must be positive, not {rate_hz}")
        chans = [channel("time")]
        for spec in channels:
            c = channel(spec)
            _check_name(c.name, "channel name")
            if c.name != "time" and c.name not in {x.name for x in chans}:
                chans.append(c)
        f = self._f
        g = f.create_group(name, track_order=True)
        g.attrs["NX_class"] = "NXentry"
        g.attrs["default"] = "data"
        set_str(g, "title", title or name)
        ds = g.create_dataset("entry_index", data=len(self._entries))
        ds.attrs["long_name"] = "position of the entry in the run (0-based)"
        set_str(g, "start_time", now_iso())
        set_str(g, "status", "running")
        set_str(g, "status_reason", "")
        ds = g.create_dataset("sample_rate", data=float(rate_hz))
        ds.attrs["units"] = "Hz"
        ds.attrs["long_name"] = "sample rate"
        set_str(g, "step_definition", json.dumps(dict(step_meta), default=str))
        write_entry_identity(g, self.metadata, self.version)
        g["instrument"] = self._g["instrument"]
        g["protocol"] = self._g["protocol"]
        g["rig"] = self._g["rig"]
        data = g.create_group("data", track_order=True)
        data.attrs["NX_class"] = "NXdata"
        data.attrs["signal"] = "strain" if "strain" in {c.name for c in chans} else chans[-1].name
        data.attrs["axes"] = np.array(["time"], dtype=_STR)
        data.attrs["time_indices"] = 0
        aux = [c.name for c in chans if c.name not in ("time", data.attrs["signal"])]
        if aux:
            data.attrs["auxiliary_signals"] = np.array(aux, dtype=_STR)
        chunk = chunk_length(rate_hz)
        for c in chans:
            ds = data.create_dataset(
                c.name,
                shape=(0,),
                maxshape=(None,),
                chunks=(chunk,),
                dtype="f8",
                fletcher32=CHECKSUM == "fletcher32",
            )
            ds.attrs["units"] = stored_units(c.units)
            ds.attrs["long_name"] = stored_long_name(c.units, c.long_name)
        if not self._entries:
            f.attrs["default"] = name
        self._entries.append(name)
        self._current = EntryWriter(self, g, rate_hz, chans)
        self.seal_and_flush(f, g, data, *(g[k] for k in ("user", "sample") if k in g))
        return self._current

    def entry_done(self) -> None:
        """An entry finished: the file's update time."""
        self._f.attrs["file_update_time"] = now_iso()

    def finish(self, status: str = "complete", reason: str | None = None) -> None:
        """Close the run with ``status``; a still-running entry gets the same status.

        Releases the reserve first. Raises :class:`StorageError` if the records cannot be
        written (the run then reads as incomplete, with every block written before)."""
        if status not in FINAL_STATUSES:
            raise ValueError(f"run status must be one of {FINAL_STATUSES}, not {status!r}")
        if self.status != "running":
            return
        self.release_reserve()
        try:
            if self._current is not None and self._current.status == "running":
                why = reason or (None if status == "complete" else f"run {status}")
                self._current.finish(status, why)
            set_str(self._g, "end_time", now_iso())
            set_str(self._g, "status_reason", reason or "")
            set_str(self._g, "status", status)
            self._f.attrs["file_update_time"] = now_iso()
            self.seal_and_flush(self._f, self._g)
        except Exception as e:
            raise self.storage_error(f"recording the run's end ({status})", e) from None
        self.status = status

    def _write_summary(self) -> None:
        """The summary a listing reads (:mod:`labrig.store.summary`), as the file is now, when
        the disk has room for it. Raises nothing but what interrupts it (Ctrl-C), after taking
        a half-written summary out: a file without a summary reads in full."""
        run = self._g
        try:
            need = len(json.dumps(self.metadata.values)) + SUMMARY_ROOM_BYTES
            if free_bytes(self.path) < need:
                log.info("%s: no summary written (disk nearly full)", self.path)
                return
            ds = write_summary(self.path, self._f)
            _renew_seal(ds)
            _renew_seal(run)
            self._f.flush()
        except BaseException as e:  # a file the reader would refuse, a full disk, Ctrl-C
            log.info("%s: no summary written (%s)", self.path, e or type(e).__name__)
            with contextlib.suppress(Exception):
                if SUMMARY_NAME in run:
                    del run[SUMMARY_NAME]
                _renew_seal(run)
            if not isinstance(e, Exception):
                raise

    def close(self) -> None:
        """Write the summary, close the file (without finishing: a closed running run stays
        ``running``) and release the reserve. Raises nothing but an interruption (Ctrl-C)
        during the summary, after closing the file: a failure is logged and kept in
        ``close_error``."""
        self.release_reserve()
        if not self._f:
            return
        self.problem()  # (kept in ``lost``: the caller says so)
        if self.status == "running":  # closed unfinished: no longer being written
            with contextlib.suppress(Exception):
                unmark_writer(self._f)
                _renew_seal(self._f)
        try:
            self._write_summary()
        finally:  # closed whatever happens (a Ctrl-C during the summary propagates after)
            try:
                self._f.close()
            except Exception as e:
                self.close_error = str(self.storage_error("closing the file", e))
                log.info("%s", self.close_error)
