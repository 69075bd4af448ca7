"""The ``remanence`` effect: remanent strain, a Bouc-Wen element beside the operator
(:class:`Remanence`).
"""

from __future__ import annotations

import numpy as np

from labrig.model.bouc_wen import bouc_wen_exact
from labrig.model.effects.base import Effect, Param

__all__ = ["Remanence"]


class Remanence(Effect):
    """Remanent strain: a Bouc-Wen element beside the paper's operator,
    ``S = H[V*] - h[V*]`` with ``dh = A dV* - beta |dV*| h - gamma dV* |h|`` (``n = 1``,
    :mod:`labrig.model.bouc_wen`; ``gamma = gamma_ratio * beta``, ``|gamma_ratio| <= 1`` keeps it
    bounded).

    Physics: part of the ceramic's domain switching is not undone when the voltage returns, so a
    loop need not close where it started; the strain left at 0 V after an excursion depends on
    the last swings and stays (it does not relax). The paper's operator closes every loop at its
    start (``S_s + F(x) - F(x)``, with either memory rule) and cannot hold it. Acts beside the
    operator, on the relaxed voltage (an actuator effect: the compensation controller inverts
    it). Signature: a constant residual at 0 V after each excursion, its size set by the last
    swing, and minor loops whose ends drift. Null: ``A = 0``. Confusable with ``offset_drift``
    (which drifts with time, not with the excursions) and ``creep`` (which relaxes).
    """

    name = "remanence"
    where = "operator"
    acts_on = "beside the operator"
    params_doc = "`A_ue_per_V` (0), `beta_per_V`, `gamma_ratio`"
    form = "`H[V*] - h[V*]`, `h` a Bouc-Wen element (`n = 1`): loops that need not close"
    physics = "remanent strain (Bouc-Wen element beside the operator: loops that do not close)"
    signature = "constant residual at 0 V after excursions, set by the last swing"
    confusable = ("offset_drift", "creep")
    tell_apart = (
        "hold 0 V after excursions of different sizes: remanence stays put and scales with the "
        "last swing; offset drift follows the clock, creep relaxes"
    )
    params = (
        Param("A_ue_per_V", "ue/V", 0.0, -2.0, 8.0, 0.5, sign=+1),
        Param(
            "beta_per_V",
            "1/V",
            0.03,
            2e-3,
            0.5,
            0.03,
            log=True,
            check_bounds=False,
            starts=(0.003, 0.3),
        ),
        Param("gamma_ratio", "", 0.3, -1.0, 1.0, 0.3, check_bounds=False),
    )

    def apply(self, x, ctx, p):
        A = p["A_ue_per_V"]
        if A == 0.0:
            return np.zeros(x.size)
        beta = p["beta_per_V"]
        h = bouc_wen_exact(np.concatenate(([0.0], x)), A, beta, p["gamma_ratio"] * beta)
        return -h[1:]
