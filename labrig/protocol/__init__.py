"""Protocol files: schema, waveform generators, expansion into a plan, preflight checks.

The modules in the order a protocol goes through them: :mod:`~labrig.protocol.schema` (the file's
keys, validated), :mod:`~labrig.protocol.expand` (steps, sweeps and repeats expanded into concrete
steps, :mod:`~labrig.protocol.concrete`, with :mod:`~labrig.protocol.waveforms`,
:mod:`~labrig.protocol.offset_sine` and :mod:`~labrig.protocol.csvsource` making their samples),
:mod:`~labrig.protocol.plan` (the result: a :class:`Plan` of :class:`PlannedStep`),
:mod:`~labrig.protocol.preflight` (every step against the rig's limits, what each asks of the
amplifier measured as one :class:`~labrig.rig.drive_load.DriveLoad`) and
:mod:`~labrig.protocol.check` (the entry points the CLI calls); the numbers in their messages are
printed by :mod:`~labrig.core.numbers`.

Typical use (what ``labrig check`` does)::

    from labrig.protocol import check_protocol, format_plan
    plan = check_protocol("experiments/sweep.yaml", limits)   # InputFileError on problems
    console.print(format_plan(plan))
    for step in plan.steps:                                   # the runner's view
        step.name, step.rate_hz, step.n_samples, step.samples(i0, i1), step.rest_after_s

The preflight alone (e.g. against the limits of a rig chosen later) is
``checks = labrig.protocol.preflight.preflight_checks(plan, limits)``; the plan keeps them with
``plan.take_checks(checks, limits)``. See docs/protocol.md for the file format.
"""

from labrig.protocol.check import check_protocol, format_plan, load_plan, load_protocol
from labrig.protocol.expand import build_plan
from labrig.protocol.plan import Plan, PlannedStep
from labrig.protocol.preflight import max_sine_amplitude_V, max_sine_frequency_hz
from labrig.protocol.schema import Protocol

__all__ = [
    "Plan",
    "PlannedStep",
    "Protocol",
    "build_plan",
    "check_protocol",
    "format_plan",
    "load_plan",
    "load_protocol",
    "max_sine_amplitude_V",
    "max_sine_frequency_hz",
]
