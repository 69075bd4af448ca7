"""The Bouc-Wen hysteresis state (``n = 1``), exact per monotone run of its input.

    dh = A dx - beta |dx| h - gamma dx |h|        (units: ``A`` ue/V; ``beta, gamma`` 1/V)

The element is rate independent: along a run of monotone input (direction ``s``, distance
``u = s (x - x_0)``) ``dh/du = s A - (beta + gamma s sign(h)) h`` is linear in ``h`` on each side of
``h = 0``, so ``h = sA/k + (h_0 - sA/k) exp(-k u)`` with ``k = beta - gamma`` while ``h`` is
opposite to the motion and ``k = beta + gamma`` once it has the motion's sign (the crossing of
zero is found in closed form), for ``A > 0``: bounded for ``beta > 0``, ``-beta < gamma <= beta``;
its loops saturate at ``h = +-A / (beta + gamma)``. For ``A < 0`` ``h`` moves against the input;
substituting ``h -> -h`` shows ``h(A, beta, gamma) = -h(-A, beta, -gamma)``, which is how every
form below computes it. Unlike the paper's operator, a Bouc-Wen loop need not close where it
started: after an excursion and back to ``x = 0`` it keeps a remanent ``h`` (what the hybrid
plant's Bouc-Wen block and the ``remanence`` effect model).

Three forms of the same closed form, one per use: :func:`bouc_wen_exact` (whole record,
vectorised over the samples of each run: fits), :func:`bouc_wen_step` (one sample from a state:
the controller's per-sample inverse) and :func:`bouc_wen_stream` (blocks with carried state: the
simulated plant).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["bouc_wen_exact", "bouc_wen_step", "bouc_wen_stream", "max_slope", "monotone_runs"]


def max_slope(A: float, beta: float, gamma: float) -> float:
    """The largest ``dh/dx`` (ue/V) the bounded element can show (``beta > 0``,
    ``|gamma| <= beta``, ``beta + gamma sign(A) > 0``).

    For ``A > 0``, rising (falling is the mirror image), ``dh/dx = A - (beta + gamma sign h) h``
    is linear in ``h`` on each side of 0 and ``h`` stays within ``+-M``, ``M = A / (beta +
    gamma)``: the supremum is at ``h = -M``, ``A + (beta - gamma) M = 2 A beta / (beta +
    gamma)``. For ``A < 0`` (the mirror image ``-h(-A, beta, -gamma)``) ``h`` never rises with
    ``x``: the supremum is 0 (approached at saturation); ``A = 0`` keeps ``h = 0``.

    Parameters
    ----------
    A : float
        Gain of the element (ue/V).
    beta, gamma : float
        Shape parameters (1/V).

    Returns
    -------
    float
        The supremum of ``dh/dx`` (ue/V).

    Examples
    --------
    >>> max_slope(1.0, 0.5, 0.5)
    1.0
    >>> max_slope(-1.0, 0.5, 0.5)
    0.0
    """
    return 2.0 * A * beta / (beta + gamma) if A > 0 else 0.0


def monotone_runs(v: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Split ``v`` (prefixed with the rest value 0) into monotone runs.

    Returns ``starts, stops, dirs``: run ``j`` goes from sample ``starts[j]`` (its start value)
    to ``stops[j]`` (inclusive) of the prefixed record, in direction ``dirs[j]`` (+1 or -1);
    flat stretches join the current run.

    Parameters
    ----------
    v : numpy.ndarray
        The rest-prefixed record (its first sample the rest value).

    Returns
    -------
    starts, stops : numpy.ndarray
        Each run's first and last sample (int).
    dirs : numpy.ndarray
        Each run's direction (+1.0 or -1.0).

    Examples
    --------
    >>> import numpy as np
    >>> starts, stops, dirs = monotone_runs(np.array([0.0, 1.0, 2.0, 2.0, 1.0, 0.0]))
    >>> starts.tolist(), stops.tolist(), dirs.tolist()
    ([0, 3], [3, 5], [1.0, -1.0])
    """
    d = np.sign(np.diff(v))
    nz = np.flatnonzero(d)
    if nz.size == 0:
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0)
    # fill zero steps with the previous direction (or the next one at the start)
    idx = np.where(d != 0, np.arange(d.size), 0)
    np.maximum.accumulate(idx, out=idx)
    filled = d[idx]
    filled[: nz[0]] = d[nz[0]]
    change = np.flatnonzero(np.diff(filled) != 0) + 1  # first step index of each new run
    starts = np.concatenate(([0], change))
    stops = np.concatenate((change, [d.size]))
    return starts, stops, filled[starts]


def _phi(k: NDArray, u: NDArray) -> NDArray:
    """``(1 - exp(-k u)) / k`` (``u`` when ``k = 0``)."""
    ku = k * u
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.abs(ku) > 1e-12, -np.expm1(-ku) / np.where(k == 0, 1.0, k), u)


def bouc_wen_exact(
    vp: NDArray, A: float, beta: float, gamma: float, runs: tuple | None = None
) -> NDArray:
    """``h`` for ``n = 1`` at the samples of the rest-prefixed record ``vp`` (closed form).

    Parameters
    ----------
    vp : numpy.ndarray
        The input (V), prefixed with its rest value.
    A : float
        Gain (ue/V).
    beta, gamma : float
        Shape parameters (1/V).
    runs : tuple, optional
        :func:`monotone_runs` of ``vp``, when already known.

    Returns
    -------
    numpy.ndarray
        ``h`` (ue) at each sample of ``vp`` (0 at the rest sample).
    """
    if A < 0:  # the mirror image (module docstring)
        return -bouc_wen_exact(vp, -A, beta, -gamma, runs)
    starts, stops, dirs = monotone_runs(vp) if runs is None else runs
    h = np.zeros(vp.size)
    if starts.size == 0:
        return h
    k_same, k_opp = beta + gamma, beta - gamma
    nrun = starts.size
    h0 = np.empty(nrun)  # state at each run's start
    u_star = np.zeros(nrun)  # distance at which h crosses zero (runs that start opposite)
    travel = dirs * (vp[stops] - vp[starts])
    hc = 0.0
    for j in range(nrun):  # scalar recursion over runs only
        s, U = float(dirs[j]), float(travel[j])
        h0[j] = hc
        us = 0.0
        if hc * s < 0:
            x = k_opp * abs(hc) / A if A != 0 else np.inf
            if abs(x) < 1e-12:
                us = abs(hc) / A
            elif 1.0 + x > 0:
                us = float(np.log1p(x) / k_opp)
            else:
                us = np.inf
            if us >= U:
                e = np.exp(-k_opp * U)
                hc = hc * e + s * A * (U if k_opp == 0 else -np.expm1(-k_opp * U) / k_opp)
                u_star[j] = np.inf
                continue
            hc, U = 0.0, U - us
        u_star[j] = us
        hc = hc * np.exp(-k_same * U) + s * A * (
            U if k_same == 0 else -np.expm1(-k_same * U) / k_same
        )
    run = np.repeat(np.arange(nrun), stops - starts)
    s = dirs[run]
    u = s * (vp[1:] - vp[starts][run])
    us = u_star[run]
    hs = h0[run]
    phase1 = u <= us  # still relaxing towards zero with k_opp (opposite-sign start)
    ko = np.full(u.size, k_opp)
    kq = np.full(u.size, k_same)
    h1 = hs * np.exp(-ko * u) + s * A * _phi(ko, u)
    u2 = np.where(phase1, 0.0, u - np.where(np.isfinite(us), us, 0.0))
    start2 = np.where(hs * s < 0, 0.0, hs)
    h2 = start2 * np.exp(-kq * u2) + s * A * _phi(kq, u2)
    h[1:] = np.where(phase1, h1, h2)
    return h


def bouc_wen_step(h: float, dx: float, A: float, beta: float, gamma: float) -> float:
    """``h`` after the input moves by ``dx`` (linearly) from state ``h`` (closed form).

    Parameters
    ----------
    h : float
        The state before the step (ue).
    dx : float
        The input's change (V).
    A : float
        Gain (ue/V).
    beta, gamma : float
        Shape parameters (1/V).

    Returns
    -------
    float
        The state after the step (ue).

    Examples
    --------
    From rest, one volt up with ``A = 1``, ``beta = gamma = 0.5``: ``h = 1 - exp(-1)``.

    >>> round(bouc_wen_step(0.0, 1.0, 1.0, 0.5, 0.5), 12)
    0.632120558829
    """
    if A < 0:  # the mirror image (module docstring)
        return -bouc_wen_step(-h, dx, -A, beta, -gamma)
    if dx == 0.0:
        return h
    s = 1.0 if dx > 0 else -1.0
    rem = dx
    for _ in range(2):  # at most one sign change of h per step
        sig = 1.0 if h > 0 else (-1.0 if h < 0 else s)
        k = beta * s + gamma * sig
        if k == 0.0:
            hn = h + A * rem
            if hn * h < 0:
                rem -= -h / A
                h = 0.0
                continue
            return hn
        hs = A / k
        hn = hs + (h - hs) * math.exp(-k * rem)
        if h != 0.0 and hn * h < 0 and hs * h < 0:
            # split where h crosses zero: exp(-k x) = -hs / (h - hs)
            rem -= -math.log(-hs / (h - hs)) / k
            h = 0.0
            continue
        return hn
    return h


def bouc_wen_stream(
    x: NDArray, h0: float, x0: float, A: float, beta: float, gamma: float
) -> tuple[NDArray[np.float64], float]:
    """``h`` after each sample of the block ``x``, from state ``h0`` at input ``x0``; returns
    ``(h, h_last)`` to carry into the next block.

    Parameters
    ----------
    x : numpy.ndarray
        The block of input samples (V).
    h0 : float
        The state before the block (ue).
    x0 : float
        The input before the block (V).
    A : float
        Gain (ue/V).
    beta, gamma : float
        Shape parameters (1/V).

    Returns
    -------
    h : numpy.ndarray
        The state after each sample (ue).
    h_last : float
        The state after the last sample, for the next block.
    """
    out = np.empty(x.size)
    h, xp = float(h0), float(x0)
    for n in range(x.size):
        xn = float(x[n])
        h = bouc_wen_step(h, xn - xp, A, beta, gamma)
        out[n] = h
        xp = xn
    return out, h
