"""Units of imported signals (pint): what a unit text means and how it converts to the run
file's units (V, ue, s, degC).

A unit text is parsed by pint with a few lab spellings first (``C`` and ``°C`` are degC, ``ue``,
``µε`` and ``microstrain`` are 1e-6 strain, ``µm`` is um). A channel whose unit has the dimension
of a run-file unit is converted to it (mV -> V, ms -> s, K -> degC; for the strain, any
dimensionless unit: ``%``, ``ppm``, ``mm/m`` -> ue); other units are kept as their text
(``raw``, ``counts``, ``um`` for an auxiliary displacement).
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: run-file unit per kind of signal
RUN_UNITS = {"voltage": "V", "strain": "ue", "time": "s", "temperature": "degC"}

_ALIASES = {
    "c": "degC",
    "°c": "degC",
    "ºc": "degC",
    "deg c": "degC",
    "degc": "degC",
    "celsius": "degC",
    "°f": "degF",
    "f": "degF",
    "µε": "microstrain",
    "με": "microstrain",
    "ue": "microstrain",
    "µm": "micrometer",
    "μm": "micrometer",
    "volt": "volt",
    "volts": "volt",
    "v": "volt",
    "vdc": "volt",
    "v dc": "volt",
    "v_dc": "volt",
    "µe": "microstrain",
    "μe": "microstrain",
    "sec": "second",
    "secs": "second",
    "pct": "percent",
}
# a conservative shape for a unit text: letters, digits, a few operators; short
_UNIT_TEXT = re.compile(r"^[A-Za-zµμΩ°º%][A-Za-z0-9µμΩ°º%/*^.· -]{0,23}$")
_KIND_OF_REFERENCE = {"V": "voltage", "s": "time", "K": "temperature", "m": "length"}
_STRAIN_UNITS = frozenset({"microstrain", "percent", "ppm", "permille"})


@functools.cache
def registry() -> Any:
    """The one pint registry (built on first use: about 0.2 s)."""
    import pint

    reg: Any = pint.UnitRegistry()
    reg.define("microstrain = 1e-6 = µε")
    return reg


@dataclass(frozen=True)
class Unit:
    """A parsed unit: the text as given, pint's unit (None if pint does not know it) and the
    kind of signal it measures (``voltage``, ``time``, ``temperature``, ``strain`` for ue, %,
    ppm, permille or a length per length, ``length``, or ``""``)."""

    text: str
    pint_unit: Any = None
    kind: str = ""


def parse_unit(text: str) -> Unit:
    """The unit of a label (never raises: an unknown unit is kept as its text)."""
    text = text.strip()
    if not text:
        return Unit("")
    key = _ALIASES.get(text.lower(), text)
    if not _UNIT_TEXT.match(key):
        return Unit(text)
    u = _pint_unit(key)
    if u is None:
        return Unit(text)
    return Unit(text, u, _kind(key, u))


def _pint_unit(key: str) -> Any:
    try:
        return registry().parse_units(key)
    except Exception:  # pint raises several types for text it cannot read
        return None


def _kind(key: str, u: Any) -> str:
    for ref, kind in _KIND_OF_REFERENCE.items():
        if u.dimensionality == _pint_unit(ref).dimensionality:
            return kind
    if str(u) in _STRAIN_UNITS:
        return "strain"
    parts = key.split("/")
    if len(parts) == 2 and all(
        (p := _pint_unit(x.strip())) is not None and _kind(x.strip(), p) == "length" for x in parts
    ):
        return "strain"
    return ""


def convert(
    values: NDArray[np.float64], unit: Unit, kind: str
) -> tuple[NDArray[np.float64], str, str]:
    """``values`` in ``unit`` converted to the run-file unit of ``kind`` when the dimensions
    agree: returns (values, unit text stored, what was done). Otherwise unchanged, the unit
    text kept."""
    target = RUN_UNITS.get(kind)
    if target is None or unit.pint_unit is None or unit.kind != kind:
        return values, unit.text, ""
    reg = registry()
    to = reg.parse_units("microstrain" if target == "ue" else target)
    if unit.pint_unit == to:
        return values, target, ""
    out = reg.Quantity(values, unit.pint_unit).to(to).magnitude
    return np.asarray(out, dtype=np.float64), target, f"{unit.text} -> {target}"


def length_to_strain(
    values: NDArray[np.float64], unit: Unit, stack_length_mm: float
) -> tuple[NDArray[np.float64], str]:
    """A displacement in a length ``unit`` over a stack of ``stack_length_mm`` as strain in ue:
    ``strain = displacement / L`` (returns values and what was done)."""
    reg = registry()
    q = reg.Quantity(values, unit.pint_unit) / reg.Quantity(stack_length_mm, "mm")
    out = np.asarray(q.to("microstrain").magnitude, dtype=np.float64)
    return out, f"{unit.text} / {stack_length_mm:g} mm stack -> ue"
