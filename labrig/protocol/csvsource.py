"""Read the voltage samples of a ``csv`` step and bring them to the protocol's sample rate.

Rules (docs/protocol.md repeats them for users):

- blank lines and lines starting with ``#`` are skipped; values are separated by commas, or by
  whitespace on lines without a comma (so whitespace-separated ``.dat`` files work too);
- the first remaining line is a header (column names) when any of its fields is not a number;
- ``column`` / ``time_column`` are header names or 0-based indices; the default voltage column
  is the first column that is not the time column;
- timebase: with ``time_column`` the rows are at those times (s, strictly increasing, shifted to
  start at 0); with ``rate_hz`` they are ``rate_hz`` apart; with neither they are taken to be at
  the protocol's rate. Unless the rows already are at the protocol's rate they are resampled
  onto it by linear interpolation (which never overshoots, so range checks on the file's values
  still hold; it does not low-pass, so downsampling a fast waveform is on you). Resampling ends
  at the last row's time;
- values are multiplied by ``scale``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from labrig.core.textfile import read_bytes_bounded
from labrig.protocol.schema import CsvStep

MAX_BYTES = 200_000_000
MAX_ROWS = 20_000_000


@dataclass
class CsvError(Exception):
    """A problem with a CSV step; ``key`` is the step's key to blame (path, column, ...)."""

    key: str
    message: str

    def __str__(self) -> str:
        return self.message


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _split(line: str) -> list[str]:
    parts = line.split(",") if "," in line else line.split()
    return [p.strip().strip('"').strip("'") for p in parts]


def _resolve_column(ref, header: list[str] | None, ncols: int, key: str, name: str) -> int:
    if isinstance(ref, int):
        if ref >= ncols:
            raise CsvError(key, f"{name} has {ncols} column(s); index {ref} does not exist")
        return ref
    if header is None:
        raise CsvError(key, f"{name} has no header line, so columns go by 0-based index")
    if ref not in header:
        raise CsvError(key, f"{name} has no column {ref!r}; its columns are {header}")
    return header.index(ref)


def resolve_csv_path(step: CsvStep, base_dir: Path) -> Path:
    p = Path(step.path).expanduser()
    return p if p.is_absolute() else base_dir / p


def _read_text(path: Path) -> str:
    """The file's text (UTF-8, an optional BOM dropped), refusing large, missing or binary files."""
    name = path.name
    try:
        if not path.exists():
            raise CsvError("path", f"CSV file not found: {path}")
        raw = read_bytes_bounded(path, MAX_BYTES)
    except ValueError:
        raise CsvError("path", f"{name} is larger than {MAX_BYTES // 1_000_000} MB") from None
    except OSError as e:
        raise CsvError("path", f"cannot read CSV file {path}: {e.strerror}") from e
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw[: e.start].count(b"\n") + 1
        raise CsvError("path", f"{name} line {line}: not a text file (invalid UTF-8)") from e
    if "\x00" in text:
        raise CsvError("path", f"{name}: binary data in a CSV file")
    return text


Rows = list[tuple[int, list[str]]]


def _table(text: str, name: str) -> tuple[list[str] | None, Rows]:
    """``(header or None, data rows as (line number, fields))`` of the file's text."""
    rows: Rows = []
    for i, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if s and not s.startswith("#"):
            rows.append((i, _split(s)))
            if len(rows) > MAX_ROWS + 1:
                raise CsvError("path", f"{name} has more than {MAX_ROWS} rows")
    if not rows:
        raise CsvError("path", f"{name} holds no data rows")
    header = None
    if not all(_is_number(t) for t in rows[0][1]):
        header = rows[0][1]
        rows = rows[1:]
    if len(rows) < 2:
        raise CsvError("path", f"{name} needs at least 2 data rows, has {len(rows)}")
    return header, rows


def _columns(
    step: CsvStep, header: list[str] | None, ncols: int, name: str
) -> tuple[int | None, int]:
    """``(time column or None, value column)``, 0-based."""
    tcol = None
    if step.time_column is not None:
        tcol = _resolve_column(step.time_column, header, ncols, "time_column", name)
    if step.column is not None:
        vcol = _resolve_column(step.column, header, ncols, "column", name)
    else:
        vcol = 1 if tcol == 0 else 0
        if vcol >= ncols:
            raise CsvError("path", f"{name} has no voltage column besides the time column")
    if vcol == tcol:
        raise CsvError("column", "column and time_column are the same column")
    return tcol, vcol


def _parse(rows: Rows, col: int, key: str, name: str) -> np.ndarray:
    """Column ``col`` of every row as finite floats (``key`` blamed otherwise)."""
    out = np.empty(len(rows))
    for j, (lineno, toks) in enumerate(rows):
        if col >= len(toks):
            raise CsvError(key, f"{name} line {lineno}: has no column {col} (0-based)")
        try:
            x = float(toks[col])
        except ValueError:
            msg = f"{name} line {lineno}: {toks[col]!r} is not a number"
            raise CsvError(key, msg) from None
        if not math.isfinite(x):
            raise CsvError(key, f"{name} line {lineno}: {toks[col]!r} is not finite")
        out[j] = x
    return out


def load_csv(step: CsvStep, base_dir: Path, rate_hz: float) -> tuple[np.ndarray, dict]:
    """Voltage samples at ``rate_hz`` and a JSON-able description; raises :class:`CsvError`."""
    path = resolve_csv_path(step, base_dir)
    name = path.name
    header, rows = _table(_read_text(path), name)
    ncols = len(header) if header is not None else len(rows[0][1])
    tcol, vcol = _columns(step, header, ncols, name)

    v = _parse(rows, vcol, "column" if step.column is not None else "path", name) * step.scale
    if not np.all(np.isfinite(v)):
        raise CsvError("scale", "scale makes the values overflow")
    info: dict = {"file": str(step.path), "rows": len(rows), "column": vcol, "scale": step.scale}
    if header is not None:
        info["column_name"] = header[vcol] if vcol < len(header) else None

    if tcol is not None:
        t = _parse(rows, tcol, "time_column", name)
        dt = np.diff(t)
        if np.any(dt <= 0):
            j = int(np.argmax(dt <= 0)) + 1
            raise CsvError("time_column", f"{name} line {rows[j][0]}: times must increase strictly")
        t = t - t[0]
        info["source"] = "time_column"
    elif step.rate_hz is not None and not math.isclose(step.rate_hz, rate_hz, rel_tol=1e-9):
        t = np.arange(len(rows)) / step.rate_hz
        info["source"] = f"rate_hz={step.rate_hz:g}"
    else:
        info["source"] = "protocol rate"
        info["resampled"] = False
        return v, info

    n = math.floor(t[-1] * rate_hz + 1e-9) + 1
    if n < 2:
        raise CsvError("path", f"{name} lasts {t[-1]:g} s: shorter than one sample period")
    if n > MAX_ROWS:
        raise CsvError("path", f"{name} resampled to {rate_hz:g} Hz would be {n} samples")
    grid = np.arange(n) / rate_hz
    info["resampled"] = True
    return np.interp(grid, t, v), info
