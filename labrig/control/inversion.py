"""Offline (whole-record) drives: the voltage that makes the model follow a strain command.

The model (the paper's Eq. 12, :class:`~labrig.model.DynamicHysteresisModel`) is

    S = alpha0 V* + H[V*],      V* = G_d G_t V

so the voltage that makes it follow a strain command ``S_com`` (ue) is (the paper's Eq. 13,
Fig. 14)

    V = G_t^-1 G_d^-1 u,        u solves  alpha0 u + H[u] = S_com:

the quasi-static operator is inverted exactly along its branches
(:meth:`~labrig.model.QuasiStaticHysteresis.invert`), then the two relaxors are inverted.
"Direct" control (the paper's baseline, :func:`direct_drive`) inverts only the linear part,
``V = S_com / alpha0``.

Discretisation (what "inverse" means here)
------------------------------------------
A command is a record ``S[n]`` at ``rate_hz``; the drive ``V[n]`` is held by the DAQ on
``[t_n, t_{n+1})`` and the actuator is at rest at 0 V before ``t_0`` (so ``S[0]`` should be 0).
The drive is the exact inverse of the model *as* :meth:`DynamicHysteresisModel.predict`
*discretises it*: ``G_t`` driven with the zero-order hold, ``G_d`` with the linear hold on
``G_t``'s samples. Both are linear convolutions with exact sampled kernels
(:func:`labrig.model.relaxor.sampled_kernel`), so the drive solves

    k_d * vt = u,        k_t * V = vt          (sample by sample, n >= 0)

- ``G_t`` (zero-order hold): ``vt[n+1]`` is the first sample ``V[n]`` reaches, so ``V[n]`` needs
  one sample of preview; for ``lam_t <= 1`` this is :meth:`Relaxor.inverse_filter`.
- ``G_d`` (linear hold): for ``lam_d > 1`` its sampled kernel can have a zero ``zeta`` *outside*
  the unit circle (it comes from the hold, not from the physics), so the causal inverse diverges.
  That zero is inverted anti-causally instead (``1/(1 - zeta z^-1) = -sum_m zeta^-m z^m``): the
  drive at ``n`` looks ahead at the command; the weights fall as ``|zeta|^-m``. The rest of the
  kernel is minimum phase and is inverted causally (power-series reciprocal).

The outside zeros are found for any relaxor and hold (:func:`~labrig.control.inverse_system.
outside_zeros`, polished on the exact kernel), so the same code serves ``lam_t > 1`` or
``lam_d < 1``.

Offline the look-ahead is exact (the command continues at its last value), so
``predict(compensated_drive(S)) == S`` up to rounding, except for a start-up transient of a few
samples: the anti-causal part would need drive before ``t_0``, so the first sample takes the
defect, whose effect then decays with the relaxors' memory. :func:`model_tracking_error` measures
it (docs/control.md has the figures). Start commands smoothly from 0 (the protocol's commands do):
a reversal inside the start-up transient would keep its error in the hysteresis memory.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labrig.control.control_model import ControlModel, as_control_model
from labrig.control.drive_check import check_drive
from labrig.control.inverse_system import outside_zeros
from labrig.control.static_inverse import static_stepper
from labrig.model import ModelParams
from labrig.model.relaxor import sampled_kernel, series_reciprocal
from labrig.rig.limits import RigLimits


def _scipy_signal():
    """``scipy.signal``, imported on first use: it costs about a second of CPU to import (it
    loads scipy.stats), which the fast paths never need."""
    from scipy import signal

    return signal


__all__ = [
    "CONTROLS",
    "compensated_drive",
    "compute_drive",
    "direct_drive",
    "model_tracking_error",
    "relaxor_inverse",
    "strain_command",
]

#: the two controls a strain-command step can ask for
CONTROLS = ("direct", "compensated")

Array = NDArray[np.float64]


def strain_command(strain_ue: ArrayLike) -> Array:
    """The command as a 1-D float array (ue); ``ValueError`` for another shape or a non-finite
    value."""
    s = np.asarray(strain_ue, dtype=np.float64)
    if s.ndim != 1:
        raise ValueError("the strain command must be a 1-D record")
    if not np.all(np.isfinite(s)):
        raise ValueError("the strain command contains NaN or infinite values")
    return s


def direct_drive(strain_ue: ArrayLike, params: ModelParams | ControlModel) -> Array:
    """``V = S_com / alpha0`` held on each sample interval: ``V[n]`` is the interval mean
    ``(S[n] + S[n+1]) / (2 alpha0)`` (the last sample repeats ``S[-1]``), the same timing as
    :func:`compensated_drive` so the two controls are compared on equal terms."""
    s = strain_command(strain_ue)
    if s.size == 0:
        return s.copy()
    nxt = np.append(s[1:], s[-1])
    return 0.5 * (s + nxt) / as_control_model(params).params.alpha0_ue_per_V


def _kernel_zeros_polished(h: Array, guesses: NDArray[np.complex128]) -> list[complex]:
    """Newton-polish the zeros of ``H(z) = sum h[n] z^-n`` (``|z| > 1``) from ``guesses``."""
    n = np.arange(h.size)
    out = []
    for z in guesses:
        z = complex(z)
        for _ in range(30):
            p = z ** (-n.astype(float))
            hz = np.sum(h * p)
            dh = np.sum(-n * h * p) / z
            if dh == 0:
                break
            step = hz / dh
            z -= step
            if abs(step) < 1e-15 * abs(z):
                break
        out.append(z)
    return out


def _deconvolve(h: Array, y: Array, zeros: list[complex]) -> Array:
    """``v`` with ``(h * v)[n] = y[n]`` for ``n >= 0``, ``y`` continued at its last value.

    Each zero ``zeta`` outside the unit circle is divided out of the kernel from its tail
    (``m[n] = -sum_j zeta^-j h[n+j]``) and inverted anti-causally on ``y``
    (``w[n] - zeta w[n-1] = y[n]``, solved backwards from the constant continuation
    ``w = y[-1] / (1 - zeta)``); the remaining minimum-phase kernel is inverted by its
    power-series reciprocal. ``h`` must be longer than ``y`` by enough samples for the tail
    division (``|zeta|^-extra`` negligible).
    """
    n = y.size
    m = h.astype(complex)
    w = y.astype(complex)
    for zeta in zeros:
        # kernel: m[k-1] = (m[k] - h[k]) / zeta, backwards from m[L-1] = 0
        rev = m[::-1]
        mm = _scipy_signal().lfilter([0.0, -1.0 / zeta], [1.0, -1.0 / zeta], rev)
        m = mm[::-1]
        # signal: w[k-1] = (w[k] - y[k]) / zeta, from w[n-1] = y[-1] / (1 - zeta) (the bounded
        # solution for y continued at its last value); reversed: out[r] = (out[r-1] - rev[r-1])
        # / zeta, and with b[0] = 0 lfilter's out[0] is its initial state
        last = w[-1] / (1.0 - zeta)
        zi = np.array([last], dtype=complex)
        w = _scipy_signal().lfilter([0.0, -1.0 / zeta], [1.0, -1.0 / zeta], w[::-1], zi=zi)[0][::-1]
    r = series_reciprocal(m[:n]) if not zeros else _series_reciprocal_complex(m[:n])
    v = _scipy_signal().fftconvolve(w, r)[:n]
    return v.real.copy()


def _series_reciprocal_complex(h: NDArray[np.complex128]) -> NDArray[np.complex128]:
    if np.all(h.imag == 0):
        return series_reciprocal(h.real).astype(complex)
    return series_reciprocal(h)  # the same Newton iteration works in complex arithmetic


def _tail(zeros: list[complex]) -> int:
    """Extra kernel samples for the tail division: ``|zeta|^-extra < 1e-18``."""
    if not zeros:
        return 0
    rho = min(abs(z) for z in zeros)
    return math.ceil(18.0 * math.log(10.0) / math.log(rho)) + 8


def relaxor_inverse(
    y: Array, tau_s: float, lam: float, rate_hz: float, hold: str
) -> tuple[Array, list[complex]]:
    """Offline inverse of one relaxor under ``hold`` (module docstring); ``y`` continues at its
    last value. ``"zoh"``: returns ``V`` (length ``y.size - 1``) with ``k * V = y`` at samples
    ``1..``; ``"linear"``: ``vt`` (same length) with ``k * vt = y``."""
    dt = 1.0 / rate_hz
    guesses = outside_zeros(tau_s, lam, rate_hz, hold)
    extra = _tail(guesses)
    if hold == "zoh":
        target = y[1:]
        h = sampled_kernel(tau_s, lam, dt, target.size + extra + 1, "zoh")[1:]
    else:
        target = y
        h = sampled_kernel(tau_s, lam, dt, target.size + extra, "linear")
    zeros = _kernel_zeros_polished(h[: max(64, min(h.size, 4096))], np.array(guesses))
    return _deconvolve(h, target, zeros), zeros


def compensated_drive(
    strain_ue: ArrayLike, params: ModelParams | ControlModel, rate_hz: float
) -> Array:
    """The drive ``V`` (V) whose model response follows ``strain_ue`` (offline, exact).

    ``V[n]`` is held on ``[t_n, t_{n+1})``; ``predict(V)[n] = strain_ue[n]`` (module docstring;
    ``strain_ue[0]`` should be 0, the actuator at rest). Uses the command's future (the
    anti-causal zero of ``G_d``) and continues it at its last value. With a
    :class:`ControlModel` holding creep, the command is first passed through the creep's
    inverse (causal and stable, :func:`labrig.model.effects.kelvin_voigt_filter`).
    """
    s = strain_command(strain_ue)
    rate_hz = float(rate_hz)
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a positive sample rate, got {rate_hz!r}")
    if s.size == 0:
        return s.copy()
    cm = as_control_model(params)
    p = cm.params
    n = s.size
    ba = cm.creep_filter(rate_hz)
    if ba is None:
        s = np.append(s, s[-1])  # one extra sample: V[N-1] reaches vt[N]
    else:
        # the *strain* command continues at its last value, so the uncrept one keeps moving:
        # uncreep it over the look-ahead the relaxor inverses use (as the per-sample form does)
        ahead = 1 + sum(
            _tail(outside_zeros(tau, lam, rate_hz, hold))
            for tau, lam, hold in ((p.tau_d_s, p.lam_d, "linear"), (p.tau_t_s, p.lam_t, "zoh"))
        )
        s = _scipy_signal().lfilter(ba[1], ba[0], np.append(s, np.full(ahead, s[-1])))
    if cm.remanence is None:
        u = p.operator().invert(s)
    else:
        stepper = static_stepper(cm)
        u = np.array([stepper.step(float(x)) for x in s])
    vt, _ = relaxor_inverse(u, p.tau_d_s, p.lam_d, rate_hz, "linear")
    v, _ = relaxor_inverse(vt, p.tau_t_s, p.lam_t, rate_hz, "zoh")
    return v[:n]


def compute_drive(
    strain_ue: ArrayLike,
    params: ModelParams | ControlModel,
    rate_hz: float,
    control: str = "compensated",
    limits: RigLimits | None = None,
    frequency_hz: float | None = None,
    on_infeasible: str = "raise",
) -> Array:
    """Drive voltage (V) for a strain command (ue) sampled at ``rate_hz``.

    ``control``: ``"compensated"`` (:func:`compensated_drive`) or ``"direct"``
    (:func:`direct_drive`). With ``limits`` the drive is checked (:func:`check_drive`;
    ``frequency_hz`` sets the averaging window of the mean current): ``on_infeasible="raise"``
    raises :class:`InfeasibleCommandError`; ``"clip"`` clips the voltage to the rig's range
    instead (the current is still checked on the clipped drive).
    """
    if control not in CONTROLS:
        raise ValueError(f"control must be one of {CONTROLS}, got {control!r}")
    if on_infeasible not in ("raise", "clip"):
        raise ValueError(f"on_infeasible must be 'raise' or 'clip', got {on_infeasible!r}")
    if control == "direct":
        v = direct_drive(strain_ue, params)
    else:
        v = compensated_drive(strain_ue, params, rate_hz)
    if limits is not None:
        if on_infeasible == "clip":
            v = np.clip(v, limits.v_min_V, limits.v_max_V)
        check_drive(v, rate_hz, limits, frequency_hz, what=f"the {control} drive")
    return v


def model_tracking_error(
    strain_ue: ArrayLike, params: ModelParams | ControlModel, rate_hz: float, method: str = "fast"
) -> Array:
    """``predict(compensated_drive(S)) - S`` (ue): how exactly the drive inverts the model
    (with a :class:`ControlModel`'s effects in the prediction, :meth:`ControlModel.predict`)."""
    s = strain_command(strain_ue)
    cm = as_control_model(params)
    return cm.predict(compensated_drive(s, cm, rate_hz), rate_hz, method) - s
