"""The fast model's compiled loop before the fused one, kept to be timed in the same run.

Until ``labrig.model.compiled.model_run`` fused both relaxor banks and the operator in one loop
over blocks of eight samples (on the compact banks of ``labrig.model.modal.compact_form``),
``predict(method="fast")`` ran them in chunks of 4096 samples: ``G_t``'s bank over the chunk into
an array, ``G_d``'s bank over that into another, then the operator, on the full banks
(``scaled_form``: 78 + 80 modes for the paper's relaxors at 1 kHz). This is that loop,
unchanged but for its name and the kernels it imports from ``labrig.model.compiled``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from labrig.model.compiled import _bank_block, _copy_rows, _pass
from labrig.model.modal import DiscreteBank, scaled_form


def previous_form(bank: DiscreteBank) -> tuple:
    """A bank as the previous loop ran it: the full scaled form, zero states."""
    a, cw, feed, ca, ccw = scaled_form(bank)
    return a, cw, feed, ca, ccw, np.zeros(a.size), np.zeros(ca.size, dtype=np.complex128)


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
