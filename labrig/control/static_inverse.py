"""The quasi-static part of the inverse, one sample at a time: ``u`` with ``H[u] - h[u] = s``.

:class:`StaticInverseStepper` is :meth:`~labrig.model.QuasiStaticHysteresis.invert` per sample
(the operator ``S = alpha0 u + H[u]`` with the same memory rule); :class:`RemanentInverseStepper`
adds the Bouc-Wen remanence ``h`` of a :class:`~labrig.control.control_model.ControlModel`
(``S = H[u] - h[u]``). Both the offline drive (with remanence) and the per-sample controller use
them, so the two forms share one static inverse. Units: strain in ue, voltage in V.
"""

from __future__ import annotations

import math

import numpy as np

from labrig.control.control_model import ControlModel
from labrig.model import QuasiStaticHysteresis
from labrig.model.bouc_wen import bouc_wen_step
from labrig.model.hysteresis import BUILTIN_SHAPES, Shape

__all__ = ["RemanentInverseStepper", "StaticInverseStepper", "static_stepper"]

#: most secant iterations of the remanence inverse per sample (3-5 reach 1e-12 in practice)
FIXED_POINT_ITER = 60


def _has_exponential_integral(op: QuasiStaticHysteresis) -> bool:
    """Whether ``op``'s hysteretic slope is the exponential shape with its closed-form integral
    (then the branch inverse is Newton on ``F(x) = (a0 + g) x - g vc (1 - exp(-x/vc))``)."""
    shape = op.shape if isinstance(op.shape, Shape) else BUILTIN_SHAPES[op.shape]
    return shape.name == "exponential" and shape.H is not None


class StaticInverseStepper:
    """:meth:`QuasiStaticHysteresis.invert` one sample at a time (same memory rule: the
    remembered turning points ``(strain, voltage)`` as a stack, the current branch's on top)."""

    def __init__(self, op: QuasiStaticHysteresis):
        self.op = op
        self._exp = _has_exponential_integral(op)
        self._a0, self._g, self._vc = op.alpha0, op.gamma, op.vc
        self._wipe = op.memory == "return_point"
        self.reset()

    def reset(self) -> None:
        self._hint = 0.0  # the last branch inverse (a start for the next)
        self.stack: list[tuple[float, float]] = [(0.0, 0.0)]  # at rest
        self.s_last = 0.0
        self.u_last = 0.0
        self.direction = 0.0

    def _advance(self, s: float) -> tuple[list[tuple[float, float]], float]:
        """The stack and direction after the strain moves to ``s`` (copied when they change,
        so that :meth:`peek` leaves the state alone)."""
        st, sgn = self.stack, self.direction
        d = s - self.s_last
        if d == 0.0:
            return st, sgn
        sgn = 1.0 if d > 0 else -1.0
        if self.direction != 0.0 and sgn != self.direction:  # reversal at the last sample
            turn = (self.s_last, self.u_last)
            st = [*st, turn] if self._wipe else [turn]
        while self._wipe and len(st) >= 2 and sgn * (s - st[-2][0]) >= 0:
            st = st[:-2] if len(st) >= 3 else st[:-1]  # a minor loop closed: forget it
        return st, sgn

    def _finv(self, y: float) -> float:
        if y <= 0.0:
            return 0.0
        if not self._exp or self._g < 0:
            return float(self.op.branch_inverse(np.array([y]))[0])
        a0, g, vc = self._a0, self._g, self._vc
        # F(x) = (a0 + g) x - g vc (1 - exp(-x/vc)): increasing and convex, so Newton from any
        # x with F(x) >= y decreases monotonically onto the root, and one Newton step from below
        # lands above it. Start from the last root (consecutive calls ask for nearby values)
        x = self._hint
        e = math.exp(-x / vc)
        f = (a0 + g) * x - g * vc * (1.0 - e) - y
        if f < 0.0:
            x -= f / (a0 + g * (1.0 - e))
        for _ in range(60):
            e = math.exp(-x / vc)
            f = (a0 + g) * x - g * vc * (1.0 - e) - y
            x_new = x - f / (a0 + g * (1.0 - e))
            if x_new >= x:
                break
            # quadratic convergence: after a step below 1e-8 x the error is ~1e-3 step^2 / V
            # (F'' / 2F' <= g / (2 vc a0)), far below rounding
            done = x - x_new <= 1e-8 * x
            x = max(x_new, 0.0)
            if done:
                break
        self._hint = x
        return x

    def _voltage(self, s: float, anchor: tuple[float, float]) -> float:
        dd = s - anchor[0]
        return anchor[1] + math.copysign(self._finv(abs(dd)), dd)

    def peek(self, s: float) -> float:
        """The voltage :meth:`step` would return for ``s``, without advancing."""
        return self._voltage(s, self._advance(s)[0][-1])

    def step(self, s: float) -> float:
        self.stack, self.direction = self._advance(s)
        u = self._voltage(s, self.stack[-1])
        self.s_last, self.u_last = s, u
        return u


class RemanentInverseStepper:
    """Per-sample inverse of ``H[u] - h[u] = s`` (operator and Bouc-Wen remanence, both with
    memory): ``u = H^-1(s + h(u))``, solved for the sample's ``h`` (a contraction: the element's
    steepest slope is below the operator's shallowest, :class:`ControlModel` checks it) by secant
    steps."""

    def __init__(self, static: StaticInverseStepper, A: float, beta: float, gamma: float):
        self.static, self.bw = static, (A, beta, gamma)
        self.reset()

    def reset(self) -> None:
        self.static.reset()
        self.h = 0.0
        self.u_last = 0.0

    def _g(self, s: float, h: float) -> float:
        """The sample's ``h`` if the operator were inverted at ``s + h``."""
        return bouc_wen_step(self.h, self.static.peek(s + h) - self.u_last, *self.bw)

    def step(self, s: float) -> float:
        # secant on r(h) = g(h) - h from the fixed-point step (r is smooth with slope in
        # (-1, 0) where the sample's direction holds: a few evaluations reach 1e-12)
        h0 = self.h
        r0 = self._g(s, h0) - h0
        h = h0 + r0
        for _ in range(FIXED_POINT_ITER):
            r = self._g(s, h) - h
            if abs(r) <= 1e-12 * (1.0 + abs(h)):
                break
            d = r - r0
            h_next = h - r * (h - h0) / d if d != 0.0 else h + r
            h0, r0, h = h, r, h_next
        u = self.static.step(s + h)
        self.h = bouc_wen_step(self.h, u - self.u_last, *self.bw)
        self.u_last = u
        return u


def static_stepper(cm: ControlModel) -> StaticInverseStepper | RemanentInverseStepper:
    """The per-sample inverse of the quasi-static part of ``cm`` (with its remanence)."""
    static = StaticInverseStepper(cm.params.operator())
    return static if cm.remanence is None else RemanentInverseStepper(static, *cm.remanence)
