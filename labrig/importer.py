"""``labrig import``: measured data from elsewhere into a run file, one entry per input file.

Inputs: delimited text (comma, semicolon, tab or whitespace; with or without a header line;
``#`` comments) and MATLAB ``.mat`` files (scipy). Columns are picked by header name or by
1-based index (as in the data's own documentation, e.g. "column 5"); for ``.mat`` files by
variable name, or ``VAR:INDEX`` for a column of a matrix variable.

A header name like ``temperature_C`` gives a channel name (``temperature``) and a unit (``C``).
With a header ``time_s,voltage_V,strain_ue`` no option is needed. Without a time column a
sample rate is required. Scale factors convert the sensor's units (``value * scale + offset``):
e.g. a displacement in um over an 18 mm stack is ``--strain-scale 55.56`` (ue per um).

Every input is read and checked before the output file is created: a bad file gives a clear
error naming the file (and line) and nothing is written.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from labrig import __version__
from labrig.errors import InputFileError, InputIssue
from labrig.store import Channel, RunWriter

_DEFAULT_NAMES = {
    "time": ("time_s", "time", "t", "t_s"),
    "voltage": ("voltage_v", "voltage", "v", "u", "command_voltage_v", "v_v"),
    "strain": ("strain_ue", "strain", "s", "strain_microstrain"),
}
_UNIT_RE = re.compile(r"^(?P<name>[A-Za-z][A-Za-z0-9]*(?:_[A-Za-z0-9]+)*?)_(?P<unit>[A-Za-z%]+)$")


@dataclass
class ImportOptions:
    """How to read the columns (see the module docstring); ``None`` means "find it"."""

    time: str | None = None
    voltage: str | None = None
    strain: str | None = None
    rate_hz: float | None = None
    voltage_scale: float = 1.0
    voltage_offset: float = 0.0
    strain_scale: float = 1.0
    strain_offset: float = 0.0
    strain_units: str = "ue"
    aux: list[str] = field(default_factory=list)  # "NAME" or "NAME=COLUMN"
    delimiter: str | None = None


@dataclass
class ImportedEntry:
    name: str
    source: Path
    rate_hz: float
    time_s: NDArray[np.float64]
    voltage_V: NDArray[np.float64]
    strain: NDArray[np.float64]
    aux: dict[str, tuple[NDArray[np.float64], str]]
    columns: dict[str, str]


def _issue(path: Path, msg: str, line: int | None = None, fld: str = "") -> InputFileError:
    return InputFileError([InputIssue(str(path), line, fld, msg)])


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter:
        return [c.strip() for c in line.split(delimiter)]
    for d in (",", ";", "\t"):
        if d in line:
            return [c.strip() for c in line.split(d)]
    return line.split()


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def read_table(path: Path, delimiter: str | None = None) -> tuple[list[str] | None, NDArray]:
    """Header (or None) and the numeric table of a delimited text file."""
    try:
        text = path.read_bytes()
    except OSError as e:
        raise _issue(path, f"cannot read file: {e.strerror}") from e
    if b"\x00" in text[:65536]:
        raise _issue(path, "binary data: expected delimited text or a .mat file")
    try:
        lines = text.decode("utf-8-sig").splitlines()
    except UnicodeDecodeError as e:
        raise _issue(path, "not UTF-8 text: expected delimited text or a .mat file") from e
    header: list[str] | None = None
    rows: list[list[float]] = []
    width = None
    for i, raw in enumerate(lines, start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        cells = _split(line, delimiter)
        if not rows and header is None and not all(_is_number(c) for c in cells):
            header = [c.strip().strip('"') for c in cells]
            width = len(header)
            continue
        if width is None:
            width = len(cells)
        if len(cells) != width:
            raise _issue(path, f"expected {width} columns, found {len(cells)}", i)
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            bad = next(c for c in cells if not _is_number(c))
            raise _issue(path, f"not a number: {bad!r}", i) from None
    if not rows:
        raise _issue(path, "no numeric rows found")
    return header, np.asarray(rows, dtype=np.float64)


def _read_mat(path: Path) -> dict[str, NDArray]:
    from scipy.io import loadmat

    try:
        mat = loadmat(path, squeeze_me=False)
    except Exception as e:  # scipy raises several types for bad files
        raise _issue(path, f"cannot read MATLAB file: {e}") from None
    return {
        k: np.asarray(v, dtype=np.float64)
        for k, v in mat.items()
        if not k.startswith("__") and isinstance(v, np.ndarray) and v.dtype.kind in "fiu"
    }


def _column(path: Path, header: list[str] | None, table: NDArray, spec: str, what: str) -> int:
    if header is not None:
        lowered = [h.lower() for h in header]
        if spec.lower() in lowered:
            return lowered.index(spec.lower())
    if spec.isdigit():
        k = int(spec)
        if 1 <= k <= table.shape[1]:
            return k - 1
        raise _issue(path, f"{what} column {k} does not exist (the file has {table.shape[1]})")
    names = ", ".join(header) if header else "no header; use a 1-based column number"
    raise _issue(path, f"no {what} column named {spec!r} (columns: {names})")


def _find_default(header: list[str] | None, role: str) -> int | None:
    if header is None:
        return None
    lowered = [h.lower() for h in header]
    for cand in _DEFAULT_NAMES[role]:
        if cand in lowered:
            return lowered.index(cand)
    return None


def _name_unit(label: str) -> tuple[str, str]:
    m = _UNIT_RE.match(label)
    if m:
        return m.group("name"), m.group("unit")
    return re.sub(r"[^A-Za-z0-9_]", "_", label) or "aux", ""


def entry_name(path: Path, taken: set[str]) -> str:
    base = re.sub(r"[^A-Za-z0-9_]", "_", path.stem)
    if not base or not base[0].isalpha():
        base = "entry_" + base
    base = base[:60]
    name, k = base, 2
    while name in taken:
        name, k = f"{base}_{k}", k + 1
    return name


def _from_columns(path: Path, header, table, opt: ImportOptions) -> dict:
    cols: dict[str, int | None] = {}
    for role in ("time", "voltage", "strain"):
        spec = getattr(opt, role)
        cols[role] = (
            _column(path, header, table, spec, role) if spec else _find_default(header, role)
        )
    for role in ("voltage", "strain"):
        if cols[role] is None:
            raise _issue(
                path,
                f"which column is the {role}? give --{role} NAME or a 1-based column number"
                + (f" (columns: {', '.join(header)})" if header else " (the file has no header)"),
            )
    aux: dict[str, tuple[int, str]] = {}
    for spec in opt.aux:
        name, _, col = spec.partition("=")
        k = _column(path, header, table, col or name, "auxiliary")
        label = header[k] if header else name
        aux_name, unit = _name_unit(name if col else label)
        aux[aux_name] = (k, unit)
    return {"cols": cols, "aux": aux}


def read_entry(path: Path, opt: ImportOptions, taken: set[str]) -> ImportedEntry:
    """Read one input file according to ``opt`` (raises InputFileError, writes nothing)."""
    path = Path(path)
    if not path.is_file():
        raise _issue(path, "file not found")
    if path.suffix.lower() == ".mat":
        mat = _read_mat(path)
        header, arrays = [], []
        for k, v in mat.items():
            v2 = v.reshape(v.shape[0], -1) if v.shape[0] > 1 else v.reshape(-1, 1)
            for j in range(v2.shape[1]):
                header.append(k if v2.shape[1] == 1 else f"{k}:{j + 1}")
                arrays.append(v2[:, j])
        if not arrays:
            raise _issue(path, "no numeric variables in the MATLAB file")
        n = max(a.size for a in arrays)
        keep = [i for i, a in enumerate(arrays) if a.size == n]
        header = [header[i] for i in keep]
        table = np.column_stack([arrays[i] for i in keep])
    else:
        header, table = read_table(path, opt.delimiter)
    spec = _from_columns(path, header, table, opt)
    cols = spec["cols"]
    n = table.shape[0]
    if n < 2:
        raise _issue(path, "need at least 2 samples")
    if cols["time"] is not None:
        t = table[:, cols["time"]]
        dt = np.diff(t)
        if np.any(dt <= 0):
            raise _issue(path, "time column is not strictly increasing")
        rate = 1.0 / float(np.median(dt))
        if np.max(np.abs(dt * rate - 1)) > 0.01:
            raise _issue(path, "time column is not uniformly sampled (more than 1 % jitter)")
        if opt.rate_hz and abs(opt.rate_hz - rate) > 1e-3 * rate:
            raise _issue(path, f"--rate-hz {opt.rate_hz} disagrees with the time column ({rate})")
        t = t - t[0]
    else:
        if not opt.rate_hz or opt.rate_hz <= 0:
            raise _issue(path, "no time column: give the sample rate with --rate-hz")
        rate = float(opt.rate_hz)
        t = np.arange(n) / rate
    v = table[:, cols["voltage"]] * opt.voltage_scale + opt.voltage_offset
    s = table[:, cols["strain"]] * opt.strain_scale + opt.strain_offset
    for role, arr in (("voltage", v), ("strain", s)):
        if not np.all(np.isfinite(arr)):
            raise _issue(path, f"{role} column has non-finite values (NaN or inf)")
    aux = {k: (table[:, j], unit) for k, (j, unit) in spec["aux"].items()}
    used = {r: (header[c] if header else str(c + 1)) for r, c in cols.items() if c is not None}
    return ImportedEntry(entry_name(path, taken), path, rate, t, v, s, aux, used)


def import_files(
    files: list[Path], out: Path, opt: ImportOptions, overwrite: bool = False
) -> list[ImportedEntry]:
    """Read every file, then write the run file (nothing is written if any input is bad)."""
    if not files:
        raise InputFileError([InputIssue("", None, "", "no input files given")])
    if out.exists() and not overwrite:
        raise InputFileError([InputIssue(str(out), None, "", "exists; pass --overwrite")])
    taken: set[str] = set()
    entries = []
    for f in files:
        e = read_entry(Path(f), opt, taken)
        taken.add(e.name)
        entries.append(e)
    description = {
        "import": {
            "software": f"labrig {__version__}",
            "files": [str(e.source) for e in entries],
            "options": {k: v for k, v in vars(opt).items()},
        }
    }
    text = json.dumps(description, indent=2, default=str)
    with RunWriter(
        out,
        protocol_text=text,
        rig_text="",
        instrument_description=description,
        seed=None,
        protocol_name="import",
        protocol_file="",
        planned_entries=[e.name for e in entries],
        overwrite=overwrite,
    ) as w:
        for e in entries:
            chans = [
                Channel("command_voltage", "V", "measured actuator voltage"),
                Channel("strain", opt.strain_units, "strain"),
            ]
            chans += [Channel(k, u or "1", k) for k, (_, u) in e.aux.items()]
            step = {
                "kind": "import",
                "source": str(e.source),
                "columns": e.columns,
                "hold": "linear",
                "voltage_scale": opt.voltage_scale,
                "strain_scale": opt.strain_scale,
                "strain_units": opt.strain_units,
            }
            ew = w.begin_entry(e.name, step, e.rate_hz, chans, title=f"imported {e.source.name}")
            block = {"time": e.time_s, "command_voltage": e.voltage_V, "strain": e.strain}
            block.update({k: a for k, (a, _) in e.aux.items()})
            ew.append(block)
            ew.finish("complete")
        w.finish("complete")
    return entries
