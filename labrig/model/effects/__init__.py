"""The effect library: physical extensions of the dynamic model for ``labrig diagnose``.

Pure numerics (no I/O). Each effect is a small, physical extension of
``V -> G_t G_d -> quasi-static operator -> S`` with few parameters; it acts in one of four
places:

- ``"voltage"``: on the driving voltage before the model (amplifier and actuator input effects:
  ``amplifier_current_limit``, ``quadratic_term``);
- ``"output"``: on the modelled strain of a whole simulated sequence (operator gain and creep:
  ``thermal_drift``, ``creep``; the measuring chain: ``sensor_lowpass``, ``time_delay``); every
  output effect is *linear* in the strain it receives;
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

The effects live in :mod:`.actuator` (the actuator's own physics) and :mod:`.electronics` (the
amplifier and the measuring chain); :mod:`.base` has their common interface and
:mod:`.empirical` the sparse terms found in a residual when no named effect passes. Forms
deliberately differ from the simulated bench's (``drivers/sim/effects.py``) where the physics
allows: a fitted first-order low-pass here against the bench's Butterworth, a pure slew
limit against the bench's peak/average fold-back, an exact logarithmic kernel with a fitted
onset time ``t0`` against the bench's mode bank from 0.01 s, a heating state driven by each entry's
mean loss power against the bench's instantaneous power.
"""

from __future__ import annotations

from labrig.model.effects.actuator import (
    Creep,
    FieldSaturation,
    QuadraticTerm,
    Remanence,
    ThermalDrift,
    ViscoelasticCreep,
    kelvin_voigt_filter,
)
from labrig.model.effects.base import Context, Effect, Param
from labrig.model.effects.electronics import (
    AmplifierCurrentLimit,
    MainsPickup,
    OffsetDrift,
    SensorLowpass,
    TimeDelay,
    measured_voltage,
    slew_limit,
)
from labrig.model.effects.empirical import EMPIRICAL_NOTE, EmpiricalTerms

__all__ = [
    "CREEP_EFFECTS",
    "EFFECT_NAMES",
    "EMPIRICAL_NOTE",
    "STRUCTURAL_EFFECT_NAMES",
    "AmplifierCurrentLimit",
    "Context",
    "Creep",
    "Effect",
    "EmpiricalTerms",
    "FieldSaturation",
    "MainsPickup",
    "OffsetDrift",
    "Param",
    "QuadraticTerm",
    "Remanence",
    "SensorLowpass",
    "ThermalDrift",
    "TimeDelay",
    "ViscoelasticCreep",
    "kelvin_voigt_filter",
    "library",
    "measured_voltage",
    "slew_limit",
]


#: the default ``diagnose`` candidates (the order is the order of the report);
#: ``viscoelastic_creep`` only where a slow mode is identifiable
#: (:func:`labrig.analysis.diagnose.procedure.slow_mode_identifiable`)
EFFECT_NAMES: tuple[str, ...] = (
    "thermal_drift",
    "amplifier_current_limit",
    "sensor_lowpass",
    "mains_pickup",
    "offset_drift",
    "creep",
    "viscoelastic_creep",
    "time_delay",
    "quadratic_term",
    "field_saturation",
)

#: structural effects of the actuator that ``labrig diagnose --also NAME`` adds to the
#: candidates and ``labrig fit --effect NAME`` fits (path-dependent: ``remanence`` is not a
#: default candidate; ``viscoelastic_creep`` is one where identifiable, and ``--also`` keeps
#: accepting it). On the hybrid bench with the paper's campaign they are what the model lacks
#: (docs/diagnose.md).
STRUCTURAL_EFFECT_NAMES: tuple[str, ...] = ("remanence", "viscoelastic_creep")
#: the effects that make the strain creep on after a step (part of the model's creep figure)
CREEP_EFFECTS: tuple[str, ...] = ("creep", "viscoelastic_creep")


def library(
    temperature: bool = False,
    amplifier_voltage: bool = False,
    mains_hz: float = 50.0,
    v_ref: float = 100.0,
) -> dict[str, Effect]:
    """The effects, configured for what a run recorded (temperature channel, amplifier monitor),
    its mains frequency and its full-scale voltage."""
    effects: list[Effect] = [
        ThermalDrift(temperature),
        AmplifierCurrentLimit(amplifier_voltage),
        SensorLowpass(),
        MainsPickup(mains_hz),
        OffsetDrift(),
        Creep(),
        ViscoelasticCreep(),
        Remanence(),
        TimeDelay(),
        QuadraticTerm(v_ref),
        FieldSaturation(v_ref),
    ]
    return {e.name: e for e in effects}
