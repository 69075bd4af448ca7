"""One candidate tried against the current model: refitted with every parameter free, cross-
validated when its in-sample gain is large enough, judged by the acceptance rule.

Steps 4-6 of :mod:`.procedure` for one effect. A refit starts from the effect's probe value
(the ranking's best) and from each of its further starts (:meth:`Effect.refit_starts`: a
filter's time constant traded against ``G_d`` has local optima): first the effect with the
operator's gains only (``V*`` does not move), then everything free; the lowest cost wins. A
voltage effect may start from the base refitted to the records driven through it (the base
compensated the distorted drive), when that is better.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from labrig.analysis.diagnose.acceptance import Candidate, accept
from labrig.analysis.diagnose.state import Model, Settings, Setup, mean_of
from labrig.analysis.diagnose.verdict import signature_clause
from labrig.analysis.extended import LAM_GAP, ExtendedProblem, FitOutcome
from labrig.analysis.simulate import PARAM_NAMES
from labrig.model.effects import Effect

__all__ = ["MAX_NFEV", "json_params", "numeric", "try_candidate"]

#: evaluation limit of a candidate's full fit (its folds get less: ExtendedProblem.heldout)
MAX_NFEV = 60
#: evaluation limit of the first, gains-only fit from each start
PRE_NFEV = 30
#: the operator's gains: what the first fit of a refit frees besides the effect
GAINS = ("alpha0_ue_per_V", "gamma_ue_per_V")
#: a candidate whose direction explains less of the residual than this (the ranking's score)
#: is refitted from its best probe only, not from each of its further starts: reaching the
#: in-sample gain that earns a cross-validation (half the minimum gain, 7.5 % of NRMSE, i.e.
#: about 14 % of the residual's energy) would take seven times what its direction explains
SCREEN_SHARE = 0.02


def numeric(params) -> dict[str, float]:
    """The fitted (numeric) parameters of a :class:`~labrig.model.ModelParams`."""
    return {n: float(getattr(params, n)) for n in PARAM_NAMES}


class FixedVoltage(Effect):
    """A voltage effect with its parameters held at given values (no free parameter): the
    records driven through it, for :func:`voltage_start`."""

    where = "voltage"

    def __init__(self, effect: Effect, values: Mapping[str, float]):
        self.effect = effect
        self.values = dict(values)
        # a name per value set: the engine's shared simulations are keyed by effect names
        self.name = f"{effect.name}@" + ",".join(f"{k}={v!r}" for k, v in sorted(values.items()))
        self.params = ()

    def apply(self, x, ctx, p):
        return self.effect.apply(x, ctx, self.values)


def voltage_start(
    setup: Setup, settings: Settings, current: Model, eff: Effect, probe: Mapping[str, float]
) -> dict[str, float] | None:
    """Base parameters refitted to the records driven by the voltage effect at ``probe`` (the
    other effects of the current model absent), from the current base, to convergence: a start
    for base + a voltage effect (``None`` if that fit fails)."""
    prob = setup.problem(settings, [FixedVoltage(eff, probe)])
    try:
        fo = prob.fit(current.fit.base, tight=True)
    except (ValueError, RuntimeError, np.linalg.LinAlgError):
        return None
    if not np.isfinite(fo.cost):
        return None
    b = dict(fo.base)
    if abs(b["lam_d"] - 1.0) < LAM_GAP:
        b["lam_d"] = 1.0 + LAM_GAP
    return b


def _start(
    setup: Setup,
    settings: Settings,
    current: Model,
    prob: ExtendedProblem,
    eff: Effect,
    probe: Mapping[str, float],
) -> dict[str, float]:
    """The base start of a refit (module docstring)."""
    start = dict(current.fit.base)
    if eff.where != "voltage":
        return start
    alt = voltage_start(setup, settings, current, eff, probe)
    if alt is None:
        return start
    e0 = {**current.fit.effects, eff.name: dict(probe)}
    costs = []
    for b in (start, alt):
        rb = prob.residual(prob.z_of(b, e0), b)
        costs.append(float(rb @ rb))
    return alt if costs[1] < costs[0] else start


def refit(
    setup: Setup,
    settings: Settings,
    current: Model,
    prob: ExtendedProblem,
    eff: Effect,
    probe: Mapping[str, float],
    score: float = 1.0,
) -> FitOutcome:
    """Base + candidate refitted from each of the effect's starts (from its best probe only
    when its ``score`` is under :data:`SCREEN_SHARE`); the lowest cost wins."""
    start = _start(setup, settings, current, prob, eff, probe)
    gains = [n for n in GAINS if n in setup.base_free]
    pre = setup.problem(settings, [*current.effects, eff], base_free=gains)
    best: FitOutcome | None = None
    starts = eff.refit_starts(probe) if score >= SCREEN_SHARE else [dict(probe)]
    for e0 in starts:
        f1 = pre.fit(start, {**current.fit.effects, eff.name: e0}, tight=False, max_nfev=PRE_NFEV)
        f2 = prob.fit(f1.base, f1.effects, max_nfev=MAX_NFEV)
        if best is None or f2.cost < best.cost:
            best = f2
    if best is None:  # refit_starts always gives the probe itself
        raise RuntimeError(f"{eff.name}: no start to refit from")
    return best


#: numerical breakdowns of a candidate's fit (a filter designed from parameters the optimiser
#: drove to NaN, a singular system): the candidate is refused with the reason
FIT_FAILURES = (np.linalg.LinAlgError, FloatingPointError, ValueError)


def try_candidate(
    setup: Setup,
    settings: Settings,
    current: Model,
    eff: Effect,
    probe: Mapping[str, float],
    rnd: int,
    score: float,
    say: Callable[[str], Any],
    workers: int = 1,
) -> tuple[Candidate, ExtendedProblem]:
    """Refit one candidate, cross-validate it if it gains enough in-sample (its folds on
    ``workers`` processes), judge it; returns the candidate (with its evidence sentence) and
    its problem."""
    c = Candidate(eff.name, rnd, score)
    say(f"round {rnd + 1}: fitting base + {eff.name}")
    prob = setup.problem(settings, [*current.effects, eff])
    try:
        fo = refit(setup, settings, current, prob, eff, probe, score)
    except FIT_FAILURES as e:  # a candidate whose fit breaks down is refused, not fatal
        c.reasons.append(f"its fit failed ({type(e).__name__}: {e})")
        c.evidence = (
            f"{signature_clause(eff, current.evidence)}; base + {eff.name} could not be "
            f"fitted ({type(e).__name__}: {e}); not added"
        )
        return c, prob
    c.tried, c.fit = True, fo
    c.insample_gain = 1.0 - fo.nrmse_pct / current.fit.nrmse_pct
    clause = signature_clause(eff, current.evidence)
    desc = eff.describe(fo.effects.get(eff.name, {}), fo.sd.get(eff.name, {}))
    if c.insample_gain < 0.5 * settings.min_gain:
        c.reasons.append(f"in-sample gain only {100 * c.insample_gain:.1f} %, not cross-validated")
        c.evidence = (
            f"{clause}; adding {eff.name} ({desc}) changes the in-sample NRMSE from "
            f"{current.fit.nrmse_pct:.3g} % to {fo.nrmse_pct:.3g} % only: not cross-validated"
        )
        return c, prob
    say(f"round {rnd + 1}: cross-validating base + {eff.name}")
    try:
        c.heldout_per_entry = prob.heldout(fo, workers=workers)
    except FIT_FAILURES as e:
        c.reasons.append(f"its cross-validation failed ({type(e).__name__}: {e})")
        c.evidence = f"{clause}; adding {eff.name} ({desc}): cross-validation failed ({e})"
        return c, prob
    c.heldout_nrmse_pct = mean_of(c.heldout_per_entry)
    a = accept(
        eff,
        fo,
        c.heldout_per_entry,
        current.heldout,
        settings.min_gain,
        setup.span_s,
        current.evidence.floor_pct,
    )
    c.judged(a)
    verb = "cuts" if a.gain > 0 else "raises"
    c.evidence = (
        f"{clause}; adding {eff.name} ({desc}) {verb} held-out NRMSE from "
        f"{current.heldout_pct:.3g} % to {c.heldout_nrmse_pct:.3g} % "
        f"(better in {a.wins}, worse in {a.losses} of {len(current.heldout)} folds)"
        + ("" if a.accepted else "; rejected: " + "; ".join(a.reasons))
        + ("; suspicious: " + "; ".join(a.suspicious) if a.suspicious and a.accepted else "")
    )
    return c, prob


def json_params(eff: Effect, fo: FitOutcome) -> dict[str, Any]:
    """An added effect's parameters as ``diagnose --json`` gives them: physical values and
    their 1-sigma, a nuisance effect's description."""
    p = fo.effects.get(eff.name, {})
    out: dict[str, Any] = {}
    for k, v in eff.physical(p).items():
        out[k] = v if isinstance(v, str) else (float(v) if np.isfinite(v) else None)
    for k, s in fo.sd.get(eff.name, {}).items():
        out[f"{k}_sd"] = s
    if eff.where == "nuisance":
        out["description"] = eff.describe({}, {})
    return out
