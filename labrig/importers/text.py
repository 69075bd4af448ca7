"""Delimited text files (CSV, TSV, semicolon files with decimal commas, whitespace columns) into
a :class:`~labrig.importers.table.Table`: the layout from :mod:`labrig.importers.sniff`, the
numbers from pandas' C parser, read in blocks of :data:`~labrig.importers.limits.CHUNK_ROWS` rows
and only for the columns an import uses, so that memory stays near the size of the values kept.

Blank lines and ``#`` comments inside the data are skipped; a row with more fields than the data
has columns, or a field that is not a number in a column the import needs, is an error naming
the line. A column that holds text (a date, a comment) and is not needed is left out and said so.
A quoted field is read like an unquoted one (``"1,5"`` with a decimal comma, spaces before the
quote allowed), as the layout was found.

A time column far from zero against its steps (time stamps since 1970 with µs digits) is read a
second time, as text, and counted from its first value exactly (:meth:`_Reader.recount`).
"""

from __future__ import annotations

import re
from decimal import Decimal
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from labrig.importers.limits import CHUNK_ROWS, MAX_COLUMNS, MAX_ROWS, SNIFF_BYTES
from labrig.importers.sniff import Layout, LayoutError, find_layout
from labrig.importers.table import Column, Table, bad, exact_floats, relative_to

#: where the values of a column are counted from: column -> origin (:func:`_counted`)
Origins = dict[int, int | Decimal]


def read_layout(
    path: Path,
    separator: str | None = None,
    decimal: str | None = None,
    encoding: str | None = None,
) -> Layout:
    """The layout of the text file ``path`` (raises InputFileError naming the file and line)."""
    with path.open("rb") as f:
        sample = f.read(SNIFF_BYTES)
        at_eof = not f.read(1)
    try:
        layout = find_layout(sample, at_eof, separator, decimal, encoding)
    except LayoutError as e:
        raise bad(path, str(e), e.line) from None
    except LookupError as e:  # an unknown --encoding
        raise bad(path, f"unknown encoding: {e}") from None
    if layout.width > MAX_COLUMNS:
        raise bad(path, f"{layout.width} columns: at most {MAX_COLUMNS} are read")
    return layout


def text_table(path: Path, layout: Layout) -> Table:
    """The table of a text file, its columns named by the header (values read on demand)."""
    columns = []
    for k in range(layout.width):
        name = layout.names[k] if layout.names else ""
        unit = layout.units[k] if layout.units else ""
        raw = layout.raw_names[k] if layout.raw_names else ""
        aliases = (raw,) if raw and raw != name else ()
        columns.append(
            Column(name, unit, f"column {k + 1}", bool(name), number=k + 1, aliases=aliases)
        )
    locator = _Locator(path, layout)
    reader = _Reader(path, layout, locator)
    return Table(
        path,
        columns,
        layout=layout.describe(),
        locate=locator.line,
        loader=reader.load,
        recount=reader.recount,
    )


class _Locator:
    """Data row -> file line: the first data line plus the row, corrected for blank lines
    (dropped from the data) and comment lines (skipped by pandas; counted only when an error
    needs a line)."""

    def __init__(self, path: Path, layout: Layout) -> None:
        self.path, self.layout = path, layout
        self.blank: NDArray[np.int64] = np.zeros(0, np.int64)  # parser rows that were blank

    def line(self, row: int) -> int | None:
        """The line of kept (non-blank) row ``row``."""
        p = row
        while (q := row + int(np.searchsorted(self.blank, p, side="right"))) != p:
            p = q
        return self.parser_line(p)

    def parser_line(self, p: int) -> int:
        """The line of the parser's row ``p`` (blank rows counted, comment lines not)."""
        first = self.layout.first_data_line
        try:
            with self.path.open(encoding=self.layout.encoding, errors="replace") as f:
                seen = -1
                for number, text in enumerate(f, start=1):
                    if number < first or text.lstrip().startswith("#"):
                        continue
                    seen += 1
                    if seen == p:
                        return number
        except OSError:
            pass
        return first + p


class _Growing:
    """A float64 column filled block by block, allocated once for the rows expected (grown by
    half when a file holds more): no list of blocks to join at the end."""

    def __init__(self, capacity: int) -> None:
        self.data = np.empty(max(capacity, 16))
        self.n = 0

    def add(self, values: NDArray[np.float64]) -> None:
        end = self.n + values.size
        if end > self.data.size:
            grown = np.empty(max(end, self.data.size * 3 // 2))
            grown[: self.n] = self.data[: self.n]
            self.data = grown
        self.data[self.n : end] = values
        self.n = end

    def result(self) -> NDArray[np.float64]:
        return self.data[: self.n] if self.n > 0.9 * self.data.size else self.data[: self.n].copy()


def _row_estimate(path: Path, layout: Layout) -> int:
    """Rows a text file holds at most: its line count (8-bit encodings), else from its size."""
    size = path.stat().st_size
    if layout.encoding.startswith(("utf-16", "utf-32")):
        return size // (2 if "16" in layout.encoding else 4) // 4
    newlines = returns = 0
    with path.open("rb") as f:
        while block := f.read(1 << 20):
            newlines += block.count(b"\n")
            returns += block.count(b"\r")
    return max(newlines, returns) + 1


class _Reader:
    """Reads the values of some columns of a text file (see the module docstring)."""

    def __init__(self, path: Path, layout: Layout, locator: _Locator) -> None:
        self.path, self.layout, self.locator = path, layout, locator
        self.integers: set[int] = set()  # columns read as integers: exact already

    def load(self, table: Table, indices: list[int], required: set[int]) -> None:
        try:
            self._load(table, indices, required, self.layout.encoding)
        except UnicodeDecodeError:
            if self.layout.encoding not in ("utf-8", "utf-8-sig"):
                raise bad(self.path, f"not valid {self.layout.encoding} text") from None
            self.layout.encoding = "cp1252"
            table.layout["encoding"] = "cp1252"
            table.layout["notes"].append("not UTF-8 throughout: read as cp1252")
            self._load(table, indices, required, "cp1252")

    def _chunks(self, encoding: str, text: int | None = None) -> pd.io.parsers.TextFileReader:
        """The data in blocks of rows: every column (numbers where they parse), or only column
        ``text`` as it is written (its texts, for :meth:`recount`). Spaces after a separator are
        skipped, so that a quoted field after them is read as the sniffer read it."""
        lay = self.layout
        return pd.read_csv(
            self.path,
            sep=lay.pandas_sep,
            decimal=lay.decimal,
            header=None,
            names=list(range(lay.width)),
            usecols=None if text is None else [text],
            dtype=None if text is None else {text: object},
            index_col=False,
            skiprows=lay.first_data_line - 1,
            encoding=encoding,
            comment="#",
            skip_blank_lines=False,
            skipinitialspace=True,
            chunksize=CHUNK_ROWS,
            engine="c",
        )

    def _load(self, table: Table, indices: list[int], required: set[int], enc: str) -> None:
        capacity = _row_estimate(self.path, self.layout)
        columns = {k: _Growing(capacity) for k in indices}
        blank_rows: list[NDArray[np.int64]] = []
        text_columns: set[int] = set()
        origins: Origins = {}  # integer columns (past 2**53: counted from their first value)
        start = 0
        try:
            for chunk in self._chunks(enc):
                blank = chunk.isna().all(axis=1).to_numpy()
                keep = np.flatnonzero(~blank) if blank.any() else None
                if keep is not None:
                    blank_rows.append(np.flatnonzero(blank) + start)
                for k in indices:
                    if k in text_columns:
                        continue
                    values = _numbers(chunk[k], origins, k)
                    if values is None:
                        if k in required:
                            raise self._not_a_number(table, chunk[k], k, start)
                        text_columns.add(k)
                        continue
                    columns[k].add(values if keep is None else values[keep])
                start += len(chunk)
                if start > MAX_ROWS:
                    raise bad(self.path, f"more than {MAX_ROWS} data rows: too large to import")
        except pd.errors.ParserError as e:
            raise self._parser_error(e) from None
        except pd.errors.EmptyDataError:
            raise bad(self.path, "no data lines", self.layout.first_data_line) from None
        self.locator.blank = np.concatenate(blank_rows) if blank_rows else np.zeros(0, np.int64)
        self.integers |= set(origins)
        for k in indices:
            if k in text_columns:
                table.skipped.append(f"{table.place(k)}: text, not numbers")
                continue
            values = columns.pop(k).result()
            table.columns[k].values = values
            table.columns[k].length = int(values.size)
            table.columns[k].origin = origins.get(k, 0)

    def recount(self, table: Table, k: int) -> None:
        """Column ``k`` read again, as text, and counted from its first value exactly (decimal
        arithmetic on the digits as written: ``1764480000.000100`` s is 1e-4 s after
        ``1764480000.000000`` s, where float64 gives 0.999e-4 s, and 1.001e-4 s for other
        steps). Rows are kept as the first reading kept them (blank lines dropped). A column
        read as integers is exact already and left as it is."""
        c = table.columns[k]
        if k in self.integers or c.values is None:
            return
        counted = _Growing(c.values.size + self.locator.blank.size)
        origins: Origins = {}
        for chunk in self._chunks(self.layout.encoding, text=k):
            counted.add(_counted(_decimal_texts(chunk[k], self.layout.decimal), origins, k))
        values = np.delete(counted.result(), self.locator.blank)
        if values.size != c.values.size:  # the file changed between the readings
            raise bad(self.path, f"changed while read ({table.place(k)}): import it again")
        c.values, c.origin = values, origins[k]

    def _not_a_number(self, table: Table, col: pd.Series, k: int, start: int) -> Exception:
        text = col.astype("string").str.strip()
        numeric = pd.to_numeric(
            text.str.replace(",", ".") if self.layout.decimal == "," else text, errors="coerce"
        )
        bad_rows = np.flatnonzero((numeric.isna() & text.notna() & (text != "")).to_numpy())
        row = int(bad_rows[0]) if bad_rows.size else 0
        cell = str(text.iloc[row]) if bad_rows.size else "?"
        line = self.locator.parser_line(start + row)
        expected = "a number" + (" with a decimal comma" if self.layout.decimal == "," else "")
        return bad(
            self.path, f"{cell[:40]!r} is not a number (expected {expected})", line, table.place(k)
        )

    def _parser_error(self, e: Exception) -> Exception:
        m = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", str(e))
        if m:
            return bad(
                self.path,
                f"{m.group(3)} fields, expected {m.group(1)} like the lines before",
                int(m.group(2)),
            )
        return bad(self.path, f"cannot parse as delimited text: {str(e).strip()[:200]}")


def _numbers(col: pd.Series, origins: Origins, k: int) -> NDArray[np.float64] | None:
    """Column ``k`` of one block as float64, or None if it holds text. An integer column is
    counted from ``origins[k]`` (:func:`_counted`), so that time stamps past 2**53
    (nanoseconds since 1970) keep their steps exact."""
    if pd.api.types.is_bool_dtype(col) or not pd.api.types.is_numeric_dtype(col):
        if col.isna().all():
            return np.full(len(col), np.nan)
        return None
    if pd.api.types.is_integer_dtype(col):
        return _counted(col.to_numpy(), origins, k)
    values = col.to_numpy(dtype=np.float64, na_value=np.nan)
    return values - float(origins[k]) if origins.get(k) else values


def _counted(raw: NDArray, origins: Origins, k: int) -> NDArray[np.float64]:
    """One block of column ``k`` (integers, or decimal texts) as float64 counted from
    ``origins[k]``, which its first block sets (:func:`~labrig.importers.table.exact_floats`:
    the first value, or 0 where float64 holds the values exactly)."""
    if k not in origins:
        values, origins[k] = exact_floats(raw)
        return values
    return relative_to(raw, origins[k])


def _decimal_texts(col: pd.Series, decimal: str) -> NDArray[np.object_]:
    """One block of a column read as text: its cells as decimal texts with ``.`` as the mark
    (``nan`` where a cell is empty)."""
    if decimal == ",":
        col = col.str.replace(",", ".", regex=False)
    return col.to_numpy(dtype=object, na_value="nan")


def read_text(
    path: Path,
    separator: str | None = None,
    decimal: str | None = None,
    encoding: str | None = None,
) -> Table:
    """A text file as a table (layout found now, values read when a column is loaded)."""
    return text_table(path, read_layout(path, separator, decimal, encoding))
