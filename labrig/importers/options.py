"""The options of ``labrig import``, checked before any file is read: a bad value is a usage
error (exit 64, :class:`~labrig.core.errors.OptionValueError`) naming the option, the value and
what would be valid."""

from __future__ import annotations

import codecs
import math
from dataclasses import dataclass, field

from labrig.core.errors import option_error
from labrig.importers.labels import CORE_NAMES, is_valid_name, split_label
from labrig.importers.limits import RATE_RANGE_HZ

_SEPARATORS = {"tab": "\t", "\\t": "\t", "\t": "\t", "space": " ", "spaces": " ", " ": " "}


@dataclass
class ImportOptions:
    """How to read the inputs; ``None`` means "find it" (docs/import.md has each option).

    Columns (``time``, ``voltage``, ``strain``, the column part of ``aux``) are a name, a
    1-based number, or for ControlDesk captures a channel's name or ``Y`` index. ``aux`` items
    are ``COLUMN`` or ``NAME=COLUMN``; ``scale`` items ``CHANNEL=FACTOR``; ``window`` is
    ``T0:T1`` in seconds of the file's time (either side may be left empty)."""

    time: str | None = None
    voltage: str | None = None
    strain: str | None = None
    rate_hz: float | None = None
    window: str | None = None
    captures: list[str] = field(default_factory=list)
    voltage_scale: float | None = None  # None: not given (1); given, even 1: raw numbers as V
    voltage_offset: float = 0.0
    strain_scale: float = 1.0
    strain_offset: float = 0.0
    strain_units: str | None = None
    stack_length_mm: float | None = None
    scale: list[str] = field(default_factory=list)
    aux: list[str] = field(default_factory=list)
    delimiter: str | None = None
    decimal: str | None = None
    encoding: str | None = None


@dataclass
class AuxRequest:
    """One ``--aux``: the channel name asked for (None: from the column's label), its unit
    from that name, and the column."""

    spec: str
    name: str | None
    unit: str
    column: str


@dataclass
class Checked:
    """The options, parsed and checked."""

    opt: ImportOptions
    window: tuple[float, float] | None
    scales: dict[str, float]
    aux: list[AuxRequest]
    separator: str | None
    decimal: str | None
    encoding: str | None


def _finite(option: str, value: float, nonzero: bool = False) -> float:
    if not math.isfinite(value) or (nonzero and value == 0):
        need = "a finite number other than 0" if nonzero else "a finite number"
        raise option_error(option, f"{value}: expected {need}")
    return float(value)


def check_rate(rate_hz: float | None) -> float | None:
    """``--rate-hz``: None, or a finite rate within :data:`RATE_RANGE_HZ`."""
    lo, hi = RATE_RANGE_HZ
    if rate_hz is not None and not (math.isfinite(rate_hz) and lo <= rate_hz <= hi):
        raise option_error(
            "--rate-hz", f"{rate_hz}: expected a sample rate from {lo:g} to {hi:g} Hz"
        )
    return rate_hz


def parse_window(text: str | None) -> tuple[float, float] | None:
    """``"T0:T1"`` -> (T0, T1) in s; an empty side is -inf / +inf."""
    if text is None:
        return None
    start, sep, end = text.partition(":")
    try:
        if not sep:
            raise ValueError
        t0 = float(start) if start.strip() else -math.inf
        t1 = float(end) if end.strip() else math.inf
    except ValueError:
        raise option_error(
            "--window", f"{text!r}: expected T0:T1 in seconds, e.g. 2.5:10"
        ) from None
    if math.isnan(t0) or math.isnan(t1) or not t0 < t1 or (math.isinf(t0) and math.isinf(t1)):
        raise option_error("--window", f"{text!r}: expected T0 < T1, at least one of them a number")
    return t0, t1


def parse_aux(spec: str) -> AuxRequest:
    """``--aux COLUMN`` or ``--aux NAME=COLUMN`` (NAME like ``temperature_C`` gives a unit)."""
    name, sep, column = spec.partition("=")
    if not sep:
        return AuxRequest(spec, None, "", spec.strip())
    channel, unit = split_label(name.strip())
    if not is_valid_name(channel):
        raise option_error(
            "--aux",
            f"{spec}: {channel!r} is not a channel name: a letter, then letters, "
            "digits or underscores (at most 63)",
        )
    if channel.lower() in CORE_NAMES:
        raise option_error(
            "--aux",
            f"{spec}: {channel!r} is a core channel (give it with --time, --voltage or "
            f"--strain); name the auxiliary channel otherwise, e.g. {channel}_aux={column}",
        )
    if not column.strip():
        raise option_error("--aux", f"{spec}: expected NAME=COLUMN with a column after '='")
    return AuxRequest(spec, channel, unit, column.strip())


def parse_scales(opt: ImportOptions) -> dict[str, float]:
    """``--scale CHANNEL=FACTOR`` items and ``--voltage-scale``/``--strain-scale``."""
    scales: dict[str, float] = {}
    for spec in opt.scale:
        name, sep, text = spec.partition("=")
        try:
            factor = float(text) if sep else math.nan
        except ValueError:
            factor = math.nan
        if not name.strip() or not math.isfinite(factor) or factor == 0:
            raise option_error(
                "--scale", f"{spec}: expected CHANNEL=FACTOR with a finite factor other than 0"
            )
        scales[name.strip()] = factor
    for role, value in (("voltage", opt.voltage_scale), ("strain", opt.strain_scale)):
        if value is None:
            continue
        _finite(f"--{role}-scale", value, nonzero=True)
        if value != 1.0 or role == "voltage":  # --voltage-scale 1 says: these are volts
            if role in scales:
                raise option_error(f"--{role}-scale", f"and --scale {role}=...: give one of them")
            scales[role] = value
    return scales


def check_options(opt: ImportOptions) -> Checked:
    """Every option checked and parsed (raises InputFileError naming the option)."""
    check_rate(opt.rate_hz)
    _finite("--voltage-offset", opt.voltage_offset)
    _finite("--strain-offset", opt.strain_offset)
    if opt.stack_length_mm is not None and not (
        math.isfinite(opt.stack_length_mm) and opt.stack_length_mm > 0
    ):
        raise option_error("--stack-length-mm", f"{opt.stack_length_mm}: expected a length > 0 mm")
    sep = opt.delimiter
    if sep is not None:
        sep = _SEPARATORS.get(sep.lower(), sep)
        if len(sep) != 1 or sep in "\"'\r\n0123456789.":
            raise option_error("--delimiter", f"{opt.delimiter!r}: expected one character or tab")
    if opt.decimal is not None and opt.decimal not in (".", ","):
        raise option_error("--decimal", f"{opt.decimal!r}: expected . or ,")
    if opt.decimal == "," and sep == ",":
        raise option_error("--decimal", ", with --delimiter ,: the two must differ")
    if opt.encoding is not None:
        try:
            codecs.lookup(opt.encoding)
        except LookupError:
            raise option_error("--encoding", f"{opt.encoding!r}: unknown encoding") from None
    aux = [parse_aux(s) for s in opt.aux]
    names = [a.name for a in aux if a.name]
    if len(names) != len(set(names)):
        raise option_error("--aux", f"the same channel name twice: {sorted(names)}")
    return Checked(
        opt, parse_window(opt.window), parse_scales(opt), aux, sep, opt.decimal, opt.encoding
    )
