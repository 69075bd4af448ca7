"""The run file's vocabulary, shared by the writer and the reader: format version, statuses,
standard channels and how timestamps are written (layout: :mod:`labrig.store`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime

import h5py

#: 1: the layout of docs/runfile.md (Fletcher32 checksums on sample datasets since labrig 0.1:
#: readers do not require them, so older files read the same)
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
