"""The ``mechanical_resonance`` effect: the stack's (and sensor's) first mechanical resonance
on the measured strain (:class:`MechanicalResonance`, its filter :func:`resonance_filter`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from labrig.model.effects.base import Effect, Param, plus_minus
from labrig.model.sections import Section, foh_section, run_section

__all__ = [
    "MIMIC_PEAK",
    "RESOLVED_NYQUIST_SHARE",
    "MechanicalResonance",
    "aliased_hz",
    "relaxor_resonance",
    "resonance_filter",
]


def resonance_filter(tau_r: float, zeta: float, rate_hz: float, internal: float = 0.0) -> Section:
    """``(1 + 2 q zeta tau_r s) / (1 + 2 zeta tau_r s + (tau_r s)^2)`` (``q = internal``, the
    share of the damping inside the stack) sampled with a first-order hold (the strain is
    smooth between samples: exact for a strain linear between them;
    :func:`labrig.model.sections.foh_section`)."""
    num = [2.0 * internal * zeta * tau_r, 1.0] if internal > 0 else [1.0]
    return foh_section(num, [tau_r * tau_r, 2.0 * zeta * tau_r, 1.0], rate_hz)


def aliased_hz(f_hz: float, rate_hz: float) -> float:
    """The frequency (Hz) at which samples taken at ``rate_hz`` show a ringing at ``f_hz``:
    ``|f - k rate|`` for the nearest integer ``k`` (a pole pair at ``f_r`` maps to
    ``z = exp(s / rate)``, whose angle is only known modulo ``2 pi``)."""
    return float(abs(f_hz - rate_hz * round(f_hz / rate_hz)))


def relaxor_resonance(lam: float, tau_s: float) -> tuple[float, float] | None:
    """The resonance the base's relaxor ``G(s) = 1 / (1 + (tau s)^lam)`` is by itself: the
    frequency of its gain's peak (Hz) and the damping ratio of a second-order section with
    the same peak height (``|G|_max = 1 / (2 zeta sqrt(1 - zeta^2))``), or ``None`` when its
    gain does not rise above 1 (``lam <= 1``: a fractional low-pass).

    ``|1 + (j w tau)^lam|^2 = 1 + 2 u cos(lam pi / 2) + u^2`` with ``u = (w tau)^lam`` is
    smallest at ``u = -cos(lam pi / 2)``: ``w tau = u^(1/lam)``, ``|G|_max = 1 / sin(lam pi / 2)``.
    With ``lam`` near 2 (``G_d`` at its order bound) it rings like a lightly damped stack at
    ``f = 1 / (2 pi tau)``: a mechanical resonance there cannot be told apart from it by its
    gain alone."""
    c = float(np.cos(lam * np.pi / 2.0))
    if c >= 0.0 or tau_s <= 0.0:
        return None
    f = (-c) ** (1.0 / lam) / (2.0 * np.pi * tau_s)
    peak = 1.0 / float(np.sin(lam * np.pi / 2.0))
    # 2 zeta sqrt(1 - zeta^2) = 1 / peak  ->  zeta^2 = (1 - sqrt(1 - 1/peak^2)) / 2
    zeta = float(np.sqrt((1.0 - np.sqrt(max(0.0, 1.0 - 1.0 / peak**2))) / 2.0))
    return float(f), zeta


#: the ranking's probes (:meth:`MechanicalResonance.probes`): resonances an octave apart from
#: this frequency (Hz; ``tau_r``'s upper bound, 5 ms, is 32 Hz) ...
PROBE_LOWEST_HZ = 50.0
#: ... up to below this share of the records' Nyquist frequency ...
PROBE_NYQUIST_SHARE = 0.9
#: ... at most this many (the highest kept)
PROBE_COUNT = 6
#: a fitted resonance above this share of the records' Nyquist frequency is not resolved by
#: their samples (the first-order-hold section there rings at an alias, :func:`aliased_hz`):
#: refused (:meth:`MechanicalResonance.refusals`)
RESOLVED_NYQUIST_SHARE = PROBE_NYQUIST_SHARE
#: the base's ``G_d`` counts as a resonance (:meth:`MechanicalResonance.mimicked`) when its gain
#: peaks at least this high (a second-order section's peak at damping 0.3)
MIMIC_PEAK = 1.0 / (2.0 * 0.3 * np.sqrt(1.0 - 0.09))


class MechanicalResonance(Effect):
    """The first mechanical resonance of the stack with its load and the sensor's mount:
    ``S -> S (1 + 2 q zeta tau_r s) / (1 + 2 zeta tau_r s + (tau_r s)^2)``, ``f_r = 1 / (2 pi
    tau_r)``, damping ``zeta`` (0.005-0.5, fitted on a log scale), ``q`` (``internal``, 0-1)
    the share of the damping that is the stack's own.

    Physics: the stack is a spring of stiffness ``k`` driving its own effective mass and the
    load ``m``; the strain the operator predicts is the free (quasi-static) stroke ``x_f``.
    The stack's own losses (the ceramic's internal friction, a Kelvin-Voigt damper ``c_i``)
    act on its deformation ``x_f - x``, like its stiffness; the load's guides and the air
    (``c_e``) act on the motion ``x`` itself:

        m x'' = k (x_f - x) + c_i (x_f' - x') - c_e x'

    so ``X / X_f = (k + c_i s) / (m s^2 + (c_i + c_e) s + k)``: a second-order low-pass with
    ``f_r = sqrt(k/m) / (2 pi)`` (kHz for a bare stack, hundreds of Hz with a heavy load), a
    small damping (``zeta = (c_i + c_e) / (2 sqrt(k m))``, 0.01-0.2) and, from the internal
    share ``q = c_i / (c_i + c_e)``, a zero at ``-k / c_i``. The zero cancels the poles'
    first-order phase lag below ``f_r`` (with ``q = 1`` the response is ``1 + (f/f_r)^2`` in
    gain with no phase to first order); ``q = 0`` is a mass damped from outside only. Sine
    sweeps far below ``f_r`` barely see it; a PRBS, a triangle's corners and steps excite it
    (ringing at ``f_r``). Acts on the measured output (linear in the strain).

    Signature: ringing at ``f_r`` after every edge (PRBS, triangle corners, steps), a residual
    spectrum peaked at ``f_r``, a gain that *rises* towards ``f_r`` (peak ``~ 1 / (2 zeta)`` at
    ``f_r``) with a quadrature part growing with frequency below it. Null: ``tau_r = 0``.
    Confusable with ``sensor_lowpass``, which has the same form with a well-damped
    ``zeta >= 0.2`` (a conditioner's Butterworth/Bessel filter): told apart by the damping
    (below ``zeta = 1/sqrt 2`` the gain peaks above 1, a conditioner's filter never rings) and
    by the experiment: a resonance moves with the load (a mass added lowers ``f_r`` as
    ``1 / sqrt(m)``), a conditioner's cutoff does not and shows in a calibration of the gauge
    chain alone.
    """

    name = "mechanical_resonance"
    where = "output"
    acts_on = "measured strain (mechanics)"
    params_doc = "`tau_r_s` (0), `zeta` (0.005-0.5, log), `internal` (0-1)"
    form = (
        "`(1 + 2 q zeta tau_r s)/(1 + 2 zeta tau_r s + (tau_r s)^2)`, `f_r = 1/(2 pi tau_r)`, "
        "lightly damped, `q` the stack's own share of the damping"
    )
    physics = "stack + load + sensor mount resonance (second-order, lightly damped)"
    signature = "ringing at f_r after edges (PRBS, triangle corners), gain rising towards f_r"
    confusable = ("sensor_lowpass", "time_delay")
    tell_apart = (
        "add a known mass to the load: a mechanical resonance moves as 1/sqrt(m), a "
        "conditioner's low-pass does not; a step rings (zeta < 0.5), a conditioner does not"
    )
    params = (
        # f_r from 32 Hz up: below that a resonance is not a stack's
        Param("tau_r_s", "s", 0.0, 0.0, 5e-3, 1e-4, sign=+1, starts=(3e-5, 3e-4, 1e-3)),
        Param("zeta", "", 0.1, 0.005, 0.5, 0.1, log=True, starts=(0.02, 0.3)),
        # both ends are physical (damped from outside only, or by the stack only)
        Param("internal", "", 0.0, 0.0, 1.0, 0.5, check_bounds=False),
    )
    #: the resonance the base's ``G_d`` was by itself when the effect was last ranked against
    #: it (:meth:`note_base`; ``None``: no peak, or not ranked)
    base_resonance: tuple[float, float] | None = None

    def __init__(self, rate_hz: float = 0.0):
        #: the records' lowest sample rate (Hz; the library's ``rate_hz`` context), for
        #: :meth:`refusals` and :meth:`describe`; ``None`` when not known
        self.rate_hz: float | None = float(rate_hz) if rate_hz and rate_hz > 0 else None

    def note_base(self, base: Mapping[str, float]) -> None:
        """Remember the resonance the base's ``G_d`` is by itself (:func:`relaxor_resonance`
        of ``lam_d`` and ``tau_d_s``), for :meth:`describe`; the ranking calls it."""
        lam, tau = base.get("lam_d"), base.get("tau_d_s")
        self.base_resonance = None if lam is None or tau is None else relaxor_resonance(lam, tau)

    def mimicked(self) -> str | None:
        """What to say when the base's ``G_d`` rang by itself (a peak at least
        :data:`MIMIC_PEAK` high) in the base this effect was tried against, else ``None``."""
        if self.base_resonance is None:
            return None
        f, zeta = self.base_resonance
        if 1.0 / (2.0 * zeta * np.sqrt(1.0 - zeta * zeta)) < MIMIC_PEAK:
            return None
        return (
            f"the base it was tried against rang by itself (G_d a {f:.4g} Hz resonance, "
            f"damping {zeta:.2g}): near that frequency a mechanical resonance and G_d can stand "
            "in for each other"
        )

    def resolved_hz(self) -> float | None:
        """The highest resonance the records' samples resolve (Hz):
        :data:`RESOLVED_NYQUIST_SHARE` of the Nyquist frequency of the records' lowest rate
        (``None`` when the effect was configured without it)."""
        return None if self.rate_hz is None else RESOLVED_NYQUIST_SHARE * self.rate_hz / 2.0

    def probes(self, contexts):
        """Resonances an octave apart from :data:`PROBE_LOWEST_HZ` up to below
        :data:`PROBE_NYQUIST_SHARE` of the lowest Nyquist frequency of ``contexts`` (at most
        :data:`PROBE_COUNT`, the highest kept), lightly damped (``zeta`` 0.05), half the
        damping the stack's own. One probe at the start's 1.6 kHz is above the Nyquist
        frequency of a 2 kHz record: its direction there is a gain the base absorbs, and a
        resonance the record shows (hundreds of Hz) would rank last, never refitted."""
        rate = min((c.rate_hz for c in contexts), default=10_000.0)
        top = PROBE_NYQUIST_SHARE * rate / 2.0
        freqs = [PROBE_LOWEST_HZ * 2.0**k for k in range(16) if PROBE_LOWEST_HZ * 2.0**k < top]
        freqs = freqs[-PROBE_COUNT:] or [PROBE_LOWEST_HZ]
        return [{"tau_r_s": 1.0 / (2.0 * np.pi * f), "zeta": 0.05, "internal": 0.5} for f in freqs]

    def _filter(self, ctx, tau, zeta, q):
        return ctx.cached(
            ("resonance", tau, zeta, q, ctx.rate_hz),
            lambda: resonance_filter(tau, zeta, ctx.rate_hz, q),
        )

    def apply(self, x, ctx, p):
        tau = p["tau_r_s"]
        if tau <= 0:
            return x
        # at rest at the first sample; a 2-D x (tangent columns) column by column
        return run_section(self._filter(ctx, tau, p["zeta"], p.get("internal", 0.0)), x)

    def tangent_columns(self, x, dX, ctx, p):
        return self.apply(dX, ctx, p)  # linear: every column in one call

    def physical(self, p):
        tau = p["tau_r_s"]
        return {
            "f_r_hz": 1.0 / (2 * np.pi * tau) if tau > 0 else float("inf"),
            "zeta": p["zeta"],
            "internal": float(p.get("internal", 0.0)),
            "tau_r_s": tau,
        }

    def unresolved(self, p) -> str | None:
        """Why the resonance ``p`` is beyond what the records' samples resolve (``f_r`` above
        :meth:`resolved_hz`), or ``None``."""
        top, tau = self.resolved_hz(), p["tau_r_s"]
        if top is None or tau <= 0:
            return None
        f = 1.0 / (2 * np.pi * tau)
        if f <= top:
            return None
        assert self.rate_hz is not None
        seen = (
            f"their samples show it at its alias, {aliased_hz(f, self.rate_hz):.4g} Hz"
            if f > self.rate_hz / 2
            else "too few samples per period to resolve it"
        )
        return (
            f"f_r = {f:.4g} Hz is above {100 * RESOLVED_NYQUIST_SHARE:.0f} % of the records' "
            f"Nyquist frequency ({self.rate_hz / 2:.4g} Hz): {seen}; not a resonance they resolve"
        )

    def refusals(self, p, sd):
        """A resonance above what the records' samples resolve (:meth:`unresolved`)."""
        why = self.unresolved(p)
        return [] if why is None else [why]

    def describe(self, p, sd):
        tau, s = p["tau_r_s"], sd.get("tau_r_s")
        if tau <= 0:
            return "no resonance"
        f = 1.0 / (2 * np.pi * tau)
        notes = [n for n in (self.unresolved(p), self.mimicked()) if n is not None]
        return (
            plus_minus("f_r", f, None if s is None else f * s / tau, "Hz")
            + plus_minus(", damping", p["zeta"], sd.get("zeta"), "")
            + plus_minus(", the stack's own share", p.get("internal", 0.0), sd.get("internal"), "")
            + "".join(f"; {n}" for n in notes)
        )
