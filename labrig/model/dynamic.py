"""The dynamic hysteresis model of the paper's Fig. 2 (Eq. 5-7).

    V*(s) = G_t(s) G_d(s) V(s),      S = alpha0 V* + H[V*]

``V`` is the driving voltage (V) sampled at ``rate_hz``, ``S`` the strain (ue). ``G_t`` is applied
with the input hold of the record (``"zoh"`` for a DAQ-driven voltage, the default; ``"linear"``
for a measured, smooth voltage), ``G_d`` with the linear hold since its input is ``G_t``'s
continuous output known at the samples (see :mod:`labrig.model.relaxor`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labrig.model.hysteresis import HysteresisState, QuasiStaticHysteresis
from labrig.model.modal import run_bank
from labrig.model.params import ModelParams
from labrig.model.relaxor import Relaxor


@dataclass(frozen=True)
class DynamicHysteresisModel:
    """``predict(v, rate_hz)``: strain (ue) for a voltage record (V), system at rest at 0 V (or
    held at ``rest_V``)."""

    params: ModelParams
    g_t: Relaxor = field(init=False)
    g_d: Relaxor = field(init=False)
    operator: QuasiStaticHysteresis = field(init=False)

    def __post_init__(self) -> None:
        p = self.params
        object.__setattr__(self, "g_t", Relaxor(p.tau_t_s, p.lam_t))
        object.__setattr__(self, "g_d", Relaxor(p.tau_d_s, p.lam_d))
        object.__setattr__(self, "operator", p.operator())

    def equivalent_static_voltage(
        self,
        v: ArrayLike,
        rate_hz: float,
        method: str = "fast",
        hold: str = "zoh",
        rest_V: float = 0.0,
    ) -> NDArray[np.float64]:
        """``V* = G_d G_t V`` (V), the paper's Eq. 7, the relaxors at rest at ``rest_V`` before
        the record (``G(0) = 1``, so ``V* = rest_V + G_d G_t (V - rest_V)``)."""
        if rest_V == 0.0:
            vt = self.g_t.filter(v, rate_hz, method=method, hold=hold)
            return self.g_d.filter(vt, rate_hz, method=method, hold="linear")
        u = np.asarray(v, dtype=float) - rest_V
        vt = self.g_t.filter(u, rate_hz, method=method, hold=hold)
        return rest_V + self.g_d.filter(vt, rate_hz, method=method, hold="linear")

    def predict(
        self,
        v: ArrayLike,
        rate_hz: float,
        method: str = "fast",
        hold: str = "zoh",
        rest_V: float = 0.0,
    ) -> NDArray[np.float64]:
        """Strain (ue) for the voltage record ``v`` (V) sampled at ``rate_hz``, the actuator held
        at ``rest_V`` before it (brought there from rest at 0 V, its relaxors settled:
        :meth:`~labrig.model.QuasiStaticHysteresis.held_state`)."""
        x = self.equivalent_static_voltage(v, rate_hz, method, hold, rest_V)
        return self.operator.apply(x, self.operator.held_state(rest_V))

    def stream(self, rate_hz: float, hold: str = "zoh") -> ModelStream:
        """A stateful evaluator for records that arrive in blocks (simulators, control loops)."""
        return ModelStream(self, rate_hz, hold)


class ModelStream:
    """Block-by-block evaluation of :class:`DynamicHysteresisModel` (the fast realisation).

    Feeding a record in any split gives the same result as ``predict(..., method="fast")``.
    """

    def __init__(self, model: DynamicHysteresisModel, rate_hz: float, hold: str = "zoh"):
        self.model = model
        self._bank_t = model.g_t.bank(rate_hz, hold)
        self._bank_d = model.g_d.bank(rate_hz, "linear")
        self.reset()

    def reset(self) -> None:
        self._xt = self._bank_t.initial_state()
        self._xd = self._bank_d.initial_state()
        self._v_prev = 0.0
        self._vt_prev = 0.0
        self._hyst = HysteresisState()

    def process(self, v_block: ArrayLike) -> NDArray[np.float64]:
        v = np.asarray(v_block, dtype=np.float64)
        if v.size == 0:
            return np.zeros(0)
        vt, self._xt = run_bank(self._bank_t, v, self._xt, self._v_prev)
        vd, self._xd = run_bank(self._bank_d, vt, self._xd, self._vt_prev)
        self._v_prev, self._vt_prev = float(v[-1]), float(vt[-1])
        return self.model.operator.apply(vd, self._hyst)
