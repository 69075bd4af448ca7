"""Plain MATLAB variables as one :class:`~labrig.importers.table.Table` per file.

Every numeric vector (``t``, ``V``, a struct's field ``data.strain``) is a named signal (a name
like ``temperature_C`` gives a unit, as a header does). A matrix gives one signal per column
(``M:1``, ``M:2``...) or, when it is wider than tall, one per ROW: time runs along the longer
side, and the orientation is stated in the layout. A square matrix, arrays of three or more
dimensions, complex and logical values are left out and listed. Signals may differ in length:
an entry keeps those as long as its voltage.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from labrig.importers.labels import split_label
from labrig.importers.limits import MAX_COLUMNS
from labrig.importers.mat_read import Tree
from labrig.importers.table import Column, Table, bad


def leaves(node: Any, path: str) -> Iterator[tuple[str, Any]]:
    """(path, value) of every non-container value under ``node``: ``s.field``, ``c{2}``."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from leaves(v, f"{path}.{k}" if path else k)
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from leaves(v, f"{path}{{{i + 1}}}")
    else:
        yield path, node


def _matrix(path: str, a: np.ndarray, notes: list[str]) -> list[Column] | str:
    rows, cols = a.shape
    if rows == cols:
        return f"{rows} x {cols}: square, cannot tell signals from samples"
    by_row = rows < cols
    if by_row:
        notes.append(f"variable {path} is {rows} x {cols}: one signal per row (time along rows)")
    signals = a if by_row else a.T
    side = "row" if by_row else "column"
    return [
        Column(f"{path}:{j + 1}", "", f"variable {path}, {side} {j + 1}", False, values=s)
        for j, s in enumerate(signals)
    ]


def plain_table(path: Path, tree: Tree, version: str) -> Table:
    """The numeric signals of a MATLAB file (see the module docstring)."""
    columns: list[Column] = []
    skipped: list[str] = []
    notes: list[str] = []
    for name, value in leaves(tree, ""):
        if isinstance(value, str):
            if value.startswith("<"):
                skipped.append(f"variable {name}: {value.strip('<>')} values")
            continue
        a = np.asarray(value)
        if a.ndim == 0 or a.size < 2:
            continue
        if a.ndim == 1:
            label, unit = split_label(name)
            aliases = (name,) if label != name else ()
            columns.append(Column(label, unit, f"variable {name}", values=a, aliases=aliases))
        elif a.ndim == 2:
            got = _matrix(name, a, notes)
            if isinstance(got, str):
                skipped.append(f"variable {name}: {got}")
            else:
                columns += got
        else:
            skipped.append(f"variable {name}: {a.ndim} dimensions")
        if len(columns) > MAX_COLUMNS:
            raise bad(path, f"more than {MAX_COLUMNS} signals: too many to import")
    for k, c in enumerate(columns, start=1):
        c.number = k
    layout = {"format": f"MATLAB v{version}", "notes": notes}
    return Table(path, columns, layout=layout, skipped=skipped)
