"""Quasi-static hysteresis operator (seed Eq. 1, 2, 10; spec model.md §1).

    dS = alpha(u, u_s) du,     alpha = alpha0 + h(|u - u_s|),     h(0) = 0

``u`` is the (equivalent static) voltage in V, ``S`` the strain in ue, ``alpha0`` and ``h`` in
ue/V. The memory ``u_s`` is the voltage at the last reversal (local extremum of ``u``); the
strain there is ``S_s``. Between reversals the branch has the closed form

    S = S_s + sign(u - u_s) F(|u - u_s|),     F(x) = alpha0 x + int_0^x h(y) dy,

so no integration error is made. Initial state: the actuator rests at 0 V with zero strain
(``u_s = 0``, ``S_s = 0``), which is the spec's ``u_s = u(0)`` for records that start at 0 V.

Shapes of ``h`` (``gamma`` in ue/V, ``vc`` in V):

- ``"exponential"`` (fitted in the seed): ``h(x) = gamma (1 - exp(-x/vc))``
- ``"linear"`` (a differential Rayleigh law): ``h(x) = gamma x`` (``vc`` unused)
- ``"gaussian"``: ``h(x) = gamma (1 - exp(-(x/vc)^2))``
- any callable ``h(x)`` with ``h(0) = 0`` via :class:`Shape` (its integral is then evaluated by
  48-point Gauss-Legendre quadrature, exact for polynomials up to degree 95).

Inversion (strain to voltage) solves ``F(x) = y`` on each branch: Lambert W for the exponential
shape, the quadratic formula for the linear one, and safeguarded Newton iterations otherwise,
finished by Newton steps to machine precision.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

SHAPES = ("exponential", "linear", "gaussian")
_GL48_X, _GL48_W = np.polynomial.legendre.leggauss(48)


@dataclass(frozen=True)
class Shape:
    """A hysteretic slope ``h(x; gamma, vc)`` and (optionally) its integral ``H(x) = int_0^x h``."""

    name: str
    h: Callable[[NDArray, float, float], NDArray]
    H: Callable[[NDArray, float, float], NDArray] | None = None

    def integral(self, x: NDArray, gamma: float, vc: float) -> NDArray:
        if self.H is not None:
            return self.H(x, gamma, vc)
        x = np.asarray(x, dtype=float)
        nodes = 0.5 * x[..., None] * (_GL48_X + 1.0)
        return 0.5 * x * np.sum(_GL48_W * self.h(nodes, gamma, vc), axis=-1)


def _exp_H(x, g, vc):
    return g * (x + vc * np.expm1(-x / vc))


def _gauss_H(x, g, vc):
    return g * (x - vc * np.sqrt(np.pi) / 2 * special.erf(x / vc))


BUILTIN_SHAPES: dict[str, Shape] = {
    "exponential": Shape("exponential", lambda x, g, vc: -g * np.expm1(-x / vc), _exp_H),
    "linear": Shape("linear", lambda x, g, vc: g * x, lambda x, g, vc: 0.5 * g * x * x),
    "gaussian": Shape("gaussian", lambda x, g, vc: -g * np.expm1(-((x / vc) ** 2)), _gauss_H),
}


@dataclass
class HysteresisState:
    """Memory of the operator between calls (streaming): last reversal and last input."""

    u_s: float = 0.0  # input at the last reversal (V)
    s_s: float = 0.0  # output at the last reversal (ue)
    u_last: float = 0.0  # last input seen (V); 0 V at rest
    s_last: float = 0.0  # last output (ue)
    direction: float = 0.0  # +1 rising, -1 falling, 0 not yet moved


@dataclass(frozen=True)
class QuasiStaticHysteresis:
    """The operator ``u (V) -> S (ue)``; see the module docstring."""

    alpha0: float
    gamma: float
    vc: float = 1.0
    shape: str | Shape = "exponential"
    _shape: Shape = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if isinstance(self.shape, Shape):
            shp = self.shape
        elif self.shape in BUILTIN_SHAPES:
            shp = BUILTIN_SHAPES[self.shape]
        else:
            raise ValueError(f"shape must be one of {SHAPES} or a Shape, got {self.shape!r}")
        if not self.alpha0 > 0:
            raise ValueError(f"alpha0 must be positive (ue/V), got {self.alpha0!r}")
        if not self.vc > 0:
            raise ValueError(f"vc must be positive (V), got {self.vc!r}")
        object.__setattr__(self, "_shape", shp)

    # -- branch function ----------------------------------------------------------------------
    def branch(self, x: ArrayLike) -> NDArray[np.float64]:
        """``F(x) = alpha0 x + int_0^x h`` for ``x >= 0`` (strain change along a branch, ue)."""
        x = np.asarray(x, dtype=float)
        return self.alpha0 * x + self._shape.integral(x, self.gamma, self.vc)

    def slope(self, x: ArrayLike) -> NDArray[np.float64]:
        """``alpha = alpha0 + h(x)`` (ue/V) at distance ``x`` from the last reversal."""
        x = np.asarray(x, dtype=float)
        return self.alpha0 + self._shape.h(x, self.gamma, self.vc)

    def _odd_branch(self, d: NDArray) -> NDArray:
        return np.sign(d) * self.branch(np.abs(d))

    def branch_inverse(self, y: ArrayLike) -> NDArray[np.float64]:
        """``x >= 0`` with ``F(x) = y`` for ``y >= 0`` (V)."""
        y = np.asarray(y, dtype=float)
        a0, g, vc = self.alpha0, self.gamma, self.vc
        name = self._shape.name if self._shape.H is not None else ""
        if name == "exponential" and a0 + g > 0 and g >= 0:
            a, b = a0 + g, g * vc
            arg = -(g / a) * np.exp(-(y + b) / (a * vc))
            x = (y + b) / a + vc * special.lambertw(arg, 0).real
        elif name == "linear" and g > 0:
            x = (-a0 + np.sqrt(a0 * a0 + 2.0 * g * y)) / g
        else:
            x = self._bracketed_inverse(y)
        x = np.maximum(x, 0.0)
        for _ in range(2):  # polish to machine precision
            x = np.maximum(x - (self.branch(x) - y) / self.slope(x), 0.0)
        return x

    def _bracketed_inverse(self, y: NDArray) -> NDArray:
        lo = np.zeros_like(y)
        hi = np.maximum(y / self.alpha0, 1e-12)
        while np.any(self.branch(hi) < y):
            hi = np.where(self.branch(hi) < y, 2 * hi, hi)
        x = 0.5 * (lo + hi)
        for _ in range(200):
            f = self.branch(x) - y
            lo = np.where(f < 0, x, lo)
            hi = np.where(f >= 0, x, hi)
            xn = x - f / self.slope(x)
            bad = (xn <= lo) | (xn >= hi) | ~np.isfinite(xn)
            xn = np.where(bad, 0.5 * (lo + hi), xn)
            if np.all(np.abs(xn - x) <= 1e-15 * np.maximum(1.0, np.abs(x))):
                return xn
            x = xn
        return x

    # -- operator -----------------------------------------------------------------------------
    def apply(self, u: ArrayLike, state: HysteresisState | None = None) -> NDArray[np.float64]:
        """Strain (ue) for the voltage record ``u`` (V). ``state`` is updated in place if given."""
        u = np.asarray(u, dtype=float)
        st = HysteresisState() if state is None else state
        if u.size == 0:
            return np.zeros(0)
        seg, u0, s0, (u_s, s_s, d) = _segments(
            u, st.u_s, st.s_s, st.u_last, st.direction, lambda a, b: self._odd_branch(b - a)
        )
        out = s0[seg] + self._odd_branch(u - u0[seg])
        st.u_s, st.s_s, st.direction = u_s, s_s, d
        st.u_last, st.s_last = float(u[-1]), float(out[-1])
        return out

    def invert(self, strain: ArrayLike, state: HysteresisState | None = None) -> NDArray:
        """Voltage (V) whose :meth:`apply` gives ``strain`` (ue), branch by branch.

        Reversals of the strain coincide with those of the voltage (``F`` is increasing), so the
        record is split at strain reversals and each branch is inverted in closed form.
        """
        s = np.asarray(strain, dtype=float)
        st = HysteresisState() if state is None else state
        if s.size == 0:
            return np.zeros(0)

        def inv(d: NDArray) -> NDArray:
            return np.sign(d) * self.branch_inverse(np.abs(d))

        seg, s0, u0, (s_s, u_s, d) = _segments(
            s, st.s_s, st.u_s, st.s_last, st.direction, lambda a, b: inv(b - a)
        )
        u = u0[seg] + inv(s - s0[seg])
        st.u_s, st.s_s, st.direction = u_s, s_s, d
        st.u_last, st.s_last = float(u[-1]), float(s[-1])
        return u


def _segments(x: NDArray, x_s: float, y_s: float, x_last: float, direction: float, delta):
    """Split the record ``x`` at its reversals (local extrema).

    Returns the segment index of each sample, the input and output at each segment's start
    (the reversal point; output continuous there), and the new ``(x_s, y_s, direction)``.
    ``delta(x_a, x_b)`` is the output change along a branch from ``x_a`` to ``x_b``.
    """
    dx = np.diff(x, prepend=x_last)
    d = np.sign(dx)
    if d[0] == 0:
        d[0] = direction
    # flat stretches keep the previous direction (they are not reversals)
    nz = d != 0
    idx = np.where(nz, np.arange(d.size), 0)
    np.maximum.accumulate(idx, out=idx)
    d = np.where(nz[idx], d[idx], 0.0)
    before = np.concatenate(([direction], d[:-1]))
    reversal = (d != 0) & (before != 0) & (d != before)
    rev = np.flatnonzero(reversal)
    # a reversal detected at sample n has its extremum at sample n-1 (or the previous call's end)
    ext = np.where(rev > 0, x[np.maximum(rev - 1, 0)], x_last)
    x0 = np.concatenate(([x_s], ext))
    y0 = (
        y_s + np.concatenate(([0.0], np.cumsum(delta(x0[:-1], x0[1:]))))
        if rev.size
        else (np.array([y_s]))
    )
    seg = np.cumsum(reversal)
    new_dir = float(d[-1]) if d[-1] != 0 else direction
    return seg, x0, y0, (float(x0[-1]), float(y0[-1]), new_dir)
