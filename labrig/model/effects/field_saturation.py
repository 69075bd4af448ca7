"""The ``field_saturation`` effect: the piezo gain falling at high field
(:class:`FieldSaturation`).
"""

from __future__ import annotations

from labrig.model.effects.base import Effect, Param, plus_minus

__all__ = ["FieldSaturation"]


class FieldSaturation(Effect):
    """Field saturation of the actuator's gain: ``V -> V (1 - s (V / V_ref)^2)`` before the
    dynamics (``V_ref``: the run's largest ``|V|``, so ``s`` is the relative loss of gain at
    full scale; ``s < 1/3`` keeps the map monotone).

    Physics: at high field the piezo coefficient falls (the extrinsic, domain-wall part of the
    response saturates), so the strain per volt is lower near both ends of a bipolar stroke and
    near the top of a unipolar one; odd about 0 V (zero field). Acts on the driving voltage (the
    field), like ``quadratic_term``.

    Signature: a negative curvature of the residual versus ``V`` near full scale; odd (3rd)
    harmonics under a bipolar drive; on a unipolar drive it is what a ``quadratic_term`` fitted
    with a *negative* coefficient stands for. Null: ``s = 0``; only ``s > 0`` is physical (a gain
    that rises with field is another effect).
    """

    name = "field_saturation"
    where = "voltage"
    acts_on = "driving voltage"
    params_doc = "`s` (0, only `s > 0` physical)"
    form = "`V (1 - s (V/V_ref)^2)`: the gain lost at full scale, odd about 0 V"
    physics = "field saturation of the piezo coefficient (gain falling at high field)"
    signature = "negative curvature near full scale, odd about 0 V (3rd harmonics when bipolar)"
    confusable = ("quadratic_term",)
    tell_apart = (
        "drive bipolar and unipolar: saturation (odd about 0 V) lowers the gain at both ends of a "
        "bipolar stroke, an even (quadratic) term raises one end and lowers the other"
    )
    params = (Param("s", "", 0.0, -0.3, 0.3, 0.01, sign=+1),)

    def __init__(self, v_ref: float = 100.0):
        self.v_ref = float(v_ref) if v_ref and v_ref > 0 else 100.0

    def probes(self, contexts):
        return [{"s": 0.01}, {"s": 0.05}]

    def apply(self, x, ctx, p):
        u = x / self.v_ref
        return x * (1.0 - p["s"] * u * u)

    def describe(self, p, sd):
        sv = sd.get("s")
        label = f"gain loss at {self.v_ref:.3g} V"
        return plus_minus(label, 100 * p["s"], None if sv is None else 100 * sv, "%")
