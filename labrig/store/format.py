"""The run file's vocabulary, shared by the writer and the reader: format version, statuses,
standard channels, how timestamps are written and the metadata seals (layout:
:mod:`labrig.store`).

**Seals.** HDF5 checksums (Fletcher32) cover the stored samples, but not the metadata of the
original file format: attribute values and text live in unchecksummed heaps, so a damaged byte
there reads back as another unit, another status or a missing entry; and another program that
rewrites samples through HDF5 recomputes their Fletcher32. Every group and dataset labrig
writes carries :data:`SEAL_ATTR` (:func:`seal_of`): the names of its attributes and members,
the CRC-32 (:func:`zlib.crc32`) of those names and values and of a non-chunked dataset's value,
and, once an entry is finished, the CRC-32 of each channel's samples. The writer renews the
seals whenever it records metadata; the reader checks every seal (:func:`check_seal`): what a
seal names must be there unchanged, while names it does not cover (an attribute, a group or a
dataset another NeXus tool added) are *additions*, reported and never taken for damage.
"""

from __future__ import annotations

import itertools
import json
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

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


#: the attribute holding an object's seal (module docstring): a JSON text, :func:`seal_of`
SEAL_ATTR = "labrig_seal"
#: the seal of files written before labrig sealed only its own names (a CRC-32 of everything
#: the object held, additions by other programs included); still checked, :func:`check_seal`
LEGACY_SEAL_ATTR = "labrig_crc32"
#: attributes no seal covers (the seals themselves)
SEAL_ATTRS = frozenset({SEAL_ATTR, LEGACY_SEAL_ATTR})
#: a legacy seal that does not match is explained by additions of at most this many names
#: (attributes or members) before the object is called changed
LEGACY_ADDITIONS = 2


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


def _attr_piece(name: str, value: object) -> bytes:
    return b"@" + name.encode() + b"=" + _canonical(value)


def _crc(
    obj: h5py.Group | h5py.Dataset,
    attrs: Sequence[str],
    members: Sequence[str] | None,
    values: Mapping[str, object] | None = None,
    read_value: Callable[[], object] | None = None,
) -> int:
    """CRC-32 of the attributes ``attrs`` (names and values, sorted by name; ``values``: the
    attribute values read already), a group's member names ``members`` and a non-chunked
    dataset's value (``read_value()``, default ``obj[()]``)."""
    crc = 0
    values = obj.attrs if values is None else values
    for name in sorted(attrs):
        crc = zlib.crc32(_attr_piece(name, values[name]), crc)
    if members is not None:
        crc = zlib.crc32(b"/" + "\x1f".join(sorted(members)).encode(), crc)
    elif isinstance(obj, h5py.Dataset) and obj.chunks is None:
        crc = zlib.crc32(b"=" + _canonical(read_value() if read_value else obj[()]), crc)
    return crc


def data_crc(values: np.ndarray, crc: int = 0) -> int:
    """CRC-32 of samples as stored (little-endian float64 bytes), continued from ``crc``: the
    writer folds in each block as it writes it, the reader checks the whole channel."""
    return zlib.crc32(np.ascontiguousarray(values, dtype="<f8").tobytes(), crc)


def seal_of(obj: h5py.Group | h5py.Dataset, data: tuple[int, int] | None = None) -> str:
    """The seal of an object as it is now (:data:`SEAL_ATTR`): a JSON text naming what it
    covers and its CRC-32 (:func:`_crc`)::

        {"crc": "1c291ca3", "attrs": ["long_name", "units"], "members": [...],
         "data": "9f0e41c2", "n": 5000}

    ``attrs``: every attribute but the seals; ``members``: a group's member names;
    ``data``, ``n``: a chunked dataset's samples (CRC-32 of their float64 bytes, their
    number), given by the writer once they are final (``data``) — chunked samples carry
    Fletcher32 besides. A reader checks exactly the names listed: what another program adds
    later is an addition, not a change (:func:`check_seal`)."""
    attrs = sorted(a for a in obj.attrs if a not in SEAL_ATTRS)
    members = sorted(obj) if isinstance(obj, h5py.Group) else None
    seal: dict[str, object] = {"crc": f"{_crc(obj, attrs, members):08x}", "attrs": attrs}
    if members is not None:
        seal["members"] = members
    if data is not None:
        seal["data"], seal["n"] = f"{data[0]:08x}", int(data[1])
    return json.dumps(seal, separators=(",", ":"))


def sealed_data(obj: h5py.Group | h5py.Dataset) -> tuple[int, int] | None:
    """The samples' CRC-32 and number an object's seal records (None: none, or no readable
    seal); not a check (:func:`check_seal` is)."""
    text = obj.attrs.get(SEAL_ATTR)
    if not isinstance(text, str | bytes):
        return None
    try:
        seal = json.loads(text)
        return (int(seal["data"], 16), int(seal["n"])) if "data" in seal else None
    except (ValueError, TypeError, KeyError, AttributeError):
        return None


def sealed_members(
    group: h5py.Group, values: Mapping[str, object] | None = None
) -> list[str] | None:
    """The member names a group's seal lists (what labrig wrote there), or None when it has no
    seal of today's kind; not a check (:func:`check_seal` is). ``values``: the group's
    attributes, read already (:func:`read_attrs`)."""
    text = (group.attrs if values is None else values).get(SEAL_ATTR)
    if not isinstance(text, str | bytes):
        return None
    try:
        members = json.loads(text)["members"]
    except (ValueError, TypeError, KeyError):
        return None
    return [str(m) for m in members] if isinstance(members, list) else None


@dataclass
class SealCheck:
    """What :func:`check_seal` found: ``sealed`` (the object carries a seal), ``problem`` (why
    it does not match, for a person; empty when it does), ``additions`` (attribute names as
    ``@name`` and member names the seal does not cover: added by another program) and, for
    chunked samples sealed by the writer, their CRC-32 and number (``data``)."""

    sealed: bool = False
    problem: str = ""
    additions: list[str] = field(default_factory=list)
    data: tuple[int, int] | None = None
    legacy: bool = False


def read_attrs(obj: h5py.Group | h5py.Dataset) -> dict[str, object]:
    """Every attribute of ``obj`` by name, as h5py reads it (a damaged attribute store raises
    here, instead of being taken for a missing attribute)."""
    attrs = obj.attrs  # one AttributeManager: h5py makes a new one at each ``.attrs``
    return {name: attrs[name] for name in attrs}


def check_seal(
    obj: h5py.Group | h5py.Dataset,
    values: Mapping[str, object] | None = None,
    read_value: Callable[[], object] | None = None,
) -> SealCheck:
    """Check an object against its seal: every attribute and member the seal names is there and
    holds what it held (CRC-32); names it does not cover are additions. Reads every attribute
    of the object (:func:`read_attrs`; ``values``: read already), sealed or not. A
    non-chunked dataset's value is read by ``read_value()`` (default ``obj[()]``) when a seal
    covers it. A legacy seal (:data:`LEGACY_SEAL_ATTR`, covering everything) that does not
    match is explained, when it can be, by up to :data:`LEGACY_ADDITIONS` names added since
    (a CRC-32 equality by chance: about 1 in 4e9 per try)."""
    values = read_attrs(obj) if values is None else values
    members = sorted(obj) if isinstance(obj, h5py.Group) else None
    if SEAL_ATTR in values:
        return _check_current(obj, values, members, read_value)
    if LEGACY_SEAL_ATTR in values:
        return _check_legacy(obj, values, members, read_value)
    return SealCheck()


def _check_current(
    obj: h5py.Group | h5py.Dataset,
    values: Mapping[str, object],
    members: list[str] | None,
    read_value: Callable[[], object] | None,
) -> SealCheck:
    text = values[SEAL_ATTR]
    text = text.decode("utf-8", "replace") if isinstance(text, bytes) else text
    try:
        seal: Any = json.loads(text) if isinstance(text, str) else None
        crc = int(seal["crc"], 16)
        attrs = [str(a) for a in seal["attrs"]]
        sealed_members = [str(m) for m in seal.get("members", [])]
        data = (int(seal["data"], 16), int(seal["n"])) if "data" in seal else None
    except (ValueError, TypeError, KeyError, AttributeError):
        return SealCheck(True, "its checksum (@labrig_seal) is not readable")
    missing = [f"@{a}" for a in attrs if a not in values]
    if members is not None:
        missing += [m for m in sealed_members if m not in members]
    if missing:
        gone = ", ".join(missing[:5])
        return SealCheck(True, f"does not match its checksum (@labrig_seal: {gone} missing)")
    listed = sealed_members if members is not None else None
    if _crc(obj, attrs, listed, values, read_value) != crc:
        return SealCheck(True, "does not match its checksum (@labrig_seal)")
    added = [f"@{a}" for a in values if a not in SEAL_ATTRS and a not in attrs]
    if members is not None:
        added += [m for m in members if m not in sealed_members]
    return SealCheck(True, "", added, data)


def _check_legacy(
    obj: h5py.Group | h5py.Dataset,
    values: Mapping[str, object],
    members: list[str] | None,
    read_value: Callable[[], object] | None,
) -> SealCheck:
    stored = values[LEGACY_SEAL_ATTR]
    attrs = sorted(a for a in values if a not in SEAL_ATTRS)
    pieces = {f"@{a}": _attr_piece(a, values[a]) for a in attrs}
    value = b""
    if members is None and isinstance(obj, h5py.Dataset) and obj.chunks is None:
        value = b"=" + _canonical(read_value() if read_value else obj[()])
    candidates = [*pieces, *(members or [])]

    def crc_without(left_out: tuple[str, ...]) -> int:
        crc = 0
        for name, piece in pieces.items():
            if name not in left_out:
                crc = zlib.crc32(piece, crc)
        if members is not None:
            kept = [m for m in members if m not in left_out]
            crc = zlib.crc32(b"/" + "\x1f".join(kept).encode(), crc)
        return zlib.crc32(value, crc) if value else crc

    for k in range(min(LEGACY_ADDITIONS, len(candidates)) + 1):
        for left_out in itertools.combinations(candidates, k):
            if crc_without(left_out) == stored:
                return SealCheck(True, "", list(left_out), legacy=True)
    return SealCheck(True, "does not match its checksum (@labrig_crc32)", legacy=True)
