"""A single long record cut into entries, so leave-one-entry-out has folds."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.metrics import drive_frequency_hz
from labrig.analysis.records import Record

__all__ = [
    "IDLE_NOISE_SIGMAS",
    "IDLE_TOL",
    "IDLE_TOL_MAX",
    "idle_lead",
    "idle_trail",
    "split_entries",
]

#: a voltage within this fraction of the record's voltage span of the held level is idle
IDLE_TOL = 0.01
#: ... or within this many standard deviations of the voltage channel's own noise, when that is
#: larger (a measured voltage, not a command) ...
IDLE_NOISE_SIGMAS = 5.0
#: ... but never a band wider than this fraction of the span (a small drive is a drive)
IDLE_TOL_MAX = 0.05


def _held(v: NDArray, need: int) -> tuple[int, float]:
    """How many samples at the start of ``v`` stay at one held level. The level is the mean of
    the first ``need`` samples (a single first sample may be a noise extreme); the band around it
    is :data:`IDLE_TOL` of the span of ``v`` or :data:`IDLE_NOISE_SIGMAS` times the noise of
    those samples (1.4826 MAD of their first differences over sqrt 2: the white noise's standard
    deviation, blind to a slow drift), whichever is larger, at most :data:`IDLE_TOL_MAX` of the
    span. Returns the number of held samples (0 unless more than ``need``) and the level (V)."""
    span = float(np.ptp(v)) if v.size else 0.0
    if not span > 0 or v.size <= need or need < 1:
        return 0, float(v[0]) if v.size else 0.0
    head = v[: need + 1]
    level = float(np.mean(head))
    sigma = 1.4826 * float(np.median(np.abs(np.diff(head)))) / np.sqrt(2.0) if need > 1 else 0.0
    tol = min(max(IDLE_TOL * span, IDLE_NOISE_SIGMAS * sigma), IDLE_TOL_MAX * span)
    moved = np.flatnonzero(np.abs(v - level) > tol)
    held = int(moved[0]) if moved.size else 0
    return (held if held > need else 0), level


def idle_lead(record: Record, parts: int = 4) -> int:
    """Samples at the start of ``record`` held idle (:func:`_held`: the voltage within a
    band around one held level), counted only when that stretch is longer than half of one of
    ``parts`` equal parts (else 0). Such a stretch holds the actuator at rest: no drive, the
    strain at its equilibrium plus the sensor's noise; as a part of its own (or most of one) it
    would be scored in percent of its noise's span."""
    return _held(record.voltage_V, record.n // (2 * parts))[0]


def idle_trail(record: Record, parts: int = 4) -> int:
    """Samples at the end of ``record`` held at one level, counted only when that stretch is
    longer than half of one of ``parts`` equal parts (else 0): :func:`idle_lead` read from the
    end."""
    return _held(record.voltage_V[::-1], record.n // (2 * parts))[0]


def split_entries(records: Sequence[Record], parts: int = 4) -> list[Record]:
    """A single long record cut into ``parts`` consecutive entries (at whole drive periods when
    the record is periodic), chained with no rest: leave-one-entry-out then has folds. The
    pieces simulated back to back reproduce the original record exactly.

    A long idle start (:func:`idle_lead`: more than half a part at one held voltage)
    is left out: the first part begins where the voltage first moves, from rest at the held
    level (``meta["rest_V"]``), and every part's ``meta["idle_lead_s"]`` says how many seconds
    were left out. A long idle end (:func:`idle_trail`) is kept, as the last part's
    tail: the parts are cut over the driven stretch, so none is a hold alone (scored in percent
    of its noise's span), and the strain's relaxation during the hold stays in the record
    (``meta["idle_trail_s"]``)."""
    out: list[Record] = []
    for r in records:
        lead, level = _held(r.voltage_V, r.n // (2 * parts))
        idle = {"idle_lead_s": lead / r.rate_hz} if lead else {}
        rest = {"rest_V": level} if lead else {}
        if lead:
            r = Record(
                r.name,
                r.rate_hz,
                r.time_s[lead:],
                r.voltage_V[lead:],
                r.strain_ue[lead:],
                {n: x[lead:] for n, x in r.aux.items()},
                r.hold,
                dict(r.meta),
            )
        trail = idle_trail(r, parts)
        trail = trail if (r.n - trail) // parts >= 2 else 0  # a drive too short to cut: as is
        idle = {**idle, "idle_trail_s": trail / r.rate_hz} if trail else idle
        driven = r.n - trail
        f = drive_frequency_hz(r)
        per = round(r.rate_hz / f) if f else 1
        per = per if 1 <= per <= driven // parts else 1
        edges = [round(k * (driven // per) / parts) * per for k in range(parts)] + [r.n]
        for k in range(parts):
            a, b = edges[k], edges[k + 1]
            meta = {**r.meta, "rest_after_s": 0.0, "split_of": r.name, **idle}
            if k == 0:
                meta.update(rest)
            out.append(
                Record(
                    f"{r.name}_part{k + 1}",
                    r.rate_hz,
                    r.time_s[a:b],
                    r.voltage_V[a:b],
                    r.strain_ue[a:b],
                    {n: x[a:b] for n, x in r.aux.items()},
                    r.hold,
                    meta,
                )
            )
    return out


def whole_records(records: Sequence[Record]) -> list[Record]:
    """``records`` with the parts of each cut record (:func:`split_entries`:
    ``meta["split_of"]``, in order) joined again into one record of that name (voltage and
    strain, time from 0; the first part's rate, hold and meta)."""
    slots: list[Record | str] = []  # a record, or the name of a cut one (joined below)
    parts: dict[str, list[Record]] = {}
    for r in records:
        src = r.meta.get("split_of")
        if src is None:
            slots.append(r)
            continue
        if str(src) not in parts:
            parts[str(src)] = []
            slots.append(str(src))
        parts[str(src)].append(r)
    out = []
    for slot in slots:
        if isinstance(slot, Record):
            out.append(slot)
            continue
        group = parts[slot]
        v = np.concatenate([g.voltage_V for g in group])
        out.append(
            Record(  # the meta as a mapping: a record's meta may hold "rate_hz", "hold", ...
                slot,
                group[0].rate_hz,
                np.arange(v.size) / group[0].rate_hz,
                v,
                np.concatenate([g.strain_ue for g in group]),
                hold=group[0].hold,
                meta=dict(group[0].meta),
            )
        )
    return out
