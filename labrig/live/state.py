"""What the live page shows, kept up to date from :class:`~labrig.live.frames.Frame` reads:
the current entry's samples (appended as the file grows), the model's prediction for them when
a parameter file is given, and the page's JSON document (:meth:`LiveState.document`); and, for
every entry that has ended, its loop (:meth:`LiveState.loops_document`, the overlay of earlier
entries and the end-of-run page) and its whole record (:func:`entry_view`, the page's view of
one entry chosen in its selector).

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

from labrig.live.frames import EntryData, EntryInfo, FileKey, Frame, StepFacts
from labrig.store.writing import writer_of

#: the time series shows this many seconds of the current entry (its last ones)
SERIES_WINDOW_S = 5.0
#: at most this many points per curve go to the page (evenly spaced samples)
MAX_POINTS = 1500
#: the loop shows the entry's last this many samples (decimated to MAX_POINTS) when its drive
#: frequency is not known
LOOP_SAMPLES = 6000
#: a loop keeps at least this many points per period of its drive (when the frequency is known)
POINTS_PER_PERIOD = 40
#: an ended entry's view (the selector's choice): at most this many points of its time series
ENTRY_SERIES_POINTS = 8000
#: the overlay of ended entries: at most this many loop points in all (at least
#: :data:`MIN_OVERLAY_POINTS`, at most :data:`MAX_POINTS` per entry)
OVERLAY_POINTS = 60_000
MIN_OVERLAY_POINTS = 200
#: the statuses a run or an entry ends with
FINAL = ("complete", "aborted", "failed")


def _decimate(n: int, limit: int = MAX_POINTS) -> slice:
    return slice(None, None, max(1, math.ceil(n / limit)))


def loop_slice(
    n: int,
    rate_hz: float | None,
    frequency_hz: float | None,
    max_points: int = MAX_POINTS,
    whole: bool = False,
) -> slice:
    """Which of an entry's ``n`` samples its strain-voltage loop draws (at most
    ``max_points``).

    With the drive's frequency known (``P = rate_hz / frequency_hz`` samples a period), every
    ``s``-th sample with ``s = max(1, floor(P / POINTS_PER_PERIOD))`` (at least
    :data:`POINTS_PER_PERIOD` points a period, so the loop is not aliased), over the last
    ``max_points * s`` samples: the whole entry when it fits (a vanishing envelope shows all its
    nested loops, not its decayed tail). Without it, evenly spaced samples of the whole entry
    (``whole``) or of its last :data:`LOOP_SAMPLES`.
    """
    if n <= 0:
        return slice(0, 0)
    if rate_hz and frequency_hz:
        stride = max(1, math.floor(rate_hz / frequency_hz / POINTS_PER_PERIOD))
        window = min(n, max_points * stride)
    else:
        window = n if whole else min(n, LOOP_SAMPLES)
        stride = max(1, math.ceil(window / max_points))
    return slice(n - window, n, stride)


def overlay_points(planned_entries: int) -> int:
    """Loop points per entry in the overlay of a run of ``planned_entries`` entries."""
    share = OVERLAY_POINTS // max(1, planned_entries)
    return max(MIN_OVERLAY_POINTS, min(MAX_POINTS, share))


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
        self.step_facts: dict[str, StepFacts] = {}
        #: entries seen ended (a final status), not read again (:func:`read_frame_here`)
        self.ended: dict[str, EntryInfo] = {}
        #: the file these facts are of (:func:`~labrig.live.frames.file_key`); a frame
        #: of another file at the path (a run replaced with --overwrite) forgets them
        self.file_id: FileKey | None = None
        self.seq = 0
        self.reads = 0
        self.skipped = 0
        self.last_error = ""
        self.read_ms = 0.0
        self.path = ""
        self._stream: Any = None
        #: the loops of the entries that have ended (the overlay), by name, and what they
        #: were read from (samples, status): an entry read again when that changes
        self.loops: dict[str, dict[str, Any]] = {}
        self.loop_keys: dict[str, tuple[int, str]] = {}
        self.loops_seq = 0
        #: requests refused by the server (a foreign Host header, a bad method or path)
        self.refused = 0
        #: files read after the first (another file at the path): the page's cue to drop the
        #: entry view it kept
        self.files = 0

    # -- reading ----------------------------------------------------------------------------
    def _another_file(self, file_id: FileKey | None) -> None:
        """What was read of another file is forgotten: its step facts, ended entries, current
        entry and loops (a run replaced at the path, even with the same entry names)."""
        self.step_facts.clear()
        self.ended.clear()
        self.entry = None
        self._stream = None
        self.frame = None
        if self.loops:
            self.loops.clear()
            self.loop_keys.clear()
            self.loops_seq += 1
        if self.file_id is not None:
            self.files += 1  # the page drops what it kept of the previous file
        self.file_id = file_id

    def next_request(self) -> tuple[str | None, int]:
        """The entry and the first sample the next read should fetch."""
        if self.entry is None:
            return None, 0
        return self.entry.name, self.entry.n

    def take(self, frame: Frame, read_ms: float) -> bool:
        """Apply a frame; True when something the page shows changed. A frame of another
        file than the last (``frame.file_id``) starts afresh (:meth:`_another_file`)."""
        self.reads += 1
        self.read_ms = read_ms
        if frame.file_id != self.file_id:
            self._another_file(frame.file_id)
        for e in frame.entries:
            self.step_facts.setdefault(e.name, (e.planned_samples, e.frequency_hz))
            if e.status in FINAL:
                self.ended.setdefault(e.name, e)
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

    # -- the entries that have ended ----------------------------------------------------------
    def ended_entries(self) -> list[tuple[str, tuple[int, str]]]:
        """The entries whose loop is still to be read (or read again): those that ended (or
        all, once the run has ended), with the (samples, status) to read them at."""
        f = self.frame
        if f is None:
            return []
        run_ended = f.status != "running"
        return [
            (e.name, (e.samples, e.status))
            for e in f.entries
            if (e.status != "running" or run_ended)
            and e.samples > 0
            and self.loop_keys.get(e.name) != (e.samples, e.status)
        ]

    def take_entry(
        self, key: tuple[int, str], view: dict[str, Any], file_id: FileKey | None = None
    ) -> bool:
        """Keep an ended entry's loop (:func:`entry_view`'s ``overlay``) for the overlay, if
        it was read from the file the frames are of (``file_id``; None: not checked)."""
        if file_id is not None and file_id != self.file_id:
            return False
        self.loops[view["name"]] = view
        self.loop_keys[view["name"]] = key
        self.loops_seq += 1
        self.seq += 1
        return True

    def loops_document(self) -> dict[str, Any]:
        """Every ended entry's loop, in the run's order: ``{"seq", "entries": [{"name",
        "title", "status", "samples", "loop": {"t", "voltage", "strain"}}]}``."""
        order = [e.name for e in self.frame.entries] if self.frame is not None else []
        return {
            "seq": self.loops_seq,
            "entries": [self.loops[n] for n in order if n in self.loops],
        }

    def is_final(self) -> bool:
        """The run has ended and every entry's loop is in :meth:`loops_document`."""
        f = self.frame
        return f is not None and f.status in FINAL and not self.ended_entries()

    def known_entry(self, name: str) -> bool:
        """Whether the run file has an entry of that name (as last read)."""
        return self.frame is not None and any(e.name == name for e in self.frame.entries)

    def planned_count(self) -> int:
        f = self.frame
        return len(f.planned or f.entries) if f is not None else 1

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
            "loops_seq": self.loops_seq,
            "refused": self.refused,
            "files": self.files,
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
            final=self.is_final(),
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
            "entries": [
                {"name": e.name, "title": e.title, "status": e.status, "samples": e.samples}
                for e in f.entries
            ],
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
        assert e is not None and self.frame is not None
        t, v, s = e.array("time"), e.array("command_voltage"), e.array("strain")
        model = e.array("model")
        n = min(t.size, v.size, s.size)
        win = np.searchsorted(t[:n], t[n - 1] - SERIES_WINDOW_S) if n else 0
        ts = slice(win, n)
        d = _decimate(n - win)
        info = next((x for x in self.frame.entries if x.name == e.name), None)
        rate, freq = (info.rate_hz, info.frequency_hz) if info is not None else (None, None)
        lp = loop_slice(n, rate, freq)
        out: dict[str, Any] = {
            "name": e.name,
            "samples": n,
            "series": {
                "t": _rounded(t[ts][d], 7),
                "strain": _rounded(s[ts][d]),
                "voltage": _rounded(v[ts][d]),
            },
            "loop": {
                "t": _rounded(t[lp], 7),
                "voltage": _rounded(v[lp]),
                "strain": _rounded(s[lp]),
            },
        }
        if model.size >= n and n:
            out["series"]["model"] = _rounded(model[ts][d])
            out["loop"]["model"] = _rounded(model[lp])
        return out


def entry_view(
    data: EntryData, params: Any, overlay_max: int = MAX_POINTS
) -> tuple[dict[str, Any], dict[str, Any]]:
    """An ended entry as the page draws it: ``(overlay, detail)``.

    ``overlay``: its loop for the overlay of ended entries (at most ``overlay_max`` points,
    :func:`loop_slice` of the whole entry). ``detail``: what the page shows when the entry is
    chosen: its time series (time s, strain ue, command voltage V; at most
    :data:`ENTRY_SERIES_POINTS` evenly spaced samples) and its loop (at most
    :data:`MAX_POINTS`), each with the model's prediction when ``params`` is given and the
    entry was read from its start: ``DynamicHysteresisModel(params).stream(rate)`` run on the
    entry's commanded voltage from rest, the prediction the live view draws block by block.
    """
    info, x = data.info, data.samples
    t, v, s = (x.get(c, np.empty(0)) for c in ("time", "command_voltage", "strain"))
    n = min(t.size, v.size, s.size)
    model = None
    if params is not None and data.start == 0 and info.rate_hz and n:
        from labrig.model import DynamicHysteresisModel

        model = DynamicHysteresisModel(params).stream(info.rate_hz).process(v[:n])
    head = {
        "name": info.name,
        "title": info.title,
        "status": info.status,
        "samples": data.start + n,
    }

    def loop(sl: slice, with_model: bool) -> dict[str, Any]:
        out = {"t": _rounded(t[sl], 7), "voltage": _rounded(v[sl]), "strain": _rounded(s[sl])}
        if with_model and model is not None:
            out["model"] = _rounded(model[sl])
        return out

    overlay = dict(
        head, loop=loop(loop_slice(n, info.rate_hz, info.frequency_hz, overlay_max, True), False)
    )
    ds = slice(0, n, max(1, math.ceil(n / ENTRY_SERIES_POINTS)))
    series = {"t": _rounded(t[ds], 7), "strain": _rounded(s[ds]), "voltage": _rounded(v[ds])}
    if model is not None:
        series["model"] = _rounded(model[ds])
    detail = dict(
        head,
        rate_hz=info.rate_hz,
        start=data.start,
        series=series,
        loop=loop(loop_slice(n, info.rate_hz, info.frequency_hz, MAX_POINTS, True), True),
    )
    return overlay, detail


def _summary(f: Frame) -> tuple:
    return (
        f.status,
        f.reason,
        f.exit_code,
        f.final_voltage_V,
        tuple((e.name, e.status) for e in f.entries),
    )
