"""Records to simulated sequences: the one engine of fit, the baselines and the extended model.

A run's entries are not independent: the model's memory is long (``G_t`` with a small order
decays algebraically, the hysteresis operator keeps its turning points), so after a few seconds
at 0 V the strain still carries the previous entries. :func:`build_sequences` therefore turns
records into the voltage sequences that are actually simulated:

- ``chain=True``: the records back to back in the given order, record ``k`` followed by
  ``record.meta["rest_after_s"]`` seconds at 0 V (absent: 0), the actuator at rest before the
  first. Use it for the entries of one run on one actuator.
- ``chain=False``: each record on its own, from rest (records from unrelated files).

A sequence starts with the actuator held at its first record's rest voltage
(:attr:`~labrig.analysis.records.Record.rest_V`): 0 V for a run and for a record that starts
moving, the held voltage for a record that begins at one (a biased drive, a capture that starts on
a hold): the relaxors settled there, the operator brought there from rest at 0 V
(:meth:`~labrig.model.QuasiStaticHysteresis.held_state`).

Each sequence is scored on :class:`Segment` objects (:func:`score_segments`): the samples of a
scored record after its warm-up. A segment's residual is weighted by
``1 / (span * sqrt(samples))``, ``span`` the measured strain's peak-to-peak over the segment, so
the sum of squared weighted residuals is ``sum_e (NRMSE_e / 100)^2``: every entry weighs the
same, whatever its length, as in the NRMSE of :mod:`labrig.analysis.metrics`.

The relaxors are realised on their modal banks (the ``"fast"`` method of
:class:`~labrig.model.Relaxor`) on the sequence padded to a whole number of
:data:`BLOCK` samples (the filters are causal, so padding changes nothing before the end and each
bank builds its block matrices once): ``G_t`` with the record's hold, ``G_d`` with the linear
hold on ``G_t``'s samples, then the quasi-static operator of the :class:`OperatorFamily`.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from labrig.analysis.records import Record
from labrig.model import ModelParams, QuasiStaticHysteresis, Relaxor
from labrig.model.effects import Context
from labrig.model.modal import run_bank

__all__ = [
    "BLOCK",
    "CONVERGED",
    "DEFAULT_BOUNDS",
    "EXTENDED_CONVERGED",
    "LOG_PARAMS",
    "LOOSE",
    "PARAM_NAMES",
    "LRUCache",
    "OperatorFamily",
    "Scored",
    "Segment",
    "SimSequence",
    "bounded_least_squares",
    "build_sequences",
    "fill_rests",
    "pad_to_block",
    "relaxor_output",
    "relaxor_sensitivities",
    "score_segments",
    "scored_names",
    "scored_sequences",
]

#: the fitted (numeric) fields of ModelParams, in the order of the parameter vector
PARAM_NAMES: tuple[str, ...] = (
    "alpha0_ue_per_V",
    "gamma_ue_per_V",
    "vc_V",
    "lam_t",
    "tau_t_s",
    "lam_d",
    "tau_d_s",
)

#: parameters fitted on a log scale (positive scales spanning decades)
LOG_PARAMS = frozenset({"vc_V", "tau_t_s", "tau_d_s"})

#: default bounds in native units (``lam_t`` below 0.9 and ``lam_d`` away from 2: the modal
#: realisation needs many more modes near ``lam = 1`` and ``G_t`` is the slow, low-order relaxor)
DEFAULT_BOUNDS: dict[str, tuple[float, float]] = {
    "alpha0_ue_per_V": (1e-6, 1e6),
    "gamma_ue_per_V": (0.0, 1e6),
    "vc_V": (1e-3, 1e5),
    "lam_t": (0.02, 0.9),
    "tau_t_s": (1e-15, 1e3),
    "lam_d": (0.3, 1.9),
    "tau_d_s": (1e-7, 10.0),
}

#: relaxor bank block length (cheaper block matrices than the bank's default, same result)
BLOCK = 128

#: least-squares tolerances of a converged base identification (``fit_model``, the baselines)
CONVERGED = {"ftol": 1e-10, "xtol": 1e-10, "gtol": 1e-10}
#: ... of a converged extended-model fit: it runs once per candidate effect, start and fold in a
#: diagnosis, so it stops a decade earlier than the base identification
EXTENDED_CONVERGED = {"ftol": 1e-9, "xtol": 1e-9, "gtol": 1e-9}
#: ... of short runs from several starts, screening and held-out refits
LOOSE = {"ftol": 1e-6, "xtol": 1e-6, "gtol": 1e-6}


@dataclass(frozen=True)
class OperatorFamily:
    """The operator family being fitted: hysteresis shape and memory rule (fixed, not fitted)."""

    shape: str = "exponential"
    memory: str = "return_point"

    def operator(self, alpha0: float, gamma: float, vc: float) -> QuasiStaticHysteresis:
        return QuasiStaticHysteresis(alpha0, gamma, vc, self.shape, self.memory)

    def params(self, values: dict[str, float]) -> ModelParams:
        """:class:`ModelParams` of this family from the numeric parameters :data:`PARAM_NAMES`."""
        return ModelParams(
            shape=self.shape, memory=self.memory, **{n: float(values[n]) for n in PARAM_NAMES}
        )


@dataclass
class Segment:
    """The scored part of one record inside a simulated sequence: the record after its warm-up.

    ``lo`` is its first sample in the sequence, ``i0`` the same in the record (the warm-up
    length); ``weight`` is ``1 / (span * sqrt(samples))``.
    """

    name: str
    lo: int
    i0: int
    measured_ue: NDArray[np.float64]
    weight: float
    time_s: NDArray[np.float64]

    @property
    def hi(self) -> int:
        return self.lo + self.measured_ue.size


def pad_to_block(v: NDArray) -> NDArray[np.float64]:
    """``v`` extended to a whole number of :data:`BLOCK` samples by repeating its last value."""
    out = np.empty(-(-v.size // BLOCK) * BLOCK)
    out[: v.size] = v
    out[v.size :] = v[-1] if v.size else 0.0
    return out


def fill_rests(parts: list[tuple[int, NDArray]], n: int, rest_value: str) -> NDArray[np.float64]:
    """One auxiliary channel over a chained sequence of ``n`` samples from its entries' samples
    (``(start, samples)`` pairs); the rests between entries are filled by linear interpolation
    (``"interp"``, temperatures) or towards 0 (``"zero"``, voltages)."""
    out = np.full(n, np.nan)
    for start, x in parts:
        out[start : start + x.size] = x
    if rest_value == "zero":
        # a voltage: towards 0 V after each entry at the fastest slope seen in that entry (an
        # amplifier at its current limit is still slewing when the rest begins)
        for k, (start, x) in enumerate(parts):
            a = start + x.size
            b = parts[k + 1][0] if k + 1 < len(parts) else n
            if b <= a or x.size < 2:
                continue
            step = max(float(np.max(np.abs(np.diff(x)))), 1e-9)
            ramp = x[-1] - np.sign(x[-1]) * step * np.arange(1, b - a + 1)
            out[a:b] = np.where(np.sign(ramp) == np.sign(x[-1]), ramp, 0.0)
        return np.nan_to_num(out, nan=0.0)
    idx = np.arange(n)
    ok = np.isfinite(out)
    return np.interp(idx, idx[ok], out[ok])


@dataclass
class SimSequence:
    """Records simulated as one voltage sequence: one record, or a run's records back to back
    with their rests at 0 V (:func:`build_sequences`).

    ``entries`` maps each record's name to its samples in the sequence.
    """

    records: tuple[Record, ...]
    rate_hz: float
    hold: str
    voltage_V: NDArray[np.float64]
    entries: dict[str, slice]
    #: the campaign's reference temperature (degC; the first record's first sample), or None
    temperature_ref: float | None = None

    @property
    def n(self) -> int:
        return int(self.voltage_V.size)

    @property
    def rest_V(self) -> float:
        """The voltage the actuator is held at before the sequence: its first record's
        :attr:`~labrig.analysis.records.Record.rest_V` (0 V for a run; the held voltage for a
        record that begins at one)."""
        return self.records[0].rest_V if self.records else 0.0

    @cached_property
    def padded(self) -> NDArray[np.float64]:
        """The voltage padded to whole relaxor blocks (:func:`pad_to_block`)."""
        return pad_to_block(self.voltage_V)

    @cached_property
    def context(self) -> Context:
        """What an effect sees of this sequence: the voltage, the entries, and the amplifier's
        measured voltage and the temperature over the whole sequence when every record has them
        (rests filled by :func:`fill_rests`)."""
        aux = {}
        for name, rest in (("amplifier_voltage", "zero"), ("temperature", "interp")):
            if all(name in r.aux for r in self.records):
                parts = [(self.entries[r.name].start, r.aux[name]) for r in self.records]
                aux[name] = fill_rests(parts, self.n, rest)
        return Context(
            self.rate_hz,
            self.voltage_V,
            dict(self.entries),
            aux.get("amplifier_voltage"),
            aux.get("temperature"),
            self.temperature_ref if "temperature" in aux else None,
            hold=self.hold,
        )


def build_sequences(records: Sequence[Record], chain: bool) -> list[SimSequence]:
    """The sequences to simulate for ``records`` (module docstring): one per record, or with
    ``chain`` one for all of them, in order, each followed by its ``meta["rest_after_s"]``.
    When every record has a temperature channel, every sequence shares the campaign's reference
    temperature (the first record's first sample).

    Raises ``ValueError`` when chained records differ in sample rate or hold."""
    t_ref = None
    if records and all("temperature" in r.aux and r.n for r in records):
        t_ref = float(records[0].aux["temperature"][0])
    if not chain:
        return [
            SimSequence((r,), r.rate_hz, r.hold, r.voltage_V, {r.name: slice(0, r.n)}, t_ref)
            for r in records
        ]
    rates = {r.rate_hz for r in records}
    holds = {r.hold for r in records}
    if len(rates) != 1 or len(holds) != 1:
        raise ValueError("chained records must share one sample rate and one hold")
    rate = rates.pop()
    parts, entries, pos = [], {}, 0
    for r in records:
        entries[r.name] = slice(pos, pos + r.n)
        parts.append(r.voltage_V)
        pos += r.n
        rest = float(r.meta.get("rest_after_s", 0.0) or 0.0)
        n_rest = round(max(rest, 0.0) * rate)
        if n_rest:
            parts.append(np.zeros(n_rest))
            pos += n_rest
    return [SimSequence(tuple(records), rate, holds.pop(), np.concatenate(parts), entries, t_ref)]


def predict_sequences(
    records: Sequence[Record],
    chain: bool,
    simulate: Callable[[SimSequence], NDArray[np.float64]],
    offsets_ue: dict[str, float] | None = None,
) -> dict[str, NDArray[np.float64]]:
    """A fitted model's strain (ue) for each record, by name: ``simulate(sequence)`` over the
    sequences of :func:`build_sequences` (chained as the fit was when ``chain`` and the records
    share one rate and hold), plus each record's fitted offset."""
    chain = chain and len({r.rate_hz for r in records}) == 1 and len({r.hold for r in records}) == 1
    out = {}
    for seq in build_sequences(records, chain):
        y = simulate(seq)
        for name, sl in seq.entries.items():
            out[name] = y[sl] + (offsets_ue or {}).get(name, 0.0)
    return out


def score_segments(seq: SimSequence, scored: Collection[str], warmup_s: float) -> list[Segment]:
    """The :class:`Segment` of each record of ``seq`` named in ``scored``, after ``warmup_s``
    seconds simulated but not scored.

    Raises ``ValueError`` when a record leaves fewer than 2 samples to score, has non-finite
    voltage or strain, or a constant strain (its NRMSE is undefined)."""
    out = []
    for r in seq.records:
        if r.name not in scored:
            continue
        i0 = round(max(warmup_s, 0.0) * r.rate_hz)
        if r.n - i0 < 2:
            raise ValueError(f"entry {r.name!r}: warm-up of {warmup_s} s leaves nothing to score")
        meas = np.asarray(r.strain_ue[i0:], dtype=float)
        if not np.all(np.isfinite(meas)) or not np.all(np.isfinite(r.voltage_V)):
            raise ValueError(f"entry {r.name!r}: voltage or strain has non-finite samples")
        span = float(np.ptp(meas))
        if not span > 0:
            raise ValueError(f"entry {r.name!r}: constant strain, NRMSE undefined")
        lo = seq.entries[r.name].start + i0
        out.append(Segment(r.name, lo, i0, meas, 1.0 / (span * np.sqrt(meas.size)), r.time_s[i0:]))
    return out


@dataclass
class Scored:
    """A simulated sequence and its scored segments."""

    seq: SimSequence
    segments: list[Segment]


def scored_names(records: Sequence[Record], scored: Sequence[str] | None) -> list[str]:
    """The names of the entries to fit and score (all by default), in run order.

    Raises ``ValueError`` for no records, repeated names, or scored names that are not among
    the records."""
    if not records:
        raise ValueError("no records to fit")
    names = [r.name for r in records]
    if len(set(names)) != len(names):
        raise ValueError(f"entry names must be unique, got {names}")
    if scored is None:
        return names
    unknown = [n for n in scored if n not in names]
    if unknown or not scored:
        raise ValueError(f"scored entries {unknown or '[]'} are not among {names}")
    return [n for n in names if n in set(scored)]


def scored_sequences(
    records: Sequence[Record], scored: Sequence[str], warmup_s: float, chain: bool
) -> list[Scored]:
    """The sequences to simulate for fitting ``scored``: the whole run as one chain (the other
    records as history), or each scored record on its own."""
    keep = set(scored)
    if not chain:
        records = [r for r in records if r.name in keep]
    return [Scored(s, score_segments(s, keep, warmup_s)) for s in build_sequences(records, chain)]


def relaxor_output(
    tau_s: float, lam: float, rate_hz: float, hold: str, v_padded: NDArray, rest_V: float = 0.0
) -> NDArray[np.float64]:
    """``G v`` for ``G(s) = 1 / (1 + (tau s)^lam)`` on a padded sequence, by the relaxor's modal
    bank (the ``"fast"`` method), the relaxor at rest at ``rest_V`` before it (``G(0) = 1``:
    ``rest_V + G (v - rest_V)``). Extreme time constants make the bank's tail-moment quadrature
    overflow harmlessly to a zero integrand; that warning is hushed."""
    with np.errstate(over="ignore"):
        bank = Relaxor(tau_s, lam).bank(rate_hz, hold)
    if rest_V == 0.0:
        return run_bank(bank, v_padded, block=BLOCK)[0]
    return rest_V + run_bank(bank, v_padded - rest_V, block=BLOCK)[0]


def relaxor_sensitivities(
    tau_s: float, lam: float, rate_hz: float, hold: str, v_padded: NDArray, rest_V: float = 0.0
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`relaxor_output` and its derivatives with respect to ``log tau`` and ``lam``: the
    bank's modes do not move with ``tau`` and ``lam`` (only their output weights do), so the
    derivatives are further outputs of the same pass
    (:meth:`labrig.model.Relaxor.filter_sensitivities`)."""
    with np.errstate(over="ignore"):
        return Relaxor(tau_s, lam).filter_sensitivities(v_padded, rate_hz, hold, rest_V)


@dataclass
class LRUCache:
    """At most ``size`` values, the least recently used dropped first."""

    size: int
    _items: OrderedDict = field(default_factory=OrderedDict, repr=False)

    def get(self, key: Any, make: Callable[[], Any]) -> Any:
        """The value for ``key``, made by ``make()`` if absent."""
        if key in self._items:
            self._items.move_to_end(key)
            return self._items[key]
        value = self._items[key] = make()
        while len(self._items) > self.size:
            self._items.popitem(last=False)
        return value


def bounded_least_squares(
    residual: Callable[[NDArray], NDArray],
    jacobian: Callable[[NDArray], NDArray],
    z0: NDArray,
    bounds: tuple[NDArray, NDArray],
    max_nfev: int | None,
    tolerances: dict[str, float],
) -> Any:
    """``scipy.optimize.least_squares`` as every fit here calls it: trust-region reflective
    within ``bounds``, scaled by the Jacobian's columns."""
    return optimize.least_squares(
        residual,
        z0,
        jac=jacobian,
        bounds=bounds,
        method="trf",
        x_scale="jac",
        max_nfev=max_nfev,
        **tolerances,
    )
