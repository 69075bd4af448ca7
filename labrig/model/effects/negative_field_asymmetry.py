"""The ``negative_field_asymmetry`` effect: the actuator's piezo coefficient falls under fields
against its poling (:class:`NegativeFieldAsymmetry`).
"""

from __future__ import annotations

import numpy as np

from labrig.model.effects.base import Effect, Param, plus_minus

__all__ = ["NegativeFieldAsymmetry"]


class NegativeFieldAsymmetry(Effect):
    """A piezo coefficient that falls under negative field, smoothly from 0 V and levelling off:
    the field ``w`` acts with ``d33(w) / d33_0 = 1 - tanh^2(sqrt(a) w / V_ref) = sech^2(sqrt(a)
    w / V_ref)`` for ``w < 0`` (1 for ``w >= 0``), so the voltage seen by the dynamics is its
    integral ``int_0^V d33(w) / d33_0 dw``:

        V -> V                                         (V >= 0)
        V -> (V_ref / sqrt(a)) tanh(sqrt(a) V / V_ref)  (V < 0, a > 0)

    before the dynamics (``V_ref``: the run's largest ``|V|``). ``a`` is the loss's lowest
    order, ``d33 / d33_0 = 1 - a (w / V_ref)^2 + O(w^4)``, so the map is ``V - a V^3 / (3
    V_ref^2)`` to third order. ``a < 0`` (a stiffer response against the poling, unexpected) is
    the mirror form ``d33 / d33_0 = 1 + tanh^2(sqrt(|a|) w / V_ref)``: ``V -> 2 V - (V_ref /
    sqrt(|a|)) tanh(sqrt(|a|) V / V_ref)``, the same third order. ``a`` in [-0.5, 4]: ``d33``
    stays between 0 and 2 ``d33_0`` at every field, so the map is monotone for any ``a``; at
    ``a = 4`` ``d33`` at ``-V_ref`` is 7 % of ``d33_0`` (a stack depoled within the run: a
    broken part, not a model).

    Physics: a poled ceramic is not symmetric about zero field: a field against the poling
    direction partly depolarises it (domains begin to back-switch well before the coercive
    field), so its piezo coefficient falls on the negative side, the more the stronger the
    field; asymmetric Bouc-Wen and Prandtl-Ishlinskii models of piezo stacks carry this with a
    separate gain for each sign of the input. A bipolar loop is then not point-symmetric about
    the origin.

    Why the square of the field at low field: ``d33`` is a smooth function of the field, equal on
    both sides at 0 V. A loss that grows as ``(w / V_ref)^2`` is the lowest order for which
    ``d33`` *and* its slope are continuous at zero field (a loss linear in ``|w|`` puts a kink in
    ``d33`` at 0 V, a constant loss a jump: both make the strain bend at 0 V, which a depoling
    onset does not). Why it levels off: the loss is a fraction of the poled domains and cannot
    exceed all of them, so ``d33`` stays positive and the map monotone at any field. The
    polynomial ``1 - a (w / V_ref)^2`` (this effect's earlier form) does not: its loss grows
    without bound (``d33`` negative beyond ``V_ref / sqrt(a)``), and over a run to ``-V_ref`` its
    cubic map overshoots at the largest negative fields and falls short at moderate ones: fitted
    to a ``d33`` that levels off (the bench's ``depoling``) it left a residual on the negative
    half-cycles only, in phase with the drive, 4.6 ue at -120..-140 V against -1 ue at -100..-20
    V (1.27x the noise floor). ``tanh^2`` is the one-parameter saturating loss with that lowest
    order whose integral is closed-form (the ``tanh`` saturation of a switching polarisation).
    A ``d33`` linear in ``w`` on both sides is the even, electrostrictive ``quadratic_term``;
    its odd, symmetric loss on both sides is ``field_saturation``.

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
    params_doc = "`a` (0), in [-0.5, 4]"
    form = (
        "`V` for `V >= 0`, `(V_ref/sqrt a) tanh(sqrt(a) V/V_ref)` for `V < 0`: `d33` falling as "
        "`sech^2(sqrt(a) V/V_ref)` (`1 - a (V/V_ref)^2` at low field) against the poling"
    )
    physics = "d33 falling under negative field (partial depolarisation against the poling)"
    signature = "residual on negative half-cycles only, growing as |V|^3; S(-V) != -S(V)"
    confusable = ("quadratic_term", "field_saturation")
    tell_apart = (
        "drive a unipolar entry and its mirror image (0..-V): the asymmetry shows as different "
        "gains; a quadratic term bends both, saturation is the same on both"
    )
    params = (Param("a", "", 0.0, -0.5, 4.0, 0.05),)

    def __init__(self, v_ref: float = 100.0):
        self.v_ref = float(v_ref) if v_ref and v_ref > 0 else 100.0

    def probes(self, contexts):
        return [{"a": 0.05}, {"a": -0.05}]

    def apply(self, x, ctx, p):
        a = p["a"]
        if a == 0.0:
            return x
        s = np.sqrt(abs(a))
        saturated = (self.v_ref / s) * np.tanh((s / self.v_ref) * np.minimum(x, 0.0))
        # a < 0: the mirror, 2 V - saturated (the same loss added instead of taken)
        return np.where(x >= 0.0, x, saturated if a > 0 else 2.0 * x - saturated)

    def secant_gain_loss(self, a: float) -> float:
        """``1 - u(-V_ref) / (-V_ref)``: the strain per volt lost at ``-V_ref`` (``a / 3`` to
        first order in ``a``)."""
        if a == 0.0:
            return 0.0
        s = np.sqrt(abs(a))
        return float(np.sign(a) * (1.0 - np.tanh(s) / s))

    def physical(self, p):
        a = float(p["a"])
        return {
            "a": a,
            "secant_gain_loss_at_v_ref": self.secant_gain_loss(a),
            "d33_loss_at_v_ref": float(np.sign(a) * np.tanh(np.sqrt(abs(a))) ** 2),
        }

    def describe(self, p, sd):
        a = float(p["a"])
        s = sd.get("a")
        loss = float(np.sign(a) * np.tanh(np.sqrt(abs(a))) ** 2)
        text = plus_minus("a", a, s, "")
        way = "lower" if loss >= 0 else "higher"
        return f"{text}: d33 {100 * abs(loss):.3g} % {way} at -{self.v_ref:.3g} V"
