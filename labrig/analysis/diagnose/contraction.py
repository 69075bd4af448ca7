"""A sparse ODE that contracts under a sustained drive: its long-run growth rate, and the
output-error refinement of its coefficients with that rate bounded below zero.

For the library of :mod:`labrig.analysis.sindy` the equation reads ``dS/dt = a(V, V') +
b(V') S + c S|S|`` with ``b = xi_S + xi_{V'S} V' + xi_{|V'|S} |V'|``; a disturbance of the
strain grows or decays as ``exp(int df/dS dt)``, ``df/dS = b(V') + 2 c |S|`` (one state
variable: this is the free run's Lyapunov exponent, :func:`~.sparse_ode.growth_rate`). Over a
drive sustained long, the mean of ``V'`` goes to 0 (the voltage stays bounded: its mean rate is
its change over the span divided by the span; exactly 0 over whole periods of a periodic drive),
so the ``V' S`` term adds nothing to the long-run rate and

    lambda = xi_S + xi_{|V'|S} mean|V'| + 2 c mean|S|  <=  g = xi_S + xi_{|V'|S} mean|V'|

whenever ``c <= 0`` (:func:`long_run_growth` is ``g``; a positive ``S|S|`` runs away from a
large enough strain, so it has no such bound and is judged along its free run, ``g + 2 c
mean|S|``). ``g < 0`` is the Duhem / Bouc-Wen condition
``dS/dt = a V' + |V'| (b V - c' S)`` contracts iff ``c' > 0``, with the lag ``S`` and the
saturation ``S|S|`` added; a linear ``dS/dt = a(t) + b(t) S`` under a periodic drive is bounded
iff the period's mean of ``b`` is negative (Floquet), so ``g <= -margin`` keeps its free run
bounded over any number of periods of the drive.

:func:`refine_contracting` refits a candidate's coefficients on its support (the lag ``S``
added when missing) by output error as :func:`~.sparse_ode.refine` does, with ``g`` itself as
a parameter in place of ``xi_S`` (``xi_S = g - xi_{|V'|S} mean|V'|``), bounded by ``g <=
-margin`` (:func:`contraction_margin`: a disturbance shrinks by at least
:data:`MARGIN_PER_PERIOD` per drive period), and ``c <= 0``: ``scipy.optimize.least_squares``
with bounds (trust region reflective).

Both refinements run on the exact Jacobian of the output error (:func:`output_jacobian`): the
forward sensitivities of the free run's recursion, ``J_{n+1} = (dS_{n+1}/dS_n) J_n +
dS_{n+1}/dxi``, computed beside the run (:func:`~labrig.analysis.sindy.free_run_sensitivities`)
and carried through the parametrisation by the chain rule. One sensitivity run costs 1.5-1.7
free runs (about 2 with the weighting of its rows), where forward differences cost one per
parameter, and it carries no difference
step's error (forward differences with a step of 1e-6 of each coefficient: 1e-9 to 1.4e-6 of
each column on a ten-term test equation).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.baseline_kernels import kernel
from labrig.analysis.sindy import LIBRARY, SindyBaseline, free_run, free_run_sensitivities
from labrig.analysis.spectra import estimate_frequency_hz

__all__ = [
    "CONTRACTING_NFEV",
    "MARGIN_PER_PERIOD",
    "REFINE_NFEV",
    "Run",
    "contraction_margin",
    "critical_rate",
    "least_squares_jacobian",
    "long_run_growth",
    "mean_abs_rate",
    "output_jacobian",
    "output_residual",
    "refine_contracting",
    "scored_runs",
    "segment_mean",
    "training_score",
]

#: a contracting ODE's disturbance shrinks by at least this fraction per drive period: the
#: bound on the long-run growth rate is ``-MARGIN_PER_PERIOD x`` the drive frequency (1/s)
MARGIN_PER_PERIOD = 0.05
#: the output-error refinement's budget of free runs (``least_squares``'s ``max_nfev``; the
#: Jacobian's sensitivity runs not counted)
REFINE_NFEV = 40
#: :func:`refine_contracting`'s budget of free runs (``max_nfev``)
CONTRACTING_NFEV = 40

_NAMES = [t.name for t in LIBRARY]
_S, _AS, _C = _NAMES.index("S"), _NAMES.index("|V'| S"), _NAMES.index("S|S|")

#: per sequence: voltage up to its last scored sample (V), rest voltage (V), rate (Hz) and the
#: scored segments as ``(lo, hi, measured, 1 / (span sqrt(n)))``
Run = tuple[NDArray, float, float, list[tuple[int, int, NDArray, float]]]


def scored_runs(items: Sequence[tuple[Any, list]]) -> list[Run]:
    """Per sequence of ``items``: its voltage up to its last scored sample, rest voltage, rate
    and the scored segments with their weights ``1 / (span sqrt(n))`` (:data:`Run`)."""
    runs = []
    for seq, segs in items:
        end = max(g.hi for g in segs)
        cuts = [
            (g.lo, g.hi, g.measured_ue, 1.0 / (float(np.ptp(g.measured_ue)) * np.sqrt(g.hi - g.lo)))
            for g in segs
            if np.ptp(g.measured_ue) > 0
        ]
        runs.append((seq.voltage_V[:end], seq.rest_V, seq.rate_hz, cuts))
    return runs


def output_residual(runs: Sequence[Run], xi: NDArray, offset: bool, limit_ue: float) -> NDArray:
    """The free run's residual on every scored segment, each divided by ``span sqrt(n)`` and,
    with ``offset``, less its mean: its sum of squares is the sum of the segments' squared
    NRMSE (as fractions)."""
    out = []
    for v, rest, rate, cuts in runs:
        y = free_run(xi, v, rate, rest, limit_ue)
        for lo, hi, m, w in cuts:
            r = m - y[lo:hi]
            out.append(w * (r - r.mean() if offset else r))
    return np.concatenate(out) if out else np.zeros(1)


def output_jacobian(
    runs: Sequence[Run], xi: NDArray, offset: bool, limit_ue: float, chain: NDArray | None = None
) -> NDArray | None:
    """The derivative of :func:`output_residual` with respect to the ten coefficients, or, with
    ``chain`` (``dxi/dp``, ``10 x len(p)``), to parameters ``p`` (rows as the residual's): the
    free runs' forward sensitivities
    (:func:`~labrig.analysis.sindy.free_run_sensitivities`), weighted and centred alike;
    ``None`` without numba."""
    width = xi.size if chain is None else chain.shape[1]
    spans = [hi - lo for *_, cuts in runs for lo, hi, _m, _w in cuts]
    out = np.empty((sum(spans), width)) if spans else np.zeros((1, width))
    at = 0
    for v, rest, rate, cuts in runs:
        run = free_run_sensitivities(xi, v, rate, rest, limit_ue)
        if run is None:
            return None
        J = run[1] if chain is None else run[1] @ chain
        for lo, hi, _m, w in cuts:
            d = out[at : at + hi - lo]  # each segment's rows written in place: no copies
            np.multiply(J[lo:hi], -w, out=d)
            if offset:
                d -= d.mean(axis=0)
            at += hi - lo
    return out


def least_squares_jacobian(
    runs: Sequence[Run],
    offset: bool,
    limit_ue: float,
    unpack: Callable[[NDArray], NDArray],
    size: int,
) -> Callable[[NDArray], NDArray] | str:
    """A ``jac`` for ``scipy.optimize.least_squares`` of :func:`output_residual` in ``size``
    parameters ``p`` with ``xi = unpack(p)`` affine: the exact one (the chain ``dxi/dp`` read
    off ``unpack`` itself, column ``j`` as ``unpack(e_j) - unpack(0)``), or ``"2-point"``
    (forward differences) without numba."""
    if kernel("free_run_sensitivities") is None:
        return "2-point"
    zero = unpack(np.zeros(size))
    chain = np.column_stack([unpack(np.eye(size)[j]) - zero for j in range(size)])

    def jac(p: NDArray) -> NDArray:
        J = output_jacobian(runs, unpack(p), offset, limit_ue, chain)
        assert J is not None
        return J

    return jac


def training_score(r: NDArray, count: int) -> float:
    """The RMS over ``count`` segments of their NRMSE (%) from :func:`output_residual`'s
    residual ``r``; ``inf`` when it is not finite (a diverged free run)."""
    return 100.0 * math.sqrt(float(r @ r) / count) if np.all(np.isfinite(r)) else math.inf


def segment_mean(
    items: Sequence[tuple[Any, list]], per_sample: Callable[[Any, NDArray], NDArray]
) -> float:
    """The mean over the scored samples of ``items`` of ``per_sample(seq, v)``, a per-sample
    quantity of each sequence computed over its voltage ``v`` up to its last scored sample; 0
    without scored samples."""
    total, count = 0.0, 0
    for seq, segs in items:
        end = max(g.hi for g in segs)
        x = per_sample(seq, seq.voltage_V[:end])
        for g in segs:
            total += float(np.sum(x[g.lo : g.hi]))
            count += g.hi - g.lo
    return total / count if count else 0.0


def mean_abs_rate(items: Sequence[tuple[Any, list]]) -> float:
    """The mean ``|V'|`` (V/s) over the scored samples of ``items``, ``V'`` as the free run sees
    it (the difference of consecutive samples, the first from the rest voltage, times the
    rate)."""
    return segment_mean(
        items,
        lambda seq, v: np.abs(np.diff(np.concatenate(([float(seq.rest_V)], v)))) * seq.rate_hz,
    )


def long_run_growth(model: SindyBaseline, rate_abs: float, strain_abs: float = math.inf) -> float:
    """``g = xi_S + xi_{|V'|S} rate_abs`` (1/s; module docstring), the long-run growth rate's
    bound under a sustained drive of mean ``|V'|`` ``rate_abs`` (V/s) when the ``S|S|``
    coefficient ``c`` is not positive. A positive ``c`` has no such bound (the ODE runs away
    from a large enough strain); it is then judged along its free run: ``g + 2 c strain_abs``
    with ``strain_abs`` the free run's mean ``|S|`` under the drive (``inf`` by default)."""
    xi = model.coefficients
    g = float(xi[_S] + xi[_AS] * rate_abs)
    return g if xi[_C] <= 0 else g + 2.0 * float(xi[_C]) * strain_abs


def critical_rate(model: SindyBaseline) -> float:
    """The mean ``|V'|`` (V/s) of a sustained drive above which ``model``'s long-run growth
    bound ``g = xi_S + xi_{|V'|S} mean|V'|`` (module docstring) is positive: ``-xi_S /
    xi_{|V'|S}`` when ``xi_{|V'|S} > 0`` (a lag ``xi_S < 0`` holds a growing ``|V'| S`` back
    only while the drive is slow enough; 0 when ``xi_S >= 0``); ``inf`` when ``xi_{|V'|S} <= 0``
    and ``xi_S < 0`` (the Duhem / Bouc-Wen sign: contracts under any drive), 0 when both are
    ``>= 0``. ``nan`` for a positive ``S|S|`` coefficient (no long-run bound)."""
    xi = model.coefficients
    s, a = float(xi[_S]), float(xi[_AS])
    if xi[_C] > 0:
        return math.nan
    if a > 0:
        return max(-s / a, 0.0)
    return math.inf if s < 0 else 0.0


def contraction_margin(items: Sequence[tuple[Any, list]]) -> float:
    """The bound ``g <= -margin`` (1/s): :data:`MARGIN_PER_PERIOD` times the lowest drive
    frequency of the sequences of ``items``, each estimated from its whole voltage
    (:func:`~labrig.analysis.spectra.estimate_frequency_hz`; a part of half a period alone
    does not tell it); without one (a PRBS, a step), per the scored span (s) instead of the
    period."""
    freqs = [f for seq, _ in items if (f := estimate_frequency_hz(seq.voltage_V, seq.rate_hz))]
    if freqs:
        return MARGIN_PER_PERIOD * min(freqs)
    span = sum((g.hi - g.lo) / seq.rate_hz for seq, segs in items for g in segs)
    return MARGIN_PER_PERIOD / span if span > 0 else MARGIN_PER_PERIOD


def refine_contracting(
    items: Sequence[tuple[Any, list]], model: SindyBaseline, offset: bool, margin: float
) -> tuple[SindyBaseline, float]:
    """``model`` refined by output error on its support and ``S``, with the long-run growth
    rate bounded (module docstring): ``g <= -margin`` (1/s) under the mean ``|V'|`` of
    ``items`` and the ``S|S|`` coefficient ``<= 0``; and the refined model's training score
    (the RMS over segments of their NRMSE, %; :func:`output_residual`).

    Parameters: each other coefficient as its ratio to ``model``'s, and ``g`` in units of
    ``|xi_S|`` (``10 margin`` when ``S`` is not in the support), started at ``model``'s
    coefficients with ``g`` lowered to ``-margin - 0.05 |xi_S|`` when it is above; at most
    :data:`REFINE_NFEV` free runs of ``scipy.optimize.least_squares`` (``trf`` with bounds,
    Jacobian-scaled). The start itself when refining does not lower the cost."""
    from scipy.optimize import least_squares

    xi0 = np.asarray(model.coefficients, dtype=float)
    others = [int(k) for k in np.flatnonzero(xi0) if k != _S]
    scale = np.abs(xi0)
    scale[_S] = scale[_S] or 10.0 * margin
    rate_abs = mean_abs_rate(items)
    runs = scored_runs(items)
    count = sum(len(c) for *_, c in runs) or 1

    def unpack(p: NDArray) -> NDArray:
        xi = np.zeros(xi0.size)
        xi[others] = p[:-1] * scale[others]
        xi[_S] = p[-1] * scale[_S] - xi[_AS] * rate_abs
        return xi

    g0 = min(float(xi0[_S] + xi0[_AS] * rate_abs), -margin - 0.05 * scale[_S])
    p0 = np.array([xi0[k] / scale[k] for k in others] + [g0 / scale[_S]])
    lo, hi = np.full(p0.size, -np.inf), np.full(p0.size, np.inf)
    hi[-1] = -margin / scale[_S]
    if _C in others:
        hi[others.index(_C)] = 0.0
    p0 = np.minimum(p0, hi)

    def residual(p: NDArray) -> NDArray:
        return output_residual(runs, unpack(p), offset, model.limit_ue)

    with np.errstate(over="ignore", invalid="ignore"):
        s0 = training_score(residual(p0), count)
        sol = least_squares(
            residual,
            p0,
            jac=least_squares_jacobian(runs, offset, model.limit_ue, unpack, p0.size),
            bounds=(lo, hi),
            method="trf",
            diff_step=1e-6,
            max_nfev=CONTRACTING_NFEV,
            x_scale="jac",
        )
        s1 = training_score(sol.fun, count)
    p = sol.x if s1 < s0 else p0
    xi = unpack(p)
    return SindyBaseline(
        tuple(float(x) for x in xi), model.rate_hz, model.threshold, model.limit_ue
    ), min(s0, s1)
