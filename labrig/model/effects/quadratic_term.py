"""The ``quadratic_term`` effect: electrostriction, a quadratic term of the voltage
(:class:`QuadraticTerm`).
"""

from __future__ import annotations

from labrig.model.effects.base import Effect, Param, plus_minus

__all__ = ["QuadraticTerm"]


class QuadraticTerm(Effect):
    """Electrostriction: ``V -> V + c2 V^2 / V_ref`` before the dynamics (``V_ref``: the
    run's largest voltage, 100 V by default, so ``c2`` is relative at full scale).

    A quadratic (even) contribution to the strain. Signature: even harmonics, a residual versus
    ``V`` that is single-valued and the same on both branches, four times larger at 100 V than
    at 50 V. Null: ``c2 = 0``. Confusable with an asymmetric hysteresis (branch test).
    """

    name = "quadratic_term"
    where = "voltage"
    acts_on = "driving voltage"
    params_doc = "`c2` (0)"
    form = "`V + c2 V^2 / V_ref`, `V_ref` the run's largest voltage"
    physics = "electrostrictive (quadratic) strain"
    signature = "even harmonics, single-valued residual versus V, x4 from 50 to 100 V"
    confusable = ("field_saturation",)
    tell_apart = (
        "drive bipolar and unipolar: an even (quadratic) term changes sign with the voltage's "
        "shape, field saturation (odd) does not; a branch test separates an asymmetric "
        "hysteresis"
    )
    params = (Param("c2", "", 0.0, -0.5, 0.5, 0.01, expect=+1),)

    def __init__(self, v_ref: float = 100.0):
        self.v_ref = float(v_ref) if v_ref and v_ref > 0 else 100.0

    def apply(self, x, ctx, p):
        return x + p["c2"] * x * x / self.v_ref

    def describe(self, p, sd):
        s = sd.get("c2")
        label = f"c2 (relative at {self.v_ref:.3g} V)"
        return plus_minus(label, 100 * p["c2"], None if s is None else 100 * s, "%")
