"""Parsing an open run file into :class:`RunFile` with every check a reader owes its user: the
metadata seals (:func:`labrig.store.format.seal_of`), the types and shapes labrig writes, sizes
bounded by the file's size, Fletcher32 checksums of the samples; anything unexpected is an
:class:`~labrig.core.errors.InputFileError` naming the file and the object (the HDF5 path). Run in a
child process with a time limit by :func:`labrig.store.reader.read_run`."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

import h5py
import numpy as np

from labrig.core.errors import InputFileError, InputIssue
from labrig.core.jsonsafe import loads_bounded
from labrig.core.words import shown
from labrig.store.format import (
    LEGACY_SEAL_ATTR,
    SEAL_ATTR,
    STATUSES,
    check_seal,
    data_crc,
    memory_long_name,
    memory_units,
    read_attrs,
    sealed_members,
)
from labrig.store.isolated import allow_cpu

#: the JSON type :meth:`json` is asked for (a dict or a list)
J = TypeVar("J")


@dataclass
class RunEntry:
    """One entry read back: arrays by channel name plus the entry's metadata."""

    name: str
    index: int
    title: str
    status: str
    reason: str
    start_time: str
    end_time: str
    rate_hz: float
    step: dict
    data: dict[str, np.ndarray]
    units: dict[str, str]
    long_names: dict[str, str]
    signal: str = "strain"
    #: True when the channels had different lengths (writer killed mid-block) and were trimmed
    trimmed: bool = False
    #: the entry's NXuser and NXsample fields (``{"name": "alice"}``; empty when absent)
    user: dict[str, str] = field(default_factory=dict)
    sample: dict[str, str] = field(default_factory=dict)

    def __getitem__(self, channel_name: str) -> np.ndarray:
        return self.data[channel_name]

    @property
    def channels(self) -> list[str]:
        return list(self.data)

    @property
    def time(self) -> np.ndarray:
        return self.data["time"]

    @property
    def n_samples(self) -> int:
        return len(self.data["time"]) if "time" in self.data else 0

    @property
    def duration_s(self) -> float:
        t = self.data.get("time")
        return float(t[-1] - t[0]) if t is not None and len(t) > 1 else 0.0

    @property
    def complete(self) -> bool:
        return self.status == "complete"


@dataclass
class RunFile:
    """A run file read back (see :func:`read_run`)."""

    path: Path
    format_version: int
    creator_version: str
    file_time: str
    status: str
    reason: str
    start_time: str
    end_time: str
    seed: int | None
    software_version: str
    protocol_name: str
    protocol_text: str
    rig_text: str
    protocol_file: str
    rig_file: str
    instrument: dict
    planned_entries: list[str]
    entries: dict[str, RunEntry] = field(default_factory=dict)
    #: the exit code ``labrig run`` ended with (None: not recorded, an older or unfinished file)
    exit_code: int | None = None
    #: ``/run/metadata``: every key of the protocol's ``metadata:`` and of ``--meta``
    metadata: dict[str, str | int | float | bool] = field(default_factory=dict)
    #: every ``labrig run --resume`` of the file, oldest first (``/run/resumes``)
    resumes: list[dict] = field(default_factory=list)
    #: the process that writes (or wrote) the file: its id (None: not recorded) and host
    writer_pid: int | None = None
    writer_host: str = ""
    #: the writer is writing the file now (set by :func:`labrig.store.reader.read_run`:
    #: :mod:`labrig.store.writing`); ``writer`` says who and when it last wrote
    being_written: bool = False
    writer: str = ""
    #: what other programs added to the file (paths below the root, ``@name`` for an
    #: attribute): not covered by labrig's seals, not checked, never taken for damage
    additions: list[str] = field(default_factory=list)

    def __getitem__(self, name: str) -> RunEntry:
        return self.entries[name]

    def __iter__(self) -> Iterator[RunEntry]:
        return iter(self.entries.values())

    def __len__(self) -> int:
        return len(self.entries)

    @property
    def incomplete(self) -> bool:
        """True when the writer has not finished the run (crash, kill, or still writing it:
        :attr:`being_written`)."""
        return self.status == "running"


#: a sample dataset may claim at most this many times the file's size in bytes (labrig writes
#: them uncompressed: a larger claim is a damaged shape, refused before anything is allocated)
MAX_EXPANSION = 64
#: ... and at least this many bytes whatever the file's size
MIN_CLAIM_BYTES = 1 << 20


def _contiguous(obj: h5py.HLObject) -> bool:
    """A dataset whose value its seal covers (not chunked samples)."""
    return isinstance(obj, h5py.Dataset) and obj.chunks is None


def _int_or_none(value: object) -> int | None:
    return int(value) if isinstance(value, int | np.integer) else None


def _first_line(e: BaseException) -> str:
    text = (str(e).strip().splitlines() or [""])[0][:160]
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


class _Reader:
    """Reads one open run file and knows which object it is reading (:attr:`where`, the
    HDF5 path without its leading ``/``): every problem is an :class:`InputFileError`
    naming the file and that object."""

    def __init__(self, path: Path | str, f: h5py.File, size_bytes: int):
        self.path, self.f = str(path), f
        self.max_bytes = max(MAX_EXPANSION * size_bytes, MIN_CLAIM_BYTES)
        self.where = ""
        #: what other programs added (paths; ``@name`` for an attribute): :meth:`check_seals`
        self.additions: list[str] = []
        #: the CRC-32 of each sealed channel's samples, by path (checked when they are read)
        self.data_seals: dict[str, int] = {}
        #: what :meth:`check_seals` read, by HDF5 path (``obj.name``), read once: each
        #: object's attributes and each scalar dataset's value
        self.attrs_read: dict[str, dict[str, object]] = {}
        self.values_read: dict[str, object] = {}

    def error(self, message: str, where: str | None = None) -> InputFileError:
        return InputFileError(
            [InputIssue(self.path, None, self.where if where is None else where, message)]
        )

    def at(self, obj: h5py.HLObject | h5py.AttributeManager, name: str = "") -> str:
        """Note the object about to be read (for messages) and give it its CPU time."""
        allow_cpu()
        base = obj.name if isinstance(obj, h5py.HLObject) else ""
        self.where = f"{(base or '').strip('/')}/{name}".strip("/")
        return self.where

    def value(self, ds: h5py.Dataset) -> object:
        """A dataset's value; a scalar's is read once (the seal check reads it first)."""
        if ds.shape != ():
            return ds[()]
        if ds.name not in self.values_read:
            self.values_read[ds.name] = ds[()]
        return self.values_read[ds.name]

    def text(self, group: h5py.Group, name: str, default: str = "") -> str:
        """A scalar text dataset (a scalar number reads as its text)."""
        if name not in group:
            return default
        self.at(group, name)
        ds = group[name]
        if not isinstance(ds, h5py.Dataset) or ds.shape != ():
            raise self.error("expected a text value (a scalar dataset)")
        v = self.value(ds)
        return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)

    def number(self, group: h5py.Group, name: str) -> float | None:
        """A scalar numeric dataset, or ``None`` when absent."""
        if name not in group:
            return None
        self.at(group, name)
        ds = group[name]
        if not isinstance(ds, h5py.Dataset) or ds.shape != () or ds.dtype.kind not in "iuf":
            raise self.error("expected a number (a scalar numeric dataset)")
        return float(self.value(ds))  # type: ignore[arg-type]

    def integer(self, group: h5py.Group, name: str) -> int | None:
        """A scalar whole number, or ``None`` when absent. An integer dataset is read as the
        integer it holds (never through a float: a 63-bit seed keeps every digit); a float
        dataset holding a whole number (older writers) is accepted."""
        v = self.number(group, name)
        if v is None:
            return None
        ds = group[name]
        if ds.dtype.kind in "iu":
            return int(self.value(ds))  # type: ignore[call-overload]
        if not (math.isfinite(v) and v == int(v)):
            raise self.error(f"expected a whole number, found {v:g}")
        return int(v)

    def attr(self, obj: h5py.HLObject, name: str, default: object = "") -> object:
        """An attribute: text decoded, a text array as a list of texts, else as stored."""
        self.at(obj, f"@{name}")
        read = self.attrs_read.get(obj.name) if obj.name else None
        v = read.get(name, default) if read is not None else obj.attrs.get(name, default)
        if isinstance(v, bytes):
            return v.decode("utf-8", "replace")
        if isinstance(v, np.ndarray) and v.dtype.kind in "OSU":
            return [x.decode("utf-8", "replace") if isinstance(x, bytes) else str(x) for x in v]
        return v

    def label(self, obj: h5py.HLObject, name: str) -> str:
        """A text attribute (``units``, ``long_name``): text or absent."""
        value = self.attr(obj, name)
        if not isinstance(value, str):
            raise self.error(f"expected text, found {type(value).__name__}")
        return value

    def status(self, group: h5py.Group) -> str:
        """A run's or an entry's status: one of :data:`~labrig.store.format.STATUSES`."""
        status = self.text(group, "status", "unknown")
        if status not in (*STATUSES, "unknown"):
            raise self.error(f"{status[:40]!r} is not a status ({', '.join(STATUSES)})")
        return status

    def json(self, group: h5py.Group, name: str, default: str, kind: type[J]) -> J:
        """A text dataset holding JSON of type ``kind`` (``default`` when absent)."""
        text = self.text(group, name, default)
        self.at(group, name)
        try:
            value = loads_bounded(text)
        except ValueError as e:
            raise self.error(f"not valid JSON ({e})") from None
        if not isinstance(value, kind):
            want = "an object" if kind is dict else "a list"
            raise self.error(f"expected JSON {want}, found {type(value).__name__}")
        return value

    def samples(self, entry: str, name: str, ds: h5py.Dataset, load: bool) -> np.ndarray:
        """A channel: a 1-D numeric dataset no larger than the file can hold. A chunk that
        fails its Fletcher32 checksum (or cannot be read) is an error naming the channel."""
        where = self.at(ds.parent, name)
        if ds.ndim != 1 or ds.dtype.kind not in "iuf":
            found = "a scalar" if ds.ndim == 0 else f"shape {ds.shape}, type {ds.dtype}"
            raise self.error(f"expected a 1-D array of numbers (samples), found {found}")
        if ds.size * ds.dtype.itemsize > self.max_bytes:
            raise self.error(
                f"claims {ds.size} samples, more than the file can hold: the file is damaged"
            )
        if not load:
            return np.empty(0)
        allow_cpu(size_bytes=ds.size * ds.dtype.itemsize)
        try:
            values = ds[()]
        except (OSError, RuntimeError) as e:
            text = str(e)
            if ds.fletcher32 and ("Fletcher32" in text or "filter" in text):
                why = "checksum mismatch: the stored samples are damaged"
            else:
                why = "unreadable: " + ((text.strip().splitlines() or [""])[0][:160])
            raise self.error(why, where) from None
        sealed = self.data_seals.get(where)
        if sealed is not None and data_crc(values) != sealed:
            raise self.error(
                "checksum mismatch: the samples differ from those labrig sealed (CRC-32 in "
                f"@{SEAL_ATTR}): another program changed them, or they are damaged",
                where,
            )
        return values

    def entry(self, name: str, g: h5py.Group, load: bool) -> tuple[RunEntry, dict]:
        """One entry and the shapes of its channels (the arrays are empty without ``load``)."""
        data_g = g.get("data")
        data: dict[str, np.ndarray] = {}
        shapes: dict[str, tuple[int, ...]] = {}
        units: dict[str, str] = {}
        long_names: dict[str, str] = {}
        if not isinstance(data_g, h5py.Group):
            raise self.error("missing: the entry has no group of channels", f"{name}/data")
        for cname in self.own(data_g):
            ds = data_g[cname]
            if not isinstance(ds, h5py.Dataset):
                continue
            units[cname] = memory_units(self.label(ds, "units"))
            long_names[cname] = memory_long_name(self.label(ds, "long_name"))
            data[cname] = self.samples(name, cname, ds, load)
            shapes[cname] = ds.shape
        signal = str(self.attr(data_g, "signal", "strain"))
        self.where = f"{name}/data"
        if "time" not in shapes:
            raise self.error("no time channel")
        if signal not in shapes:
            raise self.error(f"@signal names {signal!r}, which is not one of its channels")
        status = self.status(g)
        lengths = {c: shape[0] for c, shape in shapes.items()}
        n = min(lengths.values(), default=0)
        trimmed = any(m != n for m in lengths.values())
        if trimmed and status == "complete":  # only a writer killed mid-block leaves this
            raise self.error(
                f"the channels of a complete entry differ in length: {lengths}", f"{name}/data"
            )
        if trimmed:
            data = {k: v[:n] for k, v in data.items()} if load else data
            shapes = {k: (n,) for k in shapes}
        index = self.integer(g, "entry_index")
        if index is None:
            raise self.error("missing", f"{name}/entry_index")
        rate = self.number(g, "sample_rate")
        if rate is None or not (math.isfinite(rate) and rate > 0):
            found = "nothing" if rate is None else f"{rate:.6g}"
            raise self.error(f"expected a positive sample rate (Hz), found {found}")
        entry = RunEntry(
            name=name,
            index=index,
            title=self.text(g, "title", name),
            status=status,
            reason=self.text(g, "status_reason"),
            start_time=self.text(g, "start_time"),
            end_time=self.text(g, "end_time"),
            rate_hz=rate,
            step=dict(self.json(g, "step_definition", "{}", dict)),
            data=data,
            units=units,
            long_names=long_names,
            signal=signal,
            trimmed=trimmed,
            user={k: str(v) for k, v in self.scalars(g, "user", "NXuser").items()},
            sample={k: str(v) for k, v in self.scalars(g, "sample", "NXsample").items()},
        )
        return entry, shapes

    def scalars(self, parent: h5py.Group, name: str, nx_class: str) -> dict:
        """The scalar datasets of the group ``parent/name`` of class ``nx_class`` (text,
        numbers, booleans) by name; empty when there is no such group."""
        g = parent.get(name)
        if not isinstance(g, h5py.Group) or self.attr(g, "NX_class") != nx_class:
            return {}
        out: dict[str, str | int | float | bool] = {}
        for key, ds in g.items():
            if not isinstance(ds, h5py.Dataset) or ds.shape != ():
                continue
            self.at(g, key)
            v = self.value(ds)
            if isinstance(v, bytes):
                out[key] = v.decode("utf-8", "replace")
            elif isinstance(v, np.bool_ | bool):
                out[key] = bool(v)
            elif isinstance(v, np.integer):
                out[key] = int(v)
            elif isinstance(v, np.floating):
                out[key] = float(v)
        return out

    def resumes(self, run: h5py.Group) -> list[dict]:
        """``/run/resumes``: one record per resume, in order (:mod:`labrig.store.resume`)."""
        g = run.get("resumes")
        if not isinstance(g, h5py.Group):
            return []
        out = []
        for name in g:
            record = dict(self.scalars(g, name, "NXcollection"))
            for key in ("entries", "superseded"):
                if key in record:
                    kind = dict if key == "superseded" else list
                    record[key] = self.json(g[name], key, "null", kind)
            record["name"] = name
            out.append(record)
        return sorted(out, key=lambda r: int(r.get("number", 0)))

    def own(self, group: h5py.Group) -> list[str]:
        """The members of ``group`` that labrig wrote: those its seal lists, or (a file sealed
        before, or not at all) all but the additions :meth:`check_seals` found. A channel or
        a group another program added is not read as labrig's."""
        listed = sealed_members(group, self.attrs_read.get(group.name))
        members = list(group)
        if listed is not None:
            return [m for m in members if m in listed]
        prefix = (group.name or "").strip("/")
        return [m for m in members if (f"{prefix}/{m}" if prefix else m) not in self.additions]

    def check_seals(self) -> None:
        """Every object's attributes and values read back, and every seal matches what its
        object holds (:func:`labrig.store.format.check_seal`); what a seal does not cover (an
        attribute, a group or a dataset another program added) is kept in :attr:`additions`
        and not checked further. In a file whose root carries a seal of today's kind, every
        object labrig wrote is sealed: an object without one that is not an addition is
        refused. Files written before the seals have none."""
        strict = SEAL_ATTR in self.f.attrs
        added_groups: list[str] = []

        def check(name: str, obj: h5py.Group | h5py.Dataset) -> None:
            path = name.strip("/")
            if any(path.startswith(a + "/") for a in added_groups):
                return  # inside an addition: not labrig's
            allow_cpu(size_bytes=obj.size * obj.dtype.itemsize if _contiguous(obj) else 0)
            self.where = path
            values = self.attrs_read[obj.name] = read_attrs(obj)
            found = check_seal(obj, values, lambda: self.value(obj))
            if found.problem:
                raise self.error(
                    f"{found.problem}: the file's metadata is damaged, or another program "
                    "changed it"
                )
            if strict and not found.sealed and path not in self.additions:
                raise self.error(
                    f"has no seal (@{SEAL_ATTR}) where labrig seals every object: the file's "
                    "metadata is damaged, or another program changed it"
                )
            for a in found.additions:
                where = f"{path}/{a}" if path else a
                self.additions.append(where)
                if not a.startswith("@"):
                    added_groups.append(where)
            if found.data is not None:
                if obj.shape[:1] != (found.data[1],):
                    raise self.error(
                        f"holds {obj.shape[0] if obj.shape else 0} samples, its seal says "
                        f"{found.data[1]}: the file is damaged, or another program changed it"
                    )
                self.data_seals[path] = found.data[0]

        check("", self.f)
        self.f.visititems(check)

    def run(self, load: bool, seals: bool = True) -> tuple[RunFile, dict[str, dict]]:
        """The whole file (:func:`read_run`) and the shapes of every entry's channels;
        ``seals=False`` leaves the seals unchecked (a listing that only shows the file), but
        in a file sealed the older way (``@labrig_crc32``), where only the check tells what
        other programs added."""
        f = self.f
        if seals or LEGACY_SEAL_ATTR in f.attrs:  # an older file: its additions are found so
            self.check_seals()
        creator = self.attr(f, "creator", None)
        if creator != "labrig":
            said = (
                "no creator attribute"
                if creator is None
                else f"its creator is '{shown(creator)[:60]}'"
            )
            raise self.error(f"not a labrig run file ({said}, not 'labrig')", "")
        if not isinstance(f.get("run"), h5py.Group):
            raise self.error("not a labrig run file (no /run group)", "")
        run = f["run"]
        inst = run.get("instrument")
        instrument = (
            self.json(inst, "description_json", "{}", dict) if isinstance(inst, h5py.Group) else {}
        )
        planned = self.json(run, "planned_entries", "[]", list)
        seed = self.integer(run, "seed")
        notes = {k: run[k] for k in ("protocol", "rig") if isinstance(run.get(k), h5py.Group)}
        version = self.attr(f, "labrig_format", 0)
        out = RunFile(
            path=Path(self.path),
            format_version=int(version) if isinstance(version, int | np.integer) else 0,
            creator_version=str(self.attr(f, "creator_version")),
            file_time=str(self.attr(f, "file_time")),
            status=self.status(run),
            reason=self.text(run, "status_reason"),
            start_time=self.text(run, "start_time"),
            end_time=self.text(run, "end_time"),
            seed=None if seed is None or seed < 0 else seed,
            software_version=self.text(run, "software_version"),
            protocol_name=self.text(run, "protocol_name"),
            protocol_text=self.text(notes["protocol"], "data") if "protocol" in notes else "",
            rig_text=self.text(notes["rig"], "data") if "rig" in notes else "",
            protocol_file=self.text(notes["protocol"], "file_name") if "protocol" in notes else "",
            rig_file=self.text(notes["rig"], "file_name") if "rig" in notes else "",
            instrument=dict(instrument),
            planned_entries=[str(x) for x in planned],
            exit_code=self.integer(run, "exit_code"),
            metadata=self.scalars(run, "metadata", "NXcollection"),
            resumes=self.resumes(run),
            writer_pid=_int_or_none(self.attr(f, "writer_pid", None)),
            writer_host=str(self.attr(f, "writer_host", "")),
            additions=list(self.additions),
        )
        entries, shapes = [], {}
        for name in self.own(f):
            g = f[name]
            if name == "run" or not isinstance(g, h5py.Group):
                continue
            nx_class = self.attr(g, "NX_class")
            if nx_class != "NXentry":
                raise self.error(f"not an entry (NX_class {nx_class!r}) but beside /run")
            entry, shapes[name] = self.entry(name, g, load)
            entries.append(entry)
        self.where = ""
        indices = sorted(e.index for e in entries)
        if indices != list(range(len(entries))):
            raise self.error(f"the entries are numbered {indices} (entry_index), not 0 to n-1")
        entries.sort(key=lambda e: e.index)
        out.entries = {e.name: e for e in entries}
        return out, shapes


def read_run_here(
    path: Path | str, load_data: bool = True, seals: bool = True
) -> tuple[RunFile, dict]:
    """:func:`read_run` in this process (no time limit) and the shapes of every entry's
    channels; anything unexpected is an :class:`InputFileError` naming the object.
    ``seals=False``: the seals are not checked (the catalogue's listing of a file without a
    summary: it shows the file, it does not read its data)."""
    try:
        f = h5py.File(path, "r", locking=False)
    except Exception as e:
        raise InputFileError(
            [InputIssue(str(path), None, "", f"not a readable HDF5 run file ({e})")]
        ) from None
    with f:
        return read_open(path, f, load_data, seals)


def read_open(
    path: Path | str, f: h5py.File, load_data: bool = False, seals: bool = True
) -> tuple[RunFile, dict]:
    """:func:`read_run_here` of a file open already (the writer's summary reads the file it
    is writing: :mod:`labrig.store.summary`)."""
    reader = _Reader(path, f, Path(path).stat().st_size)
    try:
        return reader.run(load_data, seals)
    except InputFileError:
        raise
    except Exception as e:  # the file is not as labrig writes it: say where
        raise reader.error(f"damaged or not as labrig writes it ({_first_line(e)})") from None
