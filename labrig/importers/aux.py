"""Auxiliary channels of an imported entry: their names, units and values.

``--aux NAME=COLUMN`` names a channel; ``--aux COLUMN`` takes the column's own name. A name that
is a core channel's (time, voltage, strain) is refused with the option that would work. Every
other named column is kept on its own when it is numeric, finite and as long as the voltage (else
it is left out and the reason listed), under its name made HDF5-safe (``time_ms`` when ``time``
is taken; ``_2`` when a name repeats). A temperature column (unit degC, C, K, degF, or named
``temperature``/``temp`` without a unit) becomes ``temperature`` in degC, the channel the
analysis reads; other voltages, times and temperatures are converted to V, s and degC; other
units are kept as their text.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from labrig.importers.labels import CORE_NAMES, safe_name, unique
from labrig.importers.select import Selection
from labrig.importers.table import Table
from labrig.importers.units import convert, parse_unit

_TEMPERATURE_NAMES = ("temperature", "temp")


def channel(
    table: Table, k: int, name: str, unit_text: str, taken: set[str], named_by_user: bool
) -> tuple[str, NDArray[np.float64], str, str]:
    """(channel name, values, unit, conversion note) of auxiliary column ``k``; a column the
    user did not name becomes ``temperature`` when it is the first temperature."""
    values = table.columns[k].values
    assert values is not None
    unit = parse_unit(unit_text)
    is_temperature = unit.kind == "temperature" or (
        not unit.text and name.lower() in _TEMPERATURE_NAMES
    )
    first = is_temperature and "temperature" not in taken and not named_by_user
    if name == "temperature" or first:
        if unit.text and unit.kind != "temperature":
            raise table.error(
                k,
                f"is in {unit.text}: the channel 'temperature' is in degC "
                "(give this channel another name with --aux NAME=COLUMN)",
            )
        if not unit.text:
            return "temperature", values, "degC", "no unit given: taken as degC"
        out, _, note = convert(values, unit, "temperature")
        return "temperature", out, "degC", note
    origin = table.columns[k].origin
    counted = f"counted from {origin} (integers past 2**53, kept exact)" if origin else ""
    if unit.kind in ("voltage", "time", "temperature"):
        out, stored, note = convert(values, unit, unit.kind)
        return name, out, stored, "; ".join(x for x in (counted, note) if x)
    return name, values, unit.text, counted


def _own_name(table: Table, k: int, taken: set[str]) -> str:
    """An automatic channel's name: its label (``time_aux`` for a second time column, whose
    unit is converted), made unique (``_2``)."""
    name = safe_name(table.columns[k].label)
    if name.lower() in CORE_NAMES:
        name = f"{name}_aux"
    return unique(name, taken)


def _requested(table: Table, sel: Selection, n: int, taken: set[str]) -> list[tuple]:
    out = []
    for req, k in sel.requested:
        c = table.columns[k]
        name = req.name
        if name is None:
            if not c.label:
                raise table.error(
                    k, f"--aux {req.spec}: the column has no name; give one: --aux NAME={req.spec}"
                )
            name = safe_name(c.label)
            if name.lower() in CORE_NAMES:
                raise table.error(
                    k,
                    f"--aux {req.spec}: its name {name!r} is a core channel's; "
                    f"name it otherwise: --aux {name}_aux={req.spec}",
                )
        if name in taken:
            raise table.error(k, f"--aux {req.spec}: the channel {name!r} is given twice")
        if c.values is None or c.values.size != n:
            got = "text" if c.values is None else f"{c.values.size} samples"
            raise table.error(k, f"--aux {req.spec}: holds {got}, expected {n} numbers")
        bad = np.flatnonzero(~np.isfinite(c.values))
        if bad.size:
            raise table.error(k, f"--aux {req.spec}: empty or not a number (NaN/inf)", int(bad[0]))
        out.append(channel(table, k, name, req.unit or c.unit, taken, req.name is not None))
        taken.add(out[-1][0])
    return out


def _unusable(table: Table, k: int, n: int) -> str | None:
    v = table.columns[k].values
    if v is None:
        return None  # the reader has listed it (text)
    if v.size != n:
        return f"{v.size} samples, the voltage {n}"
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size == v.size:
        return "empty"
    if bad.size:
        line = table.line_of(int(bad[0]))
        where = f"line {line}" if line else f"sample {int(bad[0]) + 1}"
        return f"empty or not a number at {where} (name it with --aux to see the error)"
    return ""


def aux_channels(
    table: Table, sel: Selection, n: int
) -> tuple[dict[str, tuple[NDArray[np.float64], str]], dict[str, dict], list[str]]:
    """(channels: name -> (values, unit), metadata per channel, columns left out with why)."""
    taken: set[str] = set()
    chosen = [
        (k, ch) for (_, k), ch in zip(sel.requested, _requested(table, sel, n, taken), strict=True)
    ]
    skipped = []
    # a column named "temperature" is the temperature before any other in degC (`temp 1`)
    named_so = [k for k in sel.candidates if safe_name(table.columns[k].label) == "temperature"]
    for k in named_so + [k for k in sel.candidates if k not in named_so]:
        why = _unusable(table, k, n)
        if why is None:
            continue
        if why:
            skipped.append(f"{table.place(k)}: {why}")
            continue
        name = _own_name(table, k, taken)
        chosen.append((k, channel(table, k, name, table.columns[k].unit, taken, False)))
        taken.add(chosen[-1][1][0])
    channels, meta = {}, {}
    for k, (name, values, unit, note) in chosen:
        channels[name] = (values, unit)
        c = table.columns[k]
        meta[name] = {"from": table.place(k, False), "unit_in_file": c.unit, "unit": unit}
        if note:
            meta[name]["conversion"] = note
    return channels, meta, skipped
