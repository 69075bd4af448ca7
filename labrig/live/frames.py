"""One look at a run file that may be being written: what the live view draws next.

:func:`read_frame_here` opens the file read-only with HDF5 file locking off (the writer holds
it open; it flushes after every block, :mod:`labrig.store.writer`) and reads only what a frame
needs: the run's status, the entries' names, statuses and lengths, and the current entry's
samples from a given index on. It verifies what it reads: the seal of every scalar it takes
(:func:`labrig.store.format.seal_of`) and the Fletcher32 checksums of the samples (HDF5 checks
them on reading). A file caught between two of its writer's writes fails a check or raises:
:func:`read_frame` runs the reading in a child process with a short time limit (one
long-lived :class:`~labrig.store.isolated.IsolatedWorker` for this process's frames, not a
fork per frame) and the caller skips that frame.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from labrig.store.format import SEAL_ATTR, seal_of
from labrig.store.isolated import IsolatedWorker, allow_cpu, call_isolated
from labrig.store.writing import file_identity

#: the channels a frame reads (those an entry lacks are left out)
CHANNELS = ("time", "command_voltage", "strain", "amplifier_voltage")
#: a frame reads at most this many new samples per channel (a viewer that joins a long entry
#: late starts from its last samples)
MAX_NEW_SAMPLES = 200_000
#: a frame's read may take this long (s) before it is given up (the frame is skipped)
FRAME_WALL_S = 2.0
#: which file a frame was read from: the identity of the file opened (device, inode) and the
#: time the run file was created (``@file_time``): another file at the path, or another file
#: copied over it in place (same inode), is another key
FileKey = tuple[int, int, str]
#: the child process that reads this process's frames (started at the first frame)
FRAME_READER = IsolatedWorker()


class FrameError(Exception):
    """What was read does not verify (a torn write, a damaged file): skip the frame."""


@dataclass
class EntryInfo:
    name: str
    index: int
    status: str
    samples: int
    planned_samples: int | None
    title: str
    rate_hz: float | None = None
    #: the drive's frequency (Hz) when its step names one (sines, sweeps, envelopes)
    frequency_hz: float | None = None


@dataclass
class Frame:
    """What one read of the file gave (samples of the current entry from ``start`` on)."""

    status: str
    reason: str
    protocol: str
    planned: list[str]
    entries: list[EntryInfo]
    current: str | None
    start: int
    samples: dict[str, np.ndarray] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    exit_code: int | None = None
    final_voltage_V: float | None = None
    writer_pid: int | None = None
    writer_host: str = ""
    #: the file read (:func:`file_key`)
    file_id: FileKey | None = None


def file_key(f: h5py.File) -> FileKey:
    """The :data:`FileKey` of the open run file ``f``."""
    created = f.attrs.get("file_time", "")
    return (*file_identity(f), created.decode() if isinstance(created, bytes) else str(created))


def _value(ds: h5py.Dataset) -> object:
    """A scalar dataset's value, checked against its seal."""
    allow_cpu()
    if SEAL_ATTR in ds.attrs and ds.attrs[SEAL_ATTR] != seal_of(ds):
        raise FrameError(f"{ds.name}: does not match its seal (being written?)")
    v = ds[()]
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else v


def _get(g: h5py.Group, name: str, default: Any = None) -> Any:
    ds = g.get(name)
    return _value(ds) if isinstance(ds, h5py.Dataset) and ds.shape == () else default


#: what a step definition says that a frame keeps: planned samples, drive frequency (Hz)
StepFacts = tuple[int | None, float | None]


def _step_facts(g: h5py.Group) -> StepFacts:
    """The planned sample count and the drive frequency of an entry's step definition."""
    step = json.loads(str(_get(g, "step_definition", "{}")))
    if not isinstance(step, dict):
        return None, None
    planned, freq = step.get("n_samples"), step.get("frequency_hz")
    return (
        int(planned) if isinstance(planned, int | float) else None,
        float(freq) if isinstance(freq, int | float) and freq > 0 else None,
    )


def _entry_info(name: str, g: h5py.Group, known: dict[str, StepFacts]) -> EntryInfo:
    data = g.get("data")
    # a reader may land between two channels' writes of one block: the shortest counts
    lengths = [data[c].shape[0] for c in CHANNELS if isinstance(data, h5py.Group) and c in data]
    planned, freq = known[name] if name in known else _step_facts(g)
    return EntryInfo(
        name=name,
        index=int(_get(g, "entry_index", -1)),
        status=str(_get(g, "status", "running")),
        samples=min(lengths, default=0),
        planned_samples=planned,
        title=str(_get(g, "title", name)),
        rate_hz=_float(_get(g, "sample_rate")),
        frequency_hz=freq,
    )


def read_frame_here(
    path: str,
    entry: str | None,
    start: int,
    known: dict[str, StepFacts],
    ended: dict[str, EntryInfo] | None = None,
    file_id: FileKey | None = None,
) -> Frame:
    """Read a frame (module docstring): the current entry's samples from ``start`` on if it is
    ``entry``, else from its beginning. ``known``: the step facts (planned samples, frequency)
    of entries seen before (their step definitions are not read again); ``ended``: the entries
    of this file seen ended (a final status) before, taken as they were: an ended entry does
    not change, and reading each one's facts again (with their seals) was most of a frame's
    reading in a campaign of many entries. ``entry``, ``known`` and ``ended`` are of the file
    ``file_id``: another file found at the path (replaced since) is read from scratch."""
    with h5py.File(path, "r", locking=False) as f:
        allow_cpu()
        fid = file_key(f)
        if fid != file_id:
            entry, known, ended = None, {}, {}
        run = f["run"]
        ended = ended or {}
        entries = [
            ended[n] if n in ended else _entry_info(n, g, known)
            for n, g in f.items()
            if n != "run" and isinstance(g, h5py.Group)
        ]
        entries.sort(key=lambda e: e.index)
        frame = Frame(
            status=str(_get(run, "status", "running")),
            reason=str(_get(run, "status_reason", "")),
            protocol=str(_get(run, "protocol_name", "")),
            planned=list(json.loads(str(_get(run, "planned_entries", "[]")))),
            entries=entries,
            current=entries[-1].name if entries else None,
            start=0,
            exit_code=_int(_get(run, "exit_code")),
            final_voltage_V=_float(_get(run, "final_amplifier_voltage_V")),
            writer_pid=_int(f.attrs.get("writer_pid")),
            writer_host=str(f.attrs.get("writer_host", "")),
            file_id=fid,
        )
        if frame.current is not None:
            _read_samples(f[frame.current]["data"], frame, entry, start, entries[-1].samples)
        return frame


def _read_samples(
    data: h5py.Group,
    frame: Frame,
    entry: str | None,
    start: int,
    n: int,
    limit: int = MAX_NEW_SAMPLES,
) -> None:
    begin = start if entry == frame.current else 0
    begin = max(begin, n - limit, 0)
    frame.start = begin
    for c in CHANNELS:
        if c in data and begin < n:
            allow_cpu(size_bytes=(n - begin) * 8)
            frame.samples[c] = np.asarray(data[c][begin:n], dtype=float)
            u = data[c].attrs.get("units", "")
            frame.units[c] = u.decode() if isinstance(u, bytes) else str(u)
    t = frame.samples.get("time")
    if t is None or t.size == 0:
        return
    # samples whose extent is on disk before their values (times run k / rate, increasing;
    # an unwritten sample reads 0): keep the increasing run from the first sample
    bad = np.flatnonzero(~(np.diff(t) > 0))
    keep = t.size if bad.size == 0 else int(bad[0]) + 1
    frame.samples = {c: v[:keep] for c, v in frame.samples.items()}


def _int(v: object) -> int | None:
    return int(v) if isinstance(v, int | np.integer) else None


def _float(v: object) -> float | None:
    return float(v) if isinstance(v, int | float | np.integer | np.floating) else None


def read_frame(
    path: Path | str,
    entry: str | None,
    start: int,
    known: dict[str, StepFacts],
    ended: dict[str, EntryInfo] | None = None,
    file_id: FileKey | None = None,
) -> Frame:
    """:func:`read_frame_here` in :data:`FRAME_READER`, limited to :data:`FRAME_WALL_S`;
    raises whatever stopped it (the caller skips the frame)."""
    size = min(Path(path).stat().st_size, 64 << 20)
    return FRAME_READER.call(
        read_frame_here,
        str(path),
        entry,
        start,
        known,
        ended,
        file_id,
        size_bytes=size,
        wall_s=FRAME_WALL_S,
    )


@dataclass
class EntryData:
    """One whole entry as read once it has ended (:func:`read_entry`): its samples from
    ``start`` on (0 unless the entry is longer than :data:`MAX_ENTRY_SAMPLES`)."""

    info: EntryInfo
    start: int
    samples: dict[str, np.ndarray]
    #: the file read (:func:`file_key`)
    file_id: FileKey | None = None


#: an ended entry is read whole up to this many samples (longer: its last ones)
MAX_ENTRY_SAMPLES = 2_000_000
#: reading an ended entry may take this long (s) before it is given up (retried later)
ENTRY_WALL_S = 20.0


def read_entry_here(path: str, name: str) -> EntryData:
    """Read entry ``name`` of the run file whole (its last :data:`MAX_ENTRY_SAMPLES`
    samples), verified as :func:`read_frame_here` verifies a frame."""
    with h5py.File(path, "r", locking=False) as f:
        allow_cpu()
        g = f.get(name)
        if name == "run" or not isinstance(g, h5py.Group) or "data" not in g:
            raise FrameError(f"{path}: no entry {name!r}")
        info = _entry_info(name, g, {})
        frame = Frame("", "", "", [], [info], name, 0)
        _read_samples(g["data"], frame, None, 0, info.samples, MAX_ENTRY_SAMPLES)
        return EntryData(info, frame.start, frame.samples, file_key(f))


def read_entry(path: Path | str, name: str) -> EntryData:
    """:func:`read_entry_here` in a child process limited to :data:`ENTRY_WALL_S`."""
    size = min(Path(path).stat().st_size, 256 << 20)
    return call_isolated(read_entry_here, str(path), name, size_bytes=size, wall_s=ENTRY_WALL_S)
