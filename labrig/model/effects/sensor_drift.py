"""The ``sensor_drift`` effect: a slow drift of the strain sensor over a simulated sequence,
a few cosine terms (:class:`SensorDrift`, its basis :func:`drift_basis`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from labrig.model.effects.base import Context, Effect, Param

__all__ = ["TERMS", "SensorDrift", "drift_basis"]

#: the number of cosine terms: a drift slower than a third of the sequence's duration
TERMS = 3


def drift_basis(n: int, terms: int = TERMS) -> NDArray[np.float64]:
    """``n x terms`` columns ``cos(pi k (i + 1/2) / n)``, ``k = 1..terms``, over the samples
    ``i`` of a sequence (the DCT-II basis without its constant: orthogonal, each of mean 0 and
    RMS ``1/sqrt 2``); column ``k`` has ``k`` half-periods over the sequence."""
    i = np.arange(n) + 0.5
    k = np.arange(1, terms + 1)
    return np.cos(np.pi * np.outer(i, k) / max(n, 1))


class SensorDrift(Effect):
    """A slow drift of the strain sensor over the whole simulated sequence:
    ``S -> S + sum_k c_k cos(pi k (t + dt/2) / T)``, ``k = 1..3``, ``T`` the sequence's
    duration (:func:`drift_basis`), ``c_k`` in ue.

    Physics: the gauge bridge's zero wanders as it warms up and as its adhesive relaxes, slowly
    and independently of the voltage, over the whole run (minutes), not entry by entry.

    Why global, not a nuisance: ``offset_drift`` already is the per-entry form (an offset and a
    slope per entry, eliminated by least squares, 2 parameters per entry); a per-entry linear
    trend carrying a large share of the residual (23 % on a four-waveform record) is found by
    it. This effect is the campaign-long form: three parameters for the whole run, the drift of
    a held-out entry interpolated from its neighbours instead of refitted on it, and curvature
    within long entries that a per-entry line cannot follow. On a chained run (``chain=True``)
    the sequence is the campaign; with records simulated apart each record is its own sequence
    and the three terms are one drift shape shared by every record (a drift that restarts with
    each capture, e.g. a sensor re-zeroed at each start). Its terms have zero mean over the
    sequence: a constant offset is the per-entry offset's. Acts additively on the measured
    output (so its tangent along the strain is the identity, not the effect itself).

    Signature: a smooth trend across entries that is independent of the voltage, present in
    rests and at 0 V, continuing through the rests between entries. Null: every ``c_k = 0``.
    Confusable with ``offset_drift`` (the per-entry form), ``thermal_drift`` (which scales with
    the strain) and ``creep`` (which follows the voltage's changes).
    """

    name = "sensor_drift"
    where = "output"
    acts_on = "measured strain (additive, whole sequence)"
    params_doc = "`c1_ue`, `c2_ue`, `c3_ue` (0)"
    form = "`S + sum_k c_k cos(pi k t/T)`, `k = 1..3`, `T` the sequence's duration"
    physics = "slow drift of the strain sensor's zero over the whole run"
    signature = "smooth trend across entries, independent of V, continuing through rests"
    confusable = ("offset_drift", "thermal_drift", "creep")
    tell_apart = (
        "record the sensor at 0 V before, between and after the entries: a sensor drift moves "
        "there too; thermal drift and creep do not move at 0 V"
    )
    params = tuple(
        Param(f"c{k}_ue", "ue", 0.0, -500.0, 500.0, 1.0 if k == 1 else 0.0)
        for k in range(1, TERMS + 1)
    )

    def basis(self, ctx: Context, n: int) -> NDArray:
        """The drift columns of a sequence of ``n`` samples (cached)."""
        return ctx.cached(("drift_basis", n), lambda: drift_basis(n))

    def _coeffs(self, p) -> NDArray:
        return np.array([p[q.name] for q in self.params], dtype=float)

    def apply(self, x, ctx, p):
        c = self._coeffs(p)
        if not np.any(c):
            return x
        return x + self.basis(ctx, x.shape[0]) @ c

    def tangent(self, x, dx, ctx, p):
        return dx  # additive: the strain's changes pass unchanged

    def tangent_columns(self, x, dX, ctx, p):
        return dX

    def parameter_derivatives(self, x, ctx, p):
        B = self.basis(ctx, x.shape[0])
        return {q.name: B[:, j] for j, q in enumerate(self.params)}

    def describe(self, p, sd):
        c = self._coeffs(p)
        peak = float(np.max(np.abs(drift_basis(256) @ c)))
        terms = ", ".join(f"{v:.3g}" for v in c)
        return f"sensor drift up to {peak:.3g} ue over the sequence (cosine terms {terms} ue)"
