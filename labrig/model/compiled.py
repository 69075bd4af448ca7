"""Compiled kernels of the model (numba, ``@njit(cache=True)``).

Imported only through :func:`labrig.model.accel.kernels`, never at ``import labrig`` time:
importing this module imports numba. Each kernel here has a numpy counterpart in the module
that calls it (the reference of the tests, and the fallback without numba):

- :func:`operator_pass`: the quasi-static hysteresis operator of
  :mod:`labrig.model.hysteresis` in one sequential pass (the branch structure, the branch
  values and, on request, their derivatives together), for the builtin shapes;
- :func:`bank_run`: the relaxor banks of :mod:`labrig.model.modal`, one sample at a time over
  all modes (the recursion itself, in place of the numpy block form);
- :func:`chebyshev_panels`: the exact method's log-time Chebyshev interpolant of the step
  response (:mod:`labrig.model.relaxor`), Clenshaw sums eight samples at a time;
- :func:`rate_hysteresis_run`: the rate-dependent Duhem state of the ``rate_hysteresis``
  effect (:mod:`labrig.model.effects.rate_hysteresis`), its exact per-interval recurrence;
- :func:`section_run`: a sampled second-order section's recursion (:mod:`labrig.model.sections`).

Shapes are passed as integer codes (their index in ``labrig.model.hysteresis.SHAPES``:
exponential 0, linear 1, gaussian 2), memory rules as a flag; every array argument is
C-contiguous float64, so each kernel compiles once.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_SQRT_PI = math.sqrt(math.pi)
#: a relaxor mode's state below this magnitude is set to 0 (:func:`_flush_states`)
TINY_STATE = 1e-200
#: states are flushed when the sample count is a multiple of ``FLUSH_MASK + 1`` (64)
FLUSH_MASK = 63


# -- the hysteresis operator -------------------------------------------------------------------


@njit(cache=True)
def _branch(x: float, shape: int, a0: float, g: float, vc: float) -> float:
    """``F(x) = alpha0 x + int_0^x h`` (ue) for ``x >= 0`` (V), numpy's formulas.

    The exponential shape uses ``exp(-x/vc) - 1`` where numpy uses ``expm1`` (3x faster here):
    for ``x << vc`` that loses relative precision in ``H``, but its absolute error stays below
    ``gamma vc eps`` (~1e-13 ue for the paper's values), far below 1e-12 of full scale.
    """
    if shape == 0:
        return a0 * x + g * (x + vc * (math.exp(-x / vc) - 1.0))
    if shape == 1:
        return a0 * x + 0.5 * g * x * x
    return a0 * x + g * (x - vc * _SQRT_PI / 2 * math.erf(x / vc))


@njit(cache=True)
def _odd(d: float, shape: int, a0: float, g: float, vc: float) -> float:
    """``sign(d) F(|d|)``: strain change (ue) along a branch over ``d`` (V)."""
    if d > 0.0:
        return _branch(d, shape, a0, g, vc)
    if d < 0.0:
        return -_branch(-d, shape, a0, g, vc)
    return 0.0


@njit(cache=True)
def _slope(x: float, shape: int, a0: float, g: float, vc: float) -> float:
    """``alpha = alpha0 + h(x)`` (ue/V) at distance ``x >= 0`` (V) from the turning point."""
    if shape == 0:
        return a0 - g * math.expm1(-x / vc)
    if shape == 1:
        return a0 + g * x
    return a0 - g * math.expm1(-((x / vc) ** 2))


@njit(cache=True)
def _odd_dparams(d: float, shape: int, g: float, vc: float, out: np.ndarray) -> None:
    """``d sign(d) F(|d|) / d(alpha0, gamma, vc)`` into ``out[0:3]``.

    ``dF/dalpha0 = x``; ``dF/dgamma = H(x)/gamma`` (written without dividing by gamma);
    ``dF/dvc``: exponential ``gamma (expm1(-z) + z e^-z)``, gaussian
    ``gamma (z e^(-z^2) - sqrt(pi)/2 erf(z))`` with ``z = x/vc``, linear 0.
    """
    x = abs(d)
    s = 1.0 if d > 0.0 else (-1.0 if d < 0.0 else 0.0)
    out[0] = d
    if shape == 0:
        z = x / vc
        out[1] = s * (x + vc * math.expm1(-z))
        out[2] = s * g * (math.expm1(-z) + z * math.exp(-z))
    elif shape == 1:
        out[1] = s * 0.5 * x * x
        out[2] = 0.0
    else:
        z = x / vc
        out[1] = s * (x - vc * _SQRT_PI / 2 * math.erf(z))
        out[2] = s * g * (z * math.exp(-z * z) - _SQRT_PI / 2 * math.erf(z))


_INF = math.inf


@njit(cache=True)
def _copy_rows(src: np.ndarray, dst: np.ndarray, n: int) -> None:
    """``dst[:n] = src[:n]`` for 1-D arrays (an explicit loop compiles much faster)."""
    for i in range(n):
        dst[i] = src[i]


@njit(cache=True)
def _copy_rows2(src: np.ndarray, dst: np.ndarray, n: int) -> None:
    """``dst[:n] = src[:n]`` for 2-D arrays."""
    for i in range(n):
        for j in range(src.shape[1]):
            dst[i, j] = src[i, j]


@njit(cache=True)
def _pass(u, k, prev, cur, sx, sy, sp, su, sd, top, wipe, shape, a0, g, vc, want_p, du,
          out, dp, dq, tmp):  # fmt: skip
    """Samples ``k ..`` of :func:`operator_pass` until the end of ``u`` or until a turning point
    needs more room than the stack has; returns ``(k, prev, cur, top)`` to resume from.

    The current branch's turning point ``(xa, ya)`` and the input at which the next minor loop
    closes (``thr``, in the direction of travel) stay in registers: most samples are neither a
    reversal nor a closing and cost one branch value.
    """
    n = u.shape[0]
    kc = du.shape[1]
    xa, ya = sx[top - 1], sy[top - 1]
    thr = cur * sx[top - 2] if wipe and top >= wipe and cur != 0.0 else _INF
    while k < n:
        x = u[k]
        if (x - prev) * cur < 0.0 or (cur == 0.0 and x != prev) or cur * x >= thr:
            if (x - prev) * cur < 0.0:  # prev is a turning point
                if wipe and top == sx.shape[0]:
                    return k, prev, cur, top  # grow the stack, then resume at k
                a = top - 1
                d = prev - xa
                t = top if wipe else 0
                if want_p:
                    _odd_dparams(d, shape, g, vc, tmp)
                    for j in range(3):
                        sp[t, j] = sp[a, j] + tmp[j]
                if kc:
                    sl = _slope(abs(d), shape, a0, g, vc)
                    for j in range(kc):
                        dxt = du[k - 1, j] if k >= 1 else 0.0
                        su[t, j] = su[a, j] + sl * (dxt - sd[a, j])
                        sd[t, j] = dxt
                sy[t] = ya + _odd(d, shape, a0, g, vc)
                sx[t] = prev
                top = t + 1
                cur = -cur
            elif cur == 0.0 and x != prev:  # first move
                cur = 1.0 if x > prev else -1.0
            if wipe and cur != 0.0:  # close the minor loops the input reaches
                while top >= wipe and cur * x >= cur * sx[top - 2]:
                    top -= 2 if top >= 3 else 1
            xa, ya = sx[top - 1], sy[top - 1]
            thr = cur * sx[top - 2] if wipe and top >= wipe and cur != 0.0 else _INF
        d = x - xa
        out[k] = ya + _odd(d, shape, a0, g, vc)
        if want_p:
            _odd_dparams(d, shape, g, vc, tmp)
            for j in range(3):
                dp[k, j] = sp[top - 1, j] + tmp[j]
        if kc:
            sl = _slope(abs(d), shape, a0, g, vc)
            for j in range(kc):
                dq[k, j] = su[top - 1, j] + sl * (du[k, j] - sd[top - 1, j])
        prev = x
        k += 1
    return k, prev, cur, top


@njit(cache=True)
def operator_pass(
    u: np.ndarray,
    stack_x: np.ndarray,
    stack_y: np.ndarray,
    u_last: float,
    direction: float,
    wipe: int,
    shape: int,
    a0: float,
    g: float,
    vc: float,
    want_params: bool,
    du: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """The operator over ``u`` (V) in one sequential pass: strain (ue), its derivatives, the
    new memory.

    The memory is the remembered turning points ``(stack_x, stack_y)`` (oldest first, the last
    the current branch's), the last input ``u_last`` and the ``direction`` of travel. At each
    sample, a change of direction makes the previous sample (or ``u_last``) a turning point, its
    strain the current branch's value there; with return-point memory (``wipe`` 2 or 3) the
    point is pushed and every minor loop the input reaches is closed (its two turning points
    popped) while at least ``wipe`` turning points are remembered (the bottom one, the rest
    point, stays; with 3 no loop closes onto it), else (0) it replaces the memory. Flat samples
    keep the direction.

    Along the same pass, if ``want_params``, the derivatives of the strain with respect to
    ``(alpha0, gamma, vc)`` (N, 3), and along each column of ``du`` (N, k) with the branch
    structure held fixed (N, k). Each turning point carries its strain's derivatives:
    ``dS_t = dS_a + d/dp sign F(|x_t - x_a|)`` from the turning point ``a`` whose branch reached
    it, and along ``du`` ``dS_t = dS_a + alpha(|x_t - x_a|) (du_t - du_a)``, ``du_t`` the
    input's derivative at the turning point's sample; the carried-in turning points (and
    ``u_last``) have zero derivatives. Returns ``(S, dS_dparams, dS_du, stack_x, stack_y,
    direction)``.
    """
    n = u.shape[0]
    kc = du.shape[1]
    m = stack_x.shape[0]
    cap = max(64, 2 * m)
    sx, sy = np.empty(cap), np.empty(cap)
    sp, su, sd = np.zeros((cap, 3)), np.zeros((cap, kc)), np.zeros((cap, kc))
    _copy_rows(stack_x, sx, m)
    _copy_rows(stack_y, sy, m)
    out = np.empty(n)
    dp = np.empty((n if want_params else 0, 3))
    dq = np.empty((n, kc))
    tmp = np.empty(3)
    k, prev, cur, top = 0, u_last, direction, m
    while True:
        k, prev, cur, top = _pass(u, k, prev, cur, sx, sy, sp, su, sd, top, wipe, shape,
                                  a0, g, vc, want_params, du, out, dp, dq, tmp)  # fmt: skip
        if k >= n:
            break
        c2 = 2 * sx.shape[0]
        nx, ny = np.empty(c2), np.empty(c2)
        npp, nu, nd = np.zeros((c2, 3)), np.zeros((c2, kc)), np.zeros((c2, kc))
        _copy_rows(sx, nx, top)
        _copy_rows(sy, ny, top)
        _copy_rows2(sp, npp, top)
        _copy_rows2(su, nu, top)
        _copy_rows2(sd, nd, top)
        sx, sy, sp, su, sd = nx, ny, npp, nu, nd
    rx, ry = np.empty(top), np.empty(top)
    _copy_rows(sx, rx, top)
    _copy_rows(sy, ry, top)
    return out, dp, dq, rx, ry, cur


# -- the relaxor banks -------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _flush(x: float) -> float:
    """``x``, or 0 below :data:`TINY_STATE` in magnitude (a NaN stays NaN)."""
    return 0.0 if abs(x) < TINY_STATE else x


@njit(cache=True, inline="always")
def _flush_complex(z: complex) -> complex:
    """:func:`_flush` of each part of ``z``."""
    return complex(_flush(z.real), _flush(z.imag))


@njit(cache=True)
def _flush_states(w: np.ndarray, wc: np.ndarray) -> None:
    """A bank's states under :data:`TINY_STATE` (each part of a complex one) set to 0, every
    ``FLUSH_MASK + 1`` samples of a call and at its end. A mode decaying through a rest (its
    input exactly 0 for seconds: the relaxors act on ``v - rest_V``) would otherwise spend
    thousands of samples among subnormal numbers, on which the processor's arithmetic is many
    times slower; what a state under 1e-200 adds to an output is below the last bit of any
    output not itself below ~1e-180. (Checked outside the sweeps: a compare in the vectorised
    sweep costs more than the check every 64 samples.)"""
    for i in range(w.shape[0]):
        w[i] = _flush(w[i])
    for i in range(wc.shape[0]):
        wc[i] = _flush_complex(wc[i])


@njit(cache=True)
def bank_run(
    a: np.ndarray,
    cw: np.ndarray,
    ca: np.ndarray,
    ccw: np.ndarray,
    feed: np.ndarray,
    u: np.ndarray,
    w: np.ndarray,
    wc: np.ndarray,
    u_prev: np.ndarray,
) -> np.ndarray:
    """Run a bank of first-order modes over the columns of ``u`` (N, k); ``y`` (N, k, r).

    Each mode is kept in scaled form ``w = z / b``: ``w[n] = a w[n-1] + u[n-1]``, and output
    row ``q`` is ``y_q[n] = sum_i cw[q, i] w_i[n] + feed[q] u[n]`` (``cw = c b``: the bank's
    output weights times the folded input gains; :mod:`labrig.model.modal`). Real modes:
    ``a`` (M,), ``cw`` (r, M), state ``w`` (k, M); complex modes: ``ca`` (Mc,), ``ccw``
    (r, Mc), state ``wc`` (k, Mc), their output the real part. ``u_prev`` (k,): each column's
    input before its first sample. The states are updated in place. One pass per column and
    output row (each row's pass costs what a single-output bank does: the states are cheaper to
    recompute than to keep), eight samples per sweep over the modes.
    """
    n, kc = u.shape
    r = cw.shape[0]
    y = np.empty((n, kc, r))
    yc = np.empty(n)
    for j in range(kc):
        uc = np.ascontiguousarray(u[:, j])
        w0, wc0 = w[j].copy(), wc[j].copy()
        for q in range(r):  # one pass per output row, each from the column's initial state
            wq, wcq = w0.copy(), wc0.copy()
            _bank_block(a, cw[q], feed[q], ca, ccw[q], wq, wcq, uc, n, u_prev[j], yc)
            for k in range(n):
                y[k, j, q] = yc[k]
            if q == 0:  # loops, not ``w[j] = wq``, whose shape-error message numba compiles (~3 s)
                _copy_rows(wq, w[j], wq.shape[0])
                _copy_rows(wcq, wc[j], wcq.shape[0])
    return y


@njit(cache=True)
def mode_derivative(
    u: np.ndarray,
    a: complex,
    b0: complex,
    b1: complex,
    da: complex,
    db0: complex,
    db1: complex,
    g: np.ndarray,
    out: np.ndarray,
) -> None:
    """Add ``Re(g[p] dx/dq)`` to ``out[:, p]`` for a mode ``x[n] = a x[n-1] + b0 u[n-1] +
    b1 u[n]`` at rest before ``u``: ``dx/dq`` follows ``z[n] = a z[n-1] + a' x[n-1] +
    b0' u[n-1] + b1' u[n]`` (the derivative of the exact discretisation; ``'`` = d/dq)."""
    x = 0.0 + 0.0j
    z = 0.0 + 0.0j
    up = 0.0
    n = u.shape[0]
    k0 = 0
    while k0 < n:  # the states flushed every 64 samples, as the banks' (_flush_states)
        for k in range(k0, min(k0 + FLUSH_MASK + 1, n)):
            uk = u[k]
            z = a * z + da * x + db0 * up + db1 * uk
            x = a * x + b0 * up + b1 * uk
            for p in range(g.shape[0]):
                out[k, p] += (g[p] * z).real
            up = uk
        x = _flush_complex(x)
        z = _flush_complex(z)
        k0 += FLUSH_MASK + 1


# -- the exact method's interpolant ------------------------------------------------------------


@njit(cache=True)
def _clenshaw1(coeffs: np.ndarray, p: int, x: float) -> float:
    """``sum_k coeffs[p, k] T_k(x)`` by Clenshaw's recurrence."""
    b1 = b2 = 0.0
    tx = 2.0 * x
    for k in range(coeffs.shape[1] - 1, 0, -1):
        b0 = coeffs[p, k] + tx * b1 - b2
        b2, b1 = b1, b0
    return coeffs[p, 0] + x * b1 - b2


@njit(cache=True)
def chebyshev_panels(u: np.ndarray, u0: float, width: float, coeffs: np.ndarray) -> np.ndarray:
    """``sum_k coeffs[p, k] T_k(x)`` at each ``u = log10 t`` (``t`` in s): ``u`` falls in
    panel ``p = floor((u - u0) / width)`` (clipped to the panels), ``x`` is ``u`` mapped onto
    ``[-1, 1]`` within it; Clenshaw's recurrence. Eight samples in one panel (sorted times: the
    kernels') run as eight independent chains sharing each coefficient (they keep the
    multiplier busy); the others one at a time. Each sum is the same as alone."""
    n = u.shape[0]
    npan, nk = coeffs.shape
    out = np.empty(n)
    pan = np.empty(8, dtype=np.int64)
    i = 0
    while i < n:
        m = min(8, n - i)
        same = m == 8
        for j in range(m):
            pan[j] = min(max(int((u[i + j] - u0) / width), 0), npan - 1)
            same = same and pan[j] == pan[0]
        if not same:
            for j in range(m):
                lo = u0 + pan[j] * width
                out[i + j] = _clenshaw1(coeffs, pan[j], 2.0 * (u[i + j] - lo) / width - 1.0)
            i += m
            continue
        p = pan[0]
        lo = u0 + p * width
        x0 = 2.0 * (u[i] - lo) / width - 1.0
        x1 = 2.0 * (u[i + 1] - lo) / width - 1.0
        x2 = 2.0 * (u[i + 2] - lo) / width - 1.0
        x3 = 2.0 * (u[i + 3] - lo) / width - 1.0
        x4 = 2.0 * (u[i + 4] - lo) / width - 1.0
        x5 = 2.0 * (u[i + 5] - lo) / width - 1.0
        x6 = 2.0 * (u[i + 6] - lo) / width - 1.0
        x7 = 2.0 * (u[i + 7] - lo) / width - 1.0
        t0, t1, t2, t3 = 2.0 * x0, 2.0 * x1, 2.0 * x2, 2.0 * x3
        t4, t5, t6, t7 = 2.0 * x4, 2.0 * x5, 2.0 * x6, 2.0 * x7
        a1 = a2 = b1 = b2 = c1 = c2 = d1 = d2 = 0.0
        e1 = e2 = f1 = f2 = g1 = g2 = h1 = h2 = 0.0
        for k in range(nk - 1, 0, -1):
            c = coeffs[p, k]
            a0 = c + t0 * a1 - a2
            b0 = c + t1 * b1 - b2
            c0 = c + t2 * c1 - c2
            d0 = c + t3 * d1 - d2
            e0 = c + t4 * e1 - e2
            f0 = c + t5 * f1 - f2
            g0 = c + t6 * g1 - g2
            h0 = c + t7 * h1 - h2
            a2, a1, b2, b1, c2, c1, d2, d1 = a1, a0, b1, b0, c1, c0, d1, d0
            e2, e1, f2, f1, g2, g1, h2, h1 = e1, e0, f1, f0, g1, g0, h1, h0
        c = coeffs[p, 0]
        out[i] = c + x0 * a1 - a2
        out[i + 1] = c + x1 * b1 - b2
        out[i + 2] = c + x2 * c1 - c2
        out[i + 3] = c + x3 * d1 - d2
        out[i + 4] = c + x4 * e1 - e2
        out[i + 5] = c + x5 * f1 - f2
        out[i + 6] = c + x6 * g1 - g2
        out[i + 7] = c + x7 * h1 - h2
        i += 8
    return out


# -- the rate-dependent hysteresis state -------------------------------------------------------


@njit(cache=True)
def rate_hysteresis_run(x: np.ndarray, A: float, beta: float, inv_tau_dt: float) -> np.ndarray:
    """``h`` (ue) of ``dh/dt = A dx/dt - beta |dx/dt| h - h / tau_h`` over ``x`` (V), at rest
    (``h = 0``) at ``x[0]``, ``x`` linear between samples; ``inv_tau_dt = dt / tau_h``.

    Exact per interval: with ``d = x[n] - x[n-1]`` the rate is constant, the equation linear
    with constant coefficients, so with ``z = beta |d| + dt / tau_h``
    ``h[n] = h[n-1] exp(-z) + A d (1 - exp(-z)) / z`` (the ratio ``-expm1(-z) / z``, 1 at
    ``z = 0``).
    """
    n = x.shape[0]
    h = np.empty(n)
    if n == 0:
        return h
    hk = 0.0
    h[0] = 0.0
    for k in range(1, n):
        d = x[k] - x[k - 1]
        z = beta * abs(d) + inv_tau_dt
        if z > 1e-12:
            e = math.exp(-z)
            hk = hk * e + A * d * (-math.expm1(-z) / z)
        else:
            hk = hk * (1.0 - z) + A * d * (1.0 - 0.5 * z)
        h[k] = hk
    return h


@njit(cache=True)
def section_run(
    ad: np.ndarray, bd: np.ndarray, c: np.ndarray, dd: float, u: np.ndarray, x0: np.ndarray
) -> np.ndarray:
    """A sampled second-order section's recursion over ``u`` from the state ``x0``
    (:mod:`labrig.model.sections`): ``y[k] = c x[k] + dd u[k]``, ``x[k+1] = ad x[k] + bd u[k]``."""
    n = u.shape[0]
    y = np.empty(n)
    s0, s1 = x0[0], x0[1]
    for k in range(n):
        uk = u[k]
        y[k] = c[0] * s0 + c[1] * s1 + dd * uk
        s0, s1 = (
            ad[0, 0] * s0 + ad[0, 1] * s1 + bd[0] * uk,
            ad[1, 0] * s0 + ad[1, 1] * s1 + bd[1] * uk,
        )
    return y


# -- the whole fast model ----------------------------------------------------------------------


@njit(cache=True)
def _bank_block(a, cw, feed, ca, ccw, w, wc, u, n, up, y):  # fmt: skip
    """``y[:n]`` of a single-output bank for the inputs ``u[:n]`` (``up`` before them); the
    states ``w`` (real modes) and ``wc`` (complex) are updated. Eight samples per sweep."""
    us = np.zeros(8)
    acc = np.zeros(8)
    k = 0
    while k < n:
        nb = min(8, n - k)
        us[0] = up
        for t in range(1, nb):
            us[t] = u[k + t - 1]
        if nb == 8:
            s0, s1, s2, s3, s4, s5, s6, s7 = _sweep8s(
                a, cw, w, us[0], us[1], us[2], us[3], us[4], us[5], us[6], us[7]
            )
            acc[0], acc[1], acc[2], acc[3] = s0, s1, s2, s3
            acc[4], acc[5], acc[6], acc[7] = s4, s5, s6, s7
        else:
            for t in range(nb):
                acc[t] = 0.0
            for i in range(a.shape[0]):
                ai = a[i]
                wt = w[i]
                for t in range(nb):
                    wt = ai * wt + us[t]
                    acc[t] += cw[i] * wt
                w[i] = wt
        for i in range(ca.shape[0]):  # the complex modes (a few), in real arithmetic
            ar, ai = ca[i].real, ca[i].imag
            cr, ci = ccw[i].real, ccw[i].imag
            wr, wi = wc[i].real, wc[i].imag
            for t in range(nb):
                wr, wi = ar * wr - ai * wi + us[t], ar * wi + ai * wr
                acc[t] += cr * wr - ci * wi
            wc[i] = complex(wr, wi)
        for t in range(nb):
            y[k + t] = acc[t] + feed * u[k + t]
        up = u[k + nb - 1]
        k += nb
        if k & FLUSH_MASK == 0:
            _flush_states(w, wc)
    _flush_states(w, wc)  # and at the end: a stream of short calls flushes too


@njit(cache=True, fastmath={"reassoc", "contract"})
def _sweep8s(a, cw, w, u0, u1, u2, u3, u4, u5, u6, u7):  # fmt: skip
    """Eight samples of inputs ``u0..u7`` through the real modes ``a`` (states ``w``, updated),
    the output sums ``sum cw w`` after each (see bank_run); scalars, so they stay in
    registers."""
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
    for i in range(a.shape[0]):
        ai = a[i]
        ci = cw[i]
        w0 = ai * w[i] + u0
        w1 = ai * w0 + u1
        w2 = ai * w1 + u2
        w3 = ai * w2 + u3
        w4 = ai * w3 + u4
        w5 = ai * w4 + u5
        w6 = ai * w5 + u6
        w7 = ai * w6 + u7
        w[i] = w7
        s0 += ci * w0
        s1 += ci * w1
        s2 += ci * w2
        s3 += ci * w3
        s4 += ci * w4
        s5 += ci * w5
        s6 += ci * w6
        s7 += ci * w7
    return s0, s1, s2, s3, s4, s5, s6, s7


@njit(cache=True)
def _complex8(ca, ccw, wc, u0, u1, u2, u3, u4, u5, u6, u7):  # fmt: skip
    """The complex modes' outputs for eight inputs (real arithmetic); the states updated."""
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
    for i in range(ca.shape[0]):
        ar, ai = ca[i].real, ca[i].imag
        cr, ci = ccw[i].real, ccw[i].imag
        wr, wi = wc[i].real, wc[i].imag
        wr, wi = ar * wr - ai * wi + u0, ar * wi + ai * wr
        s0 += cr * wr - ci * wi
        wr, wi = ar * wr - ai * wi + u1, ar * wi + ai * wr
        s1 += cr * wr - ci * wi
        wr, wi = ar * wr - ai * wi + u2, ar * wi + ai * wr
        s2 += cr * wr - ci * wi
        wr, wi = ar * wr - ai * wi + u3, ar * wi + ai * wr
        s3 += cr * wr - ci * wi
        wr, wi = ar * wr - ai * wi + u4, ar * wi + ai * wr
        s4 += cr * wr - ci * wi
        wr, wi = ar * wr - ai * wi + u5, ar * wi + ai * wr
        s5 += cr * wr - ci * wi
        wr, wi = ar * wr - ai * wi + u6, ar * wi + ai * wr
        s6 += cr * wr - ci * wi
        wr, wi = ar * wr - ai * wi + u7, ar * wi + ai * wr
        s7 += cr * wr - ci * wi
        wc[i] = complex(wr, wi)
    return s0, s1, s2, s3, s4, s5, s6, s7


@njit(cache=True)
def _bank1(a, cw, feed, ca, ccw, w, wc, up, x):  # fmt: skip
    """One sample ``x`` (``up`` before it) through a bank; its output."""
    y = feed * x
    for i in range(a.shape[0]):
        w[i] = a[i] * w[i] + up
        y += cw[i] * w[i]
    for i in range(ca.shape[0]):
        z = ca[i] * wc[i] + up
        wc[i] = z
        y += (ccw[i] * z).real
    return y


@njit(cache=True)
def _turn(x, prev, cur, top, sx, sy, wipe, shape, a0, g, vc):  # fmt: skip
    """The operator's memory update at an input ``x`` that reverses, first moves or closes a
    loop (see :func:`_pass`); returns ``(cur, top, xa, ya, thr)``. ``sx``, ``sy`` have room
    for one more turning point."""
    xa, ya = sx[top - 1], sy[top - 1]
    if (x - prev) * cur < 0.0:  # prev is a turning point
        t = top if wipe else 0
        sy[t] = ya + _odd(prev - xa, shape, a0, g, vc)
        sx[t] = prev
        top = t + 1
        cur = -cur
    elif cur == 0.0 and x != prev:  # first move
        cur = 1.0 if x > prev else -1.0
    if wipe and cur != 0.0:  # close the minor loops the input reaches
        while top >= wipe and cur * x >= cur * sx[top - 2]:
            top -= 2 if top >= 3 else 1
    thr = cur * sx[top - 2] if wipe and top >= wipe and cur != 0.0 else _INF
    return cur, top, sx[top - 1], sy[top - 1], thr


@njit(cache=True)
def model_run(
    v: np.ndarray,
    rest: float,
    bt: tuple,
    bd: tuple,
    ups: np.ndarray,
    stack_x: np.ndarray,
    stack_y: np.ndarray,
    u_last: float,
    direction: float,
    wipe: int,
    shape: int,
    a0: float,
    g: float,
    vc: float,
    out: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """The fast dynamic model over ``v`` (V): ``G_t``'s bank, ``G_d``'s bank, the operator, fused
    in one loop over blocks of eight samples (no intermediate arrays: each block's ``V_t`` and
    ``V*`` stay in registers; the same arithmetic as running the stages one after the other).

    ``bt``, ``bd``: each bank as ``(a, cw, feed, ca, ccw, w, wc)`` (single output row, states
    ``w``, ``wc`` updated in place); ``ups`` = ``[v_prev, vt_prev]`` (updated); the relaxors
    act on ``v - rest`` and ``rest`` is added back before the operator; the operator's memory
    as in :func:`operator_pass`. The strain is written to ``out`` (as long as ``v``; allocated
    by the caller: numpy asks the kernel for huge pages, so a long record's first touch costs
    half of what numba's own allocation does). Returns ``out`` and the operator's new memory
    (stack, direction, last input).
    """
    n = v.shape[0]
    m = stack_x.shape[0]
    cap = max(64, 2 * m)
    sx, sy = np.empty(cap), np.empty(cap)
    _copy_rows(stack_x, sx, m)
    _copy_rows(stack_y, sy, m)
    at, cwt, ft, cat, ccwt, wt, wct = bt
    ad, cwd, fd, cad, ccwd, wd, wcd = bd
    vd = np.empty(8)
    up_t, up_d = ups[0], ups[1]
    prev, cur, top = u_last, direction, m
    xa, ya = sx[top - 1], sy[top - 1]
    thr = cur * sx[top - 2] if wipe and top >= wipe and cur != 0.0 else _INF
    k = 0
    while k < n:
        nb = min(8, n - k)
        if top + 8 >= sx.shape[0]:  # room for a turning point per sample of the block
            c2 = 2 * sx.shape[0]
            nx, ny = np.empty(c2), np.empty(c2)
            _copy_rows(sx, nx, top)
            _copy_rows(sy, ny, top)
            sx, sy = nx, ny
        if nb == 8:
            u0, u1, u2, u3 = v[k] - rest, v[k + 1] - rest, v[k + 2] - rest, v[k + 3] - rest
            u4, u5, u6, u7 = v[k + 4] - rest, v[k + 5] - rest, v[k + 6] - rest, v[k + 7] - rest
            s0, s1, s2, s3, s4, s5, s6, s7 = _sweep8s(at, cwt, wt, up_t, u0, u1, u2, u3, u4,
                                                      u5, u6)  # fmt: skip
            if cat.shape[0]:
                c0, c1, c2, c3, c4, c5, c6, c7 = _complex8(cat, ccwt, wct, up_t, u0, u1, u2,
                                                           u3, u4, u5, u6)  # fmt: skip
                s0, s1, s2, s3, s4, s5, s6, s7 = (s0 + c0, s1 + c1, s2 + c2, s3 + c3, s4 + c4,
                                                  s5 + c5, s6 + c6, s7 + c7)  # fmt: skip
            t0, t1, t2, t3 = s0 + ft * u0, s1 + ft * u1, s2 + ft * u2, s3 + ft * u3
            t4, t5, t6, t7 = s4 + ft * u4, s5 + ft * u5, s6 + ft * u6, s7 + ft * u7
            s0, s1, s2, s3, s4, s5, s6, s7 = _sweep8s(ad, cwd, wd, up_d, t0, t1, t2, t3, t4,
                                                      t5, t6)  # fmt: skip
            if cad.shape[0]:
                c0, c1, c2, c3, c4, c5, c6, c7 = _complex8(cad, ccwd, wcd, up_d, t0, t1, t2,
                                                           t3, t4, t5, t6)  # fmt: skip
                s0, s1, s2, s3, s4, s5, s6, s7 = (s0 + c0, s1 + c1, s2 + c2, s3 + c3, s4 + c4,
                                                  s5 + c5, s6 + c6, s7 + c7)  # fmt: skip
            vd[0], vd[1], vd[2], vd[3] = s0 + fd * t0, s1 + fd * t1, s2 + fd * t2, s3 + fd * t3
            vd[4], vd[5], vd[6], vd[7] = s4 + fd * t4, s5 + fd * t5, s6 + fd * t6, s7 + fd * t7
            up_t, up_d = u7, t7
        else:
            for t in range(nb):
                x = v[k + t] - rest
                xt = _bank1(at, cwt, ft, cat, ccwt, wt, wct, up_t, x)
                vd[t] = _bank1(ad, cwd, fd, cad, ccwd, wd, wcd, up_d, xt)
                up_t, up_d = x, xt
        for t in range(nb):
            x = vd[t] + rest
            if (x - prev) * cur < 0.0 or (cur == 0.0 and x != prev) or cur * x >= thr:
                cur, top, xa, ya, thr = _turn(x, prev, cur, top, sx, sy, wipe, shape, a0, g,
                                              vc)  # fmt: skip
            out[k + t] = ya + _odd(x - xa, shape, a0, g, vc)
            prev = x
        k += nb
        if k & FLUSH_MASK == 0:
            _flush_states(wt, wct)
            _flush_states(wd, wcd)
    _flush_states(wt, wct)  # and at the end: a stream of short calls flushes too
    _flush_states(wd, wcd)
    ups[0], ups[1] = up_t, up_d
    rx, ry = np.empty(top), np.empty(top)
    _copy_rows(sx, rx, top)
    _copy_rows(sy, ry, top)
    return out, rx, ry, cur, prev
