"""Physically readable candidate terms, and their sparse selection from a model's residual.

When no named effect explains what the model gets wrong, the missing term may still be found in
the data: the residual is regressed on a small library of terms a scientist can read, scaled to
comparable sizes, with sequentially thresholded least squares (STLSQ, the optimizer of SINDy,
``pysindy.optimizers.STLSQ``). Pure numerics, no I/O.

Terms
-----
Each :class:`Term` is computed over one simulated sequence (a record, or a chained run with its
rests) from the voltage acting on the actuator ``V`` (V; with a zero-order hold the sample held
over the interval that ends at each sample time, :meth:`~labrig.model.effects.Context.
acting_voltage`), its rate ``dV/dt`` (V/s, central differences), the
model's strain ``S`` (ue) and, when every record has one, the temperature ``T`` (degC). Its
values are divided by its *scale* (its size at full scale, :class:`TermScales`), so a
coefficient is the strain (ue) the term adds at full scale, whatever the term's unit:

=================  ================  ========================================  ==================
term               scale             reads as                                  library effect
=================  ================  ========================================  ==================
``V``              ``V_ref``         a direct feed-through of the voltage
``dV/dt``          ``R_ref``         a time shift of the response (a delay)    time_delay
``|dV/dt|``        ``R_ref``         a rate-dependent offset
``S``              ``S_ref``         a gain change
``S|S|``           ``S_ref^2``       saturation if < 0, hardening if > 0       field_saturation
``V^2``            ``V_ref^2``       electrostriction (even in V)              quadratic_term
``V^3``            ``V_ref^3``       saturation if < 0, hardening if > 0       field_saturation
``|dV/dt| S``      ``R_ref S_ref``   Bouc-Wen-like rate memory
``V S``            ``V_ref S_ref``   a field-dependent gain (quadratic in V)   quadratic_term
``T - T_ref``      ``dT_ref``        thermal expansion
``(T - T_ref) S``  ``dT_ref S_ref``  a thermal gain (self-heating)             thermal_drift
=================  ================  ========================================  ==================

``V_ref`` is the largest ``|V|``, ``R_ref`` the largest ``|dV/dt|``, ``S_ref`` the largest
strain span of an entry, ``T_ref`` the campaign's mean temperature (one reference for every
entry, not each entry's own start) and ``dT_ref`` the largest ``|T - T_ref|``.

Selection (:func:`select_terms`)
-------------------------------
Inputs: the residual ``r = measured - model`` (ue) at the scored samples, the terms' normalised
values there (:func:`term_columns`, or :func:`regression_data` from a fitted extended-model
problem), one weight per sample (labrig's ``1 / (span sqrt(samples))`` per entry) and an
orthonormal basis ``B`` of the current model's Jacobian columns in the weighted space (what the
model absorbs by moving its own parameters). Steps:

1. weight: ``r_w = w r``, ``Phi_w = w Phi``; project off the model:
   ``Phi_p = Phi_w - B (B^T Phi_w)``, ``r_p = r_w - B (B^T r_w)``. A term that keeps less than
   :attr:`SelectionRule.absorbed` (1 %) of its norm is *absorbed* by the model: reported, never
   selected.
2. normalise the remaining columns and ``r_p`` to unit norm, so a coefficient is the term's
   share of the residual's norm, and run STLSQ (ridge ``1e-5``, unbiased on its support) for
   each threshold of a path (24 values from 0.005 to 1, geometric).
3. **rule**: ``share(lambda) = 1 - |r_p - Phi_p xi|^2 / |r_p|^2`` is the share of the residual
   the support explains; ``best`` the largest share on the path. Keep the **sparsest** support
   whose share is at least ``(1 - tolerance) best`` (``tolerance`` 5 %; among equally sparse
   ones, the larger share). When ``best`` is below ``min_share`` (2 %), nothing is selected.
4. report each selected term's coefficient (ue at full scale, and per unit), its sign, and its
   share: what the selection loses when that term alone is dropped (least squares on the rest).

Projecting terms and residual off ``B`` makes each coefficient the one a joint linearised fit
of model parameters and terms would give (Frisch-Waugh-Lovell). The decision to keep a term is
not made here: the diagnosis refits the model with the selected terms
(:class:`~labrig.model.effects.empirical.EmpiricalTerms`) and judges them on held-out data
like a named effect.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labrig.analysis.records import Record, strain_unit
from labrig.model.effects.base import Context
from labrig.model.effects.empirical import EmpiricalTerms

__all__ = [
    "TERM_KEYS",
    "RegressionData",
    "SelectedTerm",
    "SelectionRule",
    "Term",
    "TermScales",
    "TermSelection",
    "empirical_effect",
    "regression_data",
    "select_terms",
    "term_columns",
    "term_library",
]

Fn = Callable[[NDArray, Context], NDArray]


def dvdt(ctx: Context) -> NDArray[np.float64]:
    """``dV/dt`` (V/s) of the voltage acting on the actuator (:meth:`Context.acting_voltage`)
    by central differences (cached)."""
    return ctx.cached(
        ("dvdt",),
        lambda: np.gradient(ctx.acting_voltage()) * ctx.rate_hz if ctx.n > 1 else np.zeros(ctx.n),
    )


def _temperature(ctx: Context) -> NDArray[np.float64]:
    if ctx.temperature is None:
        raise ValueError("this term needs a temperature channel, and the records have none")
    return ctx.temperature


@dataclass(frozen=True)
class Term:
    """One candidate term: ``values(S, ctx) = raw(S, ctx) / scale`` (dimensionless, about 1 at
    full scale). ``dS``: the derivative of ``raw`` with respect to ``S`` (``None`` when the term
    does not depend on ``S``)."""

    key: str  # identifier (parameter names): "V3"
    name: str  # as a scientist writes it: "V^3"
    unit: str  # unit of the raw term: "V^3"
    scale: float  # the raw term's size at full scale (its unit)
    physics: str  # what the term reads as ("" when nothing in particular)
    effect: str  # the library effect it corresponds to ("" for none)
    raw: Fn = field(repr=False, compare=False)
    dS: Fn | None = field(default=None, repr=False, compare=False)
    #: ``(physics, effect)`` when the coefficient is negative, if that reads differently
    if_negative: tuple[str, str] | None = None

    def reading(self, coefficient: float) -> tuple[str, str]:
        """``(what the term reads as, the library effect)`` for a coefficient of this sign."""
        if coefficient < 0 and self.if_negative is not None:
            return self.if_negative
        return self.physics, self.effect

    @property
    def uses_strain(self) -> bool:
        return self.dS is not None

    def values(self, S: NDArray, ctx: Context) -> NDArray[np.float64]:
        """The term over the sequence, divided by its scale."""
        return np.asarray(self.raw(S, ctx), dtype=float) / self.scale

    def slope(self, S: NDArray, ctx: Context) -> NDArray[np.float64] | float:
        """``d values / d S`` (0 for a term that does not depend on ``S``)."""
        return 0.0 if self.dS is None else np.asarray(self.dS(S, ctx), dtype=float) / self.scale


@dataclass(frozen=True)
class TermScales:
    """Full-scale sizes of a campaign (module docstring): ``V_ref`` (V), ``R_ref`` (V/s),
    ``S_ref`` (ue), the common temperature reference ``T_ref`` (degC) and ``dT_ref`` (K);
    the temperature pair is ``None`` without a temperature channel on every record."""

    v_ref_V: float
    rate_ref_V_per_s: float
    strain_ref_ue: float
    t_ref_C: float | None = None
    dt_ref_K: float | None = None
    #: the strain's unit as the records state it (``raw`` for a sensor's numbers kept by an
    #: import): the unit the terms' coefficients are written in
    strain_unit: str = "ue"

    @classmethod
    def from_records(cls, records: Sequence[Record]) -> TermScales:
        if not records:
            raise ValueError("no records to take the terms' scales from")

        def largest(xs: list[float]) -> float:
            m = max(xs)
            return m if m > 0 else 1.0

        v_ref = largest([float(np.max(np.abs(r.voltage_V))) for r in records])
        rates = [
            float(np.max(np.abs(np.gradient(r.voltage_V)))) * r.rate_hz for r in records if r.n > 1
        ]
        s_ref = largest([float(np.ptp(r.strain_ue)) for r in records])
        t_ref = dt_ref = None
        if all("temperature" in r.aux for r in records):
            temps = np.concatenate([r.aux["temperature"] for r in records])
            t_ref = float(np.mean(temps))
            dt_ref = float(np.max(np.abs(temps - t_ref))) or 1.0
        return cls(v_ref, largest(rates or [0.0]), s_ref, t_ref, dt_ref, strain_unit(records))


def term_library(scales: TermScales) -> dict[str, Term]:
    """The candidate terms for a campaign of these scales, by key (module docstring's table);
    the temperature terms only when the campaign has a temperature channel."""
    vr, rr, sr = scales.v_ref_V, scales.rate_ref_V_per_s, scales.strain_ref_ue
    u = scales.strain_unit
    sat = ("saturation (strain per volt falling at high field)", "field_saturation")
    hard = "a gain rising at high field (hardening; not in the effect library)"
    terms = [
        Term("V", "V", "V", vr, "a direct feed-through of the voltage (a gain)", "",
             lambda s, c: c.acting_voltage()),
        Term("dVdt", "dV/dt", "V/s", rr, "a time shift of the response (a delay or a lag)",
             "time_delay", lambda s, c: dvdt(c)),
        Term("absdVdt", "|dV/dt|", "V/s", rr, "a rate-dependent offset", "",
             lambda s, c: np.abs(dvdt(c))),
        Term("S", "S", u, sr, "a gain change", "", lambda s, c: s,
             lambda s, c: np.ones_like(s)),
        Term("S_absS", "S|S|", f"{u}^2", sr * sr, hard, "",
             lambda s, c: s * np.abs(s), lambda s, c: 2.0 * np.abs(s), sat),
        Term("V2", "V^2", "V^2", vr * vr, "electrostriction (even in V)", "quadratic_term",
             lambda s, c: c.acting_voltage() ** 2),
        Term("V3", "V^3", "V^3", vr**3, hard, "", lambda s, c: c.acting_voltage() ** 3, None,
             sat),
        Term("absdVdt_S", "|dV/dt| S", f"V {u}/s", rr * sr, "Bouc-Wen-like rate memory", "",
             lambda s, c: np.abs(dvdt(c)) * s, lambda s, c: np.abs(dvdt(c))),
        Term("V_S", "V S", f"V {u}", vr * sr, "a field-dependent gain (quadratic in V)",
             "quadratic_term", lambda s, c: c.acting_voltage() * s,
             lambda s, c: c.acting_voltage()),
    ]  # fmt: skip
    if scales.t_ref_C is not None and scales.dt_ref_K is not None:
        t0, dt = scales.t_ref_C, scales.dt_ref_K
        terms += [
            Term("T", "T - T_ref", "K", dt, "thermal expansion", "",
                 lambda s, c: _temperature(c) - t0),
            Term("T_S", "(T - T_ref) S", "K ue", dt * sr, "a thermal gain (self-heating)",
                 "thermal_drift", lambda s, c: (_temperature(c) - t0) * s,
                 lambda s, c: _temperature(c) - t0),
        ]  # fmt: skip
    return {t.key: t for t in terms}


#: the keys of every term (the temperature terms need a temperature channel)
TERM_KEYS: tuple[str, ...] = (*term_library(TermScales(1.0, 1.0, 1.0, 0.0, 1.0)),)


def term_columns(terms: Sequence[Term], S: NDArray, ctx: Context) -> NDArray[np.float64]:
    """The terms' normalised values over one sequence (``len(S) x len(terms)``)."""
    if not terms:
        return np.zeros((np.size(S), 0))
    return np.column_stack([t.values(S, ctx) for t in terms])


def empirical_effect(keys: Sequence[str], scales: TermScales) -> EmpiricalTerms:
    """The output effect made of the terms named by ``keys`` (:data:`TERM_KEYS`), bounded by
    the campaign's strain scale."""
    lib = term_library(scales)
    unknown = [k for k in keys if k not in lib]
    if unknown:
        raise ValueError(f"unknown terms {unknown}; known: {', '.join(lib)}")
    # Term's fields are frozen, TermLike's protocol attributes settable (docs/architecture.md,
    # "Types and docstrings": make them read-only properties)
    return EmpiricalTerms(
        [lib[k] for k in keys],  # type: ignore[misc]
        scales.strain_ref_ue,
        scales.strain_unit,
    )


# -- the regression data of a fitted extended-model problem ----------------------------------


class ExtendedLike(Protocol):
    """What :func:`regression_data` reads of an
    :class:`~labrig.analysis.extended.ExtendedProblem` (no import: the engine imports the effect
    library, which imports this module's effect)."""

    sequences: list[Any]
    segments: list[list[Any]]
    nuisance_basis: dict[str, NDArray | None]

    def strains(self, base: Mapping[str, float], eff: Mapping[str, Any]) -> list[NDArray]: ...


@dataclass
class RegressionData:
    """Rows of the scored samples, in the order of the extended problem's residual vector:
    ``residual`` (measured - model, ue), ``columns`` (the terms' normalised values), ``weights``
    (per sample); the per-entry nuisance regressors are projected out of both."""

    residual: NDArray[np.float64]
    columns: NDArray[np.float64]
    weights: NDArray[np.float64]


def regression_data(
    problem: ExtendedLike,
    base: Mapping[str, float],
    eff: Mapping[str, Mapping[str, float]],
    terms: Sequence[Term],
) -> RegressionData:
    """The residual of the model ``(base, eff)`` of ``problem`` and the terms' columns at its
    scored samples, with the model's own strain as ``S``."""
    rs, cs, ws = [], [], []
    for seq, segs, y in zip(
        problem.sequences, problem.segments, problem.strains(base, eff), strict=True
    ):
        cols = term_columns(terms, y, seq.context)
        for g in segs:
            r = g.measured_ue - y[g.lo : g.hi]
            C = cols[g.lo : g.hi]
            Q = problem.nuisance_basis.get(g.name)
            if Q is not None:
                r = r - Q @ (Q.T @ r)
                C = C - Q @ (Q.T @ C)
            rs.append(r)
            cs.append(C)
            ws.append(np.full(r.size, g.weight))
    return RegressionData(np.concatenate(rs), np.vstack(cs), np.concatenate(ws))


# -- selection --------------------------------------------------------------------------------


@dataclass(frozen=True)
class SelectionRule:
    """The threshold rule of :func:`select_terms` (module docstring)."""

    thresholds: tuple[float, ...] = tuple(float(x) for x in np.geomspace(0.005, 1.0, 24))
    tolerance: float = 0.05  # keep the sparsest support within this share of the best
    min_share: float = 0.02  # select nothing when the best support explains less
    absorbed: float = 0.01  # a term keeping less of its norm off the model is absorbed
    ridge: float = 1e-5  # STLSQ's ridge on unit-norm columns


@dataclass
class SelectedTerm:
    """One selected term: ``coefficient_ue`` is the strain it adds at full scale,
    ``coefficient`` the same per unit of the raw term (ue per ``unit``)."""

    key: str
    name: str
    unit: str
    coefficient_ue: float
    coefficient: float
    sign: int
    share: float  # share of the residual lost when this term alone is dropped
    physics: str
    effect: str

    def to_json(self) -> dict[str, Any]:
        return {
            "term": self.name,
            "unit": self.unit,
            "coefficient_ue_at_full_scale": self.coefficient_ue,
            "coefficient_per_unit": self.coefficient,
            "sign": self.sign,
            "share": self.share,
            "reads_as": self.physics,
            "effect": self.effect or None,
        }


@dataclass
class TermSelection:
    """What :func:`select_terms` found: the selected terms, the share of the (weighted,
    projected) residual they explain together, the terms the model absorbs, the threshold
    kept and the path (threshold, keys, share)."""

    terms: list[SelectedTerm]
    share: float
    best_share: float
    absorbed: list[str]
    threshold: float | None
    path: list[tuple[float, tuple[str, ...], float]] = field(default_factory=list, repr=False)

    @property
    def keys(self) -> list[str]:
        return [t.key for t in self.terms]

    def start(self) -> dict[str, float]:
        """Parameters of :class:`~labrig.model.effects.empirical.EmpiricalTerms` at the
        selected coefficients (a start for its refit)."""
        return {EmpiricalTerms.param_name(t.key): t.coefficient_ue for t in self.terms}

    def to_json(self) -> dict[str, Any]:
        return {
            "terms": [t.to_json() for t in self.terms],
            "share": self.share,
            "best_share": self.best_share,
            "absorbed_by_the_model": list(self.absorbed),
            "threshold": self.threshold,
        }


def _stlsq(X: NDArray, y: NDArray, threshold: float, ridge: float) -> NDArray:
    """pysindy's STLSQ on unit-norm columns (no normalisation of its own)."""
    from pysindy.optimizers import STLSQ

    opt = STLSQ(threshold=threshold, alpha=ridge, unbias=True, max_iter=20)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "eliminated all coefficients" at large thresholds
        opt.fit(X, y)
    return np.asarray(opt.coef_, dtype=float).ravel()


def _share(X: NDArray, y: NDArray, support: NDArray) -> float:
    """Share of the unit-norm ``y`` explained by least squares on the columns in ``support``."""
    if not support.any():
        return 0.0
    coef, *_ = np.linalg.lstsq(X[:, support], y, rcond=None)
    e = y - X[:, support] @ coef
    return float(1.0 - e @ e)


def _path(
    X: NDArray, y: NDArray, rule: SelectionRule
) -> list[tuple[float, NDArray, NDArray, float]]:
    """(threshold, support, coefficients, share) along the threshold path, unique supports."""
    # STLSQ on the small triangular system, the same minimiser: |X b - y|^2 = |R b - Q^T y|^2 + c
    q, r = np.linalg.qr(X, mode="reduced")
    qty = q.T @ y
    out, seen = [], set()
    for lam in sorted(rule.thresholds):
        coef = _stlsq(r, qty, lam, rule.ridge)
        support = coef != 0
        key = tuple(np.flatnonzero(support))
        if key in seen:
            continue
        seen.add(key)
        e = y - X @ coef
        out.append((float(lam), support, coef, float(1.0 - e @ e)))
    return out


def select_terms(
    residual: ArrayLike,
    columns: ArrayLike,
    terms: Sequence[Term],
    weights: ArrayLike | None = None,
    basis: ArrayLike | None = None,
    rule: SelectionRule | None = None,
) -> TermSelection:
    """Sparse selection of ``terms`` explaining ``residual`` (module docstring).

    ``residual``: measured - model (ue), ``n`` samples; ``columns``: the terms' normalised
    values there (``n x k``, :func:`term_columns`); ``weights``: per sample (default 1);
    ``basis``: orthonormal ``n x m`` basis of the model's weighted Jacobian columns (default
    none)."""
    rule = rule or SelectionRule()
    r = np.asarray(residual, dtype=float).ravel()
    Phi = np.asarray(columns, dtype=float).reshape(r.size, -1)
    if Phi.shape[1] != len(terms):
        raise ValueError(f"{Phi.shape[1]} columns for {len(terms)} terms")
    w = np.ones(r.size) if weights is None else np.asarray(weights, dtype=float).ravel()
    rw, Pw = w * r, w[:, None] * Phi
    if basis is not None:
        B = np.asarray(basis, dtype=float).reshape(r.size, -1)
        rw = rw - B @ (B.T @ rw)
        Pw = Pw - B @ (B.T @ Pw)
    before = np.linalg.norm(w[:, None] * Phi, axis=0)
    after = np.linalg.norm(Pw, axis=0)
    live = after > rule.absorbed * np.where(before > 0, before, np.inf)
    absorbed = [t.name for t, ok in zip(terms, live, strict=True) if not ok]
    rn = float(np.linalg.norm(rw))
    idx = np.flatnonzero(live)
    if rn == 0.0 or idx.size == 0:
        return TermSelection([], 0.0, 0.0, absorbed, None)
    X = Pw[:, idx] / after[idx]
    y = rw / rn
    path = _path(X, y, rule)
    best = max(p[3] for p in path)
    named = [(lam, tuple(terms[idx[j]].key for j in np.flatnonzero(s)), sh)
             for lam, s, _, sh in path]  # fmt: skip
    if best < rule.min_share:
        return TermSelection([], 0.0, best, absorbed, None, named)
    ok = [p for p in path if p[3] >= (1.0 - rule.tolerance) * best]
    lam, support, coef, share = min(ok, key=lambda p: (int(p[1].sum()), -p[3]))
    chosen = []
    for j in np.flatnonzero(support):
        t = terms[idx[j]]
        c_ue = float(coef[j] * rn / after[idx[j]])  # back to ue per unit normalised term
        drop = support.copy()
        drop[j] = False
        chosen.append(
            SelectedTerm(
                t.key, t.name, t.unit, c_ue, c_ue / t.scale, int(np.sign(c_ue)),
                share - _share(X, y, drop), *t.reading(c_ue),
            )
        )  # fmt: skip
    return TermSelection(chosen, share, best, absorbed, lam, named)
