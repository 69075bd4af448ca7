"""The ``negative_field_asymmetry`` effect: the actuator's piezo coefficient falls under fields
against its poling (:class:`NegativeFieldAsymmetry`).
"""

from __future__ import annotations

import numpy as np

from labrig.model.effects.base import Effect, Param, plus_minus

__all__ = ["NegativeFieldAsymmetry"]


class NegativeFieldAsymmetry(Effect):
    """A piezo coefficient that falls under negative field, smoothly from 0 V: the field ``w``
    acts with ``d33(w) / d33_0 = 1 - a (w / V_ref)^2`` for ``w < 0`` (1 for ``w >= 0``), so
    the voltage seen by the dynamics is its integral ``int_0^V d33(w) / d33_0 dw``:

        V -> V                               (V >= 0)
        V -> V - a V^3 / (3 V_ref^2)         (V < 0)

    before the dynamics (``V_ref``: the run's largest ``|V|``, so ``a`` is the relative loss of
    ``d33`` at ``-V_ref``; the strain per volt there is ``1 - a / 3``). ``a`` in [-0.5, 0.9]:
    ``a > 0`` a weaker response against the poling; ``a < 1`` keeps the map monotone.

    Physics: a poled ceramic is not symmetric about zero field: a field against the poling
    direction partly depolarises it (domains begin to back-switch well before the coercive
    field), so its piezo coefficient falls on the negative side, the more the stronger the
    field; asymmetric Bouc-Wen and Prandtl-Ishlinskii models of piezo stacks carry this with a
    separate gain for each sign of the input. A bipolar loop is then not point-symmetric about
    the origin.

    Why the square of the field: ``d33`` is a smooth function of the field, equal on both sides
    at 0 V. A loss that grows as ``(w / V_ref)^2`` is the lowest order for which ``d33`` *and*
    its slope are continuous at zero field (a loss linear in ``|w|`` puts a kink in ``d33`` at
    0 V, a constant loss a jump: both make the strain bend at 0 V, which a depoling onset does
    not). A ``d33`` linear in ``w`` on both sides is the even, electrostrictive
    ``quadratic_term``; its odd, symmetric loss on both sides is ``field_saturation``.

    Where it acts, argued: on the driving voltage, like ``field_saturation`` and
    ``quadratic_term`` (a memoryless map of the field). The same map then scales the whole
    response to a negative field (its linear part *and* its hysteresis, which the operator
    computes from the mapped field), as a lower ``d33`` against the poling does; the map is
    continuous at 0 V with its first two derivatives, so it adds no step and no kink. Acting
    beside the operator is not possible (an operator effect sees the operator's input, not its
    strain), and a gain on the output for ``S < 0`` would follow the sign of the strain, which
    after hysteresis and offsets is not the sign of the field.

    Signature: on a bipolar drive, a residual growing as ``|V|^3`` on the negative half-cycles
    only (odd and even harmonics), ``S(-V) != -S(V)``; nothing on a unipolar drive above 0 V.
    Null: ``a = 0``. Confusable with ``quadratic_term`` (which bends both halves, as ``V^2``)
    and ``field_saturation`` (symmetric about 0 V, as ``V^3`` on both halves): together they
    make a one-sided cubic's even and odd halves.
    """

    name = "negative_field_asymmetry"
    where = "voltage"
    acts_on = "driving voltage (negative field)"
    params_doc = "`a` (0), in [-0.5, 0.9]"
    form = (
        "`V` for `V >= 0`, `V - a V^3/(3 V_ref^2)` for `V < 0`: `d33` falling as "
        "`1 - a (V/V_ref)^2` against the poling"
    )
    physics = "d33 falling under negative field (partial depolarisation against the poling)"
    signature = "residual on negative half-cycles only, growing as |V|^3; S(-V) != -S(V)"
    confusable = ("quadratic_term", "field_saturation")
    tell_apart = (
        "drive a unipolar entry and its mirror image (0..-V): the asymmetry shows as different "
        "gains; a quadratic term bends both, saturation is the same on both"
    )
    params = (Param("a", "", 0.0, -0.5, 0.9, 0.05),)

    def __init__(self, v_ref: float = 100.0):
        self.v_ref = float(v_ref) if v_ref and v_ref > 0 else 100.0

    def probes(self, contexts):
        return [{"a": 0.05}, {"a": -0.05}]

    def apply(self, x, ctx, p):
        a = p["a"]
        if a == 0.0:
            return x
        neg = np.minimum(x, 0.0)
        return x - (a / (3.0 * self.v_ref * self.v_ref)) * neg * neg * neg

    def physical(self, p):
        return {"a": float(p["a"]), "secant_gain_loss_at_v_ref": float(p["a"]) / 3.0}

    def describe(self, p, sd):
        s = sd.get("a")
        label = f"d33 lost at -{self.v_ref:.3g} V"
        return plus_minus(label, 100 * p["a"], None if s is None else 100 * s, "%")
