"""The effect registry: every effect of the library, registered once.

An effect is one module of this package named after it (``creep.py`` holds the effect
``creep``) that defines one :class:`~labrig.model.effects.base.Effect` subclass, plus one
:class:`Registration` in :data:`REGISTRY` below. Everything that lists effects is derived from
the registry, in its order:

- :data:`EFFECT_NAMES`, the default candidates of ``labrig diagnose`` (the report's order);
- :data:`STRUCTURAL_EFFECT_NAMES`, the effects ``labrig diagnose --also NAME`` accepts;
- :data:`FIT_EFFECT_NAMES`, the effects ``labrig fit --effect NAME`` accepts (every effect fitted
  as global parameters: those acting on the voltage, the operator or the output, not the
  per-entry nuisance terms);
- :data:`CREEP_EFFECTS`, the effects that make the strain creep on after a step (part of the
  creep the diagnosis' verdict reports);
- :data:`INVERTIBLE_EFFECTS`, the effects the compensation controller inverts with the model;
- :func:`library`, every effect configured from what a run recorded (:class:`RunContext`);
- the command line's choices (``labrig/cli/common.py``) and the table of effects in
  docs/diagnose.md (:mod:`labrig.model.effects.table`).

Importing this module imports no numerical package (the command line reads the names when it
starts, and ``labrig --help`` stays light): the registry holds names, and the effect modules are
imported when :func:`library` or :meth:`Registration.effect_class` is called.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    from labrig.model.effects.base import Effect

__all__ = [
    "BUILT_FROM_DATA",
    "CREEP_EFFECTS",
    "EFFECT_NAMES",
    "FIT_EFFECT_NAMES",
    "INVERTIBLE_EFFECTS",
    "REGISTRY",
    "STRUCTURAL_EFFECT_NAMES",
    "Registration",
    "RunContext",
    "Where",
    "library",
    "registration",
]

#: where an effect acts (:mod:`labrig.model.effects`): on the driving voltage, beside the
#: operator, on the modelled strain, or as per-entry nuisance terms
Where = Literal["voltage", "operator", "output", "nuisance"]


@dataclass(frozen=True)
class RunContext:
    """What the library is configured from: what a run recorded and the run's scales (the
    defaults describe a run that recorded neither channel). Computed from records by
    :func:`labrig.analysis.extended.effect_context` and saved with fitted effects as
    ``effects_context``.

    - ``temperature``: every record has a temperature channel (degC);
    - ``amplifier_voltage``: every record has the amplifier's measured output voltage (V);
    - ``mains_hz``: the mains frequency (Hz);
    - ``v_ref``: the full-scale voltage, the largest ``|V|`` of the run (V);
    - ``rate_hz``: the lowest sample rate of the records (Hz; 0: not known, as in a parameter
      file written before it was recorded).
    """

    temperature: bool = False
    amplifier_voltage: bool = False
    mains_hz: float = 50.0
    v_ref: float = 100.0
    rate_hz: float = 0.0

    @classmethod
    def types(cls) -> dict[str, type]:
        """Each field's type (``bool`` or ``float``), in order: what a saved context must hold."""
        return {f.name: type(f.default) for f in fields(cls)}


@dataclass(frozen=True)
class Registration:
    """One effect of the library.

    - ``name``: the effect's name (its class's ``name``); its module is
      ``labrig/model/effects/<name>.py``;
    - ``cls``: the name of its :class:`~labrig.model.effects.base.Effect` subclass there;
    - ``where``: where it acts (its class's ``where``);
    - ``candidate``: a default candidate of ``labrig diagnose`` (:data:`EFFECT_NAMES`);
    - ``also``: tried with ``labrig diagnose --also NAME`` (:data:`STRUCTURAL_EFFECT_NAMES`);
    - ``creep``: it makes the strain creep on after a step (:data:`CREEP_EFFECTS`);
    - ``invertible``: the compensation controller inverts it (:data:`INVERTIBLE_EFFECTS`);
    - ``context``: the :class:`RunContext` fields its constructor takes, by keyword of the same
      name (how it is configured from the run).
    """

    name: str
    cls: str
    where: Where
    candidate: bool = True
    also: bool = False
    creep: bool = False
    invertible: bool = False
    context: tuple[str, ...] = ()

    @property
    def module(self) -> str:
        """The effect's module: ``labrig.model.effects.<name>``."""
        return f"{__package__}.{self.name}"

    @property
    def fit(self) -> bool:
        """``labrig fit --effect`` accepts it: fitted as global parameters (not per entry)."""
        return self.where != "nuisance"

    def effect_class(self) -> type[Effect]:
        """The effect's class (imports its module)."""
        return getattr(importlib.import_module(self.module), self.cls)

    def configured(self, context: RunContext) -> Effect:
        """The effect configured for a run: its constructor given the ``context`` fields it
        takes."""
        return self.effect_class()(**{k: getattr(context, k) for k in self.context})


#: every effect of the library; the order is :func:`library`'s and the report's
REGISTRY: tuple[Registration, ...] = (
    Registration("thermal_drift", "ThermalDrift", "output", context=("temperature",)),
    Registration(
        "amplifier_current_limit",
        "AmplifierCurrentLimit",
        "voltage",
        context=("amplifier_voltage",),
    ),
    Registration("sensor_lowpass", "SensorLowpass", "output"),
    Registration("mains_pickup", "MainsPickup", "nuisance", context=("mains_hz",)),
    Registration("offset_drift", "OffsetDrift", "nuisance"),
    Registration("creep", "Creep", "output", creep=True),
    # a default candidate where a slow mode is identifiable
    # (labrig.analysis.diagnose.procedure.slow_mode_identifiable); --also keeps accepting it
    Registration(
        "viscoelastic_creep",
        "ViscoelasticCreep",
        "output",
        also=True,
        creep=True,
        invertible=True,
    ),
    # structural and path-dependent: where the base misses it, it can come before an injected
    # effect, so it is tried only when asked (docs/diagnose.md)
    Registration("remanence", "Remanence", "operator", candidate=False, also=True, invertible=True),
    # structural candidates of the base model (docs/diagnose.md, "Structural candidates"): each
    # costs a refit and its folds, so they are tried only when asked
    Registration(
        "amplifier_bandwidth",
        "AmplifierBandwidth",
        "voltage",
        candidate=False,
        also=True,
        context=("v_ref",),
    ),
    Registration(
        "mechanical_resonance",
        "MechanicalResonance",
        "output",
        candidate=False,
        also=True,
        context=("rate_hz",),
    ),
    # a default candidate where the drive goes against the poling (a poled ceramic's d33 falls
    # there; labrig.analysis.diagnose.procedure.drives_against_poling), identically null
    # elsewhere; --also keeps accepting it
    Registration(
        "negative_field_asymmetry",
        "NegativeFieldAsymmetry",
        "voltage",
        also=True,
        context=("v_ref",),
    ),
    Registration("rate_hysteresis", "RateHysteresis", "operator", candidate=False, also=True),
    Registration("sensor_drift", "SensorDrift", "output", candidate=False, also=True),
    Registration("time_delay", "TimeDelay", "output"),
    Registration("quadratic_term", "QuadraticTerm", "voltage", context=("v_ref",)),
    Registration("field_saturation", "FieldSaturation", "voltage", context=("v_ref",)),
)

#: effects the diagnosis builds from the data, not from a run's context, so not in
#: :func:`library` (:class:`~labrig.model.effects.empirical.EmpiricalTerms`)
BUILT_FROM_DATA: tuple[str, ...] = ("empirical_terms",)

#: the default ``diagnose`` candidates, in the report's order; ``viscoelastic_creep`` only where
#: a slow mode is identifiable
EFFECT_NAMES: tuple[str, ...] = tuple(r.name for r in REGISTRY if r.candidate)
#: structural effects of the actuator that ``labrig diagnose --also NAME`` adds to the
#: candidates (on the hybrid bench with the paper's campaign they are what the model lacks)
STRUCTURAL_EFFECT_NAMES: tuple[str, ...] = tuple(r.name for r in REGISTRY if r.also)
#: the effects ``labrig fit --effect NAME`` fits with the model
FIT_EFFECT_NAMES: tuple[str, ...] = tuple(r.name for r in REGISTRY if r.fit)
#: the effects that make the strain creep on after a step (part of the model's creep figure)
CREEP_EFFECTS: tuple[str, ...] = tuple(r.name for r in REGISTRY if r.creep)
#: the effects the compensation controller inverts along with the model
INVERTIBLE_EFFECTS: tuple[str, ...] = tuple(r.name for r in REGISTRY if r.invertible)


def registration(name: str) -> Registration:
    """The registration of the effect ``name`` (``KeyError`` for an unknown one)."""
    for r in REGISTRY:
        if r.name == name:
            return r
    raise KeyError(name)


def library(**context: bool | float) -> dict[str, Effect]:
    """Every registered effect by name, in registry order, configured for what a run recorded:
    ``context`` holds :class:`RunContext` fields by keyword (``temperature``,
    ``amplifier_voltage``, ``mains_hz``, ``v_ref``, ``rate_hz``; the others at their defaults;
    an unknown keyword is a ``TypeError``)."""
    ctx = RunContext(**context)  # type: ignore[arg-type]
    return {r.name: r.configured(ctx) for r in REGISTRY}
