"""The ``amplifier_bandwidth`` effect: the amplifier's output resistance charging the actuator's
capacitance, a first-order low-pass on the driving voltage whose corner moves with the stack's
voltage-dependent capacitance (:class:`AmplifierBandwidth`; its fixed-corner filter
:func:`first_order_lowpass`, the moving one :func:`charging_lowpass`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from labrig.model.effects.base import Effect, Param, plus_minus
from labrig.model.modal import first_order_filter

__all__ = ["AmplifierBandwidth", "charging_lowpass", "first_order_lowpass"]


def first_order_lowpass(
    tau_s: float, rate_hz: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(b, a)`` (for ``lfilter``) of ``1 / (1 + tau s)`` on sampled data, ``dt = 1 / rate``,
    ``A = exp(-dt / tau)``, ``r = (tau / dt)(1 - A)``:

        y[n] = A y[n-1] + (1 - r) x[n] + (r - A) x[n-1]

    It is exact for both holds of :class:`~labrig.model.effects.base.Context`: for ``x`` linear
    between samples (``"linear"``, a first-order hold) ``y[n]`` is the filter's output at
    ``t_n``; for ``x[n]`` held over an interval (``"zoh"``) it is the mean of the filter's
    output over that interval, which is how the model's relaxors read a held sample (the two
    coincide). DC gain 1; ``y -> x`` as ``tau -> 0`` (``A, r -> 0``).
    """
    dt = 1.0 / rate_hz
    A = float(np.exp(-dt / tau_s))
    r = float(-np.expm1(-dt / tau_s)) * tau_s / dt
    return np.array([1.0 - r, r - A]), np.array([1.0, -A])


#: the longest step of the recursion (s): a sample interval is cut into equal steps of at most
#: this (the cut depends on the rate only, so the output is smooth in the parameters)
MAX_STEP_S = 50e-6
#: ... in at most this many steps
MAX_SUBSTEPS = 64


def _charging_loop(x: NDArray, tau0: float, k: float, dt: float, m: int) -> NDArray:
    """The recursion of :func:`charging_lowpass` (compiled by numba when it is available)."""
    n = x.shape[0]
    y = np.empty(n)
    if n == 0:
        return y
    h = dt / m
    yk = x[0]
    xk = x[0]
    for i in range(n):
        for j in range(m):
            xa = xk + (x[i] - xk) * (j / m)
            xb = xk + (x[i] - xk) * ((j + 1) / m)
            tau = tau0 * (1.0 + k * abs(yk))  # predictor: tau at the step's start
            q = h / tau
            A = math.exp(-q)
            r = -math.expm1(-q) / q
            yp = A * yk + (1.0 - r) * xb + (r - A) * xa
            tau = tau0 * (1.0 + k * abs(0.5 * (yk + yp)))  # corrector: tau at its middle
            q = h / tau
            A = math.exp(-q)
            r = -math.expm1(-q) / q
            yk = A * yk + (1.0 - r) * xb + (r - A) * xa
        xk = x[i]
        y[i] = yk
    return y


@functools.cache
def _compiled() -> Callable[[NDArray, float, float, float, int], NDArray]:
    """:func:`_charging_loop` compiled (numba, cached on disk), or the loop itself without
    numba (the same results)."""
    try:
        import numba

        return numba.njit(cache=True)(_charging_loop)
    except Exception:  # no numba, or no writable cache: the Python loop
        return _charging_loop


def charging_lowpass(x: NDArray, tau0_s: float, rise: float, v_ref: float, rate_hz: float):
    """``x`` (V) through ``tau(y) dy/dt = x - y``, ``tau(y) = tau0 (1 + rise |y| / v_ref)``: an
    output resistance charging a capacitance that grows with the voltage ``y`` it holds.

    ``x`` is linear between samples; each sample interval is cut into ``m`` equal steps of at
    most :data:`MAX_STEP_S` (at most :data:`MAX_SUBSTEPS`; 10 at 2 kHz, 2 at 10 kHz), and over
    each step ``h`` the time constant is held at its value in the step's middle,
    ``tau = tau((y_a + y*)/2)``, ``y*`` the step taken with ``tau(y_a)`` (a
    predictor-corrector), the step itself the exact one of :func:`first_order_lowpass`
    (``A = exp(-h/tau)``, ``r = (tau/h)(1 - A)``: ``y_b = A y_a + (1 - r) x_b + (r - A)
    x_a``); at rest at ``x[0]``. With ``rise = 0`` it is :func:`first_order_lowpass` exactly;
    otherwise second order in ``h`` (tests/model/test_structural_effects.py: against
    ``solve_ivp``).
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    k = float(rise) / float(v_ref)
    dt = 1.0 / float(rate_hz)
    m = min(MAX_SUBSTEPS, max(1, math.ceil(dt / MAX_STEP_S - 1e-9)))
    return _compiled()(x, float(tau0_s), k, dt, m)


class AmplifierBandwidth(Effect):
    """The amplifier's output resistance charging the stack: ``tau(V_s) dV_s/dt = V - V_s``,
    ``tau(V_s) = tau_amp (1 + rise |V_s| / V_ref)`` (``V_ref``: the run's largest ``|V|``), the
    dynamics driven by ``V_s``; ``fc = 1 / (2 pi tau_amp)`` at 0 V. With ``rise = 0`` a fixed
    first-order low-pass ``1 / (1 + tau_amp s)`` (:func:`first_order_lowpass`, exact sampled
    form); otherwise :func:`charging_lowpass`.

    Physics: a voltage amplifier driving a stack of capacitance ``C`` through its output
    resistance ``R_o`` (or its feedback loop's own pole) applies a first-order low-pass of the
    command, ``tau = R_o C`` (e.g. 10 ohm and 2 uF: 20 us, 8 kHz; a slow high-voltage amplifier
    on a large stack: hundreds of us). A piezo ceramic's capacitance is not constant: its
    permittivity grows with the field it holds (domain-wall contributions; a stack's
    large-signal capacitance is often 1.5-2 times its small-signal one), so the corner falls
    as the stack is charged: ``rise`` is the relative growth of ``C`` at ``|V_s| = V_ref``
    (0: a fixed corner; negative: a capacitance falling with the field, as under a strong
    bias along the poling). Unlike ``amplifier_current_limit`` (a slew limit, large signal
    only) it acts at every amplitude, its corner moving with the voltage held. Acts on the
    driving voltage, so the hysteresis operator sees the lagged voltage (the loop's width is
    not changed, its phase is).

    Signature: a quadrature residual growing with frequency, nearly the same percentage at
    every amplitude (more lag where the stack holds more voltage when ``rise > 0``); on a PRBS
    or a step, a rounded edge of time constant ``tau``, slower at the high level. Null:
    ``tau_amp = 0`` (``rise``'s null 0: a fixed corner). Confusable with ``sensor_lowpass``
    and ``time_delay`` (the same lag, on the measurement instead of the drive) and the model's
    own ``G_d``; the amplifier's monitor voltage tells them apart (the lag is already in it),
    and through the hysteresis a lag before the operator changes the loop's shape, one after
    it does not.
    """

    name = "amplifier_bandwidth"
    where = "voltage"
    acts_on = "driving voltage"
    params_doc = "`tau_amp_s` (0), `rise` (0), in [-0.6, 3]"
    form = (
        "`tau(V_s) dV_s/dt = V - V_s`, `tau = tau_amp (1 + rise |V_s|/V_ref)`: a low-pass "
        "whose corner falls as the stack's capacitance grows"
    )
    physics = "amplifier output resistance charging the stack's voltage-dependent capacitance"
    signature = "quadrature residual growing with frequency, nearly the same % at every amplitude"
    confusable = ("sensor_lowpass", "time_delay", "amplifier_current_limit")
    tell_apart = (
        "record the amplifier's monitor voltage: its lag behind the command is this effect; a "
        "lag only in the strain is the sensor's"
    )
    params = (
        Param("tau_amp_s", "s", 0.0, 0.0, 5e-3, 1e-4, sign=+1, starts=(2e-5, 3e-4, 1e-3)),
        Param("rise", "", 0.0, -0.6, 3.0, 0.0),
    )

    def __init__(self, v_ref: float = 100.0):
        self.v_ref = float(v_ref) if v_ref and v_ref > 0 else 100.0

    def apply(self, x, ctx, p):
        tau = p["tau_amp_s"]
        if tau <= 0:
            return x
        rise = p.get("rise", 0.0)
        if rise != 0.0:
            return charging_lowpass(x, tau, rise, self.v_ref, ctx.rate_hz)
        b, a = ctx.cached(
            ("amp_lp", tau, ctx.rate_hz), lambda: first_order_lowpass(tau, ctx.rate_hz)
        )
        x0 = x[0]  # at rest at the first sample (the filter's gain at DC is 1)
        return x0 + first_order_filter(b, a, x - x0)

    def physical(self, p):
        tau = p["tau_amp_s"]
        rise = float(p.get("rise", 0.0))
        fc = 1.0 / (2 * np.pi * tau) if tau > 0 else float("inf")
        return {
            "fc_hz": fc,
            "fc_at_v_ref_hz": fc / (1.0 + rise) if tau > 0 else float("inf"),
            "tau_amp_s": tau,
            "rise": rise,
        }

    def describe(self, p, sd):
        tau, s = p["tau_amp_s"], sd.get("tau_amp_s")
        if tau <= 0:
            return "no amplifier low-pass"
        fc = 1.0 / (2 * np.pi * tau)
        text = plus_minus("amplifier bandwidth", fc, None if s is None else fc * s / tau, "Hz")
        rise = p.get("rise", 0.0)
        if rise != 0.0:
            text += (
                f" at 0 V, {fc / (1.0 + rise):.3g} Hz at {self.v_ref:.3g} V ("
                + plus_minus("capacitance rise", 100 * rise, _pct(sd.get("rise")), "%")
                + ")"
            )
        return text


def _pct(s: float | None) -> float | None:
    return None if s is None else 100 * s
