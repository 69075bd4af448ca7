"""The HDF5 run file: written incrementally while a protocol runs, read back for analysis.

Layout (NeXus conventions; docs/runfile.md is the full description)::

    /                         @NX_class=NXroot @default=<first entry> @creator=labrig
                              @creator_version @file_name @file_time @file_update_time
                              @HDF5_Version @h5py_version @labrig_format=1
    /run                      NXcollection: the run as a whole
        status, status_reason   "running" | "complete" | "aborted" | "failed"; why
        start_time, end_time    ISO 8601 with UTC offset
        seed, software_version, program_name, protocol_name, planned_entries (JSON list)
        protocol              NXnote: type, file_name, data = the protocol file's text
        rig                   NXnote: type, file_name, data = the rig file's text
        instrument            NXinstrument: one group per device (identity / settings),
                              description_json = the rig's describe() as JSON
    /<entry>                  NXentry per concrete step, in run order, @default=data
        title, entry_index, start_time, end_time, status, status_reason, sample_rate (Hz),
        step_definition (JSON of the concrete step), duration (s, at finish)
        instrument, protocol, rig   hard links to the /run groups
        data                  NXdata @signal=strain @axes=time @auxiliary_signals=[...]
            time (s), command_voltage (V), amplifier_voltage (V), gauge_raw (V),
            strain (ue), temperature (degC), ...   every one with @units and @long_name

Crash safety: sample datasets are chunked and resizable; :meth:`EntryWriter.append` extends
them, writes the block and flushes the file (``H5Fflush``) before returning, so after a
``kill -9`` the file opens and holds every block whose ``append`` returned. The statuses then
still read ``running``: readers report such a run as incomplete. Tests kill a writer for real.
We do not use SWMR: it needs every object created before writing starts and leaves a file
that plain readers refuse to open after a crash; plain flushes survived every kill we tried.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import h5py
import numpy as np

from labrig import __version__
from labrig.errors import InputFileError, InputIssue

FORMAT_VERSION = 1
STATUSES = ("running", "complete", "aborted", "failed")
FINAL_STATUSES = ("complete", "aborted", "failed")

#: units and long names of the standard channels (``time`` is always present)
STANDARD_CHANNELS: dict[str, tuple[str, str]] = {
    "time": ("s", "time since the start of the entry"),
    "command_voltage": ("V", "commanded actuator voltage"),
    "amplifier_voltage": ("V", "amplifier output voltage (monitor)"),
    "gauge_raw": ("V", "strain-gauge conditioner output"),
    "strain": ("ue", "strain"),
    "temperature": ("degC", "temperature"),
}
#: units guessed from key suffixes when the instrument description is stored
_SUFFIX_UNITS = {
    "_V": "V",
    "_mV": "mV",
    "_A": "A",
    "_F": "F",
    "_uF": "uF",
    "_hz": "Hz",
    "_Hz": "Hz",
    "_s": "s",
    "_ms": "ms",
    "_ue": "ue",
    "_ohm": "ohm",
    "_degC": "degC",
    "_m": "m",
    "_um": "um",
}
_STR = h5py.string_dtype()


def _units_from_key(key: str) -> str | None:
    """``i_peak_A`` -> ``A``; ``gain_V_per_V`` -> ``V/V``; ``sensitivity_mV_per_ue`` ->
    ``mV/ue``; None when the key names no unit."""
    units = {u.lstrip("_") for u in _SUFFIX_UNITS}
    m = re.search(r"_([A-Za-z]+)_per_([A-Za-z]+)$", key)
    if m and m.group(1) in units and m.group(2) in units:
        return f"{m.group(1)}/{m.group(2)}"
    if m:
        return None
    for suffix, u in _SUFFIX_UNITS.items():
        if key.endswith(suffix):
            return u
    return None


def now_iso() -> str:
    """Local time, ISO 8601 with UTC offset, millisecond resolution."""
    return datetime.now().astimezone().isoformat(timespec="milliseconds")


@dataclass(frozen=True)
class Channel:
    """One recorded signal: dataset name, units and a human-readable long name."""

    name: str
    units: str
    long_name: str


def channel(spec: Channel | Sequence[str] | str) -> Channel:
    """A :class:`Channel` from a Channel, a ``(name, units, long_name)`` or a standard name."""
    if isinstance(spec, Channel):
        return spec
    if isinstance(spec, str):
        if spec not in STANDARD_CHANNELS:
            raise ValueError(f"{spec!r} is not a standard channel; give (name, units, long_name)")
        return Channel(spec, *STANDARD_CHANNELS[spec])
    name, units, long_name = spec
    return Channel(str(name), str(units), str(long_name))


def _check_name(name: str, what: str) -> None:
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,62}", name):
        raise ValueError(f"{what} {name!r}: use a letter, then letters, digits or underscores")


def _set_str(group: h5py.Group, name: str, value: str) -> None:
    """Create or overwrite a scalar string dataset."""
    if name in group:
        group[name][()] = value
    else:
        group.create_dataset(name, data=value, dtype=_STR)


def _write_tree(group: h5py.Group, d: Mapping, nx_class: str = "NXcollection") -> None:
    """Nested dict -> groups and scalar/array datasets (units guessed from key suffixes)."""
    group.attrs["NX_class"] = nx_class
    for key, value in d.items():
        name = str(key).replace("/", "_") or "_"
        if name in (".", ".."):
            name = "_" + name
        if isinstance(value, Mapping):
            _write_tree(group.create_group(name, track_order=True), value)
            continue
        if value is None:
            ds = group.create_dataset(name, data="null", dtype=_STR)
        elif isinstance(value, bool | np.bool_):
            ds = group.create_dataset(name, data=bool(value))
        elif isinstance(value, int | float | np.integer | np.floating) and not isinstance(
            value, bool
        ):
            ds = group.create_dataset(name, data=value)
        elif isinstance(value, str):
            ds = group.create_dataset(name, data=value, dtype=_STR)
        elif (
            isinstance(value, list | tuple)
            and value
            and all(isinstance(x, int | float) and not isinstance(x, bool) for x in value)
        ):
            ds = group.create_dataset(name, data=np.asarray(value, dtype=float))
        else:
            ds = group.create_dataset(name, data=json.dumps(value, default=str), dtype=_STR)
        units = _units_from_key(name)
        if units and not isinstance(value, str):
            ds.attrs["units"] = units


def _note(group: h5py.Group, name: str, text: str, file_name: str, description: str) -> h5py.Group:
    g = group.create_group(name)
    g.attrs["NX_class"] = "NXnote"
    _set_str(g, "type", "text/x-yaml")
    _set_str(g, "file_name", file_name)
    _set_str(g, "description", description)
    _set_str(g, "data", text)
    return g


class EntryWriter:
    """Writes one NXentry; get it from :meth:`RunWriter.begin_entry`."""

    def __init__(self, run: RunWriter, group: h5py.Group, rate_hz: float, channels: list[Channel]):
        self._run = run
        self.group = group
        self.name = group.name.lstrip("/")
        self.rate_hz = float(rate_hz)
        self.channels = channels
        self._data = group["data"]
        self._n = 0
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
        for c in self.channels:
            ds = self._data[c.name]
            ds.resize((n1,))
            ds[n0:n1] = arrays[c.name]
        self._n = n1
        self._run.flush()
        return self._n

    def finish(self, status: str = "complete", reason: str | None = None) -> None:
        """Close the entry with ``status`` (complete / aborted / failed) and flush."""
        if status not in FINAL_STATUSES:
            raise ValueError(f"entry status must be one of {FINAL_STATUSES}, not {status!r}")
        if self.status != "running":
            return
        g = self.group
        _set_str(g, "end_time", now_iso())
        ds = g.create_dataset("duration", data=max(self._n - 1, 0) / self.rate_hz)
        ds.attrs["units"] = "s"
        ds.attrs["long_name"] = "time from the first to the last sample"
        _set_str(g, "status_reason", reason or "")
        _set_str(g, "status", status)
        self.status = status
        self._run._entry_done(self)
        self._run.flush()


class RunWriter:
    """Create a run file and write it incrementally; use as a context manager.

    ``protocol_text`` / ``rig_text`` are the files' texts (``rig_text`` may be empty for the
    built-in rig); ``instrument_description`` is the rig's ``describe()``: a dict of devices,
    each a nested dict (identity, settings). The run starts ``running``; call :meth:`finish`
    (leaving the ``with`` block without it finishes ``complete``, or ``failed`` / ``aborted``
    if an exception / Ctrl-C is propagating).
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
    ):
        self.path = Path(path)
        if self.path.exists() and not overwrite:
            raise FileExistsError(f"run file {self.path} exists; refusing to overwrite it")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = h5py.File(self.path, "w", track_order=True)
        f = self._f
        version = software_version or __version__
        f.attrs["NX_class"] = "NXroot"
        f.attrs["creator"] = "labrig"
        f.attrs["creator_version"] = version
        f.attrs["file_name"] = self.path.name
        f.attrs["file_time"] = now_iso()
        f.attrs["file_update_time"] = f.attrs["file_time"]
        f.attrs["HDF5_Version"] = h5py.version.hdf5_version
        f.attrs["h5py_version"] = h5py.version.version
        f.attrs["labrig_format"] = FORMAT_VERSION
        run = f.create_group("run", track_order=True)
        run.attrs["NX_class"] = "NXcollection"
        self._g = run
        _set_str(run, "status", "running")
        _set_str(run, "status_reason", "")
        _set_str(run, "start_time", now_iso())
        _set_str(run, "program_name", "labrig")
        _set_str(run, "software_version", version)
        _set_str(run, "protocol_name", protocol_name)
        ds = run.create_dataset("seed", data=-1 if seed is None else int(seed))
        ds.attrs["long_name"] = "random seed of the simulated rig (-1: none)"
        _set_str(run, "planned_entries", json.dumps(list(planned_entries or [])))
        _note(run, "protocol", protocol_text, protocol_file, "the protocol file as run")
        _note(
            run,
            "rig",
            rig_text,
            rig_file,
            "the rig file as run" if rig_file else "built-in rig (no rig file)",
        )
        inst = run.create_group("instrument", track_order=True)
        _write_tree(inst, dict(instrument_description), "NXinstrument")
        _set_str(inst, "description_json", json.dumps(instrument_description, default=str))
        self._entries: list[str] = []
        self._current: EntryWriter | None = None
        self.status = "running"
        self.flush()

    # -- context manager ------------------------------------------------------------------
    def __enter__(self) -> RunWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self.status == "running" and self._f:
            if exc_type is None:
                self.finish("complete")
            elif issubclass(exc_type, KeyboardInterrupt):
                self.finish("aborted", "interrupted (Ctrl-C)")
            else:
                self.finish("failed", f"{exc_type.__name__}: {exc}")
        self.close()

    # -- writing --------------------------------------------------------------------------
    def flush(self) -> None:
        self._f.flush()

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
        _set_str(g, "title", title or name)
        ds = g.create_dataset("entry_index", data=len(self._entries))
        ds.attrs["long_name"] = "position of the entry in the run (0-based)"
        _set_str(g, "start_time", now_iso())
        _set_str(g, "status", "running")
        _set_str(g, "status_reason", "")
        ds = g.create_dataset("sample_rate", data=float(rate_hz))
        ds.attrs["units"] = "Hz"
        ds.attrs["long_name"] = "sample rate"
        _set_str(g, "step_definition", json.dumps(dict(step_meta), default=str))
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
        chunk = int(min(max(1024, 2 ** math.ceil(math.log2(max(rate_hz, 1)))), 65536))
        for c in chans:
            ds = data.create_dataset(
                c.name, shape=(0,), maxshape=(None,), chunks=(chunk,), dtype="f8"
            )
            ds.attrs["units"] = c.units
            ds.attrs["long_name"] = c.long_name
        if not self._entries:
            f.attrs["default"] = name
        self._entries.append(name)
        self._current = EntryWriter(self, g, rate_hz, chans)
        self.flush()
        return self._current

    def _entry_done(self, entry: EntryWriter) -> None:
        self._f.attrs["file_update_time"] = now_iso()

    def finish(self, status: str = "complete", reason: str | None = None) -> None:
        """Close the run with ``status``; a still-running entry gets the same status."""
        if status not in FINAL_STATUSES:
            raise ValueError(f"run status must be one of {FINAL_STATUSES}, not {status!r}")
        if self.status != "running":
            return
        if self._current is not None and self._current.status == "running":
            why = reason or (None if status == "complete" else f"run {status}")
            self._current.finish(status, why)
        _set_str(self._g, "end_time", now_iso())
        _set_str(self._g, "status_reason", reason or "")
        _set_str(self._g, "status", status)
        self._f.attrs["file_update_time"] = now_iso()
        self.status = status
        self.flush()

    def close(self) -> None:
        """Close the file (without finishing: a closed running run stays ``running``)."""
        if self._f:
            self._f.close()


# ---------------------------------------------------------------------------------------------
# Reading


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

    def __getitem__(self, name: str) -> RunEntry:
        return self.entries[name]

    def __iter__(self):
        return iter(self.entries.values())

    def __len__(self) -> int:
        return len(self.entries)

    @property
    def incomplete(self) -> bool:
        """True when the writer never finished the run (crash, kill, still running)."""
        return self.status == "running"


def _s(group: h5py.Group, name: str, default: str = "") -> str:
    if name not in group:
        return default
    v = group[name][()]
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


def _attr(obj, name: str, default=""):
    v = obj.attrs.get(name, default)
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.ndarray) and v.dtype.kind in "OSU":
        return [x.decode() if isinstance(x, bytes) else str(x) for x in v]
    return v


def _open(path: Path | str) -> h5py.File:
    p = Path(path)
    if not p.is_file():
        raise InputFileError([InputIssue(str(path), None, "", "run file not found")])
    try:
        return h5py.File(p, "r", locking=False)
    except OSError as e:
        raise InputFileError(
            [InputIssue(str(path), None, "", f"not a readable HDF5 run file ({e})")]
        ) from None


def _read_entry(name: str, g: h5py.Group, load_data: bool) -> RunEntry:
    data_g = g.get("data")
    data: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    long_names: dict[str, str] = {}
    trimmed = False
    if isinstance(data_g, h5py.Group):
        for cname, ds in data_g.items():
            if not isinstance(ds, h5py.Dataset):
                continue
            units[cname] = str(_attr(ds, "units"))
            long_names[cname] = str(_attr(ds, "long_name"))
            data[cname] = ds[()] if load_data else np.empty(ds.shape)
        if data:
            n = min(len(v) for v in data.values())
            if any(len(v) != n for v in data.values()):
                trimmed = True
                data = {k: v[:n] for k, v in data.items()}
    try:
        step = json.loads(_s(g, "step_definition", "{}"))
    except json.JSONDecodeError:
        step = {}
    rate = float(g["sample_rate"][()]) if "sample_rate" in g else float("nan")
    return RunEntry(
        name=name,
        index=int(g["entry_index"][()]) if "entry_index" in g else -1,
        title=_s(g, "title", name),
        status=_s(g, "status", "unknown"),
        reason=_s(g, "status_reason"),
        start_time=_s(g, "start_time"),
        end_time=_s(g, "end_time"),
        rate_hz=rate,
        step=step,
        data=data,
        units=units,
        long_names=long_names,
        signal=str(_attr(data_g, "signal", "strain")) if data_g is not None else "strain",
        trimmed=trimmed,
    )


def read_run(path: Path | str, load_data: bool = True) -> RunFile:
    """Read a run file: metadata, and every entry's arrays (in run order).

    ``load_data=False`` reads metadata only (arrays are left empty of the right shape).
    A file that is not a labrig run file raises :class:`InputFileError`.
    """
    with _open(path) as f:
        if _attr(f, "creator") != "labrig" or "run" not in f:
            raise InputFileError(
                [InputIssue(str(path), None, "", "not a labrig run file (no /run group)")]
            )
        run = f["run"]
        try:
            instrument = json.loads(_s(run["instrument"], "description_json", "{}"))
        except (KeyError, json.JSONDecodeError):
            instrument = {}
        try:
            planned = json.loads(_s(run, "planned_entries", "[]"))
        except json.JSONDecodeError:
            planned = []
        seed = int(run["seed"][()]) if "seed" in run else -1
        out = RunFile(
            path=Path(path),
            format_version=int(_attr(f, "labrig_format", 0)),
            creator_version=str(_attr(f, "creator_version")),
            file_time=str(_attr(f, "file_time")),
            status=_s(run, "status", "unknown"),
            reason=_s(run, "status_reason"),
            start_time=_s(run, "start_time"),
            end_time=_s(run, "end_time"),
            seed=None if seed < 0 else seed,
            software_version=_s(run, "software_version"),
            protocol_name=_s(run, "protocol_name"),
            protocol_text=_s(run["protocol"], "data") if "protocol" in run else "",
            rig_text=_s(run["rig"], "data") if "rig" in run else "",
            protocol_file=_s(run["protocol"], "file_name") if "protocol" in run else "",
            rig_file=_s(run["rig"], "file_name") if "rig" in run else "",
            instrument=instrument,
            planned_entries=list(planned),
        )
        entries = []
        for name, g in f.items():
            if name == "run" or not isinstance(g, h5py.Group):
                continue
            if _attr(g, "NX_class") != "NXentry":
                continue
            entries.append(_read_entry(name, g, load_data))
        entries.sort(key=lambda e: e.index)
        out.entries = {e.name: e for e in entries}
    return out


def run_summary(path: Path | str) -> dict:
    """JSON-able summary of a run: status, seed, and per entry status, samples, duration,
    rate and the largest command voltage, amplifier voltage and strain."""
    run = read_run(path)

    def mx(e: RunEntry, k: str) -> float | None:
        v = e.data.get(k)
        return float(np.max(v)) if v is not None and len(v) else None

    return {
        "path": str(run.path),
        "protocol": run.protocol_name,
        "status": run.status,
        "reason": run.reason,
        "incomplete": run.incomplete,
        "start_time": run.start_time,
        "end_time": run.end_time,
        "seed": run.seed,
        "software_version": run.software_version,
        "planned_entries": len(run.planned_entries),
        "entries": [
            {
                "name": e.name,
                "status": e.status,
                "reason": e.reason,
                "samples": e.n_samples,
                "duration_s": e.duration_s,
                "rate_hz": e.rate_hz,
                "max_command_voltage_V": mx(e, "command_voltage"),
                "max_amplifier_voltage_V": mx(e, "amplifier_voltage"),
                "max_strain_ue": mx(e, "strain"),
                "channels": e.channels,
            }
            for e in run
        ],
    }


def run_info(path: Path | str):
    """A rich renderable summarising a run file (for ``labrig info RUN``)."""
    from rich.console import Group
    from rich.table import Table
    from rich.text import Text

    s = run_summary(path)
    status = s["status"]
    if s["incomplete"]:
        status += " (incomplete: the writer stopped without finishing the run)"
    elif s["reason"]:
        status += f" ({s['reason']})"
    planned = s["planned_entries"]
    n = len(s["entries"])
    head = Text.assemble(
        ("run file ", "bold"),
        s["path"],
        "\nprotocol: ",
        s["protocol"] or "-",
        "\nstatus: ",
        (status, "green" if s["status"] == "complete" else "red"),
        f"\nentries: {n}" + (f" of {planned} planned" if planned else ""),
        f"\nstarted {s['start_time'] or '-'}, ended {s['end_time'] or '-'}",
        f"\nseed {s['seed'] if s['seed'] is not None else '-'}, "
        f"labrig {s['software_version'] or '-'}",
    )
    t = Table(
        caption="s: duration; Hz: sample rate; max V: largest command voltage; "
        "max ue: largest strain"
    )
    t.add_column("entry", no_wrap=True)
    t.add_column("status")
    for col in ("samples", "s", "Hz", "max V", "max ue"):
        t.add_column(col, justify="right")

    def g(x, spec=".1f"):
        return "-" if x is None else format(x, spec)

    for e in s["entries"]:
        st = e["status"] + (f": {e['reason']}" if e["reason"] else "")
        t.add_row(
            e["name"],
            st,
            str(e["samples"]),
            g(e["duration_s"], ".3f"),
            g(e["rate_hz"], "g"),
            g(e["max_command_voltage_V"]),
            g(e["max_strain_ue"]),
        )
    return Group(head, t)


def _col_header(name: str, units: str) -> str:
    u = re.sub(r"[^A-Za-z0-9]+", "", units or "")
    return f"{name}_{u}" if u else name


def export_csv(path: Path | str, out_dir: Path | str) -> list[Path]:
    """Write one CSV per entry (``<out_dir>/<entry>.csv``); returns the paths written.

    The header line names the columns with their units, e.g. ``time_s,command_voltage_V,
    amplifier_voltage_V,gauge_raw_V,strain_ue``; values use up to 10 significant digits.
    """
    run = read_run(path)
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputFileError(
            [InputIssue(str(out), None, "--csv", f"cannot create directory: {e.strerror}")]
        ) from None
    written = []
    for e in run:
        p = out / f"{e.name}.csv"
        cols = e.channels
        header = [_col_header(c, e.units.get(c, "")) for c in cols]
        table = np.column_stack([e.data[c] for c in cols]) if cols else np.empty((0, 0))
        np.savetxt(p, table, fmt="%.10g", delimiter=",", header=",".join(header), comments="")
        written.append(p)
    return written
