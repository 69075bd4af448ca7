"""Which columns of a table are the time, the voltage, the strain and the auxiliary channels.

A column is named by its 1-based number, its label (header cell, variable or channel name, with
or without its unit: ``temperature`` or ``temperature_C``), a ControlDesk channel's short name,
or its place (``Y(3)``, ``column 3``); case does not matter. Without an option, the time, voltage
and strain are found by name (:data:`DEFAULT_NAMES`), else each as the only column in a unit of
theirs (:data:`UNIT_KINDS`: ``Zeit [s]`` is the time); a ControlDesk channel's time is its ``X``.
Every other column with a name of its own becomes an auxiliary channel.
"""

from __future__ import annotations

from dataclasses import dataclass

from labrig.importers.options import AuxRequest, Checked
from labrig.importers.table import Table
from labrig.importers.units import parse_unit

#: names (lower case, unit removed) that mark a core column when no option names it
DEFAULT_NAMES = {
    "time": ("time", "t", "t_s", "time_s"),
    "voltage": ("voltage", "v", "u", "command_voltage", "voltage_v", "v_v"),
    "strain": ("strain", "s", "strain_ue", "strain_microstrain"),
}
#: unit kinds that mark a core column when no name does (the only such column)
UNIT_KINDS = {"time": ("time",), "voltage": ("voltage",), "strain": ("strain", "length")}


@dataclass
class Selection:
    """Column indices: the roles (time None: no time column), the ``--aux`` requests with their
    columns, and the columns that may become auxiliary channels on their own."""

    time: int | None
    voltage: int
    strain: int
    requested: list[tuple[AuxRequest, int]]
    candidates: list[int]

    @property
    def roles(self) -> dict[str, int | None]:
        return {"time": self.time, "voltage": self.voltage, "strain": self.strain}


def column_list(table: Table, limit: int = 12) -> str:
    """The columns for a message: ``1 time [s], 2 voltage [V], ...`` or how many there are,
    and what the reader left out (a complex or logical variable, a text column)."""
    listed = _listed(table, limit)
    return f"{listed}; left out: {'; '.join(table.skipped[:3])}" if table.skipped else listed


def _listed(table: Table, limit: int) -> str:
    shown = [c for c in table.columns if not c.is_axis]
    if not shown:
        return "the file holds no numeric signal"
    if not any(c.named for c in shown):
        return f"{len(shown)} columns, no names: give a number from 1 to {len(shown)}"
    parts = [
        f"{c.number or c.where} {c.label}" + (f" [{c.unit}]" if c.unit else "")
        for c in shown[:limit]
    ]
    more = f", ... ({len(shown)} in all; labrig import FILE --list shows them)"
    return ", ".join(parts) + (more if len(shown) > limit else "")


def _names(table: Table, k: int) -> set[str]:
    c = table.columns[k]
    return {n.lower() for n in (c.label, c.where, *c.aliases) if n}


def find_column(table: Table, spec: str, what: str) -> int:
    """The column ``spec`` names (raises an error naming the file, the spec and the columns)."""
    spec = spec.strip()
    if spec.isdigit():
        hits = [k for k, c in enumerate(table.columns) if c.number == int(spec)]
    else:
        hits = [k for k in range(len(table.columns)) if spec.lower() in _names(table, k)]
    if len(hits) == 1:
        return hits[0]
    if hits:
        places = ", ".join(table.place(k) for k in hits)
        raise table.error(None, f"{what} {spec!r} is ambiguous: {places}; give its number")
    raise table.error(None, f"no {what} column {spec!r} (columns: {column_list(table)})")


def _default(table: Table, role: str, taken: set[int]) -> int | None:
    """By name (:data:`DEFAULT_NAMES`), else the only free column in a unit of the role."""
    free = [k for k, c in enumerate(table.columns) if k not in taken and not c.is_axis]
    for name in DEFAULT_NAMES[role]:
        hits = [k for k in free if name in _names(table, k)]
        same = {(table.columns[k].label.lower(), table.columns[k].unit) for k in hits}
        if len(same) < len(hits):  # "voltage [V]" twice: never the first one silently
            places = ", ".join(table.place(k) for k in hits)
            raise table.error(None, f"two columns could be the {role} ({places}): "
                              f"give --{role} NUMBER")  # fmt: skip
        if hits:
            return hits[0]
    kinds = UNIT_KINDS.get(role, ())
    by_unit = [k for k in free if parse_unit(table.columns[k].unit).kind in kinds]
    return by_unit[0] if len(by_unit) == 1 else None


def _role(table: Table, checked: Checked, role: str, taken: set[int]) -> int | None:
    spec = getattr(checked.opt, role)
    k = find_column(table, spec, role) if spec else _default(table, role, taken)
    if k is None:
        return None
    if k in taken:
        raise table.error(k, f"is given as the {role} and as another core channel")
    if table.columns[k].is_axis:
        raise table.error(k, f"is a capture's time base, not a {role} channel")
    taken.add(k)
    return k


def _time(table: Table, checked: Checked, voltage: int, taken: set[int]) -> int | None:
    axis = table.columns[voltage].axis
    if axis is None:
        return _role(table, checked, "time", taken)
    if checked.opt.time:
        raise table.error(
            None, f"--time {checked.opt.time}: a capture's time is its X, leave --time out"
        )
    taken.add(axis)
    return axis


def select(table: Table, checked: Checked) -> Selection:
    """The columns an import of ``table`` uses (raises an error naming what is missing)."""
    taken: set[int] = set()
    found: dict[str, int] = {}
    for role in ("voltage", "strain"):
        k = _role(table, checked, role, taken)
        if k is None:
            raise table.error(
                None,
                f"which column is the {role}? give --{role} NAME or NUMBER "
                f"(columns: {column_list(table)})",
            )
        found[role] = k
    time = _time(table, checked, found["voltage"], taken)
    requested = []
    for req in checked.aux:
        k = find_column(table, req.column, "auxiliary")
        if k in taken:
            raise table.error(
                k, f"--aux {req.spec}: this column is already the time, voltage or strain"
            )
        requested.append((req, k))
        taken.add(k)
    candidates = [
        k for k, c in enumerate(table.columns) if k not in taken and c.named and not c.is_axis
    ]
    return Selection(time, found["voltage"], found["strain"], requested, candidates)
