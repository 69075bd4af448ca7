"""A SINDy baseline: a sparse ODE of the strain driven by the voltage, scored in free run.

The data-driven peer every verdict is read against (:func:`labrig.analysis.baselines.fit_baseline`
with ``kind="sindy"``):

    dS/dt = sum_k xi_k theta_k(S, V, V'),      V' = dV/dt

with the small readable library :data:`LIBRARY`:

==============  ===========  ==========================================================
term            xi's unit    reads as
==============  ===========  ==========================================================
``1``           ue/s         a constant drift
``S``           1/s          a first-order lag (``-1/tau``)
``V``           ue/(V s)     the drive of that lag (``gain / tau``)
``V'``          ue/V         a feed-through of the voltage's rate (instantaneous gain)
``|V'|``        ue/V         a rate-dependent offset
``V' S``        1/V          a strain-dependent gain
``V' V``        ue/V^2       a field-dependent gain (quadratic in V)
``|V'| S``      1/V          Bouc-Wen-like memory (relaxation towards a loop branch)
``|V'| V``      ue/V^2       the same memory's voltage term
``S|S|``        1/(ue s)     an odd saturation of the lag
==============  ===========  ==========================================================

The terms that carry ``V'`` make hysteresis (rate independent: ``dS = g(S, V) dV +
h(S, V) |dV|`` is a Duhem model); ``S`` and ``V`` make the response depend on the rate.

Fitting (pysindy)
-----------------
- ``dS/dt`` of the measured strain: what ``pysindy.SmoothedFiniteDifference`` computes (a
  cubic Savitzky-Golay smoother, then centred differences; :func:`smoothed_derivative`), on each
  scored segment, with a window of 1/8 of the entry's drive period (odd, 5 to 101 samples; 10 ms
  without a drive frequency); half a window is dropped at each end. ``V'`` by centred
  differences of the sequence's voltage.
- The regression ``dS/dt = Theta xi`` on the measured strain (equation error), every entry
  weighted alike (each segment's rows by ``1 / (RMS(dS/dt) sqrt(rows))``), columns and target
  normalised to unit RMS, with the STLSQ of pysindy (``pysindy.optimizers.STLSQ``, ridge
  1e-6, unbiased on its support; :func:`stlsq`) for each threshold of :data:`THRESHOLDS`.
  The derivative is pysindy's ``SmoothedFiniteDifference`` written with the scipy function it
  calls (the tests check it against pysindy's).
- A held-out fold reuses the full fit's work (:class:`SindyCache`): each segment's regression
  rows and their QR factor; the fold's system is the QR of its segments' stacked factors.
- **Selection by free run**: each distinct support is simulated from rest over the training
  sequences and scored by labrig's mean NRMSE (with one offset per entry when ``offset``); the
  sparsest support within 5 % of the best score is kept (:data:`TOLERANCE`). A model whose free
  run diverges scores as such and is never kept.
- ``offset`` (a sensor with no fixed zero): the library holds ``S``, so each entry's zero
  ``o_e`` matters. Two starts: a straight line ``S = a V + o_e`` (one slope, one ``o_e`` per
  entry), and the equation itself (alternately the fullest model and a Gauss-Newton step of
  each ``o_e`` on its equation error; their common shift, which the constant and rate terms
  absorb, fixed so that the fullest model rests at zero strain at 0 V). From each, the path is
  fitted, the zeros are taken again from the kept model's free run and the path is fitted once
  more; the start whose model free-runs better on the training data is kept. (On the
  micromanipulator data the line wins, on a simulated chained run the equation; either alone
  loses the other.)

Free run (:func:`free_run`, compiled; :func:`free_run_numpy` the reference)
--------------------------------------------------------------------------
Fixed step, one step per sample interval, ``V`` linear between samples (so ``V'`` is constant on
each interval). The library is built so that the equation reads ``dS/dt = a(t) + b S +
c S|S|`` with ``b`` a function of ``V'`` only (constant on the interval) and ``a`` affine in
``V`` (linear in time on the interval). Each step is an exponential Rosenbrock-Euler step:
``S|S|`` is linearised at the step's start, and the resulting linear ODE with linear forcing is
integrated exactly,

    S_{n+1} = exp(beta h) S_n + h phi1(beta h) (a_n - c S_n|S_n|) + h phi2(beta h) (a_n' - a_n)

(``beta = b + 2 c |S_n|``, ``a_n`` and ``a_n'`` the forcing at the interval's ends,
``phi1(z) = (e^z - 1)/z``, ``phi2(z) = (e^z - 1 - z)/z^2``): exact without ``S|S|``, second order
with it, and stable for any lag however fast. The record is preceded by the voltage it rested
at (:attr:`~labrig.analysis.records.Record.rest_V`), where the strain starts at the equation's
stable equilibrium (0 when there is none). A free run is clipped at 100 x the training
strain span at each step (diverged). A voltage sampled faster than the rate the model was
identified at is band-limited to that rate first (:meth:`SindyBaseline.predict`).
:func:`free_run_sensitivities` returns the run with its derivative with respect to each
coefficient (the forward sensitivities of the recursion, from the rest strain's,
:func:`equilibrium_gradient`), for the output-error refinements of
:mod:`labrig.analysis.diagnose.contraction`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labrig.analysis.band_limit import band_limit
from labrig.analysis.baseline_kernels import sindy_free_run, sindy_free_run_sensitivities
from labrig.analysis.metrics import drive_frequency_hz
from labrig.analysis.simulate import Segment, SimSequence

__all__ = [
    "LIBRARY",
    "THRESHOLDS",
    "TOLERANCE",
    "SindyBaseline",
    "SindyCache",
    "SindyTerm",
    "equilibrium",
    "equilibrium_gradient",
    "fit_sindy",
    "free_run",
    "free_run_numpy",
    "free_run_sensitivities",
    "library_matrix",
    "same_run_up_to",
    "smoothed_derivative",
    "smoothing_window",
    "stlsq",
    "threshold_path",
]

Factor = Callable[[NDArray, NDArray], NDArray]


@dataclass(frozen=True)
class SindyTerm:
    """One library term ``factor(V, V')`` times ``S`` (``kind`` ``"b"``), times 1 (``"a"``),
    or ``S|S|`` (``"c"``); ``unit`` is its coefficient's unit."""

    name: str
    unit: str
    kind: str
    physics: str
    factor: Factor


def _one(v: NDArray, d: NDArray) -> NDArray:
    return np.ones_like(v)


#: the library (module docstring); ``"b"`` factors depend on ``V'`` only, ``"a"`` factors are
#: affine in ``V`` at fixed ``V'`` (what makes the free-run step exact)
LIBRARY: tuple[SindyTerm, ...] = (
    SindyTerm("1", "ue/s", "a", "a constant drift", _one),
    SindyTerm("S", "1/s", "b", "a first-order lag (-1/tau)", _one),
    SindyTerm("V", "ue/(V s)", "a", "the drive of the lag (gain/tau)", lambda v, d: v),
    SindyTerm("V'", "ue/V", "a", "a feed-through of the voltage's rate", lambda v, d: d),
    SindyTerm("|V'|", "ue/V", "a", "a rate-dependent offset", lambda v, d: np.abs(d)),
    SindyTerm("V' S", "1/V", "b", "a strain-dependent gain", lambda v, d: d),
    SindyTerm("V' V", "ue/V^2", "a", "a field-dependent gain", lambda v, d: d * v),
    SindyTerm("|V'| S", "1/V", "b", "Bouc-Wen-like memory", lambda v, d: np.abs(d)),
    SindyTerm("|V'| V", "ue/V^2", "a", "Bouc-Wen-like memory", lambda v, d: np.abs(d) * v),
    SindyTerm("S|S|", "1/(ue s)", "c", "an odd saturation of the lag", _one),
)

#: STLSQ thresholds tried (on coefficients of unit-RMS columns and target): 25 from 0.001 to 5,
#: geometric
THRESHOLDS: tuple[float, ...] = tuple(float(x) for x in np.geomspace(0.001, 5.0, 25))
#: keep the sparsest support whose training free-run NRMSE is within this of the best
TOLERANCE = 0.05
#: a free run leaving this multiple of the training strain span is held there (diverged)
DIVERGED = 100.0


def library_matrix(S: ArrayLike, V: ArrayLike, D: ArrayLike) -> NDArray[np.float64]:
    """``Theta(S, V, V')``: one column per :data:`LIBRARY` term (``len(S) x 10``)."""
    s, v, d = (np.asarray(x, dtype=float) for x in (S, V, D))
    cols = []
    for t in LIBRARY:
        f = t.factor(v, d)
        cols.append(f if t.kind == "a" else f * s if t.kind == "b" else s * np.abs(s))
    return np.column_stack(cols)


# -- free run ---------------------------------------------------------------------------------


Weighted = list[tuple[float, SindyTerm]]


def _split(xi: NDArray) -> tuple[Weighted, Weighted, float]:
    """The nonzero ``"a"`` and ``"b"`` terms with their coefficients, and ``c``."""
    a = [(float(x), t) for x, t in zip(xi, LIBRARY, strict=True) if t.kind == "a" and x != 0]
    b = [(float(x), t) for x, t in zip(xi, LIBRARY, strict=True) if t.kind == "b" and x != 0]
    c = sum(float(x) for x, t in zip(xi, LIBRARY, strict=True) if t.kind == "c")
    return a, b, c


def _at_rest() -> tuple[NDArray, NDArray, NDArray, int]:
    """Each term's factor held at ``V`` (``V' = 0``) as ``f0 + f1 V`` (an ``"a"`` factor is
    affine in ``V`` at fixed ``V'``, a ``"b"`` factor depends on ``V'`` only): ``f0`` and
    ``f1`` of the ``"a"`` terms, ``f0`` of the ``"b"`` terms (0 elsewhere), and the index of
    the ``"c"`` term."""
    zero, one = np.zeros(1), np.ones(1)
    f0 = np.array([float(t.factor(zero, zero)[0]) for t in LIBRARY])
    f1 = np.array([float(t.factor(one, zero)[0]) for t in LIBRARY]) - f0
    kinds = np.array([t.kind for t in LIBRARY])
    a0, a1 = np.where(kinds == "a", f0, 0.0), np.where(kinds == "a", f1, 0.0)
    b0 = np.where(kinds == "b", f0, 0.0)
    return a0, a1, b0, int(np.flatnonzero(kinds == "c")[0])


_A0, _A1, _B0, _C = _at_rest()


def equilibrium(xi: ArrayLike, V: float) -> float:
    """The stable equilibrium strain (ue) of ``dS/dt = Theta xi`` held at ``V`` (``V' = 0``):
    ``a + b S + c S|S| = 0`` with ``b + 2 c |S| < 0``, the root nearest the linear one;
    0 when there is none. The quadratic of each sign of ``S`` is solved in closed form (the
    cancellation-free pair ``q = -(b + sign(b) sqrt(b^2 - 4 k a)) / 2``, roots ``q / k`` and
    ``a / q``; ``numpy.roots`` is the tests' reference)."""
    x = np.asarray(xi, dtype=float)
    v = float(V)
    a = float(x @ _A0 + v * (x @ _A1))
    b = float(x @ _B0)
    c = float(x[_C])
    linear = -a / b if b < 0 else 0.0
    if c == 0.0:
        return linear
    size = max(abs(a), abs(b), abs(c))
    if not 1e-100 < size < 1e100:  # the squares below would under- or overflow
        a, b, c = a / size, b / size, c / size
    roots = []
    for sgn in (1.0, -1.0):  # S >= 0: c S^2 + b S + a = 0; S < 0: -c S^2 + b S + a = 0
        k = sgn * c
        disc = b * b - 4.0 * k * a
        if disc < -1e-12 * (b * b + abs(4.0 * k * a)):
            continue
        q = -0.5 * (b + math.copysign(math.sqrt(max(disc, 0.0)), b))
        for s in (q / k, a / q if q != 0.0 else math.nan):
            if s == s and sgn * s >= 0 and b + 2 * c * abs(s) < 0:
                roots.append(s)
    return min(roots, key=lambda s: abs(s - linear)) if roots else 0.0


def equilibrium_gradient(xi: ArrayLike, V: float) -> NDArray[np.float64]:
    """The derivative of :func:`equilibrium` with respect to each coefficient (implicit
    function theorem on ``F(S) = a + b S + c S|S| = 0``: ``dS/dxi_k = -(dF/dxi_k) / (b +
    2 c |S|)``); zeros where there is no equilibrium (its 0 does not move)."""
    x = np.asarray(xi, dtype=float)
    v = float(V)
    s = equilibrium(x, v)
    b = float(x @ _B0)
    slope = b + 2.0 * float(x[_C]) * abs(s)
    a = float(x @ _A0 + v * (x @ _A1))
    if not slope < 0 or not abs(a + b * s + float(x[_C]) * s * abs(s)) <= 1e-9 * (
        abs(a) + abs(b * s) + abs(float(x[_C]) * s * s)
    ):
        return np.zeros(x.size)
    dF = _A0 + v * _A1 + _B0 * s
    dF[_C] = s * abs(s)
    return -dF / slope


def free_run_sensitivities(
    xi: ArrayLike, v: ArrayLike, rate_hz: float, rest_V: float = 0.0, limit_ue: float = math.inf
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """:func:`free_run` and its derivative with respect to each of the ten coefficients
    (``(samples, 10)``): the forward sensitivities of the recursion as computed, from the
    start's (:func:`equilibrium_gradient`). Compiled
    (:func:`labrig.analysis.baseline_kernels.sindy_free_run_sensitivities`); ``None`` without
    numba (then differentiate :func:`free_run` numerically)."""
    xi = np.asarray(xi, dtype=float)
    vp = np.concatenate(([float(rest_V)], np.asarray(v, dtype=float)))
    return sindy_free_run_sensitivities(
        xi, vp, rate_hz, equilibrium(xi, vp[0]), equilibrium_gradient(xi, vp[0]), limit_ue
    )


def _phis(z: float) -> tuple[float, float]:
    """``phi1(z) = (e^z - 1)/z`` and ``phi2(z) = (e^z - 1 - z)/z^2`` (series near 0)."""
    if abs(z) < 1e-3:
        return 1.0 + z / 2 + z * z / 6, 0.5 + z / 6 + z * z / 24
    em = math.expm1(z)
    return em / z, (em - z) / (z * z)


def free_run(
    xi: ArrayLike, v: ArrayLike, rate_hz: float, rest_V: float = 0.0, limit_ue: float = math.inf
) -> NDArray[np.float64]:
    """The strain (ue) of ``dS/dt = Theta(S, V, V') xi`` driven by ``v`` (V) sampled at
    ``rate_hz``, from rest at ``rest_V`` (module docstring: exponential Rosenbrock-Euler, one
    step per sample, ``V`` linear between samples); clipped to ``+- limit_ue`` at each step
    (it may come back). Compiled (:func:`labrig.analysis.baseline_kernels.sindy_free_run`);
    without numba :func:`free_run_numpy`."""
    xi = np.asarray(xi, dtype=float)
    vp = np.concatenate(([float(rest_V)], np.asarray(v, dtype=float)))
    out = sindy_free_run(xi, vp, rate_hz, equilibrium(xi, vp[0]), limit_ue)
    return free_run_numpy(xi, v, rate_hz, rest_V, limit_ue) if out is None else out


def free_run_numpy(
    xi: ArrayLike, v: ArrayLike, rate_hz: float, rest_V: float = 0.0, limit_ue: float = math.inf
) -> NDArray[np.float64]:
    """:func:`free_run` with the step factors prepared by NumPy and the recursion in Python
    (the reference of the compiled form)."""
    xi = np.asarray(xi, dtype=float)
    vp = np.concatenate(([float(rest_V)], np.asarray(v, dtype=float)))
    n = vp.size - 1
    h = 1.0 / float(rate_hz)
    d = np.diff(vp) * rate_hz  # V' on each interval
    a_terms, b_terms, c = _split(xi)
    a0 = sum((x * t.factor(vp[:-1], d) for x, t in a_terms), np.zeros(n))
    a1 = sum((x * t.factor(vp[1:], d) for x, t in a_terms), np.zeros(n))
    b = sum((x * t.factor(vp[1:], d) for x, t in b_terms), np.zeros(n))
    s = equilibrium(xi, vp[0])
    out = np.empty(n)
    if c == 0.0:  # linear: every step's factors at once, then the recursion
        z = b * h
        small = np.abs(z) < 1e-3
        zs = np.where(small, 1.0, z)
        em = np.expm1(zs)
        p1 = np.where(small, 1.0 + z / 2 + z * z / 6, em / zs)
        p2 = np.where(small, 0.5 + z / 6 + z * z / 24, (em - zs) / (zs * zs))
        E = (1.0 + z * p1).tolist()
        F = (h * (p1 * a0 + p2 * (a1 - a0))).tolist()
        res = out.tolist()
        for i in range(n):
            s = E[i] * s + F[i]
            if not abs(s) <= limit_ue:
                s = math.copysign(limit_ue, s) if s == s else limit_ue
            res[i] = s
        return np.asarray(res)
    A0, DA, B = a0.tolist(), (a1 - a0).tolist(), b.tolist()
    res = out.tolist()
    for i in range(n):
        sa = abs(s)
        zi = (B[i] + 2.0 * c * sa) * h
        q1, q2 = _phis(zi)
        s = (1.0 + zi * q1) * s + h * (q1 * (A0[i] - c * s * sa) + q2 * DA[i])
        if not abs(s) <= limit_ue:
            s = math.copysign(limit_ue, s) if s == s else limit_ue
        res[i] = s
    return np.asarray(res)


# -- the model --------------------------------------------------------------------------------


@dataclass(frozen=True)
class SindyBaseline:
    """A fitted sparse ODE: ``coefficients`` per :data:`LIBRARY` term (0 where not selected),
    simulated at ``rate_hz`` (the training records' rate)."""

    coefficients: tuple[float, ...]
    rate_hz: float
    threshold: float
    limit_ue: float = math.inf

    def predict(
        self, v: ArrayLike, rest_V: float = 0.0, rate_hz: float | None = None
    ) -> NDArray[np.float64]:
        """Free-run strain (ue) for the voltage ``v`` (V, sampled at ``rate_hz``; the model's
        own rate by default) from rest at ``rest_V``. A voltage sampled faster than the model's
        rate is first cut to the model's band (:func:`~labrig.analysis.band_limit.band_limit`,
        the filter that decimated the records it was identified on): its ``V'`` and ``|V'|``
        are then the ones the coefficients were fitted to, not a rate inflated by the noise
        above that band."""
        rate = self.rate_hz if rate_hz is None else rate_hz
        if rate > self.rate_hz * (1.0 + 1e-9):
            v = band_limit(v, self.rate_hz / rate)
        return free_run(self.coefficients, v, rate, rest_V, self.limit_ue)

    @property
    def support(self) -> list[SindyTerm]:
        return [t for x, t in zip(self.coefficients, LIBRARY, strict=True) if x != 0]

    def equation(self) -> str:
        """``dS/dt = ...`` with three significant digits."""
        parts = []
        for x, t in zip(self.coefficients, LIBRARY, strict=True):
            if x != 0:
                parts.append(f"{x:+.3g}" + ("" if t.name == "1" else f" {t.name}"))
        body = " ".join(parts).lstrip("+") if parts else "0"
        return f"dS/dt = {body}"

    def params(self) -> dict[str, Any]:
        kept = [(x, t) for x, t in zip(self.coefficients, LIBRARY, strict=True) if x != 0]
        return {
            "equation": self.equation(),
            "terms": [t.name for _, t in kept],
            "coefficients": [float(x) for x, _ in kept],
            "coefficient_units": [t.unit for _, t in kept],
            "threshold": float(self.threshold),
            "rate_hz": float(self.rate_hz),
        }


# -- fitting ----------------------------------------------------------------------------------

Items = Sequence[tuple[SimSequence, Sequence[Segment]]]

#: STLSQ's ridge (pysindy's ``alpha``) and iteration limit (``max_iter``)
RIDGE = 1e-6
MAX_ITER = 20


def smoothing_window(rate_hz: float, frequency_hz: float | None) -> int:
    """Savitzky-Golay window (samples, odd): 1/8 of the drive period, 5 to 101 samples; 10 ms
    without a drive frequency."""
    span = rate_hz / (8.0 * frequency_hz) if frequency_hz else 0.01 * rate_hz
    w = int(min(max(round(span), 5), 101))
    return w if w % 2 else w + 1


def _stencil(offsets: NDArray, dt: float) -> NDArray:
    """Weights of the first derivative at offset 0 from samples at ``offsets * dt`` (s): the
    solution of ``sum_k w_k (offset_k dt)^p = [p == 1]``, ``p = 0, 1, 2``."""
    m = (dt * offsets)[None, :] ** np.arange(offsets.size)[:, None]
    b = np.zeros(offsets.size)
    b[1] = 1.0
    return np.linalg.solve(m, b)


def smoothed_derivative(x: ArrayLike, rate_hz: float, window: int) -> NDArray[np.float64]:
    """``dx/dt`` (per s) of samples at ``rate_hz``: a cubic Savitzky-Golay smoother of
    ``window`` samples (``scipy.signal.savgol_filter``), then second-order finite differences,
    centred inside and one-sided (3 points) at the two ends: what
    ``pysindy.SmoothedFiniteDifference(smoother_kws={"window_length": window, "polyorder": 3})``
    computes (the tests check it against pysindy), without importing pysindy and scikit-learn
    (about 1 s of CPU at start-up)."""
    from scipy.signal import savgol_filter

    xs = savgol_filter(np.asarray(x, dtype=float), window_length=window, polyorder=3, axis=0)
    dt = 1.0 / float(rate_hz)
    n = xs.size
    out = np.full(n, np.nan)
    c = _stencil(np.array([-1.0, 0.0, 1.0]), dt)
    interior = np.zeros(n - 2)
    for i in range(3):
        if abs(c[i]) > 0:
            interior = interior + xs[i : n - 2 + i] * c[i]
    out[1:-1] = interior
    fwd, bwd = _stencil(np.array([0.0, 1.0, 2.0]), dt), _stencil(np.array([0.0, -1.0, -2.0]), dt)
    out[0] = xs[:3] @ fwd
    out[-1] = xs[::-1][:3] @ bwd
    return out


@dataclass
class _Block:
    """One segment's regression rows (half a smoothing window trimmed at each end): measured
    strain, voltage, ``V'``, smoothed ``dS/dt`` and the rows' weight."""

    name: str
    strain: NDArray
    v: NDArray
    d: NDArray
    target: NDArray
    weight: float

    def theta(self, offset: float = 0.0) -> NDArray:
        return library_matrix(self.strain - offset, self.v, self.d)


@dataclass
class SindyCache:
    """Work shared by the fits of one :func:`~labrig.analysis.baselines.fit_baseline` call (the
    full fit and its leave-one-entry-out folds, on the same sequences): each segment's
    regression rows (:class:`_Block`, ``None`` when too short) by entry name, and the QR
    factors of its weighted rows by ``(name, offset)``."""

    blocks: dict[str, _Block | None] = field(default_factory=dict)
    factors: dict[tuple[str, float], tuple[NDArray, NDArray, NDArray, float, int]] = field(
        default_factory=dict
    )


def _blocks(items: Items, cache: SindyCache) -> list[_Block]:
    """Every scored segment long enough to differentiate, as regression rows."""
    for seq, segs in items:
        todo = [g for g in segs if g.name not in cache.blocks]
        if not todo:
            continue
        d_all = np.gradient(seq.voltage_V) * seq.rate_hz if seq.n > 1 else np.zeros(seq.n)
        recs = {r.name: r for r in seq.records}
        for g in todo:
            cache.blocks[g.name] = None
            w = smoothing_window(seq.rate_hz, drive_frequency_hz(recs[g.name]))
            m = g.measured_ue
            if m.size < 3 * w:
                continue
            sl = slice(w // 2, m.size - w // 2)
            tg = smoothed_derivative(m, seq.rate_hz, w)[sl]
            rms = float(np.sqrt(np.mean(tg * tg)))
            if rms > 0:
                v, d = seq.voltage_V[g.lo : g.hi][sl], d_all[g.lo : g.hi][sl]
                cache.blocks[g.name] = _Block(
                    g.name, m[sl], v, d, tg, 1.0 / (rms * np.sqrt(tg.size))
                )
    out = [b for _, segs in items for g in segs if (b := cache.blocks[g.name]) is not None]
    if not out:
        raise ValueError("no segment long enough to differentiate for the SINDy baseline")
    return out


def _factor(b: _Block, offset: float, cache: SindyCache) -> tuple:
    """``(R, Q^T y, column sums of squares, sum of y^2, rows)`` of the block's weighted rows
    ``X = Theta w`` (``Q R`` their reduced QR) and weighted target ``y``."""
    key = (b.name, float(offset))
    if key not in cache.factors:
        X = b.theta(offset) * b.weight
        y = b.target * b.weight
        q, r = np.linalg.qr(X, mode="reduced")
        cache.factors[key] = (r, q.T @ y, np.sum(X * X, axis=0), float(y @ y), y.size)
    return cache.factors[key]


def _system(
    blocks: Sequence[_Block], offsets: dict[str, float], cache: SindyCache
) -> tuple[NDArray, NDArray, NDArray, float]:
    """The regression as STLSQ sees it: ``(r, qty, cs, ys)`` with ``Q r`` the reduced QR of
    the stacked weighted rows with columns divided by their RMS ``cs`` and ``qty = Q^T y / ys``
    (``ys`` the target's RMS): ``|X b - y|^2 = |r b - qty|^2 + const``. Made from the blocks'
    own factors (a QR of their stacked ``R``, equal to the QR of every row up to the signs of
    its rows, which no least-squares solution depends on)."""
    fs = [_factor(b, offsets.get(b.name, 0.0), cache) for b in blocks]
    rows = sum(f[4] for f in fs)
    cs = np.sqrt(sum(f[2] for f in fs) / rows)
    cs[cs == 0] = 1.0
    ys = float(np.sqrt(sum(f[3] for f in fs) / rows)) or 1.0
    q, r = np.linalg.qr(np.vstack([f[0] for f in fs]), mode="reduced")
    return r / cs, (q.T @ np.concatenate([f[1] for f in fs])) / ys, cs, ys


def stlsq(
    x: ArrayLike, y: ArrayLike, thresholds: Sequence[float]
) -> list[tuple[float, NDArray[np.float64]]]:
    """Sequentially thresholded least squares of ``y`` on the columns of ``x`` for each
    threshold: pysindy's ``STLSQ(threshold, alpha=RIDGE, unbias=True, max_iter=MAX_ITER)``
    (imported here, on first use: pysindy and scikit-learn cost about a second to import),
    with scikit-learn's input checks off (the rows are finite float64 arrays and the parameters
    fixed here; those checks are most of the cost of a call on this 10-column problem; the
    ridge solves' ``check_input=False`` alone saves about a sixth of a call, the same
    coefficients to the bit).

    A threshold is fitted only when the previous fit's result does not already answer it
    (:func:`same_run_up_to`): each iterate of STLSQ keeps the ridge coefficients ``|c| >=
    threshold``, so a threshold ``lam2 >= lam1`` at or below every coefficient ``lam1``'s
    iterates kept (``STLSQ.history_``) cuts every iterate alike, and its fit is ``lam1``'s step
    for step (same supports, same solves, same unbiased refit): its coefficients are ``lam1``'s,
    to the bit.

    Returns ``(threshold, coefficients)`` for every threshold."""
    import sklearn
    from pysindy.optimizers import STLSQ

    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    out: list[tuple[float, NDArray[np.float64]]] = []
    last: tuple[float, float, NDArray[np.float64]] | None = None  # (lam1, reach, coefficients)
    with sklearn.config_context(assume_finite=True, skip_parameter_validation=True):
        for lam in thresholds:
            if last is not None and last[0] <= lam <= last[1]:
                out.append((float(lam), last[2].copy()))
                continue
            opt = STLSQ(
                threshold=float(lam),
                alpha=RIDGE,
                max_iter=MAX_ITER,
                unbias=True,
                ridge_kw={"check_input": False},
            )
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                opt.fit(x, y)
            coef = np.asarray(opt.coef_, dtype=float).ravel()
            last = (float(lam), same_run_up_to(opt.history_, float(lam)), coef)
            out.append((float(lam), coef.copy()))
    return out


def same_run_up_to(history: Sequence[ArrayLike], threshold: float) -> float:
    """The largest threshold whose STLSQ run is step for step the run that left ``history``
    (``STLSQ.history_`` after a fit at ``threshold > 0``: the start, then each iterate with the
    coefficients below the threshold cut to 0): the smallest ``|c|`` kept by any iterate
    (``inf`` when none kept one); ``-inf`` for ``threshold <= 0`` (an exact 0 is then kept, so
    the iterates do not tell the coefficients cut)."""
    if not threshold > 0:
        return -math.inf
    kept = [np.abs(np.asarray(h, dtype=float)) for h in history[1:]]
    kept = [k[k > 0] for k in kept]
    kept = [k for k in kept if k.size]
    return float(min(np.min(k) for k in kept)) if kept else math.inf


def _equation_offsets(
    blocks: Sequence[_Block],
    offsets: dict[str, float],
    span: float,
    cache: SindyCache,
    rounds: int = 30,
) -> dict[str, float]:
    """Each entry's strain zero from the equation itself: alternately the fullest model on the
    current zeros (STLSQ at the smallest threshold) and, per entry, the Gauss-Newton step of
    its zero on that model's equation error, until no zero moves by 1e-4 of the span; then
    all shifted so that the fullest model rests at zero strain at 0 V."""
    out = dict(offsets)
    for _ in range(rounds):
        xi = _regress(blocks, out, THRESHOLDS[:1], cache)[0][1]
        _, b_terms, c = _split(xi)
        moved = 0.0
        for b in blocks:
            o = out.get(b.name, 0.0)
            s = b.strain - o
            r = b.target - b.theta(o) @ xi
            g = sum((x * t.factor(b.v, b.d) for x, t in b_terms), 2.0 * c * np.abs(s))
            gg = float(np.sum(g * g))
            step = -float(r @ g) / gg if gg > 0 else 0.0
            out[b.name] = o + step
            moved = max(moved, abs(step))
        if moved < 1e-4 * span:
            break
    # a common shift of every zero is absorbed by the constant and rate terms: fix it so the
    # strain is zero at rest at 0 V (the fullest model's equilibrium)
    s0 = equilibrium(_regress(blocks, out, THRESHOLDS[:1], cache)[0][1], 0.0)
    return {k: o + s0 for k, o in out.items()}


def _regress(
    blocks: Sequence[_Block],
    offsets: dict[str, float],
    thresholds: Sequence[float],
    cache: SindyCache,
) -> list[tuple[float, NDArray]]:
    """(threshold, xi) for each threshold giving a new support (:func:`stlsq` on the
    normalised system of :func:`_system`; ``xi`` in the library's units)."""
    r, qty, cs, ys = _system(blocks, offsets, cache)
    out, seen = [], set()
    for lam, coef in stlsq(r, qty, thresholds):
        xi = coef * ys / cs
        key = tuple(np.flatnonzero(xi))
        if key not in seen:
            seen.add(key)
            out.append((float(lam), xi))
    return out


def threshold_path(
    items: Items, start: SindyBaseline, offset: bool, cache: SindyCache
) -> list[SindyBaseline]:
    """One model per distinct nonzero, finite support of the STLSQ threshold path over
    :data:`THRESHOLDS` of the regression :func:`fit_sindy` sets up on ``items`` (the same
    blocks, weights and normalisation, :func:`_regress`), with each segment's strain zero
    (``offset``) where ``start``'s free run puts it (the mean of measured less predicted);
    empty when no segment is long enough to differentiate."""
    try:
        blocks = _blocks(items, cache)
    except ValueError:
        return []
    offsets = _Scorer(items, offset)(start)[1] if offset else {}
    return [
        SindyBaseline(tuple(float(c) for c in xi), start.rate_hz, lam, start.limit_ue)
        for lam, xi in _regress(blocks, offsets, THRESHOLDS, cache)
        if np.any(xi) and np.all(np.isfinite(xi))
    ]


class _Scorer:
    """The training free run's score of a candidate on ``items``: each sequence's scored
    samples gathered once, then per segment its offset (with ``offset``) and NRMSE."""

    def __init__(self, items: Items, offset: bool) -> None:
        self.offset = offset
        self.parts = []
        for seq, segs in items:
            idx = np.concatenate([np.arange(g.lo, g.hi) for g in segs])
            n = np.array([g.measured_ue.size for g in segs])
            starts = np.concatenate(([0], np.cumsum(n)[:-1]))
            meas = np.concatenate([g.measured_ue for g in segs])
            span = np.array([float(np.max(g.measured_ue) - np.min(g.measured_ue)) for g in segs])
            self.parts.append((seq, [g.name for g in segs], idx, n, starts, meas, span))

    def __call__(self, model: SindyBaseline) -> tuple[float, dict[str, float]]:
        """Mean training NRMSE (%) of the free run (:func:`~labrig.analysis.metrics.nrmse_pct`
        per segment) and each entry's offset (0 without ``offset``)."""
        vals: list[float] = []
        offs: dict[str, float] = {}
        for seq, names, idx, n, starts, meas, span in self.parts:
            res = meas - model.predict(seq.voltage_V, seq.rest_V, seq.rate_hz)[idx]
            if self.offset:
                off = np.add.reduceat(res, starts) / n
                res = res - np.repeat(off, n)
            else:
                off = np.zeros(n.size)
            vals.append(100.0 * np.sqrt(np.add.reduceat(res * res, starts) / n) / span)
            offs.update(zip(names, off.tolist(), strict=True))
        return float(np.mean(np.concatenate(vals))), offs


def _line_offsets(items: Items) -> dict[str, float]:
    """Per-entry zero of ``S = a V + o_e`` (one slope, one offset per entry), least squares."""
    segs = [(seq, g) for seq, gs in items for g in gs]
    n = sum(g.measured_ue.size for _, g in segs)
    M = np.zeros((n, 1 + len(segs)))
    y = np.empty(n)
    pos = 0
    for k, (seq, g) in enumerate(segs):
        m = g.measured_ue.size
        M[pos : pos + m, 0] = seq.voltage_V[g.lo : g.hi]
        M[pos : pos + m, 1 + k] = 1.0
        y[pos : pos + m] = g.measured_ue
        pos += m
    coef, *_ = np.linalg.lstsq(M, y, rcond=None)
    return {g.name: float(coef[1 + k]) for k, (_, g) in enumerate(segs)}


def _select(
    items: Items,
    blocks: Sequence[_Block],
    offsets: dict[str, float],
    offset: bool,
    rate: float,
    limit: float,
    cache: SindyCache,
) -> tuple[float, SindyBaseline, dict[str, float]]:
    """Fit the threshold path and keep the sparsest model within :data:`TOLERANCE` of the best
    training free run: its score (mean NRMSE, %), the model and its free run's offsets."""
    cands = []
    score_of = _Scorer(items, offset)
    for lam, xi in _regress(blocks, offsets, THRESHOLDS, cache):
        m = SindyBaseline(tuple(float(x) for x in xi), rate, lam, limit)
        score, offs = score_of(m)
        cands.append((score if np.isfinite(score) else math.inf, m, offs))
    best = min(c[0] for c in cands)
    ok = [c for c in cands if c[0] <= (1.0 + TOLERANCE) * best]
    return min(ok, key=lambda c: (len(c[1].support), c[0]))


def fit_sindy(items: Items, offset: bool = False, cache: SindyCache | None = None) -> SindyBaseline:
    """The SINDy baseline fitted on the scored segments of ``items`` (module docstring).
    ``cache``: work shared with other fits on the same sequences (the folds of a held-out
    score); a fresh one by default.

    Raises ``ValueError`` when the sequences differ in sample rate or no segment is long enough
    to differentiate."""
    cache = SindyCache() if cache is None else cache
    items = [(seq, list(segs)) for seq, segs in items if segs]
    rates = {seq.rate_hz for seq, _ in items}
    if len(rates) != 1:
        raise ValueError(f"the SINDy baseline needs one sample rate, got {sorted(rates)} Hz")
    rate = rates.pop()
    span = max(float(np.ptp(g.measured_ue)) for _, segs in items for g in segs)
    blocks = _blocks(items, cache)
    if not offset:
        return _select(items, blocks, {}, False, rate, DIVERGED * span, cache)[1]
    line = _line_offsets(items)
    fits = []
    for start in (line, _equation_offsets(blocks, line, span, cache)):
        _, _, offs = _select(items, blocks, start, True, rate, DIVERGED * span, cache)
        fits.append(_select(items, blocks, offs, True, rate, DIVERGED * span, cache))
    return min(fits, key=lambda f: f[0])[1]
