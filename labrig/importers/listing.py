"""``labrig import FILE --list``: what a file holds, as the import sees it: its format and layout,
then one line per column or channel (the number that picks it, its place, name, unit, number
of values, and the role it takes with the options given), and what is left out and why."""

from __future__ import annotations

import numpy as np

from labrig.core.errors import InputFileError
from labrig.importers.aux import aux_channels
from labrig.importers.options import Checked
from labrig.importers.select import select
from labrig.importers.table import Table


def _heading(table: Table) -> str:
    lay = table.layout
    if lay.get("format") == "delimited text":
        parts = [
            f"encoding {lay['encoding']}",
            f"separator {lay['separator']!r}",
            f"decimal {lay['decimal']!r}",
        ]
        if lay.get("header_line"):
            parts.append(f"header line {lay['header_line']}")
        if lay.get("units_line"):
            parts.append(f"units line {lay['units_line']}")
        parts.append(f"data from line {lay['first_data_line']}")
        return f"{table.source}: delimited text ({', '.join(parts)})"
    if table.capture:
        many = f", {table.n_captures} captures in the file" if table.n_captures > 1 else ""
        head = (
            f"{table.source}: {lay['format']} {table.capture} (MATLAB v{lay['mat_version']}{many})"
        )
        return head + (f"\n  {lay['description']}" if lay.get("description") else "")
    return f"{table.source}: {lay['format']}"


def _roles(table: Table, checked: Checked) -> tuple[dict[int, str], str]:
    """Column -> the role it takes (``voltage``, ``aux temperature [degC]``), or a problem."""
    try:
        sel = select(table, checked)
        roles = {k: r for r, k in sel.roles.items() if k is not None}
        n = table.columns[sel.voltage].length or 0
        _, meta, _ = aux_channels(table, sel, n)
    except InputFileError as e:
        return {}, f"  (roles: {e.issues[0].message})"
    places = {table.place(k, False): k for k in range(len(table.columns))}
    for name, m in meta.items():
        roles[places[m["from"]]] = f"aux {name}" + (f" [{m['unit']}]" if m["unit"] else "")
    return roles, ""


def _count(values: np.ndarray | None) -> str:
    if values is None:
        return "text"
    finite = int(np.isfinite(values).sum())
    if finite == values.size:
        return f"{values.size}"
    return f"{values.size} (empty)" if finite == 0 else f"{values.size} ({finite} numbers)"


def list_table(table: Table, checked: Checked) -> list[str]:
    """The lines ``--list`` prints for one table."""
    table.load(list(range(len(table.columns))), set())
    roles, problem = _roles(table, checked)
    lines = [_heading(table), *(f"  note: {n}" for n in table.layout.get("notes", []))]
    rows = [("#", "place", "name", "unit", "values", "role")]
    for k, c in enumerate(table.columns):
        name = c.label + (f" ({c.aliases[0]})" if table.capture and c.aliases else "")
        role = roles.get(k) or ("time base" if c.is_axis else "")
        rows.append((str(c.number or ""), c.where, name, c.unit, _count(c.values), role))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines += [
        "  " + "  ".join(x.ljust(w) for x, w in zip(r, widths, strict=True)).rstrip() for r in rows
    ]
    lines += [f"  left out: {s}" for s in table.skipped]
    return lines + ([problem] if problem else [])
