"""The effect library: physical extensions of the dynamic model for ``labrig diagnose``.

Pure numerics (no I/O). Each effect is a small, physical extension of
``V -> G_t G_d -> quasi-static operator -> S`` with few parameters; it acts in one of four
places:

- ``"voltage"``: on the driving voltage before the model (amplifier and actuator input effects:
  ``amplifier_current_limit``, ``quadratic_term``);
- ``"output"``: on the modelled strain of a whole simulated sequence (operator gain and creep:
  ``thermal_drift``, ``creep``; the measuring chain: ``sensor_lowpass``, ``time_delay``); every
  output effect is *linear* in the strain it receives, or affine: ``sensor_drift`` adds a term
  that does not depend on the strain and scales the strain by its span factor, and says so with
  its tangent (that factor);
- ``"operator"``: an additive strain term computed from the operator's input ``V*`` (hysteresis
  the paper's operator cannot hold: ``remanence``); fitted like the output effects, and the
  compensation controller inverts it with the operator;
- ``"nuisance"``: additive per-entry terms that are linear in per-entry nuisance parameters
  (``mains_pickup``, ``offset_drift``). These are not fitted as global parameters: they are
  eliminated per entry by least squares (variable projection), and on a held-out entry they are
  fitted on its first half and scored on its second half.

Every effect has a *null value* of its parameters where it equals the base model (the
``null`` of each :class:`Param`), physical bounds, an expected sign (``sign``: +1 when only
values above the null are physical, 0 when either sign is), the residual signature that points
at it, the effects it is confusable with and the experiment that tells them apart (used in the
diagnosis report).

An effect sees the simulated sequence through a :class:`Context`: the sampling rate, the time,
the driving voltage, the entries' sample ranges and, when the run recorded them, the amplifier's
measured output voltage and a temperature channel (over the whole sequence; rests between
entries filled in by :class:`Context`'s builder).

Each effect is one module named after it (``creep.py``: :class:`Creep`), registered once in
:mod:`.registry`, from which the names (:data:`EFFECT_NAMES`, :data:`STRUCTURAL_EFFECT_NAMES`,
:data:`CREEP_EFFECTS`, :data:`INVERTIBLE_EFFECTS`), :func:`library`, the command line's choices
and the table of effects in docs/diagnose.md are derived; :mod:`.base` has their common
interface, :mod:`.empirical` the sparse terms found in a residual when no named effect passes and
:mod:`.table` the table of effects. Forms deliberately differ from the simulated bench's
(``drivers/sim/effects.py``) where the physics allows: a fitted first-order low-pass here against
the bench's Butterworth, a pure slew limit against the bench's peak/average fold-back, an exact
logarithmic kernel with a fitted onset time ``t0`` against the bench's mode bank from 0.01 s, a
heating state driven by each entry's mean loss power against the bench's instantaneous power.

Importing the package imports no numerical package: the registry's names are plain data, and
the classes and helpers below are imported from their modules when first used
(``from labrig.model.effects import Creep`` works as usual).
"""

from __future__ import annotations

import importlib
from typing import Any

from labrig.model.effects.registry import (
    CREEP_EFFECTS,
    EFFECT_NAMES,
    FIT_EFFECT_NAMES,
    INVERTIBLE_EFFECTS,
    REGISTRY,
    STRUCTURAL_EFFECT_NAMES,
    Registration,
    RunContext,
    library,
)

#: names imported from their modules when first used: the common interface, the empirical
#: effect, the helpers of some effects, and every registered effect's class (from its module)
LAZY: dict[str, str] = {
    "Context": "base",
    "Effect": "base",
    "Param": "base",
    "EMPIRICAL_NOTE": "empirical",
    "EmpiricalTerms": "empirical",
    "drift_basis": "sensor_drift",
    "first_order_lowpass": "amplifier_bandwidth",
    "kelvin_voigt_filter": "viscoelastic_creep",
    "measured_voltage": "amplifier_current_limit",
    "rate_hysteresis_state": "rate_hysteresis",
    "resonance_filter": "mechanical_resonance",
    "slew_limit": "amplifier_current_limit",
    **{r.cls: r.name for r in REGISTRY},
}

__all__ = [
    "CREEP_EFFECTS",
    "EFFECT_NAMES",
    "FIT_EFFECT_NAMES",
    "INVERTIBLE_EFFECTS",
    "REGISTRY",
    "STRUCTURAL_EFFECT_NAMES",
    "Registration",
    "RunContext",
    "library",
    *LAZY,
]


def __getattr__(name: str) -> Any:
    """A name of :data:`LAZY`, imported from its module on first use (PEP 562)."""
    module = LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *LAZY})
