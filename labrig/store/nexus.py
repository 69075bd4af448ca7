"""The run file's descriptive groups (NeXus base classes), written by
:mod:`labrig.store.writer`: the instrument description (NXinstrument), the protocol and rig
texts (NXnote), the run's metadata (``/run/metadata``, NXcollection) and, in each entry,
``definition``, ``program_name``, ``user`` (NXuser) and ``sample`` (NXsample) (layout:
docs/runfile.md). Units are stored as pint and UDUNITS-2 read them
(:func:`labrig.store.format.stored_units`); an unset value (``None``) is not stored at all.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping

import h5py
import numpy as np

from labrig.core.metadata import RunMetadata
from labrig.store.format import FORMAT_VERSION, STRING_DTYPE, stored_units

#: the name written as each entry's ``definition`` (labrig's layout, docs/runfile.md)
DEFINITION = "NXlabrig"
PROGRAM_NAME = "labrig"

#: units guessed from key suffixes when the instrument description is stored (as labrig names
#: them; stored through :func:`stored_units`)
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


def units_from_key(key: str) -> str | None:
    """``i_peak_A`` -> ``A``; ``gain_V_per_V`` -> ``V/V``; ``sensitivity_mV_per_ue`` ->
    ``mV/ue``; None when the key names no unit (as labrig names units in memory)."""
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


def set_str(group: h5py.Group, name: str, value: str) -> h5py.Dataset:
    """Create or overwrite a scalar string dataset."""
    if name in group:
        group[name][()] = value
    else:
        group.create_dataset(name, data=value, dtype=STRING_DTYPE)
    return group[name]


def _scalar(group: h5py.Group, name: str, value: object) -> h5py.Dataset | None:
    """A scalar or small numeric array dataset for ``value``; ``None`` (unset) writes nothing."""
    if value is None:
        return None
    if isinstance(value, bool | np.bool_):
        return group.create_dataset(name, data=bool(value))
    if isinstance(value, int | np.integer) and _fits_int64(value):
        return group.create_dataset(name, data=np.int64(value))
    if isinstance(value, float | np.floating):
        return group.create_dataset(name, data=value)
    if isinstance(value, str):
        return group.create_dataset(name, data=value, dtype=STRING_DTYPE)
    if isinstance(value, list | tuple) and value and all(_is_number(x) for x in value):
        # whole numbers stay whole (int64): ids and counts above 2**53 keep every digit
        if all(isinstance(x, int | np.integer) and _fits_int64(x) for x in value):
            return group.create_dataset(name, data=np.asarray(value, dtype=np.int64))
        if not any(isinstance(x, int | np.integer) and not _fits_int64(x) for x in value):
            return group.create_dataset(name, data=np.asarray(value, dtype=float))
    # anything else (nested values, whole numbers beyond 64 bits) as exact JSON text
    return group.create_dataset(name, data=json.dumps(value, default=str), dtype=STRING_DTYPE)


def _is_number(x: object) -> bool:
    return isinstance(x, int | float | np.integer | np.floating) and not isinstance(
        x, bool | np.bool_
    )


def _fits_int64(x: int | np.integer) -> bool:
    return -(2**63) <= int(x) < 2**63


def write_tree(group: h5py.Group, d: Mapping, nx_class: str = "NXcollection") -> None:
    """Nested dict -> groups and scalar/array datasets, units guessed from key suffixes
    (:func:`units_from_key`); ``None`` values are left out."""
    group.attrs["NX_class"] = nx_class
    for key, value in d.items():
        name = str(key).replace("/", "_") or "_"
        if name in (".", ".."):
            name = "_" + name
        if isinstance(value, Mapping):
            write_tree(group.create_group(name, track_order=True), value)
            continue
        ds = _scalar(group, name, value)
        units = units_from_key(name)
        if ds is not None and units and not isinstance(value, str):
            ds.attrs["units"] = stored_units(units)


def write_note(
    group: h5py.Group, name: str, text: str, file_name: str, description: str
) -> h5py.Group:
    """An NXnote holding a file's text (the protocol, the rig file)."""
    g = group.create_group(name)
    g.attrs["NX_class"] = "NXnote"
    set_str(g, "type", "text/x-yaml")
    set_str(g, "file_name", file_name)
    set_str(g, "description", description)
    set_str(g, "data", text)
    return g


def write_metadata_collection(parent: h5py.Group, name: str, metadata: RunMetadata) -> h5py.Group:
    """``parent/name``, an NXcollection with one scalar per metadata key (units from the key's
    suffix, as for the instrument: ``temperature_degC`` -> ``degC``)."""
    g = parent.create_group(name, track_order=True)
    g.attrs["NX_class"] = "NXcollection"
    for key, value in metadata.values.items():
        ds = _scalar(g, key, value)
        units = units_from_key(key)
        if ds is not None and units and not isinstance(value, str):
            ds.attrs["units"] = stored_units(units)
    return g


def _fields_group(entry: h5py.Group, name: str, nx_class: str, fields: Mapping[str, str]) -> None:
    if not fields:
        return
    g = entry.create_group(name, track_order=True)
    g.attrs["NX_class"] = nx_class
    for key, value in fields.items():
        set_str(g, key, value)


def write_entry_identity(entry: h5py.Group, metadata: RunMetadata, version: str) -> None:
    """An entry's ``definition`` and ``program_name`` (with ``@version``), and its ``user``
    (NXuser) and ``sample`` (NXsample) groups when the metadata names an operator or a sample
    (:meth:`RunMetadata.user_fields`, :meth:`RunMetadata.sample_fields`)."""
    ds = set_str(entry, "definition", DEFINITION)
    ds.attrs["version"] = str(FORMAT_VERSION)
    ds = set_str(entry, "program_name", PROGRAM_NAME)
    ds.attrs["version"] = version
    _fields_group(entry, "user", "NXuser", metadata.user_fields())
    _fields_group(entry, "sample", "NXsample", metadata.sample_fields())
