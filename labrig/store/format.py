"""The run file's vocabulary, shared by the writer and the reader: format version, statuses,
standard channels, how timestamps are written and the metadata seals (layout:
:mod:`labrig.store`).

**Seals.** HDF5 checksums (Fletcher32) cover the stored samples, but not the metadata of the
original file format: attribute values and text live in unchecksummed heaps, so a damaged byte
there reads back as another unit, another status or a missing entry. Every group and dataset
labrig writes carries :data:`SEAL_ATTR`, the CRC-32 (:func:`zlib.crc32`) of what a reader
takes from it besides the samples (:func:`seal_of`); the writer renews the seals whenever it
records metadata, the reader checks every seal it finds.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime

import h5py
import numpy as np

#: 1: the layout of docs/runfile.md (Fletcher32 checksums on sample datasets since labrig 0.1:
#: readers do not require them, so older files read the same)
FORMAT_VERSION = 1
STATUSES = ("running", "complete", "aborted", "failed")
FINAL_STATUSES = ("complete", "aborted", "failed")

#: what labrig calls microstrain in memory (``RunEntry.units``, CSV headers, the analysis)
MICROSTRAIN = "ue"
#: microstrain as new run files store it: a unit text that pint (every version) and UDUNITS-2
#: read out of the box (micrometre per metre); older files stored ``ue``, which neither reads
#: (pint takes it for micro-elementary-charge)
STORED_MICROSTRAIN = "um/m"
#: the spellings of microstrain a reader accepts as :data:`MICROSTRAIN`
MICROSTRAIN_SPELLINGS = frozenset(
    {"ue", "um/m", "µm/m", "μm/m", "microstrain", "µε", "με", "ustrain", "ppm strain"}
)

#: units (as in memory) and long names of the standard channels (``time`` is always present)
STANDARD_CHANNELS: dict[str, tuple[str, str]] = {
    "time": ("s", "time since the start of the entry"),
    "command_voltage": ("V", "commanded actuator voltage"),
    "amplifier_voltage": ("V", "amplifier output voltage (monitor)"),
    "gauge_raw": ("V", "strain-gauge conditioner output"),
    "strain": (MICROSTRAIN, "strain"),
    "temperature": ("degC", "temperature"),
}


def stored_units(units: str) -> str:
    """The unit text written to a file for ``units`` as labrig names it in memory: microstrain
    (``ue``) as :data:`STORED_MICROSTRAIN`, also inside a ratio (``mV/ue`` -> ``mV/(um/m)``);
    anything else unchanged."""
    if units in MICROSTRAIN_SPELLINGS:
        return STORED_MICROSTRAIN
    parts = units.split("/")
    if len(parts) == 2 and MICROSTRAIN in parts:
        return "/".join(f"({STORED_MICROSTRAIN})" if p == MICROSTRAIN else p for p in parts)
    return units


def memory_units(units: str) -> str:
    """The unit as labrig names it in memory for a unit text read from a file: every spelling
    of microstrain (:data:`MICROSTRAIN_SPELLINGS`, older files' ``ue`` included) is ``ue``,
    also inside a ratio written by :func:`stored_units`; anything else unchanged."""
    if units.strip() in MICROSTRAIN_SPELLINGS:
        return MICROSTRAIN
    return units.replace(f"({STORED_MICROSTRAIN})", MICROSTRAIN)


def stored_long_name(units: str, long_name: str) -> str:
    """A channel's long name as written: microstrain named in words (its stored unit text,
    ``um/m``, is exact but does not say *strain*)."""
    if units in MICROSTRAIN_SPELLINGS and "microstrain" not in long_name:
        return f"{long_name} (microstrain)"
    return long_name


def memory_long_name(long_name: str) -> str:
    """A long name as read: without the ``(microstrain)`` :func:`stored_long_name` adds, so old
    and new files read the same."""
    return long_name.removesuffix(" (microstrain)")


#: HDF5 variable-length UTF-8 string type of every text dataset
STRING_DTYPE = h5py.string_dtype()


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


#: the attribute holding an object's seal (module docstring)
SEAL_ATTR = "labrig_crc32"


def _canonical(value: object) -> bytes:
    """The bytes of an attribute's or a dataset's value as h5py reads it."""
    if isinstance(value, str):
        return b"s" + value.encode("utf-8", "surrogatepass")
    if isinstance(value, bytes):
        return b"b" + value
    if isinstance(value, np.ndarray) and value.dtype.kind == "O":
        return b"o" + b"\x1f".join(_canonical(v) for v in value.ravel())
    if isinstance(value, np.ndarray | np.generic):
        a = np.asarray(value)
        return a.dtype.str.encode() + repr(a.shape).encode() + a.tobytes()
    return b"r" + repr(value).encode()


def seal_of(obj: h5py.Group | h5py.Dataset) -> int:
    """CRC-32 of an object's attributes (but its seal), a group's member names and a
    non-chunked dataset's value; chunked datasets (samples) are covered by Fletcher32."""
    crc = 0
    for name in sorted(obj.attrs):
        if name != SEAL_ATTR:
            crc = zlib.crc32(b"@" + name.encode() + b"=" + _canonical(obj.attrs[name]), crc)
    if isinstance(obj, h5py.Group):
        crc = zlib.crc32(b"/" + "\x1f".join(sorted(obj)).encode(), crc)
    elif obj.chunks is None:
        crc = zlib.crc32(b"=" + _canonical(obj[()]), crc)
    return crc
