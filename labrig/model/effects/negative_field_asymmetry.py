"""The ``negative_field_asymmetry`` effect: the actuator responds less (or more) to fields
against its poling (:class:`NegativeFieldAsymmetry`).
"""

from __future__ import annotations

import numpy as np

from labrig.model.effects.base import Effect, Param, plus_minus

__all__ = ["NegativeFieldAsymmetry"]


class NegativeFieldAsymmetry(Effect):
    """A different response to negative fields: ``V -> V`` for ``V >= 0`` and ``(1 - a) V`` for
    ``V < 0``, before the dynamics (``a`` in [-0.5, 0.9]; ``a > 0``: a weaker response against
    the poling direction).

    Physics: a poled ceramic is not symmetric about zero field: a field against the poling
    direction partly depolarises it (domains begin to back-switch well before the coercive
    field), so its piezo coefficient and its hysteresis differ from the positive side; asymmetric
    Bouc-Wen and Prandtl-Ishlinskii models of piezo stacks carry this with a separate gain for
    each sign of the input. A bipolar loop is then not point-symmetric about the origin.

    Where it acts, argued: on the driving voltage, like ``field_saturation`` and
    ``quadratic_term`` (a memoryless map of the field). The same map then scales the whole
    response to a negative field (its linear part *and* its hysteresis, which the operator
    computes from the mapped field), as a lower ``d33`` against the poling does; the map is
    continuous at 0 V, so it adds no step. Acting beside the operator is not possible (an
    operator effect sees the operator's input, not its strain), and a gain on the output for
    ``S < 0`` would follow the sign of the strain, which after hysteresis and offsets is not the
    sign of the field.

    Signature: on a bipolar drive, a residual proportional to ``V`` on the negative half-cycles
    only (odd and even harmonics), ``S(-V) != -S(V)``; nothing on a unipolar drive above 0 V.
    Null: ``a = 0``. Confusable with ``quadratic_term`` (which bends both halves, as ``V^2``)
    and ``field_saturation`` (symmetric about 0 V).
    """

    name = "negative_field_asymmetry"
    where = "voltage"
    acts_on = "driving voltage (negative field)"
    params_doc = "`a` (0), in [-0.5, 0.9]"
    form = "`V` for `V >= 0`, `(1 - a) V` for `V < 0`: a different gain against the poling"
    physics = "asymmetric response to negative fields (partial depolarisation against the poling)"
    signature = "residual on negative half-cycles only, proportional to V; S(-V) != -S(V)"
    confusable = ("quadratic_term", "field_saturation")
    tell_apart = (
        "drive a unipolar entry and its mirror image (0..-V): the asymmetry shows as different "
        "gains; a quadratic term bends both, saturation is the same on both"
    )
    params = (Param("a", "", 0.0, -0.5, 0.9, 0.05),)

    def probes(self, contexts):
        return [{"a": 0.05}, {"a": -0.05}]

    def apply(self, x, ctx, p):
        a = p["a"]
        if a == 0.0:
            return x
        return np.where(x < 0.0, (1.0 - a) * x, x)

    def describe(self, p, sd):
        s = sd.get("a")
        return plus_minus("gain lost for V < 0", 100 * p["a"], None if s is None else 100 * s, "%")
