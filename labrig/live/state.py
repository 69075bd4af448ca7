"""What the live page shows, kept up to date from :class:`~labrig.live.frames.Frame` reads:
the current entry's samples (appended as the file grows), the model's prediction for them when
a parameter file is given, and the page's JSON document (:meth:`LiveState.document`).

The prediction is :class:`~labrig.model.DynamicHysteresisModel` run block by block
(:meth:`~labrig.model.DynamicHysteresisModel.stream`) on the commanded voltage of the entry,
from rest at its start (effects fitted with the parameters are not applied): the same strain
``labrig fit``'s model gives for the entry on its own.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from labrig.live.frames import Frame
from labrig.store.writing import writer_of

#: the time series shows this many seconds of the current entry (its last ones)
SERIES_WINDOW_S = 5.0
#: at most this many points per curve go to the page (evenly spaced samples)
MAX_POINTS = 1500
#: the loop shows the entry's last this many samples (decimated to MAX_POINTS)
LOOP_SAMPLES = 6000


def _decimate(n: int, limit: int = MAX_POINTS) -> slice:
    return slice(None, None, max(1, math.ceil(n / limit)))


def _rounded(a: np.ndarray, digits: int = 5) -> list[float | None]:
    """JSON numbers with ``digits`` significant digits (non-finite values as null)."""
    out: list[float | None] = []
    for x in a.tolist():
        out.append(float(f"{x:.{digits}g}") if math.isfinite(x) else None)
    return out


@dataclass
class EntrySamples:
    """The samples of one entry read so far (and the prediction for them)."""

    name: str
    data: dict[str, list[np.ndarray]] = field(default_factory=dict)
    n: int = 0

    def extend(self, samples: dict[str, np.ndarray]) -> int:
        m = min((v.size for v in samples.values()), default=0)
        for c, v in samples.items():
            self.data.setdefault(c, []).append(v[:m])
        self.n += m
        return m

    def array(self, channel: str) -> np.ndarray:
        parts = self.data.get(channel)
        if not parts:
            return np.empty(0)
        if len(parts) > 1:
            self.data[channel] = parts = [np.concatenate(parts)]
        return parts[0]


class LiveState:
    """The live view's state (module docstring); ``params`` is a ``ModelParams`` or None."""

    def __init__(self, params: Any = None, source: str = ""):
        self.params = params
        self.source = source
        self.frame: Frame | None = None
        self.entry: EntrySamples | None = None
        self.planned_samples: dict[str, int | None] = {}
        self.seq = 0
        self.reads = 0
        self.skipped = 0
        self.last_error = ""
        self.read_ms = 0.0
        self.path = ""
        self._stream: Any = None

    # -- reading ----------------------------------------------------------------------------
    def next_request(self) -> tuple[str | None, int]:
        """The entry and the first sample the next read should fetch."""
        if self.entry is None:
            return None, 0
        return self.entry.name, self.entry.n

    def take(self, frame: Frame, read_ms: float) -> bool:
        """Apply a frame; True when something the page shows changed."""
        self.reads += 1
        self.read_ms = read_ms
        for e in frame.entries:
            self.planned_samples.setdefault(e.name, e.planned_samples)
        changed = self.frame is None or _summary(frame) != _summary(self.frame)
        if frame.current is not None:
            # a new entry, or a gap (a viewer that joined late or could not keep up)
            if self.entry is None or (self.entry.name, self.entry.n) != (
                frame.current,
                frame.start,
            ):
                self.entry = EntrySamples(frame.current)
                # the model runs from the entry's start (from rest): not for a late join
                self._stream = self._new_stream(frame) if frame.start == 0 else None
            added = self.entry.extend(frame.samples)
            if added and self._stream is not None and "command_voltage" in frame.samples:
                v = frame.samples["command_voltage"][:added]
                self.entry.data.setdefault("model", []).append(self._stream.process(v))
            changed = changed or added > 0
        self.frame = frame
        if changed:
            self.seq += 1
        return changed

    def _new_stream(self, frame: Frame) -> Any:
        if self.params is None or frame.current is None:
            return None
        from labrig.model import DynamicHysteresisModel

        rate = frame.entries[-1].rate_hz if frame.entries else None
        return DynamicHysteresisModel(self.params).stream(rate) if rate else None

    # -- the page's document ----------------------------------------------------------------
    def document(self) -> dict[str, Any]:
        f = self.frame
        doc: dict[str, Any] = {
            "seq": self.seq,
            "source": self.source,
            "reads": self.reads,
            "skipped": self.skipped,
            "read_ms": round(self.read_ms, 1),
            "error": self.last_error,
            "server_time": time.time(),
        }
        if f is None:
            doc["status"] = "waiting"
            return doc
        doc.update(
            status=f.status,
            reason=f.reason,
            protocol=f.protocol,
            writing=self._writing(f),
            progress=self._progress(f),
            amplifier=self._amplifier(f),
            model=self.params is not None,
        )
        if self.entry is not None and self.entry.n:
            doc["entry"] = self._curves()
        return doc

    def _writing(self, f: Frame) -> str:
        if f.status != "running":
            return "finished"
        try:
            w = writer_of(self.path, f.writer_pid, f.writer_host)
        except OSError:
            return "unknown"
        return "being written" if w.alive else "stopped without finishing (incomplete)"

    def _progress(self, f: Frame) -> dict[str, Any]:
        planned = f.planned or [e.name for e in f.entries]
        done = sum(1 for e in f.entries if e.status == "complete" and e.name in planned)
        cur = f.entries[-1] if f.entries else None
        frac = 0.0
        if cur is not None and cur.status == "running" and cur.planned_samples:
            frac = min(1.0, cur.samples / cur.planned_samples)
        return {
            "planned": len(planned),
            "complete": done,
            "entry": cur.name if cur else None,
            "title": cur.title if cur else "",
            "entry_status": cur.status if cur else "",
            "entry_fraction": round(frac, 4),
            "fraction": round(min(1.0, (done + frac) / max(1, len(planned))), 4),
            "entries": [{"name": e.name, "status": e.status} for e in f.entries],
        }

    def _amplifier(self, f: Frame) -> dict[str, Any]:
        out: dict[str, Any] = {"state": "output on" if f.status == "running" else "output off"}
        if self.entry is not None and self.entry.n:
            for c in ("amplifier_voltage", "command_voltage"):
                a = self.entry.array(c)
                if a.size:
                    out[c + "_V"] = round(float(a[-1]), 3)
        if f.final_voltage_V is not None:
            out["final_voltage_V"] = round(f.final_voltage_V, 4)
            out["state"] = f"ramped to 0 V; read back {f.final_voltage_V:.3f} V"
        if f.exit_code is not None:
            out["exit_code"] = f.exit_code
        return out

    def _curves(self) -> dict[str, Any]:
        e = self.entry
        assert e is not None
        t, v, s = e.array("time"), e.array("command_voltage"), e.array("strain")
        model = e.array("model")
        n = min(t.size, v.size, s.size)
        win = np.searchsorted(t[:n], t[n - 1] - SERIES_WINDOW_S) if n else 0
        ts = slice(win, n)
        d = _decimate(n - win)
        lo = max(0, n - LOOP_SAMPLES)
        dl = _decimate(n - lo)
        out: dict[str, Any] = {
            "name": e.name,
            "samples": n,
            "series": {
                "t": _rounded(t[ts][d], 7),
                "strain": _rounded(s[ts][d]),
                "voltage": _rounded(v[ts][d]),
            },
            "loop": {"voltage": _rounded(v[lo:n][dl]), "strain": _rounded(s[lo:n][dl])},
        }
        if model.size >= n and n:
            out["series"]["model"] = _rounded(model[ts][d])
            out["loop"]["model"] = _rounded(model[lo:n][dl])
        return out


def _summary(f: Frame) -> tuple:
    return (
        f.status,
        f.reason,
        f.exit_code,
        f.final_voltage_V,
        tuple((e.name, e.status) for e in f.entries),
    )
