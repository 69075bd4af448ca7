"""The ``sensor_drift`` effect: a slow drift of the strain sensor over a simulated sequence,
a cubic in time from the zero it starts at (:class:`SensorDrift`, its basis
:func:`drift_basis`).
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import legendre
from numpy.typing import NDArray

from labrig.model.effects.base import Context, Effect, Param, plus_minus

__all__ = ["TERMS", "SensorDrift", "drift_basis"]

#: the drift's degree in time (its number of terms): a drift slower than a third of the
#: sequence's duration
TERMS = 3


def drift_basis(n: int, terms: int = TERMS) -> NDArray[np.float64]:
    """``n x terms`` columns ``P_k(x_i) - P_k(x_0)``, ``k = 1..terms``, over the samples ``i``
    of a sequence, ``x_i = 2 (i + 1/2) / n - 1`` (mid-sample times mapped to [-1, 1]) and
    ``P_k`` the Legendre polynomial of degree ``k`` (:func:`numpy.polynomial.legendre.legval`):
    a polynomial drift of degree ``terms`` in time, 0 on the first sample (the drift measured
    from the zero the sequence starts at), free in value and slope elsewhere. Legendre rather
    than plain powers of ``t``: the columns are nearly orthogonal (condition number 4.4 for
    three terms, 56 for ``t, t^2, t^3``)."""
    m = max(n, 1)
    x = 2.0 * (np.arange(n) + 0.5) / m - 1.0
    x0 = 1.0 / m - 1.0
    cols = []
    for k in range(1, terms + 1):
        c = np.zeros(k + 1)
        c[k] = 1.0
        cols.append(legendre.legval(x, c) - legendre.legval(x0, c))
    return np.column_stack(cols) if cols else np.zeros((n, 0))


class SensorDrift(Effect):
    """A slow drift of the strain sensor over the whole simulated sequence, from the zero it
    starts at, in its zero and with it its span: ``S -> S (1 + g z(t) / 100 ue) + z(t)``,
    ``z(t) = sum_k c_k (P_k(x) - P_k(x_0))``, ``k = 1..3``, ``x = 2 t / T - 1`` (``t``
    mid-sample, ``T`` the sequence's duration), ``P_k`` the Legendre polynomials
    (:func:`drift_basis`), ``c_k`` in ue: a cubic in time, 0 on the first sample; ``g`` the
    span's relative change per 100 ue of zero drift.

    Physics: the gauge bridge's zero wanders as it warms up and as its adhesive relaxes, slowly
    and independently of the voltage, over the whole run (minutes), not entry by entry. The
    conditioner is balanced before the run, so the drift starts at 0 and moves one way: a
    warm-up ``D (1 - exp(-t / tau))`` has a mean of 0.3-0.6 ``D`` over a sequence of 0.8 to 2
    ``tau``, and is steepest at the start. The earlier form (three cosines ``cos(pi k t / T)``
    of zero mean) could hold neither: fitted to the bench's ``gauge_warmup`` (60 ue, tau 30 s)
    over a 24 s sequence, it left 18.7 of the warm-up's 21 ue RMS; cosines shifted to start at 0
    still left 1.1 ue (each has zero slope at the start); this cubic leaves 0.004 ue (0.02 %),
    0.4 % for tau 10 s, 2 % for tau 5 s.

    Why the span: the zero and the sensitivity of a bridge and its conditioner move with the same
    temperature (the gauge factor, the bridge's completion resistors, the conditioner's gain), so
    a warm-up changes the span along the zero's time course; the span's share is the strain
    times it, which no additive term holds and which differs between entries at different mean
    strains. One coefficient ties it to the zero (both follow one temperature); ``g = 0`` is a
    zero drift alone. On the bench's warm-up (zero 60 ue, span 1 %, so 1.7 % per 100 ue) the
    fitted ``g`` is 1.56 +- 0.04 %, and without it a per-entry offset and slope
    (``offset_drift``, refitted on each held-out entry) held the warm-up better than this drift.

    Why global, not a nuisance: ``offset_drift`` already is the per-entry form (an offset and a
    slope per entry, eliminated by least squares, 2 parameters per entry); a per-entry linear
    trend carrying a large share of the residual (23 % on a four-waveform record) is found by
    it. This effect is the campaign-long form: three parameters for the whole run, the drift of
    a held-out entry interpolated from its neighbours instead of refitted on it, and curvature
    within long entries that a per-entry line cannot follow. On a chained run (``chain=True``)
    the sequence is the campaign; with records simulated apart each record is its own sequence
    and the three terms are one drift shape shared by every record (a drift that restarts with
    each capture, e.g. a sensor re-zeroed at each start). A constant zero error (a bridge that
    was never balanced) is not a drift: it is the per-entry offset's (``--offset``), with which
    these terms stay identifiable (they are not constant). Acts on the measured output: its
    tangent along the strain is the span factor ``1 + g z / 100 ue`` (the identity when ``g =
    0``), not the effect itself.

    Signature: a smooth trend across entries that is independent of the voltage, present in
    rests and at 0 V, continuing through the rests between entries. Null: every ``c_k = 0`` (then
    ``g`` acts on nothing) and ``g = 0``.
    Confusable with ``offset_drift`` (the per-entry form), ``thermal_drift`` (which scales with
    the strain) and ``creep`` (which follows the voltage's changes).
    """

    name = "sensor_drift"
    where = "output"
    acts_on = "measured strain (zero and span, whole sequence)"
    params_doc = "`c1_ue`, `c2_ue`, `c3_ue` (0), `span_per_100ue` (0)"
    form = (
        "`S (1 + g z/100 ue) + z`, `z = sum_k c_k (P_k(2t/T - 1) - P_k(-1))`, `P_k` Legendre, "
        "`k = 1..3`: a cubic in `t` from 0, the span following the zero"
    )
    physics = "slow drift of the strain sensor's zero over the whole run"
    signature = "smooth trend across entries, independent of V, continuing through rests"
    confusable = ("offset_drift", "thermal_drift", "creep")
    tell_apart = (
        "record the sensor at 0 V before, between and after the entries: a sensor drift moves "
        "there too; thermal drift and creep do not move at 0 V"
    )
    params = (
        *(
            Param(f"c{k}_ue", "ue", 0.0, -500.0, 500.0, 1.0 if k == 1 else 0.0)
            for k in range(1, TERMS + 1)
        ),
        # the span's relative change per 100 ue of zero drift: 20 % is a broken bridge
        Param("span_per_100ue", "", 0.0, -0.2, 0.2, 0.0),
    )

    def basis(self, ctx: Context, n: int) -> NDArray:
        """The drift columns of a sequence of ``n`` samples (cached)."""
        return ctx.cached(("drift_basis", n), lambda: drift_basis(n))

    def _coeffs(self, p) -> NDArray:
        return np.array([p[f"c{k}_ue"] for k in range(1, TERMS + 1)], dtype=float)

    def zero(self, ctx: Context, n: int, p) -> NDArray:
        """The zero's drift ``z`` (ue) over a sequence of ``n`` samples."""
        return self.basis(ctx, n) @ self._coeffs(p)

    def _span(self, ctx: Context, n: int, p) -> NDArray | float:
        g = p.get("span_per_100ue", 0.0)
        return 1.0 + (g / 100.0) * self.zero(ctx, n, p) if g else 1.0

    def apply(self, x, ctx, p):
        c = self._coeffs(p)
        if not np.any(c):
            return x
        z = self.zero(ctx, x.shape[0], p)
        return x * (1.0 + (p.get("span_per_100ue", 0.0) / 100.0) * z) + z

    def tangent(self, x, dx, ctx, p):
        return dx * self._span(ctx, x.shape[0], p)  # the strain's changes through the span

    def tangent_columns(self, x, dX, ctx, p):
        span = self._span(ctx, x.shape[0], p)
        return dX * (span[:, None] if isinstance(span, np.ndarray) else span)

    def parameter_derivatives(self, x, ctx, p):
        B = self.basis(ctx, x.shape[0])
        g = p.get("span_per_100ue", 0.0) / 100.0
        out = {f"c{k}_ue": B[:, k - 1] * (1.0 + g * x) for k in range(1, TERMS + 1)}
        out["span_per_100ue"] = x * (B @ self._coeffs(p)) / 100.0
        return out

    def describe(self, p, sd):
        c = self._coeffs(p)
        peak = float(np.max(np.abs(drift_basis(256) @ c)))
        terms = ", ".join(f"{v:.3g}" for v in c)
        g = p.get("span_per_100ue", 0.0)
        return (
            f"sensor drift up to {peak:.3g} ue over the sequence (Legendre terms {terms} ue), "
            + plus_minus(
                "span",
                100 * g,
                None if sd.get("span_per_100ue") is None else 100 * sd["span_per_100ue"],
                "% per 100 ue of zero drift",
            )
        )
