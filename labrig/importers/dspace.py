"""dSPACE ControlDesk captures ("ControlDesk MATLAB File Format Revision 2.0") as tables.

A capture is a MATLAB struct (the file's variable, named after the capture) with

- ``X``: the time base, a struct (or a struct array, one per raster) with ``Name`` (e.g.
  ``Time``), ``Unit`` (``s``) and ``Data`` (1 x N);
- ``Y``: the channels, a struct array: ``Y(i).Name`` (the model path, e.g.
  ``Model Root/amp/Out1``), ``Y(i).Unit``, ``Y(i).Data`` (1 x N) and ``Y(i).XIndex`` (which
  ``X``; 1 when absent);
- ``Description``, ``RTProgram``, ``Capture``: what was recorded, kept as text.

A file may hold several captures (several variables, or a struct array): one table each.
Channels are picked by index (``3`` is ``Y(3)``), by full name, or by short name (the last part
of the path, the block's name for a port called ``Out1``). The time of a channel is its ``X``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from labrig.importers.labels import short_channel_name
from labrig.importers.mat_read import Tree
from labrig.importers.mat_tables import leaves
from labrig.importers.table import Column, Table


def _as_list(node: Any) -> list:
    return node if isinstance(node, list) else [node]


def is_capture(node: Any) -> bool:
    """A struct with ``X`` and ``Y``, each a struct (array) whose elements have ``Data``."""
    if not isinstance(node, dict) or "X" not in node or "Y" not in node:
        return False
    return all(
        isinstance(e, dict) and "Data" in e
        for part in (node["X"], node["Y"])
        for e in _as_list(part)
    )


def find_captures(tree: Tree) -> list[tuple[str, dict]]:
    """(name, capture) of every capture among the file's variables, in file order."""
    found: list[tuple[str, dict]] = []
    for name, value in tree.items():
        if is_capture(value):
            found.append((name, value))
        elif isinstance(value, list) and value and all(is_capture(v) for v in value):
            found += [(f"{name}({i + 1})", v) for i, v in enumerate(value)]
    return found


def _text(node: Any) -> str:
    return node.strip() if isinstance(node, str) and not node.startswith("<") else ""


def _signal(node: Any) -> np.ndarray | None:
    if isinstance(node, str):
        return None
    a = np.asarray(node, dtype=np.float64)
    return a.reshape(-1) if a.ndim <= 1 or min(a.shape) == 1 else None


def capture_table(path: Path, name: str, capture: dict, n_captures: int, version: str) -> Table:
    """One capture as a table: the ``X`` time bases first, then ``Y(1)``... (numbered)."""
    columns: list[Column] = []
    skipped: list[str] = []
    for r, x in enumerate(_as_list(capture["X"]), start=1):
        values = _signal(x.get("Data"))
        label = _text(x.get("Name")) or "Time"
        columns.append(
            Column(label, _text(x.get("Unit")), f"X({r})", values=values, is_axis=True)
            if values is not None
            else Column(label, "", f"X({r})", is_axis=True, values=np.zeros(0))
        )
    n_axes = len(columns)
    for i, y in enumerate(_as_list(capture["Y"]), start=1):
        full = _text(y.get("Name")) or f"Y({i})"
        values = _signal(y.get("Data"))
        axis = y.get("XIndex", 1)
        axis = int(np.asarray(axis).ravel()[0]) if not isinstance(axis, str) else 1
        if values is None:
            skipped.append(f"Y({i}) {full}: no numeric 1-D data")
            continue
        if not 1 <= axis <= n_axes:
            skipped.append(f"Y({i}) {full}: XIndex {axis} names no X (the capture has {n_axes})")
            continue
        short = short_channel_name(full)
        columns.append(
            Column(
                full,
                _text(y.get("Unit")),
                f"Y({i})",
                values=values,
                number=i,
                aliases=(short,) if short and short != full else (),
                axis=axis - 1,
            )
        )
    layout = {
        "format": "dSPACE ControlDesk capture",
        "mat_version": version,
        "capture": name,
        "description": _description(capture),
        "notes": [],
    }
    return Table(path, columns, capture=name, n_captures=n_captures, layout=layout, skipped=skipped)


def _description(capture: dict) -> str:
    texts = [
        f"{p}: {v.strip()}"
        for key in ("Description", "RTProgram", "Capture")
        if key in capture
        for p, v in leaves(capture[key], key)
        if _text(v)
    ]
    return "; ".join(texts)[:1000]
