"""A single long record cut into entries, so leave-one-entry-out has folds."""

from __future__ import annotations

from collections.abc import Sequence

from labrig.analysis.metrics import drive_frequency_hz
from labrig.analysis.records import Record

__all__ = ["split_entries"]


def split_entries(records: Sequence[Record], parts: int = 4) -> list[Record]:
    """A single long record cut into ``parts`` consecutive entries (at whole drive periods when
    the record is periodic), chained with no rest: leave-one-entry-out then has folds. The
    pieces simulated back to back reproduce the original record exactly."""
    out: list[Record] = []
    for r in records:
        f = drive_frequency_hz(r)
        per = round(r.rate_hz / f) if f else 1
        per = per if 1 <= per <= r.n // parts else 1
        edges = [round(k * (r.n // per) / parts) * per for k in range(parts)] + [r.n]
        for k in range(parts):
            a, b = edges[k], edges[k + 1]
            meta = {**r.meta, "rest_after_s": 0.0, "split_of": r.name}
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
