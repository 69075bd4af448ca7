"""Second-order linear sections sampled with a first-order hold, run at rest at the first sample.

A section ``H(s) = (n1 s + n0) / (d2 s^2 + d1 s + d0)`` (``d2 != 0``, ``d0 > 0``) is sampled as
``scipy.signal.cont2discrete(..., method="foh")`` samples it (the input linear between samples:
the matrix exponential of the system augmented with the input and its slope,
``scipy.linalg.expm``) and run as its state recursion

    x[k+1] = Ad x[k] + Bd u[k],    y[k] = C x[k] + Dd u[k],

starting from the state the input ``u[0]`` holds at rest (``x = (I - Ad)^-1 Bd u[0]``), as
``lfilter`` with ``lfilter_zi(b, a) * u[0]`` does. The recursion is compiled
(:func:`labrig.model.compiled.section_run`); the loop here is its reference and the fallback
without numba. Neither imports ``scipy.signal``, about a second of CPU to import (it loads
``scipy.stats``): the effect library's low-pass is among the candidates of every diagnosis.

The state is the controllable canonical form scaled by the natural frequency
``w0 = sqrt(d0 / d2)``, so that both states are of the input's size whatever ``w0`` (the
continuous state at rest under ``u`` is ``[0, u]``): ``A = [[-d1/d2, -w0], [w0, 0]]``,
``B = [w0, 0]``, ``C = [n1/(d2 w0), n0/d0]``. A section whose every pole decays by more than
:data:`FAST_LIMIT` per sample passes the input through at its gain at DC.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import expm

from labrig.model.accel import kernels

__all__ = ["FAST_LIMIT", "Section", "foh_section", "run_section"]

#: the decay per sample (rate times ``dt``) of a section's slowest pole above which it settles
#: within a sample: its response to an input linear between samples is then the input times
#: the gain at DC, to about ``1 / FAST_LIMIT`` of the input's step per sample
FAST_LIMIT = 1e12


@dataclass(frozen=True)
class Section:
    """A sampled second-order section (module docstring).

    Parameters
    ----------
    ad : numpy.ndarray
        The 2x2 state transition over one sample.
    bd : numpy.ndarray
        The input's gain into the state (2 values).
    c : numpy.ndarray
        The state's gain into the output (2 values).
    dd : float
        The input's direct gain into the output.
    """

    ad: NDArray[np.float64]
    bd: NDArray[np.float64]
    c: NDArray[np.float64]
    dd: float

    def rest_state(self, u0: float) -> NDArray[np.float64]:
        """The state the constant input ``u0`` holds (``(I - Ad)^-1 Bd u0``).

        Parameters
        ----------
        u0 : float
            The input held.

        Returns
        -------
        numpy.ndarray
            The two states.
        """
        return np.asarray(np.linalg.solve(np.eye(2) - self.ad, self.bd * u0), dtype=np.float64)


def foh_section(num: ArrayLike, den: ArrayLike, rate_hz: float) -> Section:
    """``num(s) / den(s)`` (coefficients highest power first: ``num`` of 1 or 2 terms, ``den``
    of 3 with ``den[0] != 0`` and ``den[2] / den[0] > 0``) sampled at ``rate_hz`` with a
    first-order hold.

    Parameters
    ----------
    num : array_like
        ``[n0]`` or ``[n1, n0]``.
    den : array_like
        ``[d2, d1, d0]``.
    rate_hz : float
        Sample rate (Hz).

    Returns
    -------
    Section
        The sampled section.

    Examples
    --------
    >>> s = foh_section([1.0], [1e-6, 2e-3, 1.0], 1000.0)  # fc 159 Hz, damping 1
    >>> round(float(s.c @ s.rest_state(1.0) + s.dd), 12)  # unit gain at DC
    1.0
    """
    n = np.asarray(num, dtype=np.float64).ravel()
    d = np.asarray(den, dtype=np.float64).ravel()
    if n.size not in (1, 2) or d.size != 3 or d[0] == 0.0 or not d[2] / d[0] > 0.0:
        raise ValueError(
            "a second-order section needs num of 1-2 terms and den [d2, d1, d0] with "
            f"d2 != 0 and d0/d2 > 0; got num={n.tolist()}, den={d.tolist()}"
        )
    n1, n0 = (0.0, n[0]) if n.size == 1 else (n[0], n[1])
    w0 = math.sqrt(d[2] / d[0])
    dt = 1.0 / float(rate_hz)
    # the slowest pole's decay rate is at least min(d1 / (2 d2), d0 / d1) (their real parts'
    # mean for a complex pair, their product over their sum for two real ones)
    if d[1] / d[0] > 0 and min(d[1] / (2 * d[0]), d[2] / d[1]) * dt > FAST_LIMIT:
        # settled within a sample: the output is the input times the gain at DC (the matrix
        # exponential overflows long before the section is this fast)
        z = np.zeros(2)
        return Section(np.zeros((2, 2)), z, z.copy(), float(n0 / d[2]))
    a = np.array([[-d[1] / d[0], -w0], [w0, 0.0]])
    em = np.zeros((4, 4))  # [[A dt, B dt, 0], [0, 0, 1], [0, 0, 0]]
    em[:2, :2] = a * dt
    em[0, 2] = w0 * dt
    em[2, 3] = 1.0
    ms = expm(em)
    ad, b1, b2 = ms[:2, :2], ms[:2, 2], ms[:2, 3]
    c = np.array([n1 / (d[0] * w0), n0 / d[2]])
    return Section(
        np.ascontiguousarray(ad), np.ascontiguousarray(b1 - b2 + ad @ b2), c, float(c @ b2)
    )


def _lfilter_form(sec: Section) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The section's transfer function ``(b, a)`` in ``z^-1`` (for ``lfilter``):
    ``a = [1, -tr Ad, det Ad]``, ``b = [Dd, C Bd - Dd tr Ad, k + Dd det Ad]`` with
    ``k = C adj(-Ad) Bd``'s constant term."""
    (a00, a01), (a10, a11) = sec.ad.tolist()
    b0, b1 = sec.bd.tolist()
    c0, c1 = sec.c.tolist()
    tr, det = a00 + a11, a00 * a11 - a01 * a10
    k = c0 * (a01 * b1 - a11 * b0) + c1 * (a10 * b0 - a00 * b1)
    d = sec.dd
    return np.array([d, c0 * b0 + c1 * b1 - d * tr, k + d * det]), np.array([1.0, -tr, det])


def run_section(sec: Section, x: ArrayLike) -> NDArray[np.float64]:
    """``x`` through the section, at rest at ``x[0]`` before it; each column apart for a 2-D
    ``x`` (samples along the first axis).

    Parameters
    ----------
    sec : Section
        The section (:func:`foh_section`).
    x : array_like
        The input record, 1-D, or 2-D with one record per column.

    Returns
    -------
    numpy.ndarray
        The output, shaped as ``x``.
    """
    u = np.asarray(x, dtype=np.float64)
    if u.ndim == 2:
        out = np.empty_like(u)
        for j in range(u.shape[1]):
            out[:, j] = run_section(sec, u[:, j])
        return out
    u = np.ascontiguousarray(u)
    if u.size == 0:
        return u.copy()
    k = kernels()
    x0 = sec.rest_state(float(u[0]))
    if k is not None:
        return k.section_run(sec.ad, sec.bd, sec.c, sec.dd, u, x0)
    from scipy import signal  # without numba only: its import costs about a second

    b, a = _lfilter_form(sec)
    return signal.lfilter(b, a, u, zi=signal.lfilter_zi(b, a) * u[0])[0]
