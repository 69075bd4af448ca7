"""``labrig fit --effect NAME``: the dynamic model fitted together with named library effects.

After the base fit (:func:`labrig.analysis.fit.fit_model`), the base parameters and the effects'
parameters (:mod:`labrig.model.effects`) are refitted jointly by least squares on the same
entries, weighting, chaining, warm-up and offsets (:class:`~labrig.analysis.extended.
ExtendedProblem`, the numerics ``labrig diagnose`` uses), from the base fit and the effects'
starts (:meth:`~labrig.model.effects.Effect.refit_starts`, every combination; each start fitted
loosely, the best cost then fitted to convergence).

The free base parameters are the base fit's (``G_d`` stays fixed where the base fit fixed it).
Uncertainties, correlations, the parameters that ended on a bound and the identifiability
judgement are a plain fit's, over the base's and the effects' parameters together
(:func:`~labrig.analysis.fit_uncertainty.fit_covariance`,
:func:`~labrig.analysis.identifiability.identifiability`); an effect's parameter is named
``"effect.param"`` there.

Held-out scoring is ``labrig diagnose``'s (leave-one-entry-out; the left-out entry scored on the
second half of its samples, its nuisance terms fitted on the first half), computed for the model
with **and** without the effects, so the two held-out NRMSE compare like with like; the JSON's
``heldout_scoring`` says so (:data:`HELDOUT_SCORING`).

Use it for an effect ``labrig diagnose`` found, to carry it into control:
``labrig fit RUN --effect viscoelastic_creep --out params.json`` gives a parameter file whose
``effects`` list the compensation controller inverts (:func:`labrig.control.load_control_model`).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from labrig.analysis.extended import ExtendedProblem, FitOutcome, effect_context
from labrig.analysis.fit import PARAM_NAMES, FitResult
from labrig.analysis.fit_uncertainty import (
    bound_notes,
    bounds_reached,
    fit_covariance,
)
from labrig.analysis.identifiability import identifiability
from labrig.analysis.records import Record
from labrig.model import ModelParams
from labrig.model.effects import FIT_EFFECT_NAMES, Effect, library

__all__ = ["HELDOUT_SCORING", "EffectsFit", "fit_effects", "known_effects", "resolve_effects"]

#: how ``labrig fit --effect`` takes its held-out NRMSE (the JSON's ``heldout_scoring``)
HELDOUT_SCORING = "leave-one-entry-out, second half of the left-out entry"


def known_effects() -> list[str]:
    """Names of the library's effects that ``--effect`` accepts (fitted as global parameters:
    voltage, operator and output effects; nuisance terms are per-entry and need no flag), in
    registry order (:data:`~labrig.model.effects.registry.FIT_EFFECT_NAMES`)."""
    return list(FIT_EFFECT_NAMES)


@dataclass
class EffectsFit:
    """The joint fit and its comparison with the base model (same scoring).

    ``uncertainty`` holds the base's parameters (``None``: fixed or not determined), each
    item of ``effects`` its effect's; ``correlation``, ``free`` and ``at_bound`` cover the
    base's and the effects' free parameters together (an effect's as ``"effect.param"``)."""

    params: ModelParams
    uncertainty: dict[str, float | None]
    effects: list[dict[str, Any]]  # {effect, params, uncertainty, correlation, description}
    nrmse_pct: float
    per_entry: dict[str, float]
    heldout_nrmse_pct: float | None
    heldout_per_entry: dict[str, float] | None
    base_nrmse_pct: float
    base_heldout_nrmse_pct: float | None
    entries: list[str]
    context: dict  # how the effects were configured (effect_context): saved for predictions
    train_files: list[str] | None = None  # as FitResult.train_files
    correlation: dict[str, dict[str, float]] = field(default_factory=dict)
    free: tuple[str, ...] = ()
    at_bound: dict[str, float] = field(default_factory=dict)
    messages: list[str] = field(default_factory=list)
    loop_span_V: float | None = None  # as FitResult.loop_span_V

    def _flat(self) -> tuple[dict[str, Any], dict[str, float | None]]:
        """The parameters and their 1-sigma, the base's and the effects' in one mapping (an
        effect's parameter as ``"effect.param"``)."""
        params: dict[str, Any] = self.params.model_dump()
        sd: dict[str, float | None] = dict(self.uncertainty)
        for e in self.effects:
            for k, v in e["params"].items():
                params[f"{e['effect']}.{k}"] = v
                sd[f"{e['effect']}.{k}"] = e["uncertainty"].get(k)
        return params, sd

    def to_json(self) -> dict[str, Any]:
        params, sd = self._flat()
        return {
            "params": self.params.model_dump(),
            "uncertainty": dict(self.uncertainty),
            "correlation": _between(self.correlation, PARAM_NAMES),
            "effects": self.effects,
            "nrmse_pct": float(self.nrmse_pct),
            "per_entry": {k: float(v) for k, v in self.per_entry.items()},
            "heldout_nrmse_pct": self.heldout_nrmse_pct,
            "heldout_scoring": HELDOUT_SCORING,
            "without_effects": {
                "nrmse_pct": float(self.base_nrmse_pct),
                "heldout_nrmse_pct": self.base_heldout_nrmse_pct,
            },
            "method": "global+effects",
            "entries": list(self.entries),
            "train_files": None if self.train_files is None else list(self.train_files),
            "effects_context": dict(self.context),
            "identifiability": identifiability(
                params,
                sd,
                self.correlation,
                self.loop_span_V,
                free=self.free,
                at_bound=self.at_bound,
            ),
        }


def _between(
    correlation: dict[str, dict[str, float]], names: Sequence[str]
) -> dict[str, dict[str, float]]:
    """The correlations between ``names`` only."""
    keep = set(names)
    rows = {a: row for a, row in correlation.items() if a in keep}
    return {a: {b: r for b, r in row.items() if b in keep} for a, row in rows.items()}


def resolve_effects(names: Sequence[str], context: dict | None = None) -> list[Effect]:
    """The library effects named (``ValueError`` naming an unknown or repeated one), configured
    with ``context`` (:func:`~labrig.analysis.extended.effect_context`; default: the
    library's defaults, enough to check names)."""
    lib, ok = library(**(context or {})), known_effects()
    out: list[Effect] = []
    for n in names:
        if n not in ok:
            raise ValueError(f"{n!r} is not a library effect; choose from: {', '.join(ok)}")
        if any(e.name == n for e in out):
            raise ValueError(f"effect {n!r} given twice")
        out.append(lib[n])
    return out


#: evaluations of each start's loose fit (the best is then fitted to convergence)
_START_NFEV = 30


def _starts(effects: Sequence[Effect]) -> list[dict[str, dict[str, float]]]:
    per_effect = [e.refit_starts(e.init) for e in effects]
    return [
        {e.name: p for e, p in zip(effects, combo, strict=True)}
        for combo in itertools.product(*per_effect)
    ]


def _mean(d: dict[str, float] | None) -> float | None:
    return None if not d else float(np.mean(list(d.values())))


def fit_effects(
    records: Sequence[Record],
    base: FitResult,
    names: Sequence[str | Effect],
    *,
    chain: bool,
    scored: Sequence[str] | None = None,
    warmup_s: float = 0.0,
    offset: bool = False,
    heldout: bool = True,
    progress: Callable[[str, int, int], None] | None = None,
) -> EffectsFit:
    """Refit ``base`` jointly with the library effects ``names`` (module docstring); an
    :class:`~labrig.model.effects.Effect` given instead of a name is used as it is (the empirical
    terms of a diagnosis, a nuisance effect: ``labrig validate`` carries what diagnose accepted).

    ``progress(stage, done, total)``: stage ``"effects"`` (the starts) then ``"heldout"``.
    Raises ``ValueError`` for an unknown effect name."""
    context = effect_context(records)
    named = resolve_effects([n for n in names if isinstance(n, str)], context)
    effects = [n if not isinstance(n, str) else named.pop(0) for n in names]
    common = dict(
        chain=chain,
        shape=base.params.shape,
        memory=base.params.memory,
        scored=scored,
        warmup_s=warmup_s,
        offset=offset,
        base_free=base.free or PARAM_NAMES,
    )
    prob = ExtendedProblem(records, effects, **common)
    base0 = {n: float(getattr(base.params, n)) for n in PARAM_NAMES}
    starts = _starts(effects)
    best: FitOutcome | None = None
    for k, e0 in enumerate(starts):
        out = prob.fit(base0, e0, tight=False, max_nfev=_START_NFEV)
        if best is None or out.cost < best.cost:
            best = out
        if progress:
            progress("effects", k + 1, len(starts) + 1)
    assert best is not None
    best = prob.fit(best.base, best.effects, sd=False)  # the best start, to convergence
    assert best.z is not None
    cov = fit_covariance(prob, best.z, best.base)
    at_bound = bounds_reached(prob.coords, best.z, best.base, best.effects)
    if progress:
        progress("effects", len(starts) + 1, len(starts) + 1)
    plain = ExtendedProblem(records, [], **common)
    base_per_entry = plain.per_entry(base0, {})
    held = base_held = None
    if heldout and len(prob.scored) >= 2:
        plain_fit = plain.fit(base0, tight=False)
        n = 2 * len(prob.scored)
        held = prob.heldout(best)
        if progress:
            progress("heldout", n // 2, n)
        base_held = plain.heldout(plain_fit)
        if progress:
            progress("heldout", n, n)
    base_notes = set(bound_notes(base.at_bound))  # the base fit's: judged again here
    sd, corr = cov.uncertainty(), cov.correlations()
    return EffectsFit(
        params=best.params(base.params.shape, base.params.memory),
        uncertainty={n: sd.get(n) for n in PARAM_NAMES},
        effects=[_listed(e, best, sd, corr) for e in effects],
        nrmse_pct=best.nrmse_pct,
        per_entry=dict(best.per_entry),
        heldout_nrmse_pct=_mean(held),
        heldout_per_entry=held,
        base_nrmse_pct=float(np.mean(list(base_per_entry.values()))),
        base_heldout_nrmse_pct=_mean(base_held),
        entries=list(prob.scored),
        context=context,
        correlation=corr,
        free=cov.names,
        at_bound=at_bound,
        messages=[m for m in base.messages if m not in base_notes] + bound_notes(at_bound),
        loop_span_V=prob.loop.span_V if prob.loop is not None else None,
    )


def _listed(
    effect: Effect,
    fit: FitOutcome,
    sd: dict[str, float | None],
    corr: dict[str, dict[str, float]],
) -> dict[str, Any]:
    """The JSON item of one fitted effect: its parameters, their 1-sigma (``sd``, every free
    parameter's: ``None``, not determined), their correlations with every free parameter
    (``corr``), its description."""
    p = {k: float(v) for k, v in fit.effects.get(effect.name, {}).items()}
    own = {k: f"{effect.name}.{k}" for k in p}
    unc = {k: sd.get(q) for k, q in own.items()}
    return {
        "effect": effect.name,
        "params": p,
        "uncertainty": unc,
        "correlation": {k: corr[q] for k, q in own.items() if q in corr},
        "description": effect.describe(p, unc),
    }
