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
- ``dS/dt`` of the measured strain: ``pysindy.SmoothedFiniteDifference`` (a cubic
  Savitzky-Golay smoother, then centred differences), on each scored segment, with a window of
  1/8 of the entry's drive period (odd, 5 to 101 samples; 10 ms without a drive frequency); half
  a window is dropped at each end. ``V'`` by centred differences of the sequence's voltage.
- The regression ``dS/dt = Theta xi`` on the measured strain (equation error), every entry
  weighted alike (each segment's rows by ``1 / (RMS(dS/dt) sqrt(rows))``), columns and target
  normalised to unit RMS, with ``pysindy.optimizers.STLSQ`` (ridge 1e-6, unbiased on its
  support) for each threshold of :data:`THRESHOLDS`.
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

Free run (:func:`free_run`)
---------------------------
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
stable equilibrium (0 when there is none). A free run that leaves 100 x the training strain
span is held there (diverged).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labrig.analysis.metrics import drive_frequency_hz, nrmse_pct
from labrig.analysis.simulate import Segment, SimSequence

__all__ = [
    "LIBRARY",
    "THRESHOLDS",
    "TOLERANCE",
    "SindyBaseline",
    "SindyTerm",
    "equilibrium",
    "fit_sindy",
    "free_run",
    "library_matrix",
    "smoothing_window",
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


def equilibrium(xi: ArrayLike, V: float) -> float:
    """The stable equilibrium strain (ue) of ``dS/dt = Theta xi`` held at ``V`` (``V' = 0``):
    ``a + b S + c S|S| = 0`` with ``b + 2 c |S| < 0``, the root nearest the linear one;
    0 when there is none."""
    a_terms, b_terms, c = _split(np.asarray(xi, dtype=float))
    v, d = np.array([float(V)]), np.zeros(1)
    a = sum(x * float(t.factor(v, d)[0]) for x, t in a_terms)
    b = sum(x * float(t.factor(v, d)[0]) for x, t in b_terms)
    linear = -a / b if b < 0 else 0.0
    if c == 0.0:
        return linear if b < 0 else 0.0
    roots = []
    for sgn in (1.0, -1.0):  # S >= 0: c S^2 + b S + a = 0; S < 0: -c S^2 + b S + a = 0
        for s in np.roots([sgn * c, b, a]):
            if abs(s.imag) < 1e-12 and sgn * s.real >= 0 and b + 2 * c * abs(s.real) < 0:
                roots.append(float(s.real))
    return min(roots, key=lambda s: abs(s - linear)) if roots else 0.0


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
    step per sample, ``V`` linear between samples); held at ``+- limit_ue`` once it leaves it."""
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
        z = (B[i] + 2.0 * c * sa) * h
        p1, p2 = _phis(z)
        s = (1.0 + z * p1) * s + h * (p1 * (A0[i] - c * s * sa) + p2 * DA[i])
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
        """Free-run strain (ue) for the voltage ``v`` from rest at ``rest_V``."""
        rate = self.rate_hz if rate_hz is None else rate_hz
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


def smoothing_window(rate_hz: float, frequency_hz: float | None) -> int:
    """Savitzky-Golay window (samples, odd): 1/8 of the drive period, 5 to 101 samples; 10 ms
    without a drive frequency."""
    span = rate_hz / (8.0 * frequency_hz) if frequency_hz else 0.01 * rate_hz
    w = int(min(max(round(span), 5), 101))
    return w if w % 2 else w + 1


def _derivative(x: NDArray, rate_hz: float, window: int) -> NDArray:
    from pysindy import SmoothedFiniteDifference

    sfd = SmoothedFiniteDifference(smoother_kws={"window_length": window, "polyorder": 3})
    return np.asarray(sfd(x, t=1.0 / rate_hz), dtype=float).ravel()


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
class _Rows:
    """The regression's rows: library, target ``dS/dt``, row weights."""

    theta: NDArray
    target: NDArray
    weight: NDArray


def _blocks(items: Items) -> list[_Block]:
    """Every scored segment long enough to differentiate, as regression rows."""
    out = []
    for seq, segs in items:
        d_all = np.gradient(seq.voltage_V) * seq.rate_hz if seq.n > 1 else np.zeros(seq.n)
        recs = {r.name: r for r in seq.records}
        for g in segs:
            w = smoothing_window(seq.rate_hz, drive_frequency_hz(recs[g.name]))
            m = g.measured_ue
            if m.size < 3 * w:
                continue
            sl = slice(w // 2, m.size - w // 2)
            tg = _derivative(m, seq.rate_hz, w)[sl]
            rms = float(np.sqrt(np.mean(tg * tg)))
            if rms > 0:
                v, d = seq.voltage_V[g.lo : g.hi][sl], d_all[g.lo : g.hi][sl]
                out.append(_Block(g.name, m[sl], v, d, tg, 1.0 / (rms * np.sqrt(tg.size))))
    if not out:
        raise ValueError("no segment long enough to differentiate for the SINDy baseline")
    return out


def _rows(blocks: Sequence[_Block], offsets: dict[str, float]) -> _Rows:
    return _Rows(
        np.vstack([b.theta(offsets.get(b.name, 0.0)) for b in blocks]),
        np.concatenate([b.target for b in blocks]),
        np.concatenate([np.full(b.target.size, b.weight) for b in blocks]),
    )


def _equation_offsets(
    blocks: Sequence[_Block], offsets: dict[str, float], span: float, rounds: int = 30
) -> dict[str, float]:
    """Each entry's strain zero from the equation itself: alternately the fullest model on the
    current zeros (STLSQ at the smallest threshold) and, per entry, the Gauss-Newton step of
    its zero on that model's equation error, until no zero moves by 1e-4 of the span; then
    all shifted so that the fullest model rests at zero strain at 0 V."""
    out = dict(offsets)
    for _ in range(rounds):
        xi = _regress(_rows(blocks, out), THRESHOLDS[:1])[0][1]
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
    s0 = equilibrium(_regress(_rows(blocks, out), THRESHOLDS[:1])[0][1], 0.0)
    return {k: o + s0 for k, o in out.items()}


def _regress(rows: _Rows, thresholds: Sequence[float]) -> list[tuple[float, NDArray]]:
    """(threshold, xi) for each threshold giving a new support (pysindy's STLSQ)."""
    from pysindy.optimizers import STLSQ

    X = rows.theta * rows.weight[:, None]
    y = rows.target * rows.weight
    cs = np.sqrt(np.mean(X * X, axis=0))
    cs[cs == 0] = 1.0
    ys = float(np.sqrt(np.mean(y * y))) or 1.0
    # the same minimiser on the small triangular system: |X b - y|^2 = |R b - Q^T y|^2 + const
    q, r = np.linalg.qr(X / cs, mode="reduced")
    qty = q.T @ (y / ys)
    out, seen = [], set()
    for lam in thresholds:
        opt = STLSQ(threshold=lam, alpha=1e-6, unbias=True, max_iter=20)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            opt.fit(r, qty)
        xi = np.asarray(opt.coef_, dtype=float).ravel() * ys / cs
        key = tuple(np.flatnonzero(xi))
        if key not in seen:
            seen.add(key)
            out.append((float(lam), xi))
    return out


def _score(model: SindyBaseline, items: Items, offset: bool) -> tuple[float, dict[str, float]]:
    """Mean training NRMSE (%) of the free run and each entry's offset (0 without ``offset``)."""
    vals, offs = [], {}
    for seq, segs in items:
        p = model.predict(seq.voltage_V, seq.rest_V, seq.rate_hz)
        for g in segs:
            pg = p[g.lo : g.hi]
            offs[g.name] = float(np.mean(g.measured_ue - pg)) if offset else 0.0
            vals.append(nrmse_pct(g.measured_ue, pg + offs[g.name]))
    return float(np.mean(vals)), offs


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
) -> tuple[float, SindyBaseline, dict[str, float]]:
    """Fit the threshold path and keep the sparsest model within :data:`TOLERANCE` of the best
    training free run: its score (mean NRMSE, %), the model and its free run's offsets."""
    cands = []
    for lam, xi in _regress(_rows(blocks, offsets), THRESHOLDS):
        m = SindyBaseline(tuple(float(x) for x in xi), rate, lam, limit)
        score, offs = _score(m, items, offset)
        cands.append((score if np.isfinite(score) else math.inf, m, offs))
    best = min(c[0] for c in cands)
    ok = [c for c in cands if c[0] <= (1.0 + TOLERANCE) * best]
    return min(ok, key=lambda c: (len(c[1].support), c[0]))


def fit_sindy(items: Items, offset: bool = False) -> SindyBaseline:
    """The SINDy baseline fitted on the scored segments of ``items`` (module docstring).

    Raises ``ValueError`` when the sequences differ in sample rate or no segment is long enough
    to differentiate."""
    items = [(seq, list(segs)) for seq, segs in items if segs]
    rates = {seq.rate_hz for seq, _ in items}
    if len(rates) != 1:
        raise ValueError(f"the SINDy baseline needs one sample rate, got {sorted(rates)} Hz")
    rate = rates.pop()
    span = max(float(np.ptp(g.measured_ue)) for _, segs in items for g in segs)
    blocks = _blocks(items)
    if not offset:
        return _select(items, blocks, {}, False, rate, DIVERGED * span)[1]
    line = _line_offsets(items)
    fits = []
    for start in (line, _equation_offsets(blocks, line, span)):
        _, _, offs = _select(items, blocks, start, True, rate, DIVERGED * span)
        fits.append(_select(items, blocks, offs, True, rate, DIVERGED * span))
    return min(fits, key=lambda f: f[0])[1]
