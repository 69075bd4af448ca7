"""Compiled kernels of the baselines (numba), beside the NumPy forms they replace.

Every loop the baselines (:mod:`labrig.analysis.baselines`, :mod:`labrig.analysis.sindy`) run
over the samples of a sequence is here, written once as a plain Python function that numba
compiles on first use (``@njit(cache=True)``, so later processes load it from the cache):

- :func:`play_operators` (Prandtl-Ishlinskii): the play recursion
  ``y_r[n] = max(V[n] - r, min(V[n] + r, y_r[n-1]))``, ``y_r[-1] = V_rest``, for every
  threshold at once. It takes the same values as the run-by-run closed form
  (:func:`play_operators_numpy`, the reference), exactly: each output is one of ``V - r``,
  ``V + r`` or the previous output.
- :func:`bouc_wen_h1` (Bouc-Wen, ``n = 1``, ``A = 1``): the closed form of
  :func:`labrig.model.bouc_wen.bouc_wen_exact` (the reference; equal within rounding) per
  monotone run, with the exact derivatives of ``h`` with respect to ``k_s = beta + gamma``
  and ``k_o = beta - gamma`` (module docstring of :mod:`labrig.model.bouc_wen`): along a run
  from ``h_0`` (direction ``s``, distance ``u``) ``h = h_0 e^(-k u) + s phi(k, u)``,
  ``phi(k, u) = (1 - e^(-k u)) / k``, so ``dh/dk = e^(-k u) dh_0/dk - u h_0 e^(-k u) +
  s psi(k, u)`` with ``psi = dphi/dk = (u e^(-k u) - phi) / k`` (a series below
  ``|k u| = 0.01``); after ``h`` crosses zero at ``u*`` the sensitivity of the first phase at
  ``u*`` carries on as ``e^(-k_s (u - u*))`` (``dh/du = s`` on both sides of ``h = 0``, so the
  crossing adds no jump).
- :func:`segment_moments` and :func:`residual_gram`: the sums of the Bouc-Wen fit over the
  scored segments (means, centred second moments; the Gram matrix of the residual and its
  Jacobian formed sample by sample, so the residual's square is not a difference of large sums).
- :func:`sindy_free_run`: the exponential Rosenbrock-Euler free run of
  :func:`labrig.analysis.sindy.free_run_numpy` (the reference) with the library's factors
  inlined, one step per sample; :func:`sindy_free_run_sensitivities` the same run with the
  derivative of every output with respect to each coefficient, the recursion's own
  (``J_{n+1} = (dS_{n+1}/dS_n) J_n + dS_{n+1}/dxi``, the derivatives of ``phi1`` and
  ``phi2`` taken of the forms evaluated, series included; tested against central
  differences of the reference).

Without numba (it cannot be imported) each function warns once and computes the same values
with NumPy (the Bouc-Wen sensitivities then by forward differences of the closed form).
numba is imported inside :func:`kernel` only, never when this module is imported.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
from numpy.typing import NDArray

from labrig.model.bouc_wen import bouc_wen_exact

__all__ = [
    "COMPILED",
    "N_COLS",
    "bouc_wen_h1",
    "kernel",
    "play_operators",
    "play_operators_numpy",
    "residual_gram",
    "segment_moments",
    "sindy_free_run",
    "sindy_free_run_sensitivities",
]

#: compiled kernels by name (``None``: numba could not be imported; emptied, the next use
#: imports numba again)
COMPILED: dict[str, Any] = {}


def kernel(name: str) -> Any:
    """The compiled form of ``_<name>_py`` (numba ``njit(cache=True)``), or ``None`` (with a
    warning, once) when numba cannot be imported."""
    if name in COMPILED:
        return COMPILED[name]
    try:
        from numba import njit
    except ImportError:
        if not any(v is None for v in COMPILED.values()):
            warnings.warn(
                "numba cannot be imported: the baselines run on their NumPy forms (slower)",
                RuntimeWarning,
                stacklevel=3,
            )
        COMPILED[name] = None
        return None
    global _psi, _forcing
    if _psi is _psi_py:
        _psi = njit(cache=True)(_psi_py)
    if _forcing is _forcing_py:
        _forcing = njit(cache=True)(_forcing_py)
    fn = njit(cache=True)(globals()[f"_{name}_py"])
    COMPILED[name] = fn
    return fn


# -- Prandtl-Ishlinskii ------------------------------------------------------------------------


def _play_py(vp: NDArray, r: NDArray, out: NDArray) -> None:
    y = np.empty(r.size)
    for j in range(r.size):
        y[j] = vp[0]
    for i in range(vp.size - 1):
        x = vp[i + 1]
        for j in range(r.size):
            # max(x - r, min(x + r, y)); x - r <= x + r for r >= 0
            hi = x + r[j]
            yj = hi if y[j] > hi else y[j]
            lo = x - r[j]
            yj = lo if lo > yj else yj
            y[j] = yj
            out[i, j] = yj


def play_operators_numpy(vp: NDArray, r: NDArray, runs: tuple) -> NDArray[np.float64]:
    """The play outputs for the rest-prefixed record ``vp`` (thresholds ``r``, V) run by run:
    ``max(V - r, y_s)`` on a rising run, ``min(V + r, y_s)`` on a falling one, ``y_s`` the
    outputs at the run's start (the reference of :func:`play_operators`); shape
    ``(len(vp) - 1, len(r))``."""
    out = np.full((vp.size, r.size), vp[0])  # relaxed at rest (and held there if V never moves)
    y = np.full(r.size, vp[0])
    for a, b, s in zip(*runs, strict=True):
        seg = vp[a + 1 : b + 1, None]
        blk = np.maximum(seg - r, y) if s > 0 else np.minimum(seg + r, y)
        out[a + 1 : b + 1] = blk
        y = blk[-1]
    return out[1:]


def play_operators(vp: NDArray, r: NDArray, runs: tuple | None = None) -> NDArray[np.float64]:
    """Outputs (V) of play operators of thresholds ``r`` (V, ``>= 0``) for the rest-prefixed
    record ``vp``, every operator relaxed at ``vp[0]``: shape ``(len(vp) - 1, len(r))``.
    ``runs`` (:func:`~labrig.model.bouc_wen.monotone_runs` of ``vp``) is used by the NumPy
    form only."""
    vp = np.ascontiguousarray(vp, dtype=float)
    r = np.ascontiguousarray(r, dtype=float)
    k = kernel("play")
    if k is None:
        from labrig.model.bouc_wen import monotone_runs

        return play_operators_numpy(vp, r, monotone_runs(vp) if runs is None else runs)
    out = np.empty((vp.size - 1, r.size))
    if out.size:
        k(vp, r, out)
    return out


# -- Bouc-Wen ----------------------------------------------------------------------------------


def _psi_py(k: float, u: float, e: float, phi: float) -> float:
    """``dphi/dk`` for ``phi(k, u) = (1 - e^(-k u)) / k`` given ``e = e^(-k u)`` and ``phi``:
    ``(u e - phi) / k``, or below ``|k u| = 0.01`` its series
    ``-u^2 (1/2 - ku/3 + (ku)^2/8 - (ku)^3/30 + (ku)^4/144)`` (truncation below 3e-13)."""
    ku = k * u
    if abs(ku) < 1e-2:
        return -u * u * (0.5 - ku * (1.0 / 3.0 - ku * (0.125 - ku * (1.0 / 30.0 - ku / 144.0))))
    return (u * e - phi) / k


#: the helper the Bouc-Wen kernel calls: rebound to its compiled form by :func:`kernel` before
#: any kernel is compiled (so the kernels also run uncompiled, as plain Python)
_psi = _psi_py


def _bw_h1_py(
    vp: NDArray,
    starts: NDArray,
    stops: NDArray,
    dirs: NDArray,
    ks: float,
    ko: float,
    sens: bool,
    h: NDArray,
    hks: NDArray,
    hko: NDArray,
) -> None:
    if starts.size == 0:  # no movement: h stays 0
        for i in range(vp.size):
            h[i] = 0.0
            hks[i] = 0.0
            hko[i] = 0.0
        return
    # per sample one expm1: e^(-k u) = 1 + expm1(-k u) and 1/k once (within an ulp of the
    # reference's exp and division; 25 % less time, measured)
    iks = 1.0 / ks if ks != 0 else 0.0
    iko = 1.0 / ko if ko != 0 else 0.0
    h[0] = 0.0
    hks[0] = 0.0
    hko[0] = 0.0
    hc = 0.0  # state at the run's start and its derivatives to ks, ko
    gs = 0.0
    go = 0.0
    for j in range(starts.size):
        a = starts[j]
        b = stops[j]
        s = dirs[j]
        v0 = vp[a]
        travel = s * (vp[b] - v0)
        h0 = hc
        g0s = gs
        g0o = go
        opposite = h0 * s < 0
        us = 0.0  # distance at which h crosses zero (inf: not in this run)
        ps = 0.0  # derivatives of the first phase at the crossing
        po = 0.0
        if opposite:
            x = ko * abs(h0)
            if abs(x) < 1e-12:
                us = abs(h0)
            elif 1.0 + x > 0:
                us = math.log1p(x) / ko
            else:
                us = math.inf
            if us >= travel:
                us = math.inf
            elif sens:
                e = math.exp(-ko * us)
                phi = -math.expm1(-(ko * us)) / ko if abs(ko * us) > 1e-12 else us
                ps = e * g0s
                po = e * g0o - us * h0 * e + s * _psi(ko, us, e, phi)
        # the samples of the run (a flat sample repeats the previous one)
        for i in range(a + 1, b + 1):
            if i > a + 1 and vp[i] == vp[i - 1]:
                h[i] = h[i - 1]
                hks[i] = hks[i - 1]
                hko[i] = hko[i - 1]
                continue
            u = s * (vp[i] - v0)
            if u <= us:  # opposite start, before the crossing (or u = 0)
                em = math.expm1(-(ko * u))
                e = 1.0 + em
                phi = -em * iko if abs(ko * u) > 1e-12 else u
                h[i] = h0 * e + s * phi
                if sens:
                    hks[i] = e * g0s
                    hko[i] = e * g0o - u * h0 * e + s * _psi(ko, u, e, phi)
            else:
                u2 = u - us if opposite else u
                start2 = 0.0 if opposite else h0
                em = math.expm1(-(ks * u2))
                e = 1.0 + em
                phi = -em * iks if abs(ks * u2) > 1e-12 else u2
                h[i] = start2 * e + s * phi
                if sens:
                    psi = _psi(ks, u2, e, phi)
                    if opposite:
                        hks[i] = s * psi + e * ps
                        hko[i] = e * po
                    else:
                        hks[i] = e * g0s - u2 * h0 * e + s * psi
                        hko[i] = e * g0o
        # the state at the run's end (as the reference's recursion computes it)
        if opposite and us == math.inf:
            e = math.exp(-ko * travel)
            phi = travel if ko == 0 else -math.expm1(-ko * travel) / ko
            hc = h0 * e + s * phi
            if sens:
                gs = e * g0s
                go = e * g0o - travel * h0 * e + s * _psi(ko, travel, e, phi)
            continue
        rem = travel - us if opposite else travel
        start2 = 0.0 if opposite else h0
        e = math.exp(-ks * rem)
        phi = rem if ks == 0 else -math.expm1(-ks * rem) / ks
        hc = start2 * e + s * phi
        if sens:
            psi = _psi(ks, rem, e, phi)
            if opposite:
                gs = s * psi + e * ps
                go = e * po
            else:
                gs = e * g0s - rem * h0 * e + s * psi
                go = e * g0o


def bouc_wen_h1(
    vp: NDArray, runs: tuple, ks: float, ko: float, sens: bool = False, out: NDArray | None = None
) -> NDArray[np.float64]:
    """``h`` (ue) of the Bouc-Wen element with ``A = 1`` (ue/V), ``beta + gamma = ks``,
    ``beta - gamma = ko`` (1/V) at the samples of the rest-prefixed record ``vp`` (so
    ``h[0] = 0``), and with ``sens`` its exact derivatives ``dh/dks``, ``dh/dko`` (ue V): rows
    0, 1, 2 of the returned ``(3, len(vp))`` array (``out`` if given; rows 1 and 2 zero without
    ``sens``). ``runs`` is :func:`~labrig.model.bouc_wen.monotone_runs` of ``vp``."""
    starts, stops, dirs = runs
    if out is None:
        out = np.empty((3, vp.size))
    k = kernel("bw_h1")
    if k is None:  # the closed form; derivatives by forward differences
        beta, gamma = 0.5 * (ks + ko), 0.5 * (ks - ko)
        out[0] = bouc_wen_exact(vp, 1.0, beta, gamma, runs)
        out[1:] = 0.0
        if sens:
            eps = 1.4901161193847656e-08  # sqrt(machine epsilon)
            ds, do = eps * abs(ks), eps * max(abs(ko), abs(ks))
            hs = bouc_wen_exact(vp, 1.0, 0.5 * (ks + ds + ko), 0.5 * (ks + ds - ko), runs)
            ho = bouc_wen_exact(vp, 1.0, 0.5 * (ks + ko + do), 0.5 * (ks - ko - do), runs)
            out[1] = (hs - out[0]) / ds
            out[2] = (ho - out[0]) / do
        return out
    if not sens:
        out[1:] = 0.0
    k(
        np.ascontiguousarray(vp, dtype=float),
        np.ascontiguousarray(starts, dtype=np.int64),
        np.ascontiguousarray(stops, dtype=np.int64),
        np.ascontiguousarray(dirs, dtype=float),
        float(ks),
        float(ko),
        bool(sens),
        out[0],
        out[1],
        out[2],
    )
    return out


#: the columns of the Bouc-Wen sums: voltage, h, dh/dks, dh/dko, measured strain
N_COLS = 5


def _moments_py(
    cols: NDArray, meas: NDArray, lo: NDArray, m0: NDArray, n: NDArray, centre: bool, out: NDArray
) -> None:
    for g in range(lo.size):
        a = lo[g]
        c = m0[g]
        k = n[g]
        mv = mh = ms = mo = mm = 0.0
        if centre:
            for i in range(k):
                mv += cols[0, a + i]
                mh += cols[1, a + i]
                ms += cols[2, a + i]
                mo += cols[3, a + i]
                mm += meas[c + i]
            mv /= k
            mh /= k
            ms /= k
            mo /= k
            mm /= k
        vv = vh = vs = vo = vm = hh = hs = ho = hm = ss = so = sm = oo = om = mmm = 0.0
        for i in range(k):
            v = cols[0, a + i] - mv
            h = cols[1, a + i] - mh
            s = cols[2, a + i] - ms
            o = cols[3, a + i] - mo
            m = meas[c + i] - mm
            vv += v * v
            vh += v * h
            vs += v * s
            vo += v * o
            vm += v * m
            hh += h * h
            hs += h * s
            ho += h * o
            hm += h * m
            ss += s * s
            so += s * o
            sm += s * m
            oo += o * o
            om += o * m
            mmm += m * m
        out[g, 0, 0] = mv
        out[g, 0, 1] = mh
        out[g, 0, 2] = ms
        out[g, 0, 3] = mo
        out[g, 0, 4] = mm
        sums = (vv, vh, vs, vo, vm, hh, hs, ho, hm, ss, so, sm, oo, om, mmm)
        t = 0
        for r in range(N_COLS):
            for q in range(r, N_COLS):
                out[g, 1 + r, q] = sums[t]
                out[g, 1 + q, r] = sums[t]
                t += 1


def segment_moments(
    cols: NDArray, meas: NDArray, lo: NDArray, m0: NDArray, n: NDArray, centre: bool
) -> NDArray[np.float64]:
    """Per segment ``g`` (samples ``lo[g] : lo[g] + n[g]`` of the rows of ``cols``, shape
    ``(4, samples)``: V, h, dh/dks, dh/dko; its measured strain ``meas[m0[g] : m0[g] + n[g]]``):
    ``out[g, 0]`` the five columns' means (zeros unless ``centre``) and ``out[g, 1:]`` their
    5 x 5 second moments about those means (unweighted)."""
    out = np.zeros((lo.size, 1 + N_COLS, N_COLS))
    k = kernel("moments")
    if k is not None:
        k(cols, meas, lo, m0, n, bool(centre), out)
        return out
    for g in range(lo.size):
        y = np.vstack((cols[:, lo[g] : lo[g] + n[g]], meas[m0[g] : m0[g] + n[g]]))
        mean = y.mean(axis=1) if centre else np.zeros(N_COLS)
        yc = y - mean[:, None]
        out[g, 0] = mean
        out[g, 1:] = yc @ yc.T
    return out


def _gram_py(
    cols: NDArray,
    meas: NDArray,
    lo: NDArray,
    m0: NDArray,
    n: NDArray,
    means: NDArray,
    coef: NDArray,
    out: NDArray,
) -> None:
    a00 = a01 = a02 = a11 = a12 = a22 = 0.0
    for g in range(lo.size):
        a = lo[g]
        c = m0[g]
        mv, mh, ms, mo, mm = means[g, 0], means[g, 1], means[g, 2], means[g, 3], means[g, 4]
        k0, k1, k2 = coef[g, 0], coef[g, 1], coef[g, 2]
        for i in range(n[g]):
            v = cols[0, a + i] - mv
            h = cols[1, a + i] - mh
            s = cols[2, a + i] - ms
            o = cols[3, a + i] - mo
            m = meas[c + i] - mm
            q0 = k0[0] * v + k0[1] * h + k0[2] * s + k0[3] * o + k0[4] * m
            q1 = k1[0] * v + k1[1] * h + k1[2] * s + k1[3] * o + k1[4] * m
            q2 = k2[0] * v + k2[1] * h + k2[2] * s + k2[3] * o + k2[4] * m
            a00 += q0 * q0
            a01 += q0 * q1
            a02 += q0 * q2
            a11 += q1 * q1
            a12 += q1 * q2
            a22 += q2 * q2
    out[0, 0] = a00
    out[0, 1] = out[1, 0] = a01
    out[0, 2] = out[2, 0] = a02
    out[1, 1] = a11
    out[1, 2] = out[2, 1] = a12
    out[2, 2] = a22


def residual_gram(
    cols: NDArray,
    meas: NDArray,
    lo: NDArray,
    m0: NDArray,
    n: NDArray,
    means: NDArray,
    coef: NDArray,
) -> NDArray[np.float64]:
    """``sum_g sum_i q_gi q_gi^T`` with ``q_gi = coef[g] @ (y_gi - means[g])``, ``y_gi`` the five
    columns of :func:`segment_moments` at sample ``i`` of segment ``g``: the 3 x 3 Gram matrix of
    the three vectors whose coefficients on the centred columns are the rows of ``coef[g]``
    (shape ``(segments, 3, 5)``), each formed sample by sample."""
    if coef.shape[1:] != (3, N_COLS):
        raise ValueError(f"coef must have shape (segments, 3, {N_COLS}), got {coef.shape}")
    out = np.zeros((3, 3))
    k = kernel("gram")
    if k is not None:
        k(cols, meas, lo, m0, n, means, coef, out)
        return out
    for g in range(lo.size):
        y = np.vstack((cols[:, lo[g] : lo[g] + n[g]], meas[m0[g] : m0[g] + n[g]]))
        qv = coef[g] @ (y - means[g][:, None])
        out += qv @ qv.T
    return out


# -- SINDy -------------------------------------------------------------------------------------


def _forcing_py(xi: NDArray, v0: float, v1: float, rate: float) -> tuple:
    # one interval of the free run, the library of labrig.analysis.sindy.LIBRARY in its order
    # (1, S, V, V', |V'|, V' S, V' V, |V'| S, |V'| V, S|S|): V' = d, |V'| = ad, the forcing
    # a0 at the interval's start and a1 at its end, and b, the coefficient of S
    d = (v1 - v0) * rate
    ad = abs(d)
    a0 = 0.0 + xi[0] * 1.0
    a0 = a0 + xi[2] * v0
    a0 = a0 + xi[3] * d
    a0 = a0 + xi[4] * ad
    a0 = a0 + xi[6] * (d * v0)
    a0 = a0 + xi[8] * (ad * v0)
    a1 = 0.0 + xi[0] * 1.0
    a1 = a1 + xi[2] * v1
    a1 = a1 + xi[3] * d
    a1 = a1 + xi[4] * ad
    a1 = a1 + xi[6] * (d * v1)
    a1 = a1 + xi[8] * (ad * v1)
    b = 0.0 + xi[1] * 1.0
    b = b + xi[5] * d
    b = b + xi[7] * ad
    return d, ad, a0, a1, b


_forcing = _forcing_py


def _free_run_py(
    xi: NDArray, vp: NDArray, rate: float, s0: float, limit: float, out: NDArray
) -> None:
    c = xi[9]
    h = 1.0 / rate
    s = s0
    z_last = math.nan
    p1 = p2 = 0.0
    for i in range(vp.size - 1):
        _d, _ad, a0, a1, b = _forcing(xi, vp[i], vp[i + 1], rate)
        if c == 0.0:
            z = b * h
        else:
            sa = abs(s)
            z = (b + 2.0 * c * sa) * h
        if z != z_last:  # phi1, phi2 of the step (the same z gives the same values)
            z_last = z
            if abs(z) < 1e-3:
                p1 = 1.0 + z / 2 + z * z / 6
                p2 = 0.5 + z / 6 + z * z / 24
            else:
                em = math.expm1(z)
                p1 = em / z
                p2 = (em - z) / (z * z)
        if c == 0.0:
            s = (1.0 + z * p1) * s + h * (p1 * a0 + p2 * (a1 - a0))
        else:
            s = (1.0 + z * p1) * s + h * (p1 * (a0 - c * s * sa) + p2 * (a1 - a0))
        if not abs(s) <= limit:
            s = math.copysign(limit, s) if s == s else limit
        out[i] = s


def _free_run_sensitivities_py(
    xi: NDArray,
    vp: NDArray,
    rate: float,
    s0: float,
    ds0: NDArray,
    limit: float,
    out: NDArray,
    jac: NDArray,
) -> None:
    # _free_run_py's recursion and its derivative with respect to each coefficient, step by
    # step: S_{n+1} = E S_n + h p1 g + h p2 (a1 - a0), E = 1 + z p1, g = a0 - c S_n|S_n|,
    # z = (b + 2 c |S_n|) h; with Q = dS_{n+1}/dz = (p1 + z p1') S_n + h p1' g + h p2' (a1 - a0)
    # (p1', p2' the derivatives of the forms the recursion evaluates, series included),
    # J_{n+1} = dS_{n+1}/dS_n J_n + the step's own derivative of each coefficient.
    c = xi[9]
    h = 1.0 / rate
    s = s0
    m = xi.size
    js = np.empty(m)
    for k in range(m):
        js[k] = ds0[k]
    step = np.empty(m)
    for i in range(vp.size - 1):
        v0 = vp[i]
        v1 = vp[i + 1]
        d, ad, a0, a1, b = _forcing(xi, v0, v1, rate)
        sa = abs(s)
        sg = 1.0 if s > 0 else (-1.0 if s < 0 else 0.0)
        z = b * h if c == 0.0 else (b + 2.0 * c * sa) * h  # as _free_run_py (no 0 * inf)
        if abs(z) < 1e-3:
            p1 = 1.0 + z / 2 + z * z / 6
            p2 = 0.5 + z / 6 + z * z / 24
            q1 = 0.5 + z / 3
            q2 = 1.0 / 6 + z / 12
        else:
            em = math.expm1(z)
            p1 = em / z
            p2 = (em - z) / (z * z)
            q1 = (1.0 + em - p1) / z
            q2 = (p1 - 2.0 * p2) / z
        g = a0 - c * s * sa
        e = 1.0 + z * p1
        dq = (p1 + z * q1) * s + h * (q1 * g + q2 * (a1 - a0))
        ds = e - 2.0 * h * p1 * c * sa + dq * 2.0 * c * h * sg
        wa0 = h * (p1 - p2)
        wa1 = h * p2
        step[0] = wa0 + wa1
        step[1] = dq * h
        step[2] = wa0 * v0 + wa1 * v1
        step[3] = (wa0 + wa1) * d
        step[4] = (wa0 + wa1) * ad
        step[5] = dq * h * d
        step[6] = (wa0 * v0 + wa1 * v1) * d
        step[7] = dq * h * ad
        step[8] = (wa0 * v0 + wa1 * v1) * ad
        step[9] = -h * p1 * s * sa + dq * 2.0 * h * sa
        s = e * s + h * (p1 * g + p2 * (a1 - a0))
        if not abs(s) <= limit:
            s = math.copysign(limit, s) if s == s else limit
            for k in range(m):
                js[k] = 0.0
        else:
            for k in range(m):
                js[k] = ds * js[k] + step[k]
        out[i] = s
        for k in range(m):
            jac[i, k] = js[k]


def sindy_free_run_sensitivities(
    xi: NDArray, vp: NDArray, rate_hz: float, s0: float, ds0: NDArray, limit_ue: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """:func:`sindy_free_run` and the derivative of each output with respect to each of the
    ten coefficients (``(samples, 10)``), the exact derivative of the recursion as computed
    (forward sensitivities; a held output's is 0); ``ds0``: the start's derivative.
    ``None`` without numba."""
    if np.size(xi) != 10:
        raise ValueError(f"the sensitivities need the 10 coefficients, got {np.size(xi)}")
    k = kernel("free_run_sensitivities")
    if k is None:
        return None
    n = vp.size - 1
    out, jac = np.empty(n), np.empty((n, 10))
    k(
        np.ascontiguousarray(xi, dtype=float),
        np.ascontiguousarray(vp, dtype=float),
        float(rate_hz),
        float(s0),
        np.ascontiguousarray(ds0, dtype=float),
        float(limit_ue),
        out,
        jac,
    )
    return out, jac


def sindy_free_run(
    xi: NDArray, vp: NDArray, rate_hz: float, s0: float, limit_ue: float
) -> NDArray[np.float64] | None:
    """The free run of :func:`labrig.analysis.sindy.free_run` (strain, ue, after each sample of
    the rest-prefixed voltage ``vp``, from ``s0``), compiled; ``None`` without numba."""
    k = kernel("free_run")
    if k is None:
        return None
    out = np.empty(vp.size - 1)
    k(
        np.ascontiguousarray(xi, dtype=float),
        np.ascontiguousarray(vp, dtype=float),
        float(rate_hz),
        float(s0),
        float(limit_ue),
        out,
    )
    return out
