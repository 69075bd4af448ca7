"""One measured (or simulated) entry of a run, as the analysis sees it.

The run-file reader and ``labrig import`` produce :class:`Record` objects; fitting, metrics and
reports consume them. Units: s, V, ue (microstrain), Hz.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

HOLDS = ("zoh", "linear")

#: keys of ``Record.meta`` read as the drive frequency (Hz), first match wins
FREQUENCY_KEYS = ("frequency_hz", "freq_hz", "f_hz", "frequency")

#: a record "begins at a held voltage" when its voltage moves, over its first HELD_S seconds
#: (at least HELD_SAMPLES samples), at under HELD_TOL of its RMS rate over the whole record
HELD_S = 0.1
HELD_SAMPLES = 20
HELD_TOL = 0.1


@dataclass
class Record:
    """One entry: a voltage record and the strain it produced, sampled at ``rate_hz``.

    ``hold`` says how the voltage behaves between samples, which the model needs:
    ``"zoh"`` for a voltage a DAQ drove (held on each sample interval, the default) and
    ``"linear"`` for a measured smooth voltage (e.g. imported data). ``aux`` holds other
    channels by name (same length); ``meta`` holds whatever the source knows, e.g.
    ``frequency_hz`` and ``amplitude_V`` of a sine entry (see :data:`FREQUENCY_KEYS`).
    """

    name: str
    rate_hz: float
    time_s: NDArray[np.float64]
    voltage_V: NDArray[np.float64]
    strain_ue: NDArray[np.float64]
    aux: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    hold: str = "zoh"
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.rate_hz = float(self.rate_hz)
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ValueError(f"record {self.name!r}: rate_hz must be positive, got {self.rate_hz}")
        if self.hold not in HOLDS:
            raise ValueError(
                f"record {self.name!r}: hold must be one of {HOLDS}, got {self.hold!r}"
            )
        self.voltage_V = np.asarray(self.voltage_V, dtype=np.float64).ravel()
        self.strain_ue = np.asarray(self.strain_ue, dtype=np.float64).ravel()
        n = self.voltage_V.size
        if self.time_s is None:
            self.time_s = np.arange(n) / self.rate_hz
        self.time_s = np.asarray(self.time_s, dtype=np.float64).ravel()
        if self.strain_ue.size != n or self.time_s.size != n:
            raise ValueError(
                f"record {self.name!r}: time ({self.time_s.size}), voltage ({n}) and strain "
                f"({self.strain_ue.size}) must have the same length"
            )
        self.aux = {k: np.asarray(v, dtype=np.float64).ravel() for k, v in self.aux.items()}
        for k, v in self.aux.items():
            if v.size != n:
                raise ValueError(f"record {self.name!r}: aux channel {k!r} has {v.size} != {n}")

    @classmethod
    def from_arrays(
        cls,
        name: str,
        rate_hz: float,
        voltage_V: ArrayLike,
        strain_ue: ArrayLike,
        hold: str = "zoh",
        **meta: Any,
    ) -> Record:
        """A record with time ``n / rate_hz`` and no auxiliary channels."""
        v = np.asarray(voltage_V, dtype=np.float64)
        s = np.asarray(strain_ue, dtype=np.float64)
        return cls(name, rate_hz, np.arange(v.size) / float(rate_hz), v, s, {}, hold, meta)

    @property
    def n(self) -> int:
        return int(self.voltage_V.size)

    @property
    def duration_s(self) -> float:
        return self.n / self.rate_hz

    @property
    def frequency_hz(self) -> float | None:
        """The drive frequency stated in ``meta`` (Hz), or ``None``."""
        for k in FREQUENCY_KEYS:
            f = self.meta.get(k)
            if f is not None:
                try:
                    f = float(f)
                except (TypeError, ValueError):
                    continue
                if np.isfinite(f) and f > 0:
                    return f
        return None

    @property
    def rest_V(self) -> float:
        """The voltage (V) the actuator was held at before the record.

        ``meta["rest_V"]`` when the source states it; else the first sample when the record
        begins at a held voltage (over its first :data:`HELD_S` s, and at least
        :data:`HELD_SAMPLES` samples, its mean ``|dV/dt|`` is under :data:`HELD_TOL` of its RMS
        ``dV/dt`` over the whole record: a biased drive whose envelope grows from zero, a capture
        that starts on a hold); else 0 V (a record that starts at 0 V, or starts moving, is taken
        to begin from rest at 0 V)."""
        stated = self.meta.get("rest_V")
        if stated is not None:
            try:
                r = float(stated)
            except (TypeError, ValueError):
                r = float("nan")
            if np.isfinite(r):
                return r
        v = self.voltage_V
        if v.size < 2 or v[0] == 0.0:
            return 0.0
        k = max(HELD_SAMPLES, round(HELD_S * self.rate_hz))
        dv = np.diff(v)
        rms = float(np.sqrt(np.mean(dv * dv)))
        if v.size <= 2 * k or not rms > 0:
            return float(v[0]) if not rms > 0 else 0.0
        held = float(np.mean(np.abs(dv[:k]))) <= HELD_TOL * rms
        return float(v[0]) if held else 0.0

    def with_strain(self, strain_ue: ArrayLike, name: str | None = None) -> Record:
        """A copy with another strain (e.g. a prediction), same voltage, time, hold and meta."""
        return Record(
            self.name if name is None else name,
            self.rate_hz,
            self.time_s,
            self.voltage_V,
            np.asarray(strain_ue, dtype=np.float64),
            dict(self.aux),
            self.hold,
            dict(self.meta),
        )


def warmup_samples(record: Record, warmup_s: float) -> int:
    """The samples at the start of ``record`` simulated but not scored.

    Parameters
    ----------
    record : Record
        A record (its sample rate ``rate_hz``, Hz).
    warmup_s : float
        The warm-up (s); a negative one is none.

    Returns
    -------
    int
        ``round(max(warmup_s, 0) * rate_hz)``: the record's scored samples are the others.
    """
    return round(max(warmup_s, 0.0) * record.rate_hz)


def unit_of(r: Record, channel: str) -> str:
    """A channel's unit as the record states it (``meta["units"][channel]``, which the run-file
    reader sets), ``""`` when it states none."""
    units = r.meta.get("units") if isinstance(r.meta, dict) else None
    u = units.get(channel) if isinstance(units, dict) else None
    return str(u) if u else ""


def strain_unit(records: Iterable[Record]) -> str:
    """The strain's unit as the records state it (:func:`unit_of`: ``ue``, or what an import
    kept, e.g. ``raw``); ``ue`` when none does."""
    for r in records:
        if u := unit_of(r, "strain"):
            return u
    return "ue"
