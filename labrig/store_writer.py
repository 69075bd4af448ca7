"""Writing a run file incrementally while a protocol runs (layout: :mod:`labrig.store`).

Crash safety: :meth:`EntryWriter.append` extends every channel, writes the block and flushes the
file (``H5Fflush``) before returning, so after a ``kill -9`` the file opens and holds every block
whose ``append`` returned. Sample datasets carry Fletcher32 checksums (a damaged chunk is
reported on reading, not read back as numbers).

Disk full (:mod:`labrig.store_space`): before each block the free space is checked against the
chunks the block allocates; a block that does not fit, or a write HDF5 refuses, raises
:class:`~labrig.errors.StorageError` with the file as it was before the block (the channels are
cut back to the last complete block). The final records (:meth:`RunWriter.set_run_value`,
:meth:`RunWriter.add_run_collection`, :meth:`RunWriter.finish`) first release the writer's
reserve file, so they fit on a disk another program filled.
"""

from __future__ import annotations

import json
import logging
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import h5py
import numpy as np

from labrig import __version__
from labrig.errors import StorageError
from labrig.interrupts import reason_for, signum_of
from labrig.store_format import (
    FINAL_STATUSES,
    FORMAT_VERSION,
    SEAL_ATTR,
    STRING_DTYPE,
    Channel,
    channel,
    now_iso,
    seal_of,
)
from labrig.store_space import (
    BLOCK_MARGIN_BYTES,
    Reserve,
    chunk_bytes,
    chunk_length,
    free_bytes,
    is_disk_full,
)

log = logging.getLogger("labrig.store")
_STR = STRING_DTYPE
#: the HDF5 filter every sample dataset of a new run file carries
CHECKSUM = "fletcher32"

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


def _renew_seal(obj: h5py.Group | h5py.Dataset) -> None:
    crc = seal_of(obj)
    if obj.attrs.get(SEAL_ATTR) != crc:
        obj.attrs[SEAL_ATTR] = np.uint32(crc)


def seal_all(f: h5py.File) -> None:
    """Renew the seal (:func:`labrig.store_format.seal_of`) of every object in ``f`` whose
    seal no longer matches (new objects, changed metadata)."""
    _renew_seal(f)
    f.visititems(lambda _name, obj: _renew_seal(obj))


def seal_groups(groups: Iterable[h5py.Group]) -> None:
    """Renew the seals of ``groups`` and of the datasets directly in them (what the writer
    changes when it begins or finishes an entry or the run)."""
    for g in groups:
        _renew_seal(g)
        for obj in g.values():
            if isinstance(obj, h5py.Dataset):
                _renew_seal(obj)


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
        Raises :class:`~labrig.errors.StorageError` if the block does not fit on the disk or
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
                ds = self._data[c.name]
                ds.resize((n1,))
                ds[n0:n1] = arrays[c.name]
            self._run.flush()
        except Exception as e:
            self._cut_back(n0)
            raise self._run.storage_error(operation, e) from None
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
                self._data[c.name].resize((n,))
            except Exception as e:
                log.error("cutting %s/%s back to %d samples failed: %s", self.name, c.name, n, e)

    def finish(self, status: str = "complete", reason: str | None = None) -> None:
        """Close the entry with ``status`` (complete / aborted / failed) and flush; raises
        :class:`~labrig.errors.StorageError` if that cannot be written."""
        if status not in FINAL_STATUSES:
            raise ValueError(f"entry status must be one of {FINAL_STATUSES}, not {status!r}")
        if self.status != "running":
            return
        g = self.group
        try:
            _set_str(g, "end_time", now_iso())
            if "duration" not in g:
                ds = g.create_dataset("duration", data=max(self._n - 1, 0) / self.rate_hz)
                ds.attrs["units"] = "s"
                ds.attrs["long_name"] = "time from the first to the last sample"
            _set_str(g, "status_reason", reason or "")
            _set_str(g, "status", status)
            self._run.entry_done()
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
    ):
        self.path = Path(path)
        if self.path.exists() and not overwrite:
            raise FileExistsError(f"run file {self.path} exists; refusing to overwrite it")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.close_error = ""
        self._reserve = Reserve(self.path, reserve_bytes)
        try:
            # no chunk cache: a block goes to the file in its own write call, so a write the
            # disk refuses fails there and then, and no unwritable chunk waits in a cache (with
            # a cache, cutting a channel back after a refused flush read back zeros)
            self._f = h5py.File(self.path, "w", track_order=True, rdcc_nbytes=0)
        except BaseException:
            self._reserve.release()
            raise
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
        self.seal_and_flush()

    # -- context manager ------------------------------------------------------------------
    def __enter__(self) -> RunWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
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
        """Write everything to disk (``H5Fflush``)."""
        self._f.flush()

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
        free on the run file's filesystem."""
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
            detail = "disk full (no space left on the device or quota exceeded)"
        else:
            detail = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
        return StorageError(str(self.path), operation, detail)

    def release_reserve(self) -> None:
        """Give the reserve file's room back (before the final records; idempotent)."""
        self._reserve.release()

    def set_run_value(
        self, name: str, value: float | int | str, units: str = "", long_name: str = "", **attrs
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
        arrays: Mapping[str, tuple[Sequence[float], str, str]],
        **attrs,
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
            ds.attrs["units"] = c.units
            ds.attrs["long_name"] = c.long_name
        if not self._entries:
            f.attrs["default"] = name
        self._entries.append(name)
        self._current = EntryWriter(self, g, rate_hz, chans)
        self.seal_and_flush(f, g, data)
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
            _set_str(self._g, "end_time", now_iso())
            _set_str(self._g, "status_reason", reason or "")
            _set_str(self._g, "status", status)
            self._f.attrs["file_update_time"] = now_iso()
            self.seal_and_flush(self._f, self._g)
        except Exception as e:
            raise self.storage_error(f"recording the run's end ({status})", e) from None
        self.status = status

    def close(self) -> None:
        """Close the file (without finishing: a closed running run stays ``running``) and
        release the reserve. Never raises: a failure is logged and kept in ``close_error``."""
        self.release_reserve()
        if not self._f:
            return
        try:
            self._f.close()
        except Exception as e:
            self.close_error = str(self.storage_error("closing the file", e))
            log.info("%s", self.close_error)
