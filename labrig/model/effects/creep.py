"""The ``creep`` effect: logarithmic creep under sustained voltage (:class:`Creep`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import fft as sp_fft

from labrig.model.effects.base import Context, Effect, Param, plus_minus

__all__ = ["Creep"]


class Creep(Effect):
    """Logarithmic creep under sustained voltage: ``S -> S + c (k * dS)``, ``k(t) = log10(1 +
    t / t0)``, ``c`` and ``t0`` fitted.

    Physics: slow domain-wall motion keeps the strain rising by a fraction ``c`` (1-2 %) per
    decade of time after every change, from about ``t0`` on. Acts on the output of the operator
    (each strain change creeps on). Signature: slow trend after level changes that scales with
    the amplitude, strain shift after the drive stops; with ``t0`` of milliseconds, also a gain
    and phase that fall slowly with frequency across the sweep. Null: ``c = 0``. Confusable with
    offset drift, thermal drift and the model's own slow relaxor ``G_t``, which follows most of a
    logarithmic creep by itself: what remains is 0.05-0.08 % of the span for 2-4 %/decade
    (docs/diagnose.md), so the effect is found only on a gauge quiet enough to show it.

    ``t0`` is fitted (0.1 ms to 10 s, log scale) because the part of a creep that starts within
    the sweep's periods is what ``G_t`` cannot take. Measured on a noise-free campaign with
    4 %/decade of creep (the bench's mode bank): base alone 0.083 % in-sample NRMSE; with this
    effect and ``t0`` fixed at 0.05 s, 0.079 %; with ``t0`` fitted, 0.016 % (c 3.9 %/decade,
    ``t0`` 1.7 ms, the base back at its creep-free values), the same campaign without creep
    0.014 %.
    """

    name = "creep"
    where = "output"
    acts_on = "operator output"
    params_doc = "`c_per_decade` (0), `t0_s` (0.1 ms-10 s)"
    form = "`S + c (log10(1 + t/t0) * dS)`"
    physics = "logarithmic creep (domain-wall motion) under sustained voltage"
    signature = "slow trend after level changes, scaling with the amplitude"
    confusable = ("offset_drift", "thermal_drift")
    tell_apart = (
        "a step-and-hold entry at 50 and 100 V (creep scales with the step, drift does not)"
    )
    params = (
        Param("c_per_decade", "", 0.0, -0.05, 0.2, 0.005, sign=+1),
        Param("t0_s", "s", 0.05, 1e-4, 10.0, 0.05, log=True, starts=(0.001, 0.01, 0.1, 1.0)),
    )

    def probes(self, contexts):
        return [{"c_per_decade": 0.005, "t0_s": t0} for t0 in (0.002, 0.05, 1.0)]

    def caveats(self, p, span_s):
        """A log creep seen over less than two decades of time (``t0`` above 1 % of the data's
        span) is not told from one slow mode, and its rate per decade is an extrapolation."""
        t0 = p["t0_s"]
        if p["c_per_decade"] <= 0 or 100.0 * t0 <= span_s:
            return []
        decades = np.log10(span_s / t0)
        seen = f"{decades:.1f} decades" if decades >= 0.1 else "less than a decade"
        return [
            f"creep is seen over {seen} of time only (t0 = {1e3 * t0:.3g} ms, {span_s:.3g} s "
            "simulated at a stretch): one slow mode (viscoelastic_creep) may do as well, and the "
            "rate per decade is an extrapolation"
        ]

    def kernel(self, ctx: Context, t0_s: float) -> NDArray:
        """``log10(1 + t / t0)`` on the context's time base (cached per ``t0``)."""
        return ctx.cached(("creep_kernel", t0_s), lambda: np.log10(1.0 + ctx.t / t0_s))

    def _spectra(self, ctx: Context, t0_s: float) -> tuple[int, NDArray, NDArray]:
        """The FFT length and the spectra of the kernel and of its derivative with respect to
        ``t0`` (``-t / (t0 (t0 + t) ln 10)``), cached per ``t0``: every convolution of a fit's
        evaluation (the strain, each Jacobian column) reuses them."""

        def make() -> tuple[int, NDArray, NDArray]:
            nf = sp_fft.next_fast_len(2 * ctx.n - 1, real=True)
            t = ctx.t
            dk = -t / (t0_s * (t0_s + t) * np.log(10.0))
            return nf, sp_fft.rfft(self.kernel(ctx, t0_s), nf), sp_fft.rfft(dk, nf)

        return ctx.cached(("creep_spectra", t0_s), make)

    def _convolve(self, ds: NDArray, spectrum: NDArray, nf: int) -> NDArray:
        """``ds * kernel`` (causal, the first ``N`` samples), column-wise for a 2-D ``ds``: the
        columns are transformed as the rows of a transposed copy (the same numbers as along
        axis 0, a quarter less CPU)."""
        if ds.ndim == 1:
            return sp_fft.irfft(sp_fft.rfft(ds, nf) * spectrum, nf)[: ds.size]
        rows = np.ascontiguousarray(ds.T)
        spec = spectrum.T if spectrum.ndim == 2 else spectrum
        out = sp_fft.irfft(sp_fft.rfft(rows, nf, axis=1) * spec, nf, axis=1)
        return out[:, : ds.shape[0]].T

    def _steps(self, x: NDArray, ctx: Context, t0_s: float) -> tuple[NDArray, NDArray]:
        """For a strain ``x`` (1-D): the spectrum of its steps ``dS`` and ``dS * kernel``. The
        last strain's are kept on the context (one entry, compared sample by sample), so the
        Jacobian pass that applies the effect to a strain and then differentiates it with
        respect to ``c`` and ``t0`` transforms that strain once."""
        nf, K, _ = self._spectra(ctx, t0_s)
        last = ctx.cache.get(_LAST)
        if (
            last is not None
            and last[0] == (t0_s, nf)
            and last[1].shape == x.shape
            and np.array_equal(last[1], x)
        ):
            return last[2], last[3]
        spec = sp_fft.rfft(np.diff(x, prepend=0.0), nf)
        conv = sp_fft.irfft(spec * K, nf)[: x.size]
        ctx.cache[_LAST] = ((t0_s, nf), x.copy(), spec, conv)
        return spec, conv

    def apply(self, x, ctx, p):
        c = p["c_per_decade"]
        if c == 0.0:
            return x
        if np.ndim(x) == 1:
            return x + c * self._steps(np.asarray(x, dtype=float), ctx, p["t0_s"])[1]
        nf, K, _ = self._spectra(ctx, p["t0_s"])
        return x + c * self._convolve(np.diff(x, axis=0, prepend=0.0), K, nf)

    def tangent_columns(self, x, dX, ctx, p):
        return self.apply(dX, ctx, p)

    def parameter_derivatives(self, x, ctx, p):
        nf, _, dK = self._spectra(ctx, p["t0_s"])
        spec, conv = self._steps(np.asarray(x, dtype=float), ctx, p["t0_s"])
        d_t0 = sp_fft.irfft(spec * dK, nf)[: conv.size]
        return {"c_per_decade": conv, "t0_s": p["c_per_decade"] * d_t0}

    def describe(self, p, sd):
        s, s0 = sd.get("c_per_decade"), sd.get("t0_s")
        return (
            plus_minus("c", 100 * p["c_per_decade"], None if s is None else 100 * s, "% per decade")
            + ", "
            + plus_minus("t0", 1e3 * p["t0_s"], None if s0 is None else 1e3 * s0, "ms")
        )


#: the context's cache key of the last strain's step spectrum (:meth:`Creep._steps`)
_LAST = ("creep_last_steps",)
