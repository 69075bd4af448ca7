"""Metrics of strain-command entries: how well the measured strain followed the command.

Plain functions of arrays (command and measured strain in ue, at ``rate_hz``):

- :func:`tracking_nrmse_pct`: ``100 RMS(S - S_com) / (max S_com - min S_com)``.
- :func:`hysteresis_width_pct`: over the last command period, the largest difference between the
  falling and the rising branch of the measured strain at the same command (both interpolated on
  101 commands spanning the middle 90 % of the loop), in % of the command span; signed, positive
  for the piezo's orientation (falling above rising), report ``abs`` for "width".
- :func:`zero_command_strain_ue`: over the last command period, the strain where the command is
  at its minimum (0 for a unipolar sine; averaged over the samples within 1 % of the span of it):
  the paper's "strain bias at zero command".
- :func:`final_strain_ue`: mean strain over the last ``window_s`` of the command (the vanishing
  command's end), with its noise-limited standard error.
- :func:`command_metrics`: all of them for one command and its measured strain.

And of recorded entries (:class:`labrig.analysis.records.Record`, from
:func:`labrig.analysis.load.records_from_run`):

- :func:`entry_metrics`: all of them for one strain-command entry, over its command samples, with
  ``control``, ``kind``, ``frequency_hz`` and ``amplitude_ue``;
- :func:`control_metrics`: entry name -> the :data:`REPORT_KEYS` of :func:`entry_metrics` for
  every strain-command entry of a run (what ``labrig report --json`` gives for each).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "REPORT_KEYS",
    "command_metrics",
    "control_metrics",
    "entry_metrics",
    "final_strain_ue",
    "hysteresis_width_pct",
    "is_control_entry",
    "tracking_nrmse_pct",
    "zero_command_strain_ue",
]

#: zero-command strain: samples whose command is within this fraction of the span of its minimum
ZERO_BAND = 0.01
#: the keys ``labrig report --json`` gives for each strain-command entry
REPORT_KEYS = (
    "control",
    "frequency_hz",
    "tracking_nrmse_pct",
    "hysteresis_width_pct",
    "zero_command_strain_ue",
)

Array = NDArray[np.float64]


def _pair(command: ArrayLike, measured: ArrayLike) -> tuple[Array, Array]:
    c = np.asarray(command, dtype=float).ravel()
    m = np.asarray(measured, dtype=float).ravel()
    if c.shape != m.shape or c.size == 0:
        raise ValueError(f"command {c.shape} and measured {m.shape} must match and be non-empty")
    return c, m


def tracking_nrmse_pct(command: ArrayLike, measured: ArrayLike) -> float:
    """``100 RMS(measured - command) / (max command - min command)`` (percent)."""
    c, m = _pair(command, measured)
    span = float(np.ptp(c))
    if not span > 0:
        raise ValueError("tracking NRMSE is undefined for a constant command")
    return 100.0 * float(np.sqrt(np.mean((m - c) ** 2))) / span


def _last_period(c: Array, m: Array, rate_hz: float, frequency_hz: float) -> tuple[Array, Array]:
    p = round(rate_hz / frequency_hz)
    if p < 4 or c.size < p:
        raise ValueError("no full command period in the record (frequency or length)")
    return c[-p:], m[-p:]


def hysteresis_width_pct(
    command: ArrayLike, measured: ArrayLike, rate_hz: float, frequency_hz: float
) -> float:
    """Largest falling-minus-rising strain gap at equal command over the last period, in % of
    the command span (signed; positive when the falling branch lies above the rising one)."""
    c, m = _last_period(*_pair(command, measured), rate_hz, frequency_hz)
    span = float(np.ptp(c))
    if not span > 0:
        raise ValueError("hysteresis width is undefined for a constant command")
    i_lo, i_hi = int(np.argmin(c)), int(np.argmax(c))
    p = c.size
    rise = (i_lo + np.arange((i_hi - i_lo) % p + 1)) % p
    fall = (i_hi + np.arange((i_lo - i_hi) % p + 1)) % p
    grid = c[i_lo] + span * np.linspace(0.05, 0.95, 101)

    def branch(idx: NDArray) -> Array:
        order = np.argsort(c[idx], kind="stable")
        return np.interp(grid, c[idx][order], m[idx][order])

    gap = branch(fall) - branch(rise)
    return 100.0 * float(gap[np.argmax(np.abs(gap))]) / span


def zero_command_strain_ue(
    command: ArrayLike, measured: ArrayLike, rate_hz: float, frequency_hz: float
) -> float:
    """Measured strain (ue) where the command is at its minimum (0 for a unipolar sine), over
    the last period: ``min command + mean(measured - command)`` over the samples whose command
    is within 1 % of the command span of its minimum (about 30 samples around each minimum at
    1 Hz and 1 kHz, 3 at 40 Hz: a few gauge-noise samples are averaged, and the tracking error
    barely changes over 1 % of the stroke)."""
    c, m = _last_period(*_pair(command, measured), rate_hz, frequency_hz)
    lo = float(np.min(c))
    near = c <= lo + ZERO_BAND * float(np.ptp(c))
    return float(np.mean(m[near] - c[near])) + lo


def final_strain_ue(
    measured: ArrayLike, rate_hz: float, window_s: float = 1.0
) -> tuple[float, float]:
    """Mean measured strain over the last ``window_s`` and its standard error (ue):
    ``std / sqrt(n)`` (white noise). For "the strain returns to zero as the command ends"."""
    m = np.asarray(measured, dtype=float).ravel()
    n = max(2, min(m.size, round(window_s * rate_hz)))
    tail = m[-n:]
    return float(np.mean(tail)), float(np.std(tail, ddof=1) / math.sqrt(tail.size))


def command_metrics(
    command: ArrayLike,
    measured: ArrayLike,
    rate_hz: float,
    frequency_hz: float | None = None,
    periodic: bool = True,
) -> dict[str, Any]:
    """All metrics of one strain-command entry (the command part of it): keys
    ``tracking_nrmse_pct``, ``hysteresis_width_pct`` (``abs`` of the signed width),
    ``zero_command_strain_ue`` (``None`` unless ``periodic`` and ``frequency_hz``), and
    ``final_strain_ue`` / ``final_strain_se_ue`` (last second)."""
    c, m = _pair(command, measured)
    out: dict[str, Any] = {"tracking_nrmse_pct": tracking_nrmse_pct(c, m)}
    if periodic and frequency_hz:
        out["hysteresis_width_pct"] = abs(hysteresis_width_pct(c, m, rate_hz, frequency_hz))
        out["zero_command_strain_ue"] = zero_command_strain_ue(c, m, rate_hz, frequency_hz)
    else:
        out["hysteresis_width_pct"] = None
        out["zero_command_strain_ue"] = None
    out["final_strain_ue"], out["final_strain_se_ue"] = final_strain_ue(m, rate_hz)
    return out


def entry_metrics(record: Any) -> dict[str, Any]:
    """Metrics of one recorded strain-command entry (a :class:`labrig.analysis.records.Record`
    from :func:`labrig.analysis.load.records_from_run`), over its command samples only
    (``meta["command_start_index"]:meta["command_stop_index"]``, leaving out the 0 V sample
    before and the ramp to 0 V after). Keys: ``control``, ``frequency_hz``, ``kind``,
    ``amplitude_ue`` and those of :func:`command_metrics` (``hysteresis_width_pct`` and
    ``zero_command_strain_ue`` for ``strain_sine`` entries only, else ``None``). Raises
    ``ValueError`` for an entry without a ``command_strain`` channel."""
    meta = record.meta
    if not is_control_entry(record):
        raise ValueError(f"entry {record.name!r} is not a strain-command entry")
    i0 = int(meta.get("command_start_index", 0))
    i1 = int(meta.get("command_stop_index", record.strain_ue.size))
    c = record.aux["command_strain"][i0:i1]
    m = record.strain_ue[i0:i1]
    f = meta.get("frequency_hz")
    periodic = meta.get("kind") == "strain_sine" and bool(f)
    out = {
        "control": meta["control"],
        "kind": meta.get("kind"),
        "frequency_hz": f,
        "amplitude_ue": meta.get("amplitude_ue"),
    }
    out.update(command_metrics(c, m, record.rate_hz, f, periodic=periodic))
    return out


def is_control_entry(record: Any) -> bool:
    """Whether ``record`` is a strain-command entry: a ``command_strain`` channel and a
    ``control`` key in its step definition."""
    return "command_strain" in record.aux and "control" in record.meta


def control_metrics(records: Iterable[Any]) -> dict[str, dict[str, Any]]:
    """Entry name -> the :data:`REPORT_KEYS` of :func:`entry_metrics` for every strain-command
    entry of ``records`` (other entries are left out)."""
    out = {}
    for r in records:
        if is_control_entry(r):
            m = entry_metrics(r)
            out[r.name] = {k: m.get(k) for k in REPORT_KEYS}
    return out
