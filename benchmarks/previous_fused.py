"""The fast model's compiled loop before the fused one, kept to be timed in the same run.

Until ``labrig.model.compiled.model_run`` fused both relaxor banks and the operator in one loop
over blocks of eight samples (on the compact banks of ``labrig.model.modal.compact_form``),
``predict(method="fast")`` ran them in chunks of 4096 samples: ``G_t``'s bank over the chunk into
an array, ``G_d``'s bank over that into another, then the operator, on the full banks
(``scaled_form``: 78 + 80 modes for the paper's relaxors at 1 kHz). This is that loop,
unchanged but for its name, with the kernels it called (copied from that module as they were).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from labrig.model.modal import DiscreteBank, scaled_form


def previous_form(bank: DiscreteBank) -> tuple:
    """A bank as the previous loop ran it: the full scaled form, zero states."""
    a, cw, feed, ca, ccw = scaled_form(bank)
    return a, cw, feed, ca, ccw, np.zeros(a.size), np.zeros(ca.size, dtype=np.complex128)


_SQRT_PI = math.sqrt(math.pi)
_INF = math.inf


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


@njit(cache=True)
def _slope(x: float, shape: int, a0: float, g: float, vc: float) -> float:
    """``alpha = alpha0 + h(x)`` (ue/V) at distance ``x >= 0`` (V) from the turning point."""
    if shape == 0:
        return a0 - g * math.expm1(-x / vc)
    if shape == 1:
        return a0 + g * x
    return a0 - g * math.expm1(-((x / vc) ** 2))


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
def _copy_rows(src: np.ndarray, dst: np.ndarray, n: int) -> None:
    """``dst[:n] = src[:n]`` for 1-D arrays (an explicit loop compiles much faster)."""
    for i in range(n):
        dst[i] = src[i]


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
            s0, s1, s2, s3, s4, s5, s6, s7 = _sweep8(a, cw, w, us)
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


@njit(cache=True, fastmath={"reassoc", "contract"})
def _sweep8(a, cw, w, us):  # fmt: skip
    """Eight samples of inputs ``us`` through the real modes, output sums (see bank_run)."""
    u0, u1, u2, u3, u4, u5, u6, u7 = us[0], us[1], us[2], us[3], us[4], us[5], us[6], us[7]
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
def previous_model_run(
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
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """The fast dynamic model over ``v`` (V): ``G_t``'s bank, ``G_d``'s bank, the operator, in
    chunks of 4096 samples that stay in cache (the same arithmetic as running them one after
    the other over the whole record).

    ``bt``, ``bd``: each bank as ``(a, cw, feed, ca, ccw, w, wc)`` (single output row, states
    ``w``, ``wc`` updated in place); ``ups`` = ``[v_prev, vt_prev]`` (updated); the relaxors
    act on ``v - rest`` and ``rest`` is added back before the operator; the operator's memory
    as in :func:`operator_pass`. Returns the strain and the operator's new memory (stack,
    direction, last input).
    """
    n = v.shape[0]
    chunk = 4096
    ub = np.empty(chunk)
    vt = np.empty(chunk)
    vd = np.empty(chunk)
    out = np.empty(n)
    m = stack_x.shape[0]
    cap = max(64, 2 * m)
    sx, sy = np.empty(cap), np.empty(cap)
    _copy_rows(stack_x, sx, m)
    _copy_rows(stack_y, sy, m)
    sp, su, sd = np.zeros((cap, 3)), np.zeros((cap, 0)), np.zeros((cap, 0))
    none2 = np.empty((0, 0))
    dp = np.empty((0, 3))
    tmp = np.empty(3)
    prev, cur, top = u_last, direction, m
    for c0 in range(0, n, chunk):
        nc = min(chunk, n - c0)
        for i in range(nc):
            ub[i] = v[c0 + i] - rest
        _bank_block(bt[0], bt[1], bt[2], bt[3], bt[4], bt[5], bt[6], ub, nc, ups[0], vt)
        _bank_block(bd[0], bd[1], bd[2], bd[3], bd[4], bd[5], bd[6], vt, nc, ups[1], vd)
        ups[0] = ub[nc - 1]
        ups[1] = vt[nc - 1]
        for i in range(nc):
            vd[i] += rest
        o = out[c0 : c0 + nc]
        x = vd[:nc]
        k = 0
        while True:
            k, prev, cur, top = _pass(x, k, prev, cur, sx, sy, sp, su, sd, top, wipe, shape,
                                      a0, g, vc, False, none2, o, dp, none2, tmp)  # fmt: skip
            if k >= nc:
                break
            c2 = 2 * sx.shape[0]
            nx, ny = np.empty(c2), np.empty(c2)
            _copy_rows(sx, nx, top)
            _copy_rows(sy, ny, top)
            sx, sy = nx, ny
            sp, su, sd = np.zeros((c2, 3)), np.zeros((c2, 0)), np.zeros((c2, 0))
    rx, ry = np.empty(top), np.empty(top)
    _copy_rows(sx, rx, top)
    _copy_rows(sy, ry, top)
    return out, rx, ry, cur, prev
