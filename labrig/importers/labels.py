"""Names from labels: a header cell, a MATLAB variable or a ControlDesk channel name gives a
channel name and a unit; a file gives an entry name. Names in a run file are HDF5-safe: a letter,
then letters, digits or underscores, at most 63 characters.

Header forms understood (the unit is then converted by :mod:`labrig.importers.units`):
``strain [ue]``, ``strain (ue)``, ``strain <ue>``, ``strain / ue``, ``strain in ue`` and
``strain_ue`` (the last one only for the units of :data:`SUFFIX_UNITS`, so that ``strain_raw``
stays a name); ``t/ms`` (quantity/unit without spaces, DIN 1313 style), ``voltage: mV`` and
``voltage - mV`` only when what follows is a unit pint knows and the whole is not a ratio of
like units (``mm/m`` stays a strain unit, ``force/disp`` a name).
"""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

#: units recognised after the last underscore of a label (``temperature_C``, ``disp_um``)
SUFFIX_UNITS = frozenset((
    "s", "ms", "us", "ns", "min", "h", "V", "mV", "uV", "kV", "A", "mA", "uA", "nA", "ue",
    "microstrain", "ppm", "pct", "percent", "um", "µm", "μm", "nm", "mm", "cm", "m", "degC",
    "C", "K",
    "degF", "Hz", "kHz", "N", "kN", "Pa", "kPa", "MPa", "bar", "W", "mW", "ohm", "Ohm", "rad",
    "deg",
))  # fmt: skip
#: channel names of the run file that imported columns may not take as auxiliary channels
CORE_NAMES = frozenset({"time", "voltage", "command_voltage", "strain"})
#: names an entry may not take (groups of the run file itself)
RESERVED_ENTRY_NAMES = frozenset({"run"})

_BRACKETED = re.compile(r"^(?P<name>.*?)\s*[\[\(\{<](?P<unit>[^\[\]\(\)\{\}<>]*)[\]\)\}>]\s*$")
_SLASH = re.compile(r"^(?P<name>.*?\S)\s+(?:/|in)\s+(?P<unit>\S.*)$")
#: ``t/ms``, ``voltage: mV``, ``voltage - mV``: taken only when the unit parses (:func:`_known`)
_TIGHT = re.compile(r"^(?P<name>[^/:]*?[A-Za-z][^/:]*?)\s*(?:/|:|\s-)\s*(?P<unit>[^/\s][^:]*)$")
_NAME_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}")
_MAX_LABEL = 200


def split_label(label: str) -> tuple[str, str]:
    """``"Voltage [mV]"`` -> ``("Voltage", "mV")``; ``"temperature_C"`` -> ``("temperature",
    "C")``; ``"strain_raw"`` -> ``("strain_raw", "")``. Quotes and spaces around are removed."""
    text = label.strip().strip("\"'").strip()[:_MAX_LABEL]
    for pattern in (_BRACKETED, _SLASH):
        m = pattern.match(text)
        if m and m.group("name").strip():
            return m.group("name").strip(), m.group("unit").strip()
    m = _TIGHT.match(text)
    if m and _known(m.group("unit").strip()) and not _a_ratio(text):
        return m.group("name").strip(), m.group("unit").strip()
    head, sep, tail = text.rpartition("_")
    if sep and head and tail in SUFFIX_UNITS:
        return head, tail
    return text, ""


def _known(text: str) -> bool:
    from labrig.importers.units import parse_unit

    return parse_unit(text).pint_unit is not None


def _a_ratio(text: str) -> bool:
    """``mm/m``, ``um/m``: the whole label is a dimensionless unit (a strain), not a name/unit."""
    from labrig.importers.units import parse_unit

    u = parse_unit(text).pint_unit
    return u is not None and bool(u.dimensionless)


def safe_name(text: str, fallback: str = "ch") -> str:
    """``text`` made HDF5-safe: other characters become ``_``; a name that does not start with a
    letter gets ``fallback_`` in front; cut to 63 characters."""
    # a letter with a mark keeps its base letter (ümlaut -> umlaut); one with none is dropped
    plain = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    name = re.sub(r"[^A-Za-z0-9_]+", "_", plain).strip("_")
    if not name or not name[0].isalpha():
        name = f"{fallback}_{name}" if name else fallback
    return name[:63].rstrip("_") or fallback


def is_valid_name(name: str) -> bool:
    """A channel or entry name the run file takes as it is."""
    return bool(_NAME_RE.fullmatch(name))


def unique(name: str, taken: set[str] | frozenset[str]) -> str:
    """``name``, or ``name_2``, ``name_3``... the first not in ``taken`` (at most 63 chars)."""
    out, k = name, 2
    while out in taken:
        suffix = f"_{k}"
        out, k = name[: 63 - len(suffix)] + suffix, k + 1
    return out


def entry_name(path: Path, capture: str, n_captures: int, taken: set[str]) -> str:
    """The entry's name: the file's stem (``my-run 1.csv`` -> ``my_run_1``), followed by the
    capture's name when the file holds several captures; made unique against ``taken`` and the
    run file's own groups (an input named ``run.csv`` becomes ``run_2``)."""
    base = safe_name(path.stem, "entry")
    if capture and n_captures > 1:
        base = safe_name(f"{base}_{capture}", "entry")
    return unique(base, taken | RESERVED_ENTRY_NAMES)


def short_channel_name(full: str) -> str:
    """A ControlDesk channel's short name: the last part of its model path (``Model Root/
    amp/Out1`` -> ``amp``: a block's generic port name ``Out1``/``In1`` gives the block's name;
    ``.../scale\\gm_ia`` -> ``gm_ia``)."""
    parts = [p.strip().strip('"') for p in re.split(r"[/\\]", full) if p.strip().strip('"')]
    if not parts:
        return ""
    if len(parts) > 1 and re.fullmatch(r"(?i)(out|in)\d*", parts[-1]):
        return parts[-2]
    return parts[-1]
