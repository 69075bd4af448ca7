"""An empirical effect: terms found in the residual, added to the modelled strain.

``S -> S + sum_k c_k theta_k(S, ctx)``, each ``theta_k`` a readable term of the voltage, its
rate, the strain and an auxiliary channel divided by its full-scale size (the library and the
selection are :mod:`labrig.analysis.terms`), so ``c_k`` is the strain (ue) the term adds at full
scale. One parameter per term: null 0, either sign, bounded by the campaign's strain scale.

It is **empirical**: a description of the residual, never a physical attribution. Its
description says so, and where a term corresponds to a named physical effect (``V^2``:
electrostriction, ``quadratic_term``; ``V^3`` or ``S|S|``: saturation, ``field_saturation``;
``(T - T_ref) S``: a thermal gain, ``thermal_drift``) it names that effect as the one to try.

An ``"output"`` effect, but not linear in the strain it receives when a term does not depend
on ``S`` (``V^3``) or depends on it nonlinearly (``S|S|``): :meth:`EmpiricalTerms.tangent` is
its linearisation, ``dS -> dS + sum_k c_k d theta_k / dS dS``, for propagating a derivative of
the strain through it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from labrig.model.effects.base import Context, Effect, Param, fmt3

__all__ = ["EMPIRICAL_NOTE", "EmpiricalTerms", "TermLike"]

#: what the description and the caveats say of every empirical term
EMPIRICAL_NOTE = "EMPIRICAL terms found in the residual, not a physical attribution"


class TermLike(Protocol):
    """What the effect needs of a term (:class:`labrig.analysis.terms.Term`)."""

    key: str
    name: str
    unit: str
    scale: float
    physics: str
    effect: str

    def values(self, S: NDArray, ctx: Context) -> NDArray: ...

    def slope(self, S: NDArray, ctx: Context) -> NDArray | float: ...

    def reading(self, coefficient: float) -> tuple[str, str]: ...


class EmpiricalTerms(Effect):
    """``S -> S + sum_k c_k theta_k(S, ctx)`` for the given terms (module docstring);
    ``strain_scale_ue`` (the campaign's largest strain span) bounds every ``c_k`` to
    ``+- strain_scale_ue``."""

    name = "empirical_terms"
    where = "output"
    acts_on = "measured strain"
    params_doc = "one coefficient per selected term (0)"
    form = "`S + sum_k c_k theta_k`, terms selected from the residual by sparse regression"
    physics = EMPIRICAL_NOTE
    signature = "whatever the selected terms describe (found by sparse regression)"
    confusable = ()
    tell_apart = (
        "try the named effect a term corresponds to; an experiment that changes only that "
        "term's variable (amplitude, rate, temperature) tells whether the term is physical"
    )

    def __init__(self, terms: Sequence[TermLike], strain_scale_ue: float, strain_unit: str = "ue"):
        if not terms:
            raise ValueError("an empirical effect needs at least one term")
        keys = [t.key for t in terms]
        if len(set(keys)) != len(keys):
            raise ValueError(f"terms repeated: {keys}")
        b = float(strain_scale_ue)
        if not (np.isfinite(b) and b > 0):
            raise ValueError(f"strain_scale_ue must be positive, got {strain_scale_ue}")
        self.terms = tuple(terms)
        self.strain_scale_ue = b
        self.strain_unit = strain_unit
        self.params = tuple(
            Param(self.param_name(t.key), strain_unit, 0.0, -b, b, 0.01 * b) for t in self.terms
        )

    @staticmethod
    def param_name(key: str) -> str:
        """The parameter of the term ``key``: its strain at full scale (ue)."""
        return f"c_{key}"

    def apply(self, x: NDArray, ctx: Context, p: Mapping[str, float]) -> NDArray:
        out = np.array(x, dtype=float, copy=True)
        for t in self.terms:
            c = p[self.param_name(t.key)]
            if c != 0.0:
                out += c * t.values(x, ctx)
        return out

    def tangent(self, x: NDArray, dx: NDArray, ctx: Context, p: Mapping[str, float]) -> NDArray:
        """The derivative of :meth:`apply` at the strain ``x`` along ``dx``."""
        gain: NDArray | float = 1.0
        for t in self.terms:
            c = p[self.param_name(t.key)]
            if c != 0.0:
                gain = gain + c * t.slope(x, ctx)
        return gain * np.asarray(dx, dtype=float)

    def correspondences(self) -> list[tuple[str, str, str]]:
        """``(term, what it reads as, library effect)`` for each term that corresponds to one."""
        out = []
        for t in self.terms:
            for phys, eff in {t.reading(1.0), t.reading(-1.0)}:
                if eff:
                    out.append((t.name, phys, eff))
        return out

    def caveats(self, p: Mapping[str, float], span_s: float) -> list[str]:
        return [
            f"{EMPIRICAL_NOTE}: they describe the residual; the named effects they correspond "
            "to (if any) are the ones to test"
        ]

    def physical(self, p: Mapping[str, float]) -> dict[str, float]:
        return {self.param_name(t.key): float(p[self.param_name(t.key)]) for t in self.terms}

    def describe(self, p: Mapping[str, float], sd: Mapping[str, float | None]) -> str:
        parts = []
        for t in self.terms:
            n = self.param_name(t.key)
            c, s = p.get(n), sd.get(n)
            if c is None:
                text = f"{t.name}"
            else:
                pm = "" if s is None or not np.isfinite(s) else f" +- {fmt3(s)}"
                text = (
                    f"{t.name}: {fmt3(c)}{pm} {self.strain_unit} at full scale "
                    f"({fmt3(c / t.scale)} {self.strain_unit} per {t.unit})"
                )
            physics, effect = t.reading(c if c is not None else 1.0)
            if effect:
                text += f", reads as {physics} (cf. {effect})"
            elif physics:
                text += f", reads as {physics}"
            parts.append(text)
        return f"{EMPIRICAL_NOTE}: " + "; ".join(parts)
