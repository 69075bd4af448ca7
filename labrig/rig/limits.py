"""What the amplifier and actuator can do: the numbers preflight checks every waveform against.

Shared by the rig files (which fill it in), the runner's preflight and the protocol checker.
Current into the stack is ``i = C dV/dt``; for large signals the stack's effective capacitance is
about ``large_signal_factor`` (1.7) times its small-signal value.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, model_validator


class RigLimits(BaseModel):
    """Limits of one rig (E-503-style amplifier into a P-888.51-class stack by default)."""

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True, allow_inf_nan=False)

    v_min_V: float = Field(-20.0, description="lowest actuator voltage allowed (V)")
    v_max_V: float = Field(100.0, description="highest actuator voltage allowed (V)")
    capacitance_F: float = Field(6e-6, gt=0, description="small-signal stack capacitance (F)")
    large_signal_factor: float = Field(1.7, ge=1, description="large-signal C / small-signal C")
    i_peak_A: float = Field(0.18, gt=0, description="amplifier peak output current (A)")
    i_avg_A: float = Field(0.12, gt=0, description="amplifier average |current| limit (A)")
    rate_min_hz: float = Field(10.0, gt=0, description="lowest DAQ sample rate (Hz)")
    rate_max_hz: float = Field(100_000.0, gt=0, description="highest DAQ sample rate (Hz)")

    @model_validator(mode="after")
    def _ordered(self) -> RigLimits:
        if self.v_min_V >= self.v_max_V:
            raise ValueError("v_min_V must be below v_max_V")
        if self.rate_min_hz > self.rate_max_hz:
            raise ValueError("rate_min_hz must not exceed rate_max_hz")
        return self

    @property
    def effective_capacitance_F(self) -> float:
        return self.capacitance_F * self.large_signal_factor

    def current_A(self, v: NDArray[np.float64], rate_hz: float) -> NDArray[np.float64]:
        """Current the amplifier must deliver to follow ``v`` sampled at ``rate_hz``: C dV/dt."""
        v = np.asarray(v, dtype=float)
        if v.size < 2:
            return np.zeros(v.size)
        return self.effective_capacitance_F * np.gradient(v) * rate_hz
