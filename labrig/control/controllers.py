"""Per-sample controllers: the drive for a strain command one sample at a time.

:class:`CompensationController` is :func:`~labrig.control.inversion.compensated_drive` for a
real-time loop: the creep's inverse (a first-order recursion), the static inverse
(:mod:`labrig.control.static_inverse`), then the inverses of ``G_d`` and ``G_t`` on their modal
banks (:mod:`labrig.control.bank_inverse`). :class:`DirectController` is
:func:`~labrig.control.inversion.direct_drive`. Both take the command ``preview`` samples ahead of
the drive (V) they return, and clip to a rig's voltage range when given its limits.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labrig.control.bank_inverse import PREVIEW_TOL, BankInverse
from labrig.control.control_model import ControlModel, as_control_model
from labrig.control.inversion import strain_command
from labrig.control.static_inverse import static_stepper
from labrig.model import ModelParams
from labrig.rig.limits import RigLimits

__all__ = ["CompensationController", "DirectController"]

Array = NDArray[np.float64]


class CompensationController:
    """The compensated drive one sample at a time (O(modes + preview) per sample, no history).

    ``step(s)`` takes the command ``preview`` samples ahead of the drive it returns::

        ctl = CompensationController(params, rate_hz)
        ctl.prime(s_com[: ctl.preview])               # the first preview command samples
        for n in range(N):                            # the real-time loop
            v[n] = ctl.step(s_com[min(n + ctl.preview, N - 1)])

    ``preview = P_d + 1 + P_t``: one sample for the zero-order hold of ``G_t`` plus the
    anti-causal windows of the relaxors' outside zeros (``P_d`` for a sampled ``G_d`` with a zero
    outside the unit circle, which some ``lam_d > 1`` have at some rates; 0 otherwise), cut where
    the weights fall below ``tol``. :meth:`run` does the whole loop and agrees with
    :func:`~labrig.control.inversion.compensated_drive` to the modal banks' quadrature error plus
    ``tol`` (docs/control.md has the figures). With ``limits`` the output is clipped to the rig's
    voltage range and ``n_clipped`` counts the clipped samples (the controller runs open loop: its
    model state does not see the clipping).

    The stages are public for benchmarks and tests: :meth:`uncreep`, ``static_inverse``
    (:func:`~labrig.control.static_inverse.static_stepper`), ``gd_inverse`` and ``gt_inverse``
    (:class:`~labrig.control.bank_inverse.BankInverse`).
    """

    def __init__(
        self,
        params: ModelParams | ControlModel,
        rate_hz: float,
        limits: RigLimits | None = None,
        tol: float = PREVIEW_TOL,
    ):
        cm = as_control_model(params)
        p = cm.params
        self.params, self.rate_hz, self.limits = p, float(rate_hz), limits
        ba = cm.creep_filter(self.rate_hz)
        # inverse creep filter a(z)/b(z): one state (the previous input and output)
        self._creep = None if ba is None else (ba[1], ba[0])
        self.static_inverse = static_stepper(cm)
        self.gd_inverse = BankInverse(p.tau_d_s, p.lam_d, self.rate_hz, "linear", tol)
        self.gt_inverse = BankInverse(p.tau_t_s, p.lam_t, self.rate_hz, "zoh", tol)
        self.preview = self.gd_inverse.preview + 1 + self.gt_inverse.preview
        self.reset()

    def reset(self) -> None:
        """Back to rest: 0 V, zero strain, no command seen."""
        self.static_inverse.reset()
        self.gd_inverse.reset()
        self.gt_inverse.reset()
        self._creep_x = self._creep_y = 0.0
        self._vt_seen = 0
        self._pushed = 0
        self.n_clipped = 0

    def prime(self, first: ArrayLike) -> None:
        """Feed the first ``preview`` command samples (no drive is due yet)."""
        for s in np.asarray(first, dtype=float).ravel():
            if self._push(float(s)) is not None:  # pragma: no cover - guarded by preview
                raise RuntimeError("prime() got more than preview samples")

    def uncreep(self, s: float) -> float:
        """The creep's inverse for the next command sample (ue; ``s`` itself without creep)."""
        if self._creep is None:
            return s
        (n0, n1), (d0, d1) = self._creep
        y = (n0 * s + n1 * self._creep_x - d1 * self._creep_y) / d0
        self._creep_x, self._creep_y = s, y
        return y

    def _push(self, s: float) -> float | None:
        self._pushed += 1
        vt = self.gd_inverse.push(self.static_inverse.step(self.uncreep(s)))
        if vt is None:
            return None
        self._vt_seen += 1
        if self._vt_seen == 1:  # vt[0] = 0 at rest: V[0] aims at vt[1]
            return None
        return self.gt_inverse.push(vt)

    def step(self, s_ahead: float) -> float:
        """Take the command sample ``preview`` ahead; return the drive (V) due now."""
        v = self._push(float(s_ahead))
        if v is None:
            raise RuntimeError(f"call prime() with the first {self.preview} command samples first")
        if self.limits is not None:
            c = min(max(v, self.limits.v_min_V), self.limits.v_max_V)
            if c != v:
                self.n_clipped += 1
            v = c
        return v

    def run(self, strain_ue: ArrayLike) -> Array:
        """The drive for a whole command, sample by sample (from rest; the command continues
        at its last value for the look-ahead)."""
        s = strain_command(strain_ue)
        self.reset()
        n = s.size
        if n == 0:
            return s.copy()
        ext = np.concatenate((s, np.full(self.preview, s[-1])))
        self.prime(ext[: self.preview])
        return np.array([self.step(ext[k + self.preview]) for k in range(n)])


class DirectController:
    """``V = S_com / alpha0`` one sample at a time, with the timing of :func:`direct_drive`
    (one sample of preview: ``V[n] = (S[n] + S[n+1]) / (2 alpha0)``)."""

    preview = 1

    def __init__(
        self, params: ModelParams | ControlModel, rate_hz: float, limits: RigLimits | None = None
    ):
        self.alpha0 = as_control_model(params).params.alpha0_ue_per_V
        self.rate_hz, self.limits = float(rate_hz), limits
        self.reset()

    def reset(self) -> None:
        self._prev: float | None = None
        self.n_clipped = 0

    def prime(self, first: ArrayLike) -> None:
        vals = np.asarray(first, dtype=float).ravel()
        if vals.size:
            self._prev = float(vals[-1])

    def step(self, s_ahead: float) -> float:
        if self._prev is None:
            raise RuntimeError("call prime() with the first command sample first")
        v = 0.5 * (self._prev + float(s_ahead)) / self.alpha0
        self._prev = float(s_ahead)
        if self.limits is not None:
            c = min(max(v, self.limits.v_min_V), self.limits.v_max_V)
            self.n_clipped += c != v
            v = c
        return v

    def run(self, strain_ue: ArrayLike) -> Array:
        s = strain_command(strain_ue)
        self.reset()
        if s.size == 0:
            return s.copy()
        self.prime(s[:1])
        ext = np.append(s, s[-1])
        return np.array([self.step(ext[k + 1]) for k in range(s.size)])
