"""The layout of a delimited text file, found from its first bytes: encoding, separator, decimal
mark, the header line, a units line under it, and the first data line. pandas then reads the
data with that layout (:mod:`labrig.importers.text`).

- **Encoding**: a byte-order mark (UTF-8, UTF-16, UTF-32), UTF-16 without one (every other byte
  NUL), else UTF-8 if the bytes decode, else cp1252 (Windows Western; latin-1 if even that
  fails).
- **Separator and decimal mark**: of tab, ``;``, ``,``, ``|`` and runs of spaces, with ``.`` or
  ``,`` as the decimal mark, the pair under which the most lines parse as numbers with the same
  number of fields (ties in that order: a tab file with an empty first field stays a tab file).
- **Data** starts at the first line of numbers (at least half of its non-empty fields numbers,
  ``nan`` or ``inf``; a date beside them is allowed) with the data's number of fields; lines
  before it are the preamble. Blank lines and lines starting with
  ``#``, ``%`` or ``//`` are comments.
- **Header**: the last preamble line with as many fields as the data (one fewer: the data's
  first column is an unnamed index); if the line above it has that many fields too and this one
  holds only units (``s``, ``V``, ``[um]``, empty), it is the units line under the header. A
  commented header (``# time_s,voltage_V``, as numpy writes) counts when no other line does.
"""

from __future__ import annotations

import codecs
import re
from dataclasses import dataclass, field

from labrig.importers.labels import split_label
from labrig.importers.units import parse_unit

#: candidate separators, in the order that wins a tie (``" "`` means runs of white space)
SEPARATORS = ("\t", ";", ",", "|", " ")
_NA = r"(?:nan|na|n/a|null|none|[+-]?inf(?:inity)?)"
_NUMBER = {
    ".": re.compile(rf"^(?:[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|{_NA})$", re.IGNORECASE),
    ",": re.compile(rf"^(?:[+-]?(?:\d+,?\d*|,\d+)(?:[eE][+-]?\d+)?|{_NA})$", re.IGNORECASE),
}
_REAL = re.compile(r"\d")
_COMMENT = ("#", "%", "//")
_MAX_LINES = 400  # lines looked at: preamble and enough data to see its shape
_CONTROL = re.compile(r"[\x00-\x08\x0e-\x1f]")


class LayoutError(Exception):
    """The file is not delimited text with numbers: message and line (1-based, or None)."""

    def __init__(self, message: str, line: int | None = None) -> None:
        super().__init__(message)
        self.line = line


@dataclass
class Layout:
    """How to read a text file. Lines are 1-based; ``names``/``units`` have ``width`` cells
    (``""`` where the header names no column)."""

    encoding: str
    separator: str
    decimal: str
    width: int
    first_data_line: int
    names: list[str] | None = None
    raw_names: list[str] | None = None
    units: list[str] | None = None
    header_line: int | None = None
    units_line: int | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def pandas_sep(self) -> str:
        return r"\s+" if self.separator == " " else self.separator

    def describe(self) -> dict:
        """The layout for the entry's metadata (JSON-ready)."""
        sep = {"\t": "tab", " ": "spaces"}.get(self.separator, self.separator)
        return {
            "format": "delimited text",
            "encoding": self.encoding,
            "separator": sep,
            "decimal": self.decimal,
            "header_line": self.header_line,
            "units_line": self.units_line,
            "first_data_line": self.first_data_line,
            "notes": list(self.notes),
        }


def detect_encoding(sample: bytes, at_eof: bool) -> str:
    """The encoding of a text file from its first bytes (see the module docstring)."""
    if sample.startswith(codecs.BOM_UTF8):
        return "utf-8-sig"
    if sample.startswith((codecs.BOM_UTF32_LE, codecs.BOM_UTF32_BE)):
        return "utf-32"
    if sample.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        return "utf-16"
    even, odd = sample[0::2], sample[1::2]
    if len(sample) >= 4 and even.count(0) == 0 and odd.count(0) > 0.4 * len(odd):
        return "utf-16-le"
    if len(sample) >= 4 and odd.count(0) == 0 and even.count(0) > 0.4 * len(even):
        return "utf-16-be"
    for encoding in ("utf-8", "cp1252"):
        try:
            codecs.getincrementaldecoder(encoding)().decode(sample, final=at_eof)
            return encoding
        except UnicodeDecodeError:
            continue
    return "latin-1"


def decode_lines(sample: bytes, encoding: str, at_eof: bool) -> list[str]:
    """The sample's complete lines (the last one only at the end of the file)."""
    text = codecs.getincrementaldecoder(encoding)(errors="replace").decode(sample, final=at_eof)
    found = _CONTROL.search(text[:65536].replace("\x1a", " "))
    if found:
        line = text[: found.start()].count("\n") + 1
        raise LayoutError(
            f"binary data (byte 0x{ord(found.group()):02x}): expected delimited text or a "
            ".mat file",
            line,
        )
    lines = re.split(r"\r\n|\r|\n", text)
    if not at_eof and len(lines) > 1:
        lines = lines[:-1]
    return lines[:_MAX_LINES]


def split(line: str, sep: str) -> list[str]:
    """The fields of a line (quotes and spaces around each removed)."""
    cells = line.split() if sep == " " else line.split(sep)
    return [c.strip().strip('"').strip() for c in cells]


def is_comment(line: str) -> bool:
    s = line.strip()
    return not s or s.startswith(_COMMENT)


def numeric(cells: list[str], decimal: str) -> bool:
    """A data line: at least one real number, and numbers (or nan/inf) in at least half of the
    non-empty fields (a date or a label beside the numbers is allowed)."""
    pattern = _NUMBER[decimal]
    filled = [c for c in cells if c]
    numbers = [c for c in filled if pattern.match(c)]
    return 2 * len(numbers) >= len(filled) and any(_REAL.search(c) for c in numbers)


def _data_of(lines: list[str], sep: str, decimal: str) -> tuple[int, int, int] | None:
    """(score, first data line index, width) of the lines read with ``sep``/``decimal``: the
    data are the lines of numbers with the most common number of fields."""
    rows = []
    for i, raw in enumerate(lines):
        if not is_comment(raw):
            cells = split(raw.split("#", 1)[0], sep)
            rows.append((i, numeric(cells, decimal), len(cells)))
    widths: dict[int, int] = {}  # number of fields -> lines of numbers with it, in order met
    for _, is_number, width in rows:
        if is_number:
            widths[width] = widths.get(width, 0) + 1
    if not widths:
        return None
    width, count = max(widths.items(), key=lambda kv: kv[1])  # a tie: the first one met
    first = next(i for i, is_number, w in rows if is_number and w == width)
    off = sum(1 for i, is_number, w in rows if i > first and not (is_number and w == width))
    score = count - off
    if width < 2:
        score -= len(lines)  # one column: only if no separator gives more
    return score, first, width


def _choose(lines: list[str], sep: str | None, decimal: str | None) -> tuple[str, str, int, int]:
    best = None
    for s in [sep] if sep else SEPARATORS:
        if sep is None and s != " " and not any(s in line for line in lines):
            continue
        for d in [decimal] if decimal else (".", ","):
            if s == "," and d == ",":
                continue
            found = _data_of(lines, s, d)
            if found and (best is None or found[0] > best[0]):
                best = (found[0], s, d, found[1], found[2])
    if best is None:
        first = next((i for i, line in enumerate(lines) if not is_comment(line)), None)
        if first is None:
            raise LayoutError("no data: the file is empty or holds only comments")
        raise LayoutError(
            f"no line of numbers found (line {first + 1} reads {lines[first][:60]!r}): "
            "expected delimited numbers, e.g. '0.001,1.5,12.3'",
            first + 1,
        )
    return best[1], best[2], best[3], best[4]


def _looks_like_units(cells: list[str]) -> bool:
    filled = [c for c in cells if c]
    if not filled or any(len(c) > 24 for c in filled):
        return False
    known = 0
    for c in filled:
        inner = c[1:-1] if c[:1] in "[(" and c[-1:] in "])" else c
        if parse_unit(inner).pint_unit is not None or c != inner:
            known += 1
        elif not re.fullmatch(r"[-A-Za-z%µμ°]{1,12}", c):
            return False
    return known >= max(1, len(filled) // 2)


def _header_cells(line: str, sep: str, width: int) -> list[str] | None:
    text = line.strip()
    for prefix in _COMMENT:
        if text.startswith(prefix):
            text = text[len(prefix) :].strip()
    cells = split(text, sep)
    if sep == " " and len(cells) not in (width, width - 1):
        cells = [c.strip() for c in re.split(r"\s{2,}|\t", text)]
    if len(cells) == width - 1:
        cells = ["", *cells]  # the data's first column is an unnamed index
    return cells if len(cells) == width else None


def _header(lines: list[str], first: int, sep: str, width: int, layout: Layout) -> None:
    plain = [
        i for i in range(first)
        if not is_comment(lines[i]) and not numeric(split(lines[i], sep), layout.decimal)
    ]  # fmt: skip
    commented = [i for i in range(first) if lines[i].strip().startswith(_COMMENT)]
    for candidates in (plain, commented):
        fitting = [i for i in candidates if _header_cells(lines[i], sep, width)]
        if not fitting or fitting[-1] != candidates[-1]:
            continue
        last = fitting[-1]
        cells = _header_cells(lines[last], sep, width) or []
        above = candidates[-2] if len(candidates) > 1 and candidates[-2] in fitting else None
        if above is not None and _looks_like_units(cells):
            layout.names = _header_cells(lines[above], sep, width)
            layout.units, layout.header_line, layout.units_line = cells, above + 1, last + 1
        else:
            layout.names, layout.header_line = cells, last + 1
        break
    used = {layout.header_line, layout.units_line}
    others = [i + 1 for i in range(first) if not is_comment(lines[i])]
    skipped = [n for n in others if n not in used]
    if skipped:
        layout.notes.append(f"skipped lines {_ranges(skipped)} (not a header)")


def _ranges(lines: list[int]) -> str:
    if len(lines) == 1:
        return str(lines[0])
    return f"{lines[0]}-{lines[-1]}" if lines[-1] - lines[0] == len(lines) - 1 else str(lines)


def find_layout(
    sample: bytes,
    at_eof: bool,
    separator: str | None = None,
    decimal: str | None = None,
    encoding: str | None = None,
) -> Layout:
    """The layout of a text file from its first bytes (``separator``, ``decimal`` and
    ``encoding`` given by the user are taken as they are). Raises :class:`LayoutError`."""
    enc = encoding or detect_encoding(sample, at_eof)
    lines = decode_lines(sample, enc, at_eof)
    sep, dec, first, width = _choose(lines, separator, decimal)
    layout = Layout(enc, sep, dec, width, first + 1)
    _header(lines, first, sep, width, layout)
    if layout.names is not None:
        layout.raw_names = list(layout.names)
        layout.units = layout.units or [""] * width
        for k, name in enumerate(layout.names):
            label, unit = split_label(name)
            if unit and not layout.units[k]:
                layout.names[k], layout.units[k] = label, unit
        layout.units = [u[1:-1] if u[:1] in "[(" and u[-1:] in "])" else u for u in layout.units]
    return layout
