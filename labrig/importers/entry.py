"""One table and the options -> one run-file entry: values checked, units converted, sign and
scale applied, the time base found, the window cut; every step stated in the entry's metadata.

- **Time**: the time column (converted to s), strictly increasing and uniform within
  :data:`~labrig.importers.limits.TIME_JITTER`; the rate is 1 / the median step. Without one,
  ``--rate-hz`` gives time = row / rate. The stored time starts at 0.
- **Units** (:mod:`labrig.importers.units`): voltage to V, strain to ue (a displacement needs
  ``--stack-length-mm``), time to s, temperatures to degC; a strain without a unit is refused
  (``--strain-units`` states it: a sensor's raw numbers are not microstrain); another missing
  unit is taken as the run file's and said so; a unit pint does not know is kept as its text.
- **Sign and scale**: ``value_in_run_units * scale + offset`` per channel.
- **Auxiliary channels**: ``--aux`` columns, then every other named column that is numeric,
  finite and as long as the voltage. A temperature column (unit degC, C, K, degF, or named
  ``temperature``/``temp``) becomes the channel ``temperature`` in degC.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from labrig.importers.aux import aux_channels
from labrig.importers.limits import RATE_RANGE_HZ, TIME_JITTER
from labrig.importers.options import Checked
from labrig.importers.select import Selection, select
from labrig.importers.table import Table
from labrig.importers.units import RUN_UNITS, convert, length_to_strain, parse_unit


@dataclass
class ImportedEntry:
    """One record ready for the run file: time (s, from 0), voltage (V), strain (``strain_unit``,
    normally ue), auxiliary channels (values, unit) and the metadata for its step definition."""

    name: str
    source: Path
    rate_hz: float
    time_s: NDArray[np.float64]
    voltage_V: NDArray[np.float64]
    strain: NDArray[np.float64]
    strain_unit: str
    aux: dict[str, tuple[NDArray[np.float64], str]]
    meta: dict = field(default_factory=dict)


def _finite(table: Table, k: int, values: NDArray[np.float64], what: str) -> None:
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise table.error(
            k, f"empty or not a number (NaN/inf) where the {what} is needed", int(bad[0])
        )


def _column(table: Table, k: int, n: int, what: str, voltage: int) -> NDArray[np.float64]:
    c = table.columns[k]
    if c.values is None:
        raise table.error(k, f"holds text, not numbers: cannot be the {what}")
    if c.values.size != n:
        raise table.error(
            k,
            f"has {c.values.size} samples, the voltage ({table.place(voltage, False)}) has "
            f"{n}: cannot be the {what}",
        )
    _finite(table, k, c.values, what)
    return c.values


def _in_unit(
    table: Table, k: int, role: str, unit_text: str, checked: Checked
) -> tuple[NDArray[np.float64], str, str]:
    """(values, stored unit, conversion note) of a core column in its run-file unit."""
    values = table.columns[k].values
    assert values is not None
    unit = parse_unit(unit_text)
    if not unit.text and role == "strain":  # a sensor's raw numbers are not microstrain
        raise table.error(
            k,
            "the strain states no unit (no unit in a header, a units row or the file's "
            "metadata): give --strain-units UNIT, e.g. ue (microstrain), %, mm/m, um with "
            "--stack-length-mm, or raw to keep a sensor's numbers as they are",
        )
    if not unit.text:
        return values, RUN_UNITS[role], f"no unit given: taken as {RUN_UNITS[role]}"
    if role == "strain" and unit.kind == "length":
        if checked.opt.stack_length_mm is None:
            raise table.error(
                k,
                f"is a displacement in {unit.text}: give --stack-length-mm L to convert it "
                "to strain (displacement / L), or --strain-units raw to keep the numbers as "
                "they are",
            )
        out, note = length_to_strain(values, unit, checked.opt.stack_length_mm)
        return out, "ue", note
    if unit.pint_unit is not None and unit.kind and unit.kind != role and role != "strain":
        raise table.error(
            k, f"is in {unit.text}, not a {role} unit (expected e.g. {RUN_UNITS[role]})"
        )
    other = unit.pint_unit is not None and not unit.pint_unit.dimensionless
    if role == "strain" and other and unit.kind != "strain":  # a time or voltage as the strain
        raise table.error(
            k,
            f"is in {unit.text}, not a strain unit (expected e.g. ue, %, mm/m, or um with "
            "--stack-length-mm): a swapped column? (--strain-units raw keeps the numbers as "
            "they are)",
        )
    if role == "voltage" and unit.kind != "voltage":
        # volts are the model's input: another quantity (mA, um) never, raw numbers if scaled
        if other or "voltage" not in checked.scales:
            raise table.error(
                k,
                f"is in {unit.text!r}, not a voltage unit (V, mV, kV...): give the column's "
                "unit in the file"
                + ("" if other else ", or --voltage-scale K to turn these numbers into volts"),
            )
        note = f"{unit.text} * --voltage-scale taken as V"
        return values, "V", note
    out, stored, note = convert(values, unit, role)
    if unit.kind != role:
        note = f"unit {unit.text!r} kept as it is (no conversion to {RUN_UNITS[role]} defined)"
    if role == "strain" and checked.opt.stack_length_mm is not None:
        unused = f"--stack-length-mm not used: the strain is in {unit.text}, not a displacement"
        note = f"{note}; {unused}" if note else unused
    return out, stored, note


def conversion_notes(meta: Mapping[str, Any]) -> list[str]:
    """What an import did to the units of an entry's columns, as ``CHANNEL: note``: the time's
    conversion (``taken as s`` when the column states no unit), then each channel's (the
    ``conversion`` notes of ``meta["channels"]``); for the person importing, who would not see
    an assumption otherwise."""
    notes = [f"time: {meta['time_conversion']}"] if meta.get("time_conversion") else []
    for name, ch in meta.get("channels", {}).items():
        if isinstance(ch, Mapping) and ch.get("conversion"):
            notes.append(f"{name}: {ch['conversion']}")
    return notes


def _time_base(
    table: Table, sel: Selection, checked: Checked, n: int
) -> tuple[NDArray[np.float64], float, dict, float]:
    """(time in s from the first sample, rate in Hz, metadata, the first sample's time in s as
    the file gives it) of the record. The time column is counted from its first value before
    its unit is converted: stamps of large magnitude (nanoseconds since 1970) keep their steps
    (their differences are exact; 9e15 ns converted first would keep steps of 2e-5 s to 1e-4),
    and so do decimal stamps far from zero (seconds since 1970 with µs digits: counted from
    the text, :meth:`~labrig.importers.table.Table.count_exactly`)."""
    lo, hi = RATE_RANGE_HZ
    rate_opt = checked.opt.rate_hz
    if sel.time is None:
        if rate_opt is None:
            raise table.error(None, "no time column: give the sample rate with --rate-hz")
        return np.arange(n) / rate_opt, float(rate_opt), {"rate_from": "--rate-hz"}, 0.0
    table.count_exactly(sel.time)  # before the checks: they see the values stored
    _column(table, sel.time, n, "time", sel.voltage)
    c = table.columns[sel.time]
    assert c.values is not None
    first = float(c.values[0])
    c.values = c.values - first  # exact for stamps of one binade, and for integer counts
    t, stored, note = _in_unit(table, sel.time, "time", c.unit, checked)
    start_s = float(convert(np.array([float(c.origin) + first]), parse_unit(c.unit), "time")[0][0])
    if stored != "s":
        raise table.error(sel.time, f"{note}: a time column needs a time unit (s, ms...)")
    dt = np.diff(t)
    back = np.flatnonzero(dt <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise table.error(
            sel.time,
            f"time {t[i] + start_s:.9g} s does not increase (the sample before: "
            f"{t[i - 1] + start_s:.9g} s)",
            i,
        )
    step = float(np.median(dt))
    dt /= step  # in place: a long record's time steps are not copied again
    dt -= 1.0
    uneven = np.flatnonzero(np.abs(dt, out=dt) > TIME_JITTER)
    if uneven.size:
        i = int(uneven[0]) + 1
        raise table.error(
            sel.time,
            f"time step {t[i] - t[i - 1]:.6g} s differs from the typical "
            f"{step:.6g} s by more than {TIME_JITTER:.0%}: not uniformly sampled",
            i,
        )
    rate = 1.0 / step
    if not lo <= rate <= hi:
        raise table.error(sel.time, f"sample rate {rate:g} Hz: expected {lo:g} to {hi:g} Hz")
    if rate_opt is not None and abs(rate_opt - rate) > 1e-3 * rate:
        raise table.error(
            sel.time, f"--rate-hz {rate_opt:g} disagrees with the time column ({rate:.9g} Hz)"
        )
    if c.origin:  # integers past 2**53, decimals far from zero: counted exactly from the first
        note = "; ".join(x for x in (f"counted from its first value {c.origin}", note) if x)
    meta = {"rate_from": "time column"} | ({"time_conversion": note} if note else {})
    return t, rate, meta, start_s


def _window(
    table: Table, t: NDArray[np.float64], checked: Checked, start_s: float
) -> tuple[slice, dict]:
    """The samples inside ``--window`` (in the file's time: ``t + start_s``)."""
    if checked.window is None:
        return slice(None), {}
    t = t + start_s
    t0, t1 = checked.window
    inside = np.flatnonzero((t >= t0) & (t <= t1))
    if inside.size < 2:
        raise table.error(
            None,
            f"--window {checked.opt.window}: fewer than 2 samples inside "
            f"(the record spans {t[0]:.6g} to {t[-1]:.6g} s)",
        )
    cut = slice(int(inside[0]), int(inside[-1]) + 1)
    meta = {
        "window_s": [t0 if np.isfinite(t0) else None, t1 if np.isfinite(t1) else None],
        "window_first_sample_s": float(t[cut.start]),
        "window_samples": int(inside.size),
    }
    return cut, meta


def _scaled(
    role: str, values: NDArray[np.float64], checked: Checked, offset: float = 0.0
) -> tuple[NDArray[np.float64], dict]:
    """``values * scale + offset`` (``--scale``, ``--voltage-scale``...) and what was done."""
    scale = checked.scales.get(role, 1.0)
    if scale == 1.0 and offset == 0.0:
        return values, {}
    return values * scale + offset, {"scale": scale, "offset": offset}


def _core(table: Table, sel: Selection, checked: Checked, n: int) -> dict:
    """Voltage and strain in run-file units, scaled, with their metadata."""
    out = {}
    opt = checked.opt
    for role, k, offset, unit in (
        ("voltage", sel.voltage, opt.voltage_offset, table.columns[sel.voltage].unit),
        (
            "strain",
            sel.strain,
            opt.strain_offset,
            opt.strain_units or table.columns[sel.strain].unit,
        ),
    ):
        _column(table, k, n, role, sel.voltage)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            values, stored, note = _in_unit(table, k, role, unit, checked)
            values, how = _scaled(role, values, checked, offset)
        if not np.all(np.isfinite(values)):  # finite in the file: the conversion overflowed
            i = int(np.flatnonzero(~np.isfinite(values))[0])
            raise table.error(
                k,
                f"becomes {values[i]} in {stored} after the unit conversion and scale: "
                "check --stack-length-mm and the --*-scale options",
                i,
            )
        meta = {"from": table.place(k, False), "unit_in_file": unit, "unit": stored, **how}
        out[role] = (values, stored, meta | ({"conversion": note} if note else {}))
    return out


def build_entry(table: Table, checked: Checked, name: str) -> ImportedEntry:
    """The entry of ``table`` under ``checked`` options (raises InputFileError naming the file,
    the line or variable, what was found and what was expected)."""
    sel = select(table, checked)
    needed = [k for k in sel.roles.values() if k is not None] + [k for _, k in sel.requested]
    table.load(needed + sel.candidates, set(needed))
    n = table.columns[sel.voltage].length or 0
    if n < 2:
        raise table.error(sel.voltage, f"{n} sample{'s' * (n != 1)}: need at least 2")
    t, rate, time_meta, start_s = _time_base(table, sel, checked, n)
    core = _core(table, sel, checked, n)
    aux, aux_meta, skipped = aux_channels(table, sel, n)
    unknown = set(checked.scales) - {"voltage", "strain"} - set(aux)
    if unknown:
        raise table.error(
            None,
            f"--scale {sorted(unknown)[0]}=...: no such channel (channels: "
            f"voltage, strain{''.join(', ' + a for a in aux)})",
        )
    for ch in list(aux):
        values, how = _scaled(ch, aux[ch][0], checked)
        aux[ch] = (values, aux[ch][1])
        aux_meta[ch].update(how)
    cut, window_meta = _window(table, t, checked, start_s)
    meta = {
        "kind": "import",
        "hold": "linear",
        "source": str(table.source),
        **({"capture": table.capture} if table.capture else {}),
        "format": table.layout,
        "columns": {
            role: table.place(k, False) if k is not None else None for role, k in sel.roles.items()
        },
        "channels": {"command_voltage": core["voltage"][2], "strain": core["strain"][2]} | aux_meta,
        **time_meta,
        **window_meta,
        "skipped": table.skipped + skipped,
    }
    time = t[cut]
    time -= time[0]  # in place: the table's copy of the time is not used again
    return ImportedEntry(
        name,
        table.source,
        rate,
        time,
        core["voltage"][0][cut],
        core["strain"][0][cut],
        core["strain"][1],
        {k: (v[cut], u) for k, (v, u) in aux.items()},
        meta,
    )
