"""What every reader produces: the columns (signals) of one record, with names, units and where
each came from, so that later steps can name the place of a problem.

A text file gives one :class:`Table`; a MATLAB file one per set of signals of the same length
(plain variables), or one per ControlDesk capture. A text file's values are read only for the
columns an import uses (:meth:`Table.load`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from decimal import Context, Decimal, localcontext
from itertools import repeat
from operator import sub
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from labrig.core.errors import InputFileError, InputIssue

#: integers of larger magnitude lose their low bits as float64 (2**53)
EXACT_INTEGER = 2**53
#: a time column of decimals whose first value is more than this many of its steps from zero
#: is counted from that value exactly, from its text (:meth:`Table.count_exactly`). As float64
#: each value is rounded to 2**-53 of its magnitude, k steps from zero to k 2**-53 of a step:
#: below this the first value keeps 2**-33 of a step, and a record's last one (2**20 + n steps
#: out, n its samples) 1e-9 past 4e6 rows, as it always has (records that start late in a
#: longer one read as before); time stamps since 1970 (1.7e9 s, or ms) are past it at every
#: rate accepted (a step of at most 1000 s)
EXACT_STEPS = 2**20
#: the arithmetic of decimal texts: a difference is exact up to 60 digits (rounded past them,
#: to 1e-60 of itself); a text that is no number becomes NaN (nothing trapped)
_DECIMAL = Context(prec=60, traps=[])


def exact_floats(values: NDArray) -> tuple[NDArray[np.float64], int | Decimal]:
    """``values`` as float64, and the origin they are counted from: an integer array holding a
    magnitude past :data:`EXACT_INTEGER` (nanoseconds since 1970, a sample counter) becomes the
    exact differences from its first value, computed in integers (exact while the record spans
    less than 2**53 counts), with that value as the origin; decimal texts (an object array of
    str, ``.`` as the decimal mark: a time column read again by :meth:`Table.count_exactly`)
    become their differences from the first, computed in decimal, with that value as a
    :class:`~decimal.Decimal` origin; anything else converts as it is, origin 0."""
    a = np.asarray(values).reshape(-1)
    if a.size and _is_text(a):
        with localcontext(_DECIMAL):
            first = Decimal(a[0])
        return relative_to(a, first), first
    if a.size == 0 or a.dtype.kind not in "iu":
        return np.asarray(a, dtype=np.float64), 0
    if int(a.max()) <= EXACT_INTEGER and int(a.min()) >= -EXACT_INTEGER:
        return a.astype(np.float64), 0
    origin = int(a[0])
    return relative_to(a, origin), origin


def relative_to(a: NDArray, origin: int | Decimal) -> NDArray[np.float64]:
    """``a - origin`` as float64, the subtraction in integers when ``a`` holds integers (uint64
    wraps, and is read back as the signed difference), in decimal when it holds decimal texts
    (each difference exact, then rounded once to float64; ``nan`` stays NaN)."""
    if _is_text(a):
        with localcontext(_DECIMAL):  # a text that is no number is NaN, not an exception
            differences = map(sub, map(Decimal, a), repeat(Decimal(origin)))
            return np.fromiter(map(float, differences), np.float64, count=a.size)
    if a.dtype.kind == "u":
        return (a - np.uint64(origin % 2**64)).view(np.int64).astype(np.float64)
    if a.dtype.kind == "i":
        return (a - np.int64(origin)).astype(np.float64)
    return np.asarray(a, dtype=np.float64) - float(origin)


def _is_text(a: NDArray) -> bool:
    """Whether ``a`` holds texts (an object array of str), not numbers."""
    return a.dtype.kind == "O" and a.size > 0 and isinstance(a.flat[0], str)


def far_from_zero(values: NDArray[np.float64]) -> bool:
    """Whether the first of ``values`` (a time column as float64, in its own unit) is more than
    :data:`EXACT_STEPS` of its mean step from zero: ``(n - 1) |t0| > EXACT_STEPS |t[-1] - t0|``
    (False when either is NaN or infinite)."""
    if values.size < 2:
        return False
    first, last = float(values[0]), float(values[-1])
    return (values.size - 1) * abs(first) > EXACT_STEPS * abs(last - first)


def bad(path: Path | str, message: str, line: int | None = None, where: str = "") -> InputFileError:
    """The error for one problem in an input file: ``FILE:LINE: [WHERE] MESSAGE`` (exit 2)."""
    return InputFileError([InputIssue(str(path), line, where, message)])


@dataclass
class Column:
    """One signal: its label as the file gives it ("" if none), the unit the file states (""
    if none), its place for messages (``"column 3"``, ``"Y(2)"``), whether it has a name of its
    own (False for columns known only by position), its values (float64, NaN where a cell was
    empty; None until loaded), the number that picks it (``--voltage 3``), other names that
    pick it (a raw header cell, a ControlDesk channel's short name), and for a ControlDesk
    channel the index of its time column (``axis``; ``is_axis`` marks a time column).
    ``origin``: the values are counted from it (:func:`exact_floats`, :meth:`Table.count_exactly`;
    0 for nearly every column)."""

    label: str
    unit: str
    where: str
    named: bool = True
    values: NDArray[np.float64] | None = None
    length: int | None = None
    number: int | None = None
    aliases: tuple[str, ...] = ()
    axis: int | None = None
    is_axis: bool = False
    origin: int | Decimal = 0

    def __post_init__(self) -> None:
        if self.values is not None:
            self.values, self.origin = exact_floats(self.values)
            self.length = int(self.values.size)


#: a text reader's loader: (columns to read, columns that must be numbers) -> fills the values
Loader = Callable[["Table", list[int], set[int]], None]
#: a text reader's second reading of one column from its text, counted exactly from its first
#: value (:meth:`Table.count_exactly`) -> sets the column's values and origin
Recount = Callable[["Table", int], None]


@dataclass
class Table:
    """The signals of one record (``capture``: its name when the file holds captures, of which
    it has ``n_captures``). ``locate`` maps a data row (0-based) to
    its line in the file (text files; None when rows are not lines). ``layout`` says how the file
    was read (for the entry's metadata); ``skipped`` lists columns not kept, with why.
    ``loader`` and ``recount``: a text reader's (None when the values came with the table)."""

    source: Path
    columns: list[Column]
    capture: str = ""
    n_captures: int = 1
    layout: dict = field(default_factory=dict)
    skipped: list[str] = field(default_factory=list)
    locate: Callable[[int], int | None] | None = None
    loader: Loader | None = None
    recount: Recount | None = None

    def load(self, indices: list[int], required: set[int]) -> None:
        """Make sure the values of ``indices`` are read; a column in ``required`` that holds
        text is an error, another one is dropped (its values stay None, ``skipped`` says why)."""
        missing = [k for k in indices if self.columns[k].values is None]
        if missing and self.loader is not None:
            self.loader(self, missing, required)

    def count_exactly(self, k: int) -> None:
        """Column ``k``, the time, counted from its first value exactly when that value is far
        from zero against its steps (:func:`far_from_zero`: time stamps since 1970 with µs
        digits, whose steps float64 keeps to 2.4e-7 s at best): read again from the file's text,
        the differences taken in decimal before anything is rounded to float64. Nothing for
        columns already exact (integers) or for values that came without text (MATLAB)."""
        c = self.columns[k]
        if self.recount is None or c.origin or c.values is None or not far_from_zero(c.values):
            return
        self.recount(self, k)

    def line_of(self, row: int) -> int | None:
        """The file line of data row ``row`` (0-based), or None when rows are not lines."""
        return self.locate(row) if self.locate is not None else None

    def place(self, k: int, capture: bool = True) -> str:
        """Where column ``k`` is, for messages: ``column 3 (strain_ue)``, ``capture c1, Y(2)
        (Model Root/amp/Out1)`` (``capture=False``: without the capture)."""
        c = self.columns[k]
        place = c.where if not c.label or c.label in c.where else f"{c.where} ({c.label})"
        return f"capture {self.capture}, {place}" if self.capture and capture else place

    def error(self, k: int | None, message: str, row: int | None = None) -> InputFileError:
        """An error about column ``k`` (and data row ``row``) of this table."""
        where = self.place(k) if k is not None else ""
        if k is None and self.capture:
            where = f"capture {self.capture}"
        line = self.line_of(row) if row is not None else None
        if row is not None and line is None:
            where = f"{where}, sample {row + 1}" if where else f"sample {row + 1}"
        return bad(self.source, message, line, where)
