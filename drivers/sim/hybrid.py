"""The paper's section-4 reference plant ("hybrid" truth preset of the virtual bench).

The paper tests its controller on a different, previously validated actuator model (its ref. [28]):
a quasi-static part made of linear, system-level and Bouc-Wen blocks, followed by the transfer
function of the paper's Eq. 11 (docs/model.md, section 7)::

    S_stat = L[V] - h,                 L = system-level operator (alpha0_ue_per_V, gamma, Vc)
    dh/dt  = A dV/dt - beta |dV/dt| h - gamma_bw dV/dt |h|          (Bouc-Wen, n = 1)
    S(s)/S_stat(s) = (92144 s^3 - 68696e3 s^2 + 114816e6 s + 432e9)
                   / (148196 s^3 + 154912e3 s^2 + 123824e6 s + 432e9)

``L`` is the paper's quasi-static operator (``labrig.model.QuasiStaticHysteresis``: the linear
block is its ``alpha0`` term, the system-level block its exponential ``h``), with its own values,
so the hybrid plant is never the object being fitted. The paper does not give the Bouc-Wen
parameters; :data:`HYBRID_DEFAULT` was chosen (and is checked in the tests) so that a 0-100 V
unipolar sine at 1 Hz gives a loop of about 1 180 ue (steady state) with a hysteresis width (largest
ascending/descending difference at equal voltage) of about 12.6 % of the span; the strain at
0 V settles near 60 ue (the slow pole of Eq. 11 and the hysteresis memory).

Numerics: the Bouc-Wen equation is rate independent, so ``dh/dV = A - (beta s + gamma_bw
sign(h)) h`` with ``s`` the sign of the voltage change; between samples (voltage linear, ``s``
fixed) it is a linear ODE in ``V`` and is integrated in closed form, splitting the step where
``h`` changes sign. Eq. 11 is discretised with the first-order hold (``scipy.signal.cont2discrete``
``"foh"``, exact for an input linear between samples) and run with ``lfilter`` and its state.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import BaseModel, ConfigDict, Field

from labrig.model.bouc_wen import bouc_wen_stream
from labrig.model.hysteresis import HysteresisState, QuasiStaticHysteresis

#: the paper's Eq. 11, numerator and denominator in descending powers of s (DC gain 1)
EQ11_NUM = (92144.0, -68696e3, 114816e6, 432e9)
EQ11_DEN = (148196.0, 154912e3, 123824e6, 432e9)


class HybridParams(BaseModel):
    """Parameters of the hybrid reference plant (units in the names; Bouc-Wen ``n = 1``)."""

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)

    alpha0_ue_per_V: float = Field(11.5, gt=0, description="linear block (ue/V)")
    gamma_ue_per_V: float = Field(3.0, ge=0, description="system-level hysteretic slope (ue/V)")
    vc_V: float = Field(65.0, gt=0, description="system-level saturation voltage (V)")
    bw_A_ue_per_V: float = Field(1.5, description="Bouc-Wen gain A (ue/V)")
    bw_beta_per_V: float = Field(0.040, ge=0, description="Bouc-Wen beta (1/V)")
    bw_gamma_per_V: float = Field(0.013, description="Bouc-Wen gamma (1/V), |gamma| <= beta")
    use_eq11: bool = Field(True, description="apply the paper's Eq. 11 transfer function")


HYBRID_DEFAULT = HybridParams()


def eq11_discrete(rate_hz: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Eq. 11 discretised for ``rate_hz`` with the first-order hold: ``(b, a)`` for lfilter."""
    from scipy import signal

    b, a, _ = signal.cont2discrete((EQ11_NUM, EQ11_DEN), 1.0 / rate_hz, method="foh")
    b = np.atleast_1d(np.squeeze(b))
    return b / a[0], np.asarray(a, dtype=float) / a[0]


class HybridPlant:
    """Block-by-block evaluation of the hybrid plant: voltage (V) to strain (ue), at rest at 0 V."""

    def __init__(self, params: HybridParams, rate_hz: float, engine: str = "auto"):
        self.params = params
        self.rate_hz = float(rate_hz)
        self.engine = engine  # the operator's code (QuasiStaticHysteresis.apply)
        self.operator = QuasiStaticHysteresis(
            params.alpha0_ue_per_V, params.gamma_ue_per_V, params.vc_V, "exponential"
        )
        self._b, self._a = eq11_discrete(self.rate_hz)
        self.reset()

    def reset(self) -> None:
        self._hyst = HysteresisState()
        self._h = 0.0
        self._v_prev = 0.0
        self._zi = np.zeros(max(len(self._a), len(self._b)) - 1)

    def static(self, v_block: ArrayLike) -> NDArray[np.float64]:
        """Quasi-static strain ``S_stat`` (ue), advancing the hysteresis states."""
        v = np.asarray(v_block, dtype=float)
        p = self.params
        lin = self.operator.apply(v, self._hyst, engine=self.engine)
        h, self._h = bouc_wen_stream(
            v, self._h, self._v_prev, p.bw_A_ue_per_V, p.bw_beta_per_V, p.bw_gamma_per_V
        )
        self._v_prev = float(v[-1]) if v.size else self._v_prev
        return lin - h

    def process(self, v_block: ArrayLike) -> NDArray[np.float64]:
        from scipy import signal

        v = np.asarray(v_block, dtype=float)
        if v.size == 0:
            return np.zeros(0)
        s = self.static(v)
        if not self.params.use_eq11:
            return s
        y, self._zi = signal.lfilter(self._b, self._a, s, zi=self._zi)
        return y
