"""Identification of :class:`~labrig.model.ModelParams` from records (``labrig fit`` numerics).

Objective
---------
Free-run simulation error of ``DynamicHysteresisModel(params).predict(v, rate, method="fast",
hold=record.hold)`` against the measured strain. Each entry's residual is divided by its measured
strain span and by the square root of its number of scored samples, so the cost is
``sum_e (NRMSE_e / 100)^2``: every entry weighs the same, whatever its length, as in the NRMSE
definition of :mod:`labrig.analysis.metrics`.

Warm-up, runs and offsets
-------------------------
Every record is simulated from its first sample with the model at rest at 0 V (the model's
convention). A record that does not start at rest (a measurement cut out of a longer run, a drive
that starts at a non-zero voltage) can be given ``warmup_s``: its first ``warmup_s`` seconds are
still simulated, so the model's memory builds up, but they are left out of the residual, of the
NRMSE and of the strain span used for normalisation.

The model's memory is long (``G_t`` with a small order decays algebraically, and the hysteresis
operator keeps its turning points), so the entries of one run are *not* independent: after a few
seconds at 0 V the strain still carries tens of ue of the previous entries (on the seed's campaign
with 3 s rests: up to 30 times the 2 ue noise floor, and a 2 s warm-up removes almost none of
it). ``chain=True`` therefore simulates the records as the run they came from: back to back in
the given order, record ``k`` followed by ``record.meta["rest_after_s"]`` seconds at 0 V (absent:
0), the actuator at rest before the first; each entry is scored on its own samples. With
``scored`` a subset is fitted while the others remain history (leave-one-out works the same way).
Records from unrelated files (imports) are independent: leave ``chain`` off.

``offset=True`` fits one constant strain offset per entry (eliminated in closed form: each
entry's residual is taken about its mean), for sensors with an arbitrary zero.

Global fit (default)
--------------------
``scipy.optimize.least_squares`` (trust-region reflective, bounded) in transformed coordinates:
``alpha0, gamma`` as they are, ``log vc``, ``lam_t``, ``log tau_t``, ``lam_d``, ``log tau_d``
(``vc`` is fixed for the ``linear`` shape, which does not use it). The Jacobian is structured
instead of generic finite differences: ``S = alpha0 V* + gamma G_vc(V*)`` exactly (the operator
is linear in ``alpha0`` and ``gamma`` for a fixed input, and its reversals depend on the input
only), so those two columns are exact, ``vc`` needs the operator alone, and the four relaxor
parameters need one new relaxor bank each; ``G_t``'s output is cached for the ``G_d`` columns.
Starts: the staged procedure below (cheap: each stage fits a few parameters on a few entries)
and, if given, ``initial``; each start gets a short run, the best is then converged tightly
(``ftol = xtol = 1e-10``) with a final central-difference Jacobian for the uncertainties.

Staged fit (seed section 3.1)
-----------------------------
1. *Static*: ``alpha0, gamma, vc`` from the steady state of the lowest-frequency periodic entries
   (all their amplitudes): the quasi-static operator driven by the measured voltage is fitted to
   the last full period of each (plus one offset per entry, the strain shift not modelled at this
   stage). This fits the branch closed form to the loop, the integral of the seed's fit of
   ``alpha = dS/dV``, so no numerical differentiation is needed. These are *apparent* values:
   the transient relaxor scales the voltage by ``|G_t|`` (about 0.74 at 1 Hz).
2. *Transient*: ``lam_t, tau_t`` with the refined static part (``alpha0, gamma, vc`` free again)
   from the whole lowest-frequency records, whose strain shift drifts over the cycles, with
   ``G_d`` left out (``|G_d| - 1 < 1e-3`` there); a few starts of ``lam_t``.
3. *Harmonic*: ``lam_d, tau_d`` from the periodic entries above the lowest frequency (the seed's
   5-40 Hz), everything else fixed; a few starts. Without such entries ``G_d`` is set to a
   negligible ``lam_d = 1.2, tau_d = 1e-5 s`` and the result says so in ``messages``; when
   every entry is periodic at one frequency the global fit keeps that ``G_d`` fixed too (it is
   not identifiable there, and left free it wandered towards ``lam_d = 1``, where relaxor banks
   are slowest: 160 s instead of 2 s on the real 1 Hz micromanipulator data, same NRMSE).

Stage 1 looks at each record on its own, from rest. With ``chain`` stages 2 and 3 simulate the
run up to their last record, the other records as history (a later entry does not start at
rest: stage 2 from rest ended at ``tau_t`` = 1e3 s on the simulated paper campaign), stage 2
with each entry's residual taken about its mean (``G_d``, left out there, shapes the history's
reversals and leaves a constant error of about 16 ue in later entries). The starts of
stages 2 and 3 are screened by their cost, the best one converged loosely (``1e-6``): it is a
sequential, approximate procedure (on our synthetic campaigns its NRMSE is about 1.3 times the
global fit's, its static parameters a few percent off), kept because it is the seed's and because
it is a good, cheap start for the global fit. If no entry is periodic (no frequency to work with)
the global fit starts from a static fit of all records and two guesses of the relaxors instead.

Uncertainty
-----------
One standard deviation from the Jacobian at the optimum, in the native parameters. Entries are
weighted differently (span, length), so the weighted residual's variance differs between them:
the covariance is the per-entry sandwich ``A^-1 (sum_e s_e^2 J_e^T J_e) A^-1``, ``A = J^T J``,
``s_e^2`` entry ``e``'s residual variance (with a single pooled ``s^2`` it would reduce to
``s^2 A^-1``, which underestimated the spread over noise realisations up to twofold in our
checks; the sandwich matched it within about 25 %). Residuals of a free-run model are correlated
in time when the model is not exact, so on real data these are lower bounds; the correlations
are the informative part.

Held-out NRMSE
--------------
Leave-one-entry-out: the same method refitted without each entry (warm-started from the full fit)
and scored on it; the mean over entries. With ``offset=True`` the held-out entry's offset is fitted
on the first half of its scored samples and the error taken on the second half, in percent of
the whole entry's span (:func:`~labrig.analysis.metrics.second_half_nrmse_pct`).

Performance
-----------
OpenBLAS threads are limited to one while fitting: the model's block products are small, and on
a shared 2-core machine threaded BLAS made them ten times slower. Records are padded to a whole
number of blocks (the filters are causal, so padding changes nothing before the end) so each
relaxor bank builds its block matrices once. The seed's 11-entry campaign at 1 kHz as one run
(57.5 s recorded, 90.5 s simulated with the rests) fits in 5-9 s on a loaded 2-core machine, the
leave-one-out adds as much; the time goes to the relaxor filtering (~40 %), building relaxor banks
for new parameters (~40 %, mostly the quadrature of the modal tails) and the hysteresis operator
(~13 %).
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from labrig.analysis.metrics import (
    drive_frequency_hz,
    is_periodic,
    last_period,
    nrmse_pct,
    second_half_nrmse_pct,
)
from labrig.analysis.records import Record
from labrig.blas import single_thread_blas
from labrig.model import DynamicHysteresisModel, ModelParams, QuasiStaticHysteresis, Relaxor
from labrig.model.modal import run_bank

__all__ = [
    "DEFAULT_BOUNDS",
    "PARAM_NAMES",
    "FitResult",
    "fit_model",
    "predict_record",
    "single_thread_blas",
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
_LOG = frozenset({"vc_V", "tau_t_s", "tau_d_s"})

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

_BLOCK = 128  # run_bank block length (cheaper block matrices than the default, same result)
_FD_FORWARD = 1e-6  # forward-difference step in transformed coordinates (iterations)
_FD_CENTRAL = 1e-4  # central-difference step (final Jacobian)
_FD_VC = 1e-5  # central step in log vc (operator only)
_TIGHT = {"ftol": 1e-10, "xtol": 1e-10, "gtol": 1e-10}

Progress = Callable[[str, int, int], Any]


# -- the campaign: cached simulation and structured Jacobian -----------------------------------


@dataclass
class _Seg:
    """A scored stretch of a simulated sequence: one record after its warm-up."""

    name: str
    lo: int  # first scored sample in the sequence
    i0: int  # the same in the record (its warm-up length)
    meas: NDArray[np.float64]  # measured strain there
    w: float  # 1 / (span * sqrt(samples))

    @property
    def hi(self) -> int:
        return self.lo + self.meas.size


@dataclass
class _Entry:
    """One simulated voltage sequence (a record, or a chain of records) and its scored parts."""

    rate_hz: float
    hold: str
    n: int
    v: NDArray[np.float64]  # padded to a whole number of blocks
    segs: list[_Seg]
    starts: dict[str, int]  # start sample of each record in the sequence


def _seg(r: Record, offset: int, warmup_s: float) -> _Seg:
    i0 = round(max(warmup_s, 0.0) * r.rate_hz)
    if r.n - i0 < 2:
        raise ValueError(f"entry {r.name!r}: warm-up of {warmup_s} s leaves nothing to score")
    meas = np.asarray(r.strain_ue[i0:], dtype=float)
    if not np.all(np.isfinite(meas)) or not np.all(np.isfinite(r.voltage_V)):
        raise ValueError(f"entry {r.name!r}: voltage or strain has non-finite samples")
    span = float(np.ptp(meas))
    if not span > 0:
        raise ValueError(f"entry {r.name!r}: constant strain, NRMSE undefined")
    return _Seg(r.name, offset + i0, i0, meas, 1.0 / (span * np.sqrt(meas.size)))


def _padded(v: NDArray) -> NDArray:
    out = np.empty(-(-v.size // _BLOCK) * _BLOCK)
    out[: v.size] = v
    out[v.size :] = v[-1] if v.size else 0.0
    return out


def _make_entry(r: Record, warmup_s: float) -> _Entry:
    """A record simulated on its own, from rest."""
    seg = _seg(r, 0, warmup_s)
    return _Entry(r.rate_hz, r.hold, r.n, _padded(r.voltage_V), [seg], {r.name: 0})


def _chain_entry(records: Sequence[Record], scored: set[str], warmup_s: float) -> _Entry:
    """The records back to back, as one run: record ``k`` is followed by
    ``meta["rest_after_s"]`` seconds at 0 V; only the ``scored`` records are scored."""
    rates = {r.rate_hz for r in records}
    holds = {r.hold for r in records}
    if len(rates) != 1 or len(holds) != 1:
        raise ValueError("chained records must share one sample rate and one hold")
    rate = rates.pop()
    parts, segs, starts, pos = [], [], {}, 0
    for r in records:
        starts[r.name] = pos
        if r.name in scored:
            segs.append(_seg(r, pos, warmup_s))
        parts.append(r.voltage_V)
        pos += r.n
        rest = float(r.meta.get("rest_after_s", 0.0) or 0.0)
        n_rest = round(max(rest, 0.0) * rate)
        if n_rest:
            parts.append(np.zeros(n_rest))
            pos += n_rest
    v = np.concatenate(parts)
    return _Entry(rate, holds.pop(), v.size, _padded(v), segs, starts)


def _entries(
    records: Sequence[Record], scored: Sequence[str], warmup_s: float, chain: bool
) -> list[_Entry]:
    if chain:
        return [_chain_entry(records, set(scored), warmup_s)]
    keep = set(scored)
    return [_make_entry(r, warmup_s) for r in records if r.name in keep]


def _banks(g: Relaxor, entries: Sequence[_Entry], holds) -> None:
    """Build (and cache) the relaxor's banks for these entries. Extreme time constants make
    the bank's tail-moment quadrature overflow harmlessly to a zero integrand; hush that."""
    with np.errstate(over="ignore"):
        for e, hold in zip(entries, holds, strict=True):
            g.bank(e.rate_hz, hold)


class _LRU(OrderedDict):
    def __init__(self, size: int):
        super().__init__()
        self.size = size

    def put(self, key, value):
        self[key] = value
        self.move_to_end(key)
        while len(self) > self.size:
            self.popitem(last=False)
        return value


class _Campaign:
    """Simulation of a set of entries with caches for the relaxor outputs.

    ``with_gd=False`` leaves ``G_d`` out (stage 2 of the staged fit).
    """

    def __init__(
        self,
        entries: Sequence[_Entry],
        family: _Family,
        offset: bool = False,
        with_gd: bool = True,
    ):
        self.entries = list(entries)
        self.family = family
        self.offset = offset
        self.with_gd = with_gd
        self._vt: _LRU = _LRU(6)
        self._vd: _LRU = _LRU(8)
        self.segs = [g for e in self.entries for g in e.segs]
        self.n_scored = sum(g.meas.size for g in self.segs)
        self.nfev = 0

    # relaxor outputs, padded length
    def vt(self, lam_t: float, tau_t: float) -> list[NDArray]:
        key = (lam_t, tau_t)
        hit = self._vt.get(key)
        if hit is None:
            g = Relaxor(tau_t, lam_t)
            _banks(g, self.entries, (e.hold for e in self.entries))
            hit = self._vt.put(
                key,
                [run_bank(g.bank(e.rate_hz, e.hold), e.v, block=_BLOCK)[0] for e in self.entries],
            )
        return hit

    def vd(self, th: dict[str, float]) -> list[NDArray]:
        vt = self.vt(th["lam_t"], th["tau_t_s"])
        if not self.with_gd:
            return vt
        key = (th["lam_t"], th["tau_t_s"], th["lam_d"], th["tau_d_s"])
        hit = self._vd.get(key)
        if hit is None:
            g = Relaxor(th["tau_d_s"], th["lam_d"])
            _banks(g, self.entries, ("linear" for _ in self.entries))
            hit = self._vd.put(
                key,
                [
                    run_bank(g.bank(e.rate_hz, "linear"), x, block=_BLOCK)[0]
                    for e, x in zip(self.entries, vt, strict=True)
                ],
            )
        return hit

    def _op(self, th: dict[str, float]) -> QuasiStaticHysteresis:
        return self.family.operator(th["alpha0_ue_per_V"], th["gamma_ue_per_V"], th["vc_V"])

    def strains(self, th: dict[str, float]) -> list[NDArray]:
        """Predicted strain of each simulated sequence (full length)."""
        op = self._op(th)
        return [op.apply(x[: e.n]) for e, x in zip(self.entries, self.vd(th), strict=True)]

    def _weighted(self, per_entry: Sequence[NDArray], subtract: bool = False) -> NDArray:
        """Stack the scored parts of per-sequence arrays, weighted (and offset-free if asked).

        ``subtract``: the arrays are predictions, subtract the measurements (residuals)."""
        out = []
        for e, x in zip(self.entries, per_entry, strict=True):
            for g in e.segs:
                d = x[g.lo : g.hi] - g.meas if subtract else x[g.lo : g.hi]
                if self.offset:
                    d = d - d.mean()
                out.append(g.w * d)
        return np.concatenate(out)

    def residuals(self, th: dict[str, float]) -> NDArray:
        self.nfev += 1
        return self._weighted(self.strains(th), subtract=True)

    def predictions(self, th: dict[str, float]) -> dict[str, NDArray]:
        """Prediction over each scored record's whole length (warm-up included)."""
        out = {}
        for e, s in zip(self.entries, self.strains(th), strict=True):
            for g in e.segs:
                a = e.starts[g.name]
                out[g.name] = s[a : g.hi].copy()
        return out

    def _hyst_part(self, vd: NDArray, vc: float) -> NDArray:
        """``G_vc(V*)``: the operator's output per unit gamma (alpha0 part removed)."""
        return self.family.operator(1.0, 1.0, vc).apply(vd) - vd

    def jacobian(self, space: _Space, z: NDArray, central: bool = False) -> NDArray:
        """d(weighted residual)/dz, structured (module docstring)."""
        th = space.full(z)
        cols: list[list[NDArray]] = [[] for _ in space.free]
        vd = [x[: e.n] for e, x in zip(self.entries, self.vd(th), strict=True)]
        base = None

        def strains_at(zp: NDArray) -> list[NDArray]:
            return self.strains(space.full(zp))

        for j, name in enumerate(space.free):
            if name == "alpha0_ue_per_V":
                cols[j] = vd
            elif name == "gamma_ue_per_V":
                cols[j] = [self._hyst_part(x, th["vc_V"]) for x in vd]
            elif name == "vc_V":
                g, vc, h = th["gamma_ue_per_V"], th["vc_V"], _FD_VC
                cols[j] = [
                    g
                    * (self._hyst_part(x, vc * np.exp(h)) - self._hyst_part(x, vc * np.exp(-h)))
                    / (2 * h)
                    for x in vd
                ]
            else:
                h = _FD_CENTRAL if central else _FD_FORWARD
                zp = z.copy()
                lo, hi = space.lo[j], space.hi[j]
                if central:
                    zp[j] = z[j] + h
                    zm = z.copy()
                    zm[j] = z[j] - h
                    sp, sm = strains_at(zp), strains_at(zm)
                    cols[j] = [(a - b) / (2 * h) for a, b in zip(sp, sm, strict=True)]
                else:
                    step = h if z[j] + h <= hi or z[j] - h < lo else -h
                    zp[j] = z[j] + step
                    if base is None:
                        base = self.strains(th)
                    sp = strains_at(zp)
                    cols[j] = [(a - b) / step for a, b in zip(sp, base, strict=True)]
        J = np.empty((self.n_scored, len(space.free)))
        for j in range(len(space.free)):  # all columns are d/dz (vc: d/dlog vc)
            J[:, j] = self._weighted(cols[j])
        return J


class _Space:
    """Free parameters, their transform (log for vc, tau) and bounds; the rest fixed."""

    def __init__(
        self,
        free: Sequence[str],
        values: dict[str, float],
        bounds: dict[str, tuple[float, float]],
    ):
        self.free = tuple(free)
        self.values = dict(values)
        lo, hi = [], []
        for name in self.free:
            a, b = bounds[name]
            if name in _LOG:
                a, b = np.log(a), np.log(b)
            lo.append(a)
            hi.append(b)
        self.lo, self.hi = np.array(lo), np.array(hi)

    def z(self, values: dict[str, float]) -> NDArray:
        out = np.array(
            [np.log(values[n]) if n in _LOG else float(values[n]) for n in self.free], dtype=float
        )
        # strictly inside the bounds (least_squares needs a feasible start)
        return np.clip(out, self.lo + self._pad(self.lo), self.hi - self._pad(self.hi))

    @staticmethod
    def _pad(bound: NDArray) -> NDArray:
        return 1e-10 * np.maximum(1.0, np.abs(bound))

    def at_bound(self, z: NDArray) -> NDArray:
        """Which coordinates sit on their bound (to 1e-6, relative to the bound)."""
        lo, hi = 1e-6 * np.maximum(1.0, np.abs(self.lo)), 1e-6 * np.maximum(1.0, np.abs(self.hi))
        return (z - self.lo <= lo) | (self.hi - z <= hi)

    def full(self, z: NDArray) -> dict[str, float]:
        th = dict(self.values)
        for n, x in zip(self.free, z, strict=True):
            th[n] = float(np.exp(x)) if n in _LOG else float(x)
        return th


def _solve(
    camp: _Campaign,
    space: _Space,
    z0: NDArray,
    max_nfev: int | None,
    tight: bool = True,
) -> optimize.OptimizeResult:
    tol = _TIGHT if tight else {"ftol": 1e-6, "xtol": 1e-6, "gtol": 1e-6}
    return optimize.least_squares(
        lambda z: camp.residuals(space.full(z)),
        z0,
        jac=lambda z: camp.jacobian(space, z),
        bounds=(space.lo, space.hi),
        method="trf",
        x_scale="jac",
        max_nfev=max_nfev,
        **tol,
    )


def _best_of(
    camp: _Campaign,
    space: _Space,
    starts: Sequence[dict[str, float]],
    short_nfev: int,
    polish_nfev: int | None,
    tight: bool = True,
) -> tuple[dict[str, float], optimize.OptimizeResult]:
    """Short runs from each start (``short_nfev > 0``) or, with ``short_nfev = 0``, just the
    cost at each start; then the best one converged."""
    if len(starts) == 1:
        res = _solve(camp, space, space.z(starts[0]), polish_nfev, tight)
        return space.full(res.x), res
    if short_nfev == 0:
        costs = []
        for s in starts:
            r = camp.residuals(space.full(space.z(s)))
            costs.append(float(r @ r) if np.all(np.isfinite(r)) else np.inf)
        z0 = space.z(starts[int(np.argmin(costs))])
        res = _solve(camp, space, z0, polish_nfev, tight)
        return space.full(res.x), res
    trials = []
    for s in starts:
        try:
            res = _solve(camp, space, space.z(s), short_nfev, tight=False)
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            continue
        trials.append(res)
    if not trials:
        raise RuntimeError("every start of the fit failed")
    best = min(trials, key=lambda r: r.cost)
    res = _solve(camp, space, best.x, polish_nfev, tight)
    return space.full(res.x), res


# -- results -----------------------------------------------------------------------------------


@dataclass
class FitResult:
    """The identified parameters and how well they explain the data (see the module doc).

    :meth:`to_json` gives exactly the keys of ``labrig fit --json``; the other attributes are
    diagnostics for reports and the diagnosis step.
    """

    params: ModelParams
    uncertainty: dict[str, float | None]
    correlation: dict[str, dict[str, float]]
    nrmse_pct: float
    per_entry: dict[str, float]
    heldout_nrmse_pct: float | None
    method: str
    entries: list[str]
    heldout_per_entry: dict[str, float] | None = None
    offsets_ue: dict[str, float] | None = None
    warmup_s: float = 0.0
    chain: bool = False
    cost: float = float("nan")  # 0.5 * sum of squared weighted residuals
    optimality: float = float("nan")  # gradient norm at the end (first-order optimality)
    nfev: int = 0  # model evaluations (all stages and starts, heldout excluded)
    elapsed_s: float = 0.0
    heldout_elapsed_s: float = 0.0
    messages: list[str] = field(default_factory=list)
    #: the fitted model's strain for each scored entry (its whole record, offset included;
    #: with ``chain`` the run's history included) - what reports should plot
    predictions: dict[str, NDArray[np.float64]] = field(default_factory=dict, repr=False)
    jacobian: NDArray[np.float64] | None = field(default=None, repr=False)
    free: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {
            "params": self.params.model_dump(),
            "uncertainty": dict(self.uncertainty),
            "correlation": {k: dict(v) for k, v in self.correlation.items()},
            "nrmse_pct": float(self.nrmse_pct),
            "per_entry": {k: float(v) for k, v in self.per_entry.items()},
            "heldout_nrmse_pct": (
                None if self.heldout_nrmse_pct is None else float(self.heldout_nrmse_pct)
            ),
            "method": self.method,
            "entries": list(self.entries),
        }

    def predict(self, record: Record) -> NDArray[np.float64]:
        """The fitted model's strain for ``record`` simulated on its own from rest (plus its
        fitted offset, if any). For the fitted entries of a chained fit use ``predictions``."""
        s = predict_record(self.params, record)
        if self.offsets_ue and record.name in self.offsets_ue:
            s = s + self.offsets_ue[record.name]
        return s


def predict_record(params: ModelParams, record: Record) -> NDArray[np.float64]:
    """``DynamicHysteresisModel(params).predict`` for a record (fast method, record's hold)."""
    with single_thread_blas(), np.errstate(over="ignore"):
        return DynamicHysteresisModel(params).predict(
            record.voltage_V, record.rate_hz, method="fast", hold=record.hold
        )


# -- staged procedure (seed 3.1) ---------------------------------------------------------------


@dataclass
class _Info:
    index: int
    f_hz: float | None
    periodic: bool


def _classify(records: Sequence[Record]) -> list[_Info]:
    out = []
    for i, r in enumerate(records):
        f = drive_frequency_hz(r)
        out.append(_Info(i, f, is_periodic(r.voltage_V, r.rate_hz, f)))
    return out


def _fit_static(
    records: Sequence[Record],
    entries: Sequence[_Entry],
    family: _Family,
    windows: Sequence[slice],
    bounds: dict[str, tuple[float, float]],
) -> dict[str, float]:
    """``alpha0, gamma, vc`` (+ one offset per entry) of the operator driven by the voltage,
    fitted on the given windows (stage 1). Linear in all but ``vc``: scan, then refine."""
    vmax = max(float(np.max(np.abs(r.voltage_V))) for r in records)
    vmax = vmax if vmax > 0 else 1.0
    k = len(records)

    def solve(log_vc: float) -> tuple[float, NDArray]:
        vc = float(np.exp(log_vc))
        rows, rhs = [], []
        for i, (r, e, w) in enumerate(zip(records, entries, windows, strict=True)):
            v = r.voltage_V
            g = family.operator(1.0, 1.0, vc).apply(v) - v
            a = np.zeros((w.stop - w.start, 2 + k))
            a[:, 0], a[:, 1], a[:, 2 + i] = v[w], g[w], 1.0
            rows.append(a * e.segs[0].w)
            rhs.append(r.strain_ue[w] * e.segs[0].w)
        A, b = np.vstack(rows), np.concatenate(rhs)
        lo = np.full(2 + k, -np.inf)
        lo[0], lo[1] = bounds["alpha0_ue_per_V"][0], bounds["gamma_ue_per_V"][0]
        sol = optimize.lsq_linear(A, b, bounds=(lo, np.inf), method="bvls")
        return float(np.sum((A @ sol.x - b) ** 2)), sol.x

    if family.shape == "linear":
        x = solve(np.log(vmax))[1]
        return {"alpha0_ue_per_V": x[0], "gamma_ue_per_V": x[1], "vc_V": vmax}
    grid = np.log(vmax) + np.linspace(np.log(0.05), np.log(20.0), 25)
    costs = [solve(g)[0] for g in grid]
    i = int(np.argmin(costs))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    best = optimize.minimize_scalar(
        lambda x: solve(x)[0], bounds=(a, b), method="bounded", options={"xatol": 1e-4}
    )
    x = solve(best.x)[1]
    return {
        "alpha0_ue_per_V": float(x[0]),
        "gamma_ue_per_V": float(x[1]),
        "vc_V": float(np.exp(best.x)),
    }


def _relaxor_gain(tau: float, lam: float, f_hz: float) -> float:
    return float(abs(Relaxor(tau, lam).frequency_response(f_hz)))


def _stage_entries(
    records: Sequence[Record],
    entries: Sequence[_Entry],
    chosen: Sequence[int],
    run: Sequence[Record] | None,
    warmup_s: float,
) -> list[_Entry]:
    """The simulated sequences of a stage: the chosen records on their own, or (``run``) the
    run up to the last chosen record with only the chosen ones scored."""
    if run is None:
        return [entries[i] for i in chosen]
    names = {records[i].name for i in chosen}
    last = max(k for k, r in enumerate(run) if r.name in names)
    return [_chain_entry(run[: last + 1], names, warmup_s)]


def _staged(
    records: Sequence[Record],
    entries: Sequence[_Entry],
    family: _Family,
    offset: bool,
    bounds: dict[str, tuple[float, float]],
    messages: list[str],
    run: Sequence[Record] | None = None,
    warmup_s: float = 0.0,
) -> tuple[dict[str, float], int]:
    """The seed's three stages (module docstring); returns the parameters and evaluations.

    ``run``: the whole run (``chain``): stages 2 and 3 then simulate it up to their last record,
    the other records as history (a later entry of a run does not start at rest)."""
    info = _classify(records)
    periodic = [i for i in info if i.periodic and i.f_hz is not None]
    if not periodic:
        raise ValueError(
            "staged identification needs periodic entries (sines at known or detectable "
            "frequencies); use method='global'"
        )
    f_low = min(i.f_hz for i in periodic)
    low = [i.index for i in periodic if i.f_hz <= 1.1 * f_low]
    high = [i.index for i in periodic if i.f_hz > 1.1 * f_low]
    free_static = ["alpha0_ue_per_V", "gamma_ue_per_V"]
    free_static += [] if family.shape == "linear" else ["vc_V"]

    # 1. static part from the steady state (last full period) of the lowest-frequency entries
    wins = []
    for i in low:
        r = records[i]
        sl = last_period(r.n, r.rate_hz, info[i].f_hz)
        assert sl is not None
        wins.append(slice(max(sl.start, entries[i].segs[0].i0), sl.stop))
    static = _fit_static([records[i] for i in low], [entries[i] for i in low], family, wins, bounds)

    # 2. transient: lam_t, tau_t and the refined static part from the whole low records
    w_low = 2 * np.pi * f_low
    # in a run, G_d (left out here) shapes the history's reversals: the operator then carries a
    # constant strain error into later entries (16 ue on the seed's campaign), so take each
    # entry's residual about its mean in this stage
    off2 = offset or run is not None
    camp2 = _Campaign(_stage_entries(records, entries, low, run, warmup_s), family, off2, False)
    starts = []
    for lam in (0.1, 0.25, 0.5):
        tau = float(np.clip(0.35 ** (1 / lam) / w_low, *bounds["tau_t_s"]))
        g0 = _relaxor_gain(tau, lam, f_low)
        s = {
            "alpha0_ue_per_V": static["alpha0_ue_per_V"] / g0,
            "gamma_ue_per_V": static["gamma_ue_per_V"] / g0,
            "vc_V": static["vc_V"] * g0,
            "lam_t": lam,
            "tau_t_s": tau,
            "lam_d": 1.0,
            "tau_d_s": 1.0,
        }
        starts.append(s)
    space2 = _Space([*free_static, "lam_t", "tau_t_s"], starts[0], bounds)
    th2, _ = _best_of(camp2, space2, starts, short_nfev=0, polish_nfev=40, tight=False)

    # 3. harmonic: lam_d, tau_d from the higher-frequency entries
    nfev = camp2.nfev
    if not high:
        messages.append(
            "staged: no periodic entry above the lowest frequency; G_d not identified "
            "(lam_d = 1.2, tau_d = 1e-5 s, negligible)"
        )
        th = dict(th2, lam_d=1.2, tau_d_s=1e-5)
        return th, nfev
    f_high = max(info[i].f_hz for i in high)
    w_high = 2 * np.pi * f_high
    camp3 = _Campaign(_stage_entries(records, entries, high, run, warmup_s), family, offset)
    starts = []
    for lam in (0.7, 1.0, 1.35):
        for ratio in (0.1, 0.3, 0.6):
            tau = float(np.clip(ratio ** (1 / lam) / w_high, *bounds["tau_d_s"]))
            starts.append(dict(th2, lam_d=lam, tau_d_s=tau))
    space3 = _Space(["lam_d", "tau_d_s"], starts[0], bounds)
    th, _ = _best_of(camp3, space3, starts, short_nfev=0, polish_nfev=40, tight=False)
    return th, nfev + camp3.nfev


def _generic_start(
    records: Sequence[Record], entries: Sequence[_Entry], family: _Family, bounds
) -> list[dict[str, float]]:
    """Starts when the staged procedure cannot run (no periodic entries)."""
    wins = [slice(e.segs[0].i0, e.n) for e in entries]
    static = _fit_static(records, entries, family, wins, bounds)
    fs = [f for f in (drive_frequency_hz(r) for r in records) if f is not None]
    f_lo = min(fs) if fs else 1.0
    f_hi = max(fs) if fs else 1.0
    out = []
    for lam_d in (0.8, 1.35):
        lam_t = 0.2
        tau_t = 0.35 ** (1 / lam_t) / (2 * np.pi * f_lo)
        g0 = _relaxor_gain(tau_t, lam_t, f_lo)
        out.append(
            {
                "alpha0_ue_per_V": static["alpha0_ue_per_V"] / g0,
                "gamma_ue_per_V": static["gamma_ue_per_V"] / g0,
                "vc_V": static["vc_V"] * g0,
                "lam_t": lam_t,
                "tau_t_s": tau_t,
                "lam_d": lam_d,
                "tau_d_s": 0.3 ** (1 / lam_d) / (2 * np.pi * f_hi),
            }
        )
    return out


# -- public entry point ------------------------------------------------------------------------


@dataclass(frozen=True)
class _Family:
    """The operator family being fitted: hysteresis shape and memory rule (fixed, not fitted)."""

    shape: str = "exponential"
    memory: str = "return_point"

    def operator(self, alpha0: float, gamma: float, vc: float) -> QuasiStaticHysteresis:
        return QuasiStaticHysteresis(alpha0, gamma, vc, self.shape, self.memory)

    def params(self, th: dict[str, float]) -> ModelParams:
        return ModelParams(
            shape=self.shape, memory=self.memory, **{n: float(th[n]) for n in PARAM_NAMES}
        )


def _uncertainty(
    J: NDArray,
    r: NDArray,
    sizes: Sequence[int],
    space: _Space,
    th: dict[str, float],
    nuisance_per_entry: int,
) -> tuple[dict[str, float | None], dict[str, dict[str, float]]]:
    """1-sigma and correlations in native units from the z-space Jacobian (module doc).

    The weighted residual's variance differs between entries (each is scaled by its span and
    length), so the covariance is the per-entry sandwich ``A^-1 (sum_e s_e^2 J_e^T J_e) A^-1``,
    ``A = J^T J``, with ``s_e^2`` the mean squared weighted residual of entry ``e`` corrected
    for the degrees of freedom the fit used (its share of the parameters, and its nuisance
    offset if any).
    """
    chain = np.array([th[n] if n in _LOG else 1.0 for n in space.free])
    Jn = J / chain[None, :]
    p, n_tot = len(space.free), r.size
    # pseudo-inverse of A through the SVD of a column-scaled Jacobian (well conditioned)
    scale = np.linalg.norm(Jn, axis=0)
    scale[scale == 0] = 1.0
    _, sv, vt = np.linalg.svd(Jn / scale, full_matrices=False)
    keep = sv > sv[0] * 1e-12
    inv = ((vt[keep].T / sv[keep] ** 2) @ vt[keep]) / np.outer(scale, scale)
    B = np.zeros((p, p))
    pos = 0
    for m in sizes:
        re, Je = r[pos : pos + m], Jn[pos : pos + m]
        dof = max(m - p * m / n_tot - nuisance_per_entry, 1.0)
        B += (float(re @ re) / dof) * (Je.T @ Je)
        pos += m
    cov = inv @ B @ inv
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    unc: dict[str, float | None] = dict.fromkeys(PARAM_NAMES)
    corr: dict[str, dict[str, float]] = {}
    for i, a in enumerate(space.free):
        unc[a] = float(sd[i])
        corr[a] = {
            b: float(cov[i, j] / (sd[i] * sd[j])) if sd[i] > 0 and sd[j] > 0 else 0.0
            for j, b in enumerate(space.free)
        }
    return unc, corr


def _one_frequency(records: Sequence[Record]) -> float | None:
    """The common drive frequency (Hz) when every record is periodic at (within 10 %) the same
    frequency, else ``None``."""
    info = _classify(records)
    fs = [i.f_hz for i in info if i.periodic and i.f_hz is not None]
    if not info or len(fs) != len(info) or max(fs) > 1.1 * min(fs):
        return None
    return min(fs)


def _fit_once(
    records: Sequence[Record],
    scored: Sequence[str],
    chain: bool,
    method: str,
    family: _Family,
    initial: ModelParams | None,
    warmup_s: float,
    offset: bool,
    bounds: dict[str, tuple[float, float]],
    messages: list[str],
    warm: dict[str, float] | None = None,
    tight: bool = True,
) -> tuple[dict[str, float], _Campaign, _Space, optimize.OptimizeResult | None, int]:
    """One identification on the ``scored`` records; returns the parameters, the campaign, the
    space, the final least-squares result (global) and the evaluations used."""
    camp = _Campaign(_entries(records, scored, warmup_s, chain), family, offset)
    free = [n for n in PARAM_NAMES if not (family.shape == "linear" and n == "vc_V")]
    keep = set(scored)
    f_one = _one_frequency([r for r in records if r.name in keep])
    if f_one is not None and method == "global":
        # nothing above the lowest frequency: G_d is not identifiable (at 1 Hz it changes the
        # strain by far less than the noise) and, left free, it wanders (towards lam_d = 1,
        # where the relaxor banks are slowest); keep the staged procedure's negligible G_d
        free = [n for n in free if n not in ("lam_d", "tau_d_s")]
        if warm is None:
            messages.append(
                f"every entry is periodic at {f_one:.3g} Hz: G_d is not identifiable and stays "
                "fixed (lam_d = 1.2, tau_d = 1e-5 s, negligible)"
            )
    nfev = 0
    if warm is not None and method == "global":
        starts = [warm]
    else:
        # the staged procedure and the generic starts look at each record on its own
        keep = set(scored)
        srecs = [r for r in records if r.name in keep]
        singles = [_make_entry(r, warmup_s) for r in srecs]
        starts = []
        try:
            th_staged, n_st = _staged(
                srecs,
                singles,
                family,
                offset,
                bounds,
                [] if f_one is not None and method == "global" else messages,
                records if chain else None,
                warmup_s,
            )
            nfev += n_st
            starts.append(th_staged)
        except ValueError as exc:
            if method == "staged":
                raise
            messages.append(f"no staged start: {exc}")
        if method == "staged":
            space = _Space(free, starts[0], bounds)
            return starts[0], camp, space, None, nfev
        if initial is not None:
            starts.append(initial.model_dump())
        if not starts:
            starts = _generic_start(srecs, singles, family, bounds)
    space = _Space(free, starts[0], bounds)
    th, res = _best_of(camp, space, starts, short_nfev=8, polish_nfev=300, tight=tight)
    if res.status == 0:
        messages.append(f"global fit stopped at the evaluation limit ({res.nfev})")
    return th, camp, space, res, nfev + camp.nfev


def fit_model(
    records: list[Record],
    method: str = "global",
    shape: str = "exponential",
    initial: ModelParams | None = None,
    heldout: bool = True,
    warmup_s: float = 0.0,
    progress: Progress | None = None,
    *,
    memory: str = "return_point",
    chain: bool = False,
    scored: Sequence[str] | None = None,
    offset: bool = False,
    bounds: dict[str, tuple[float, float]] | None = None,
) -> FitResult:
    """Identify :class:`ModelParams` from ``records`` (module docstring for the method).

    - ``method``: ``"global"`` (least squares over all entries, default) or ``"staged"``
      (seed section 3.1).
    - ``shape``: the hysteretic slope (``"exponential"``, ``"linear"``, ``"gaussian"``).
    - ``memory``: the operator's memory rule (``"return_point"`` or ``"last_reversal"``,
      :mod:`labrig.model.hysteresis`).
    - ``initial``: an extra start for the global fit (the staged result is always one).
    - ``heldout``: also compute the leave-one-entry-out NRMSE (needs 2 scored entries or more).
    - ``warmup_s``: seconds at the start of each record simulated but not scored.
    - ``progress``: called as ``progress(stage, done, total)`` with stage ``"fit"`` or
      ``"heldout"``.
    - ``chain``: the records are consecutive entries of one run, in this order, each followed by
      ``record.meta["rest_after_s"]`` seconds at 0 V (module docstring); simulate them as one
      sequence. Use it for runs recorded on one actuator (the model's memory spans entries).
    - ``scored``: names of the entries to fit and score (default all); with ``chain`` the
      others still drive the simulation as history.
    - ``offset``: fit one constant strain offset per entry (sensors with an arbitrary zero).
    - ``bounds``: native-unit bounds overriding :data:`DEFAULT_BOUNDS` per parameter.
    """
    if method not in ("global", "staged"):
        raise ValueError(f"method must be 'global' or 'staged', got {method!r}")
    if not records:
        raise ValueError("no records to fit")
    names = [r.name for r in records]
    if len(set(names)) != len(names):
        raise ValueError(f"entry names must be unique, got {names}")
    if scored is None:
        scored = names
    else:
        unknown = [n for n in scored if n not in names]
        if unknown or not scored:
            raise ValueError(f"scored entries {unknown or '[]'} are not among {names}")
        scored = [n for n in names if n in set(scored)]  # run order
    bnd = dict(DEFAULT_BOUNDS)
    bnd.update(bounds or {})
    messages: list[str] = []
    t0 = time.perf_counter()
    with single_thread_blas(), np.errstate(over="ignore"):
        if progress:
            progress("fit", 0, 1)
        family = _Family(shape, memory)
        common = (chain, method, family, initial, warmup_s, offset, bnd)
        th, camp, space, res, nfev = _fit_once(records, scored, *common, messages)
        params = family.params(th)
        J = camp.jacobian(space, space.z(th), central=True)
        r = camp.residuals(th)
        sizes = [g.meas.size for g in camp.segs]
        unc, corr = _uncertainty(J, r, sizes, space, th, 1 if offset else 0)
        preds = camp.predictions(th)
        per_entry, offsets = {}, {} if offset else None
        for g in camp.segs:
            p = preds[g.name]
            c = float(np.mean(g.meas - p[g.i0 :])) if offset else 0.0
            if offsets is not None:
                offsets[g.name] = c
                preds[g.name] = p + c
            per_entry[g.name] = nrmse_pct(g.meas, preds[g.name][g.i0 :])
        elapsed = time.perf_counter() - t0
        if progress:
            progress("fit", 1, 1)

        held, held_per = None, None
        t1 = time.perf_counter()
        if heldout and len(scored) >= 2:
            held_per = {}
            for k, name in enumerate(scored):
                if progress:
                    progress("heldout", k, len(scored))
                rest = [n for n in scored if n != name]
                th_k, *_ = _fit_once(records, rest, *common, [], warm=th, tight=True)
                rec = records[names.index(name)]
                held_per[name] = _score_heldout(
                    family.params(th_k), rec, records, chain, warmup_s, offset
                )
            if progress:
                progress("heldout", len(scored), len(scored))
            held = float(np.mean(list(held_per.values())))
        held_elapsed = time.perf_counter() - t1

    g = J.T @ r
    z = space.z(th)
    on = space.at_bound(z)
    mid = 0.5 * (space.lo + space.hi)
    # a gradient pushing against an active bound is optimal (J^T r > 0 means "decrease z")
    g[on & (((z < mid) & (g > 0)) | ((z > mid) & (g < 0)))] = 0.0
    for j, name in enumerate(space.free):
        if on[j]:
            messages.append(
                f"{name} ended at a bound ({th[name]:.4g}): the data do not determine it "
                "within the bounds (see its uncertainty)"
            )
    return FitResult(
        params=params,
        uncertainty=unc,
        correlation=corr,
        nrmse_pct=float(np.mean(list(per_entry.values()))),
        per_entry=per_entry,
        heldout_nrmse_pct=held,
        method=method,
        entries=list(scored),
        heldout_per_entry=held_per,
        offsets_ue=offsets,
        warmup_s=warmup_s,
        chain=chain,
        cost=0.5 * float(r @ r),
        optimality=float(np.max(np.abs(g))) if res is not None else float("nan"),
        nfev=nfev,
        elapsed_s=elapsed,
        heldout_elapsed_s=held_elapsed,
        messages=messages,
        predictions=preds,
        jacobian=J,
        free=space.free,
    )


def _score_heldout(
    params: ModelParams,
    rec: Record,
    records: Sequence[Record],
    chain: bool,
    warmup_s: float,
    offset: bool,
) -> float:
    if chain:
        camp = _Campaign(
            _entries(records, [rec.name], warmup_s, True), _Family(params.shape, params.memory)
        )
        p = camp.predictions(params.model_dump())[rec.name]
    else:
        p = predict_record(params, rec)
    i0 = round(max(warmup_s, 0.0) * rec.rate_hz)
    m, p = rec.strain_ue[i0:], p[i0:]
    if not offset:
        return nrmse_pct(m, p)
    return second_half_nrmse_pct(m, p, fit_offset=True)
