"""Identification of :class:`~labrig.model.ModelParams` from records (``labrig fit`` numerics).

Objective: the free-run simulation error of the dynamic model (the ``"fast"`` method with the
record's hold) against the measured strain, each entry weighted so that the cost is
``sum_e (NRMSE_e / 100)^2`` (:mod:`labrig.analysis.simulate`). ``chain`` simulates a run's entries
back to back with their rests, ``warmup_s`` simulates the start of each record without scoring
it, ``offset`` fits one constant strain offset per entry (sensors with an arbitrary zero).

Global fit (default): bounded least squares on the structured Jacobian of
:mod:`labrig.analysis.base_problem`, from the paper's staged procedure
(:mod:`labrig.analysis.staged`) and, if given, ``initial``; each start gets a short run, the best
is then converged tightly with a final central-difference Jacobian for the uncertainties. When
every scored entry is periodic at one frequency, ``G_d`` is not identifiable and stays at the
staged procedure's negligible value.

Uncertainty: one standard deviation from the Jacobian at the optimum, in the native parameters,
by the per-entry sandwich ``A^+ (sum_e s_e^2 J_e^T J_e) A^+``, ``A = J^T J``, ``s_e^2`` entry
``e``'s residual variance (entries are weighted differently, so a single pooled variance would
be wrong), computed from the SVD of the weighted Jacobian so that the covariance is symmetric
and the correlations within [-1, 1]; a parameter the data do not determine has none
(:mod:`labrig.analysis.fit_uncertainty`). Residuals of a free-run model are correlated in time
when the model is not exact, so on real data these are lower bounds; the correlations are the
informative part.

Held-out NRMSE: leave-one-entry-out; the same method refitted without each entry (warm-started
from the full fit) and scored on it; the mean over entries. With ``offset`` the held-out entry's
offset is fitted on the first half of its scored samples and the error taken on the second half
(:func:`~labrig.analysis.metrics.second_half_nrmse_pct`).

OpenBLAS threads are limited to one while fitting (:mod:`labrig.core.blas`). docs/analysis.md has
the method's measurements.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from labrig.analysis.engine import Coordinates, Problem, base_problem, best_of, chord_refit
from labrig.analysis.fit_uncertainty import bound_notes, bounds_reached, fit_covariance
from labrig.analysis.metrics import nrmse_pct, scores_json, second_half_nrmse_pct
from labrig.analysis.parallel import map_tasks
from labrig.analysis.records import Record, warmup_samples
from labrig.analysis.simulate import (
    DEFAULT_BOUNDS,
    PARAM_NAMES,
    OperatorFamily,
    scored_names,
    scored_sequences,
)
from labrig.analysis.staged import classify, generic_starts, staged_fit
from labrig.core.blas import single_thread_blas
from labrig.model import DynamicHysteresisModel, ModelParams

__all__ = [
    "DEFAULT_BOUNDS",
    "PARAM_NAMES",
    "FitResult",
    "fit_model",
    "predict_record",
    "single_thread_blas",
]

Progress = Callable[[str, int, int], Any]


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
    #: the free parameters that ended on a bound, with their values
    #: (:func:`~labrig.analysis.fit_uncertainty.bounds_reached`)
    at_bound: dict[str, float] = field(default_factory=dict)
    #: the stroke (V) of the operator's loop coordinates (the records' largest peak-to-peak
    #: voltage; :class:`~labrig.analysis.engine.LoopScale`), ``None`` without them
    loop_span_V: float | None = None
    #: the run files the records came from (absolute paths; set by ``labrig fit``), so that a
    #: report on other records can fit its peers on the same ones
    train_files: list[str] | None = None

    def to_json(self) -> dict[str, Any]:
        from labrig.analysis.identifiability import identifiability

        params = self.params.model_dump()
        return {
            "params": params,
            "uncertainty": dict(self.uncertainty),
            "correlation": {k: dict(v) for k, v in self.correlation.items()},
            **scores_json(
                self.nrmse_pct, self.per_entry, self.heldout_nrmse_pct, self.method, self.entries
            ),
            "train_files": None if self.train_files is None else list(self.train_files),
            "identifiability": identifiability(
                params,
                self.uncertainty,
                self.correlation,
                self.loop_span_V,
                free=self.free,
                at_bound=self.at_bound,
            ),
        }

    def predict(self, target: Any) -> Any:
        """The fitted model's strain (ue). ``target`` a :class:`Record` or a run file's entry
        (``run[name]``): its strain simulated on its own from rest (plus its fitted offset, if
        any). A run (``labrig.Run``): ``{entry: strain}`` for its complete entries, simulated
        back to back as the fit did when it chained them."""
        from labrig.analysis.load import as_records
        from labrig.analysis.simulate import predict_sequences

        records, single = as_records(target)
        if single:
            s = predict_record(self.params, records[0])
            if self.offsets_ue and records[0].name in self.offsets_ue:
                s = s + self.offsets_ue[records[0].name]
            return s

        def simulate(seq) -> NDArray[np.float64]:
            with single_thread_blas(), np.errstate(over="ignore"):
                model = DynamicHysteresisModel(self.params)
                return model.predict(
                    seq.voltage_V, seq.rate_hz, method="fast", hold=seq.hold, rest_V=seq.rest_V
                )

        return predict_sequences(records, self.chain, simulate, self.offsets_ue)


def predict_record(params: ModelParams, record: Record) -> NDArray[np.float64]:
    """``DynamicHysteresisModel(params).predict`` for a record (fast method, record's hold), the
    actuator held at the record's :attr:`~labrig.analysis.records.Record.rest_V` before it."""
    with single_thread_blas(), np.errstate(over="ignore"):
        return DynamicHysteresisModel(params).predict(
            record.voltage_V, record.rate_hz, method="fast", hold=record.hold, rest_V=record.rest_V
        )


def _one_frequency(records: Sequence[Record]) -> float | None:
    """The common drive frequency (Hz) when every record is periodic at (within 10 %) the same
    frequency, else ``None``."""
    info = classify(records)
    fs = [i.f_hz for i in info if i.periodic and i.f_hz is not None]
    if not info or len(fs) != len(info) or max(fs) > 1.1 * min(fs):
        return None
    return min(fs)


#: what every identification of one campaign shares: chain, method, family, initial
#: parameters, warm-up (s), offset, bounds (the arguments of :func:`_fit_once` after ``scored``)
Common = tuple[
    bool, str, OperatorFamily, ModelParams | None, float, bool, dict[str, tuple[float, float]]
]


def _fit_once(
    records: Sequence[Record],
    scored: Sequence[str],
    chain: bool,
    method: str,
    family: OperatorFamily,
    initial: ModelParams | None,
    warmup_s: float,
    offset: bool,
    bounds: dict[str, tuple[float, float]],
    messages: list[str],
    warm: dict[str, float] | None = None,
    tight: bool = True,
    parent: Problem | None = None,
) -> tuple[dict[str, float], Problem, optimize.OptimizeResult | None, int]:
    """One identification on the ``scored`` records; returns the parameters, the problem, the
    final least-squares result (global) and the evaluations used. ``parent``: the problem of a
    fit on more entries whose simulations this one shares (a held-out fold)."""
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
    if parent is not None:
        camp = parent.subset(scored, free)
    else:
        camp = base_problem(
            scored_sequences(records, scored, warmup_s, chain), family, offset, free, bounds
        )
    nfev = 0
    if warm is not None and method == "global":
        starts = [warm]
    else:
        # the staged procedure and the generic starts look at each record on its own
        srecs = [r for r in records if r.name in keep]
        singles = scored_sequences(srecs, [r.name for r in srecs], warmup_s, False)
        starts = []
        try:
            th_staged, n_st = staged_fit(
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
            return starts[0], camp, None, nfev
        if initial is not None:
            starts.append(initial.model_dump())
        if not starts:
            starts = generic_starts(srecs, singles, family, bounds)
    th, res = best_of(camp, starts, short_nfev=8, polish_nfev=300, tight=tight)
    if res.status == 0:
        messages.append(f"global fit stopped at the evaluation limit ({res.nfev})")
    return th, camp, res, nfev + camp.nfev


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
    workers: int = 1,
) -> FitResult:
    """Identify :class:`ModelParams` from ``records`` (module docstring for the method).

    - ``method``: ``"global"`` (default) or ``"staged"`` (the paper's section 3.1).
    - ``shape``, ``memory``: the operator family; ``initial``: an extra start for the global fit.
    - ``heldout``: also the leave-one-entry-out NRMSE (needs 2 scored entries or more).
    - ``warmup_s``: seconds at the start of each record simulated but not scored.
    - ``progress``: ``progress(stage, done, total)``, stage ``"fit"`` or ``"heldout"``.
    - ``chain``: the records are a run's consecutive entries, each followed by
      ``record.meta["rest_after_s"]`` at 0 V: simulate them as one sequence.
    - ``scored``: the entries to fit and score (default all); with ``chain`` the others still
      drive the simulation as history.
    - ``offset``: fit one constant strain offset per entry (sensors with an arbitrary zero).
    - ``bounds``: native-unit bounds overriding :data:`DEFAULT_BOUNDS` per parameter.
    - ``workers``: processes for the leave-one-entry-out folds (the result does not depend on
      it).
    """
    if method not in ("global", "staged"):
        raise ValueError(f"method must be 'global' or 'staged', got {method!r}")
    scored = scored_names(records, scored)
    bnd = {**DEFAULT_BOUNDS, **(bounds or {})}
    messages: list[str] = []
    t0 = time.perf_counter()
    with single_thread_blas(), np.errstate(over="ignore"):
        if progress:
            progress("fit", 0, 1)
        family = OperatorFamily(shape, memory)
        common = (chain, method, family, initial, warmup_s, offset, bnd)
        th, camp, res, nfev = _fit_once(records, scored, *common, messages)
        z = camp.coords.z(th, strict=True)
        J = camp.jacobian(z, th)
        r = camp.residual_at(th)
        cov = fit_covariance(camp, z, th, J, r)
        unc = {**dict.fromkeys(PARAM_NAMES), **cov.uncertainty()}
        at_bound = bounds_reached(camp.coords, z, th)
        per_entry, offsets, preds = _in_sample(camp, th, offset)
        elapsed = time.perf_counter() - t0
        if progress:
            progress("fit", 1, 1)
        t1 = time.perf_counter()
        held_per = None
        if heldout and len(scored) >= 2:
            held_per = _heldout(records, scored, common, th, progress, camp, workers)
        held_elapsed = time.perf_counter() - t1
    optimality = _optimality(J, r, camp.coords, th)
    messages += bound_notes(at_bound)
    if res is None:  # the staged procedure ends with no converged least-squares run
        optimality = float("nan")
    return FitResult(
        params=family.params(th),
        uncertainty=unc,
        correlation=cov.correlations(),
        nrmse_pct=float(np.mean(list(per_entry.values()))),
        per_entry=per_entry,
        heldout_nrmse_pct=None if held_per is None else float(np.mean(list(held_per.values()))),
        method=method,
        entries=list(scored),
        heldout_per_entry=held_per,
        offsets_ue=offsets,
        warmup_s=warmup_s,
        chain=chain,
        cost=0.5 * float(r @ r),
        optimality=optimality,
        nfev=nfev,
        elapsed_s=elapsed,
        heldout_elapsed_s=held_elapsed,
        messages=messages,
        predictions=preds,
        jacobian=J,
        free=camp.coords.base_free,
        at_bound=at_bound,
        loop_span_V=camp.loop.span_V if camp.loop is not None else None,
    )


def _in_sample(
    camp: Problem, th: dict[str, float], offset: bool
) -> tuple[dict[str, float], dict[str, float] | None, dict[str, NDArray]]:
    """NRMSE per scored entry, the fitted offsets (``offset``) and the predictions (offsets
    included)."""
    preds = camp.predictions(th, nuisance=False)
    per_entry: dict[str, float] = {}
    offsets: dict[str, float] | None = {} if offset else None
    for g in (g for segs in camp.segments for g in segs):
        p = preds[g.name]
        c = float(np.mean(g.measured_ue - p[g.i0 :])) if offset else 0.0
        if offsets is not None:
            offsets[g.name] = c
            preds[g.name] = p + c
        per_entry[g.name] = nrmse_pct(g.measured_ue, preds[g.name][g.i0 :])
    return per_entry, offsets, preds


def _heldout(
    records: Sequence[Record],
    scored: list[str],
    common: Common,
    th: dict[str, float],
    progress: Progress | None,
    parent: Problem,
    workers: int = 1,
) -> dict[str, float]:
    """Leave-one-entry-out NRMSE of each scored entry, refitted from ``th`` (each fold shares
    the full fit's simulations and starts with its Jacobian: :func:`_chord_fold`), the folds
    on ``workers`` processes."""
    chain, _method, family, _initial, warmup_s, offset, _bounds = common
    names = [r.name for r in records]

    def fold(k: int) -> float:
        name = scored[k]
        if progress and workers <= 1:
            progress("heldout", k, len(scored))
        rest = [n for n in scored if n != name]
        th_k = _chord_fold(parent, records, rest, th, common)
        if th_k is None:
            th_k, *_ = _fit_once(records, rest, *common, [], warm=th, tight=True, parent=parent)
        rec = records[names.index(name)]
        return _score_heldout(family.params(th_k), rec, records, chain, warmup_s, offset, parent)

    scores = map_tasks(fold, len(scored), workers)
    if progress:
        progress("heldout", len(scored), len(scored))
    return dict(zip(scored, scores, strict=True))


def _chord_fold(
    parent: Problem,
    records: Sequence[Record],
    rest: list[str],
    th: dict[str, float],
    common: Common,
) -> dict[str, float] | None:
    """A held-out fold refitted from the full fit ``th`` by the chord method
    (:func:`~labrig.analysis.engine.chord_refit`), or ``None`` (then by least squares)."""
    family = common[2]
    free = [n for n in PARAM_NAMES if not (family.shape == "linear" and n == "vc_V")]
    keep = set(rest)
    if _one_frequency([r for r in records if r.name in keep]) is not None and common[1] == "global":
        free = [n for n in free if n not in ("lam_d", "tau_d_s")]
    sub = parent.subset(rest, free)
    got = chord_refit(sub, sub.coords.z(th, strict=True), th)
    return None if got is None else sub.coords.unpack(got[0], th)[0]


def _optimality(J: NDArray, r: NDArray, coords: Coordinates, th: dict[str, float]) -> float:
    """First-order optimality (largest gradient component, those pushing against an active
    bound excluded)."""
    g = J.T @ r
    z = coords.z(th, strict=True)
    on = coords.at_bound(z)
    mid = 0.5 * (coords.lo + coords.hi)
    # a gradient pushing against an active bound is optimal (J^T r > 0 means "decrease z")
    g[on & (((z < mid) & (g > 0)) | ((z > mid) & (g < 0)))] = 0.0
    return float(np.max(np.abs(g)))


def _score_heldout(
    params: ModelParams,
    rec: Record,
    records: Sequence[Record],
    chain: bool,
    warmup_s: float,
    offset: bool,
    parent: Problem,
) -> float:
    if chain:
        # the whole run at the fold's parameters: its last simulation
        p = parent.subset([rec.name]).predictions(params.model_dump(), nuisance=False)[rec.name]
    else:
        p = predict_record(params, rec)
    i0 = warmup_samples(rec, warmup_s)
    m, p = rec.strain_ue[i0:], p[i0:]
    if not offset:
        return nrmse_pct(m, p)
    return second_half_nrmse_pct(m, p, fit_offset=True)
