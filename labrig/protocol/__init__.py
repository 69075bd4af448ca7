"""Protocol files: schema, waveform generators, expansion into a plan, preflight checks.

Typical use (what ``labrig check`` does)::

    from labrig.protocol import check_protocol, format_plan
    plan = check_protocol("experiments/sweep.yaml", limits)   # InputFileError on problems
    console.print(format_plan(plan))
    for step in plan.steps:                                   # the runner's view
        step.name, step.rate_hz, step.n_samples, step.samples(i0, i1), step.rest_after_s

The preflight alone (e.g. against the limits of a rig chosen later) is
``labrig.protocol.preflight.preflight(plan, limits)``. See docs/protocol.md for the file format.
"""

from labrig.protocol.check import check_protocol, format_plan, load_plan, load_protocol
from labrig.protocol.plan import Plan, PlannedStep, build_plan
from labrig.protocol.preflight import StepCheck, max_sine_amplitude_V, max_sine_frequency_hz
from labrig.protocol.schema import Protocol

__all__ = [
    "Plan",
    "PlannedStep",
    "Protocol",
    "StepCheck",
    "build_plan",
    "check_protocol",
    "format_plan",
    "load_plan",
    "load_protocol",
    "max_sine_amplitude_V",
    "max_sine_frequency_hz",
]
