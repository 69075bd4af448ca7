"""A single long record cut into entries, so leave-one-entry-out has folds."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from labrig.analysis.metrics import drive_frequency_hz
from labrig.analysis.records import Record

__all__ = ["IDLE_TOL", "idle_lead", "idle_trail", "split_entries"]

#: a voltage within this fraction of the record's voltage span of its first sample is idle
IDLE_TOL = 0.01


def idle_lead(record: Record, parts: int = 4) -> int:
    """Samples at the start of ``record`` held idle: the voltage within :data:`IDLE_TOL` of its
    span of the first sample, counted only when that stretch is longer than half of one of
    ``parts`` equal parts (else 0). Such a stretch holds the actuator at rest: no drive, the
    strain at its equilibrium plus the sensor's noise; as a part of its own (or most of one) it
    would be scored in percent of its noise's span."""
    v = record.voltage_V
    span = float(np.ptp(v)) if v.size else 0.0
    if not span > 0:
        return 0
    moved = np.flatnonzero(np.abs(v - v[0]) > IDLE_TOL * span)
    lead = int(moved[0]) if moved.size else 0
    return lead if lead > record.n / (2 * parts) else 0


def idle_trail(record: Record, parts: int = 4) -> int:
    """Samples at the end of ``record`` held at its last sample's voltage (within
    :data:`IDLE_TOL` of its span), counted only when that stretch is longer than half of one of
    ``parts`` equal parts (else 0): :func:`idle_lead` read from the end."""
    v = record.voltage_V
    span = float(np.ptp(v)) if v.size else 0.0
    if not span > 0:
        return 0
    moved = np.flatnonzero(np.abs(v - v[-1]) > IDLE_TOL * span)
    trail = int(v.size - 1 - moved[-1]) if moved.size else 0
    return trail if trail > record.n / (2 * parts) else 0


def split_entries(records: Sequence[Record], parts: int = 4) -> list[Record]:
    """A single long record cut into ``parts`` consecutive entries (at whole drive periods when
    the record is periodic), chained with no rest: leave-one-entry-out then has folds. The
    pieces simulated back to back reproduce the original record exactly.

    A long idle start (:func:`idle_lead`: more than half a part at the first sample's voltage)
    is left out: the first part begins where the voltage first moves, from rest at the held
    voltage (``meta["rest_V"]``), and every part's ``meta["idle_lead_s"]`` says how many
    seconds were left out. A long idle end (:func:`idle_trail`) is kept, as the last part's
    tail: the parts are cut over the driven stretch, so none is a hold alone (scored in percent
    of its noise's span), and the strain's relaxation during the hold stays in the record
    (``meta["idle_trail_s"]``)."""
    out: list[Record] = []
    for r in records:
        lead = idle_lead(r, parts)
        idle = {"idle_lead_s": lead / r.rate_hz} if lead else {}
        rest = {"rest_V": float(r.voltage_V[0])} if lead else {}
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
