"""Campaigns of the structural study: one drive and one bench truth per structural effect.

Each structural effect of the library (``labrig diagnose --also NAME``) has a bench truth of a
different form (:mod:`labrig.drivers.sim.structural`, so finding it is not circular) and a
campaign that mixes the drives able to show it: unipolar sines, triangles, PRBS, multisines,
bipolar drives and drives biased to -100..+73 V, planned and preflighted as protocol steps
(:func:`labrig.studies.campaign.bench_campaign`) on the ``bipolar`` bench rig (-150..150 V).

==============================  =====================================  =========================
library effect (``--also``)     bench truth                            campaign (:data:`DRIVES`)
==============================  =====================================  =========================
``amplifier_bandwidth``         ``amplifier_output_rc``: 250 ohm into  ``wideband``: multisine
                                the stack (1 uF, rising to 1.7 uF at   to 200 Hz, PRBS, fast
                                100 V): corner 640 Hz at 0 V, 375 Hz   triangles
                                at 100 V
``mechanical_resonance``        ``stack_resonance``: 20 N/um, 8 kg     ``wideband``
                                (252 Hz), damping ratio 0.05
``negative_field_asymmetry``    ``depoling``: V_c 250 V (4.9 % less    ``bipolar``: bipolar and
                                strain per volt at -100 V)             -100..+73 V triangles,
                                                                       sines, a PRBS
``rate_hysteresis``             ``viscous_slip``: 4 elements, 2..20 V  ``rates``: triangles and
                                thresholds, tau 2 ms, 1 ue/V           sines from 0.5 to 40 Hz
``sensor_drift``                ``gauge_warmup``: 60 ue zero, 1 %      ``rates``
                                span, tau 30 s
==============================  =====================================  =========================

:data:`NULL_DRIVES` are the drives the nulls (no structural truth) are run on.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from labrig.analysis.records import Record
from labrig.studies.campaign import Drive, bench_campaign

__all__ = ["CASES", "DRIVES", "NULL_DRIVES", "STRUCTURAL_NAMES", "structural_campaign"]

#: the library's structural effects the study covers (``labrig diagnose --also``)
STRUCTURAL_NAMES = (
    "amplifier_bandwidth",
    "mechanical_resonance",
    "negative_field_asymmetry",
    "rate_hysteresis",
    "sensor_drift",
)


def _around(kind: str, offset: float, amplitude: float, **keys: Any) -> dict[str, Any]:
    return {"kind": kind, "offset_V": offset, "amplitude_V": amplitude, **keys}


#: multisines, a PRBS, fast triangles and a biased 60 Hz sine: 13.8 s recorded at 2 kHz
WIDEBAND: tuple[dict[str, Any], ...] = (
    {"kind": "sine", "amplitude_V": 100.0, "frequency_hz": 10.0, "cycles": 20},
    _around("multisine", 20.0, 80.0, frequencies_hz=[2, 5, 11, 23, 47, 97], duration_s=3.0),
    _around("prbs", 10.0, 60.0, clock_hz=200.0, order=8, seed=3, transition_s=0.0015, periods=1),
    _around("triangle", 0.0, 70.0, frequency_hz=25.0, cycles=50),
    _around("offset_sine", -13.5, 86.5, frequency_hz=60.0, cycles=120, ramp_s=0.3, settle_s=0.2),
    _around("multisine", 0.0, 100.0, frequencies_hz=[1, 3, 7, 13, 29, 61], duration_s=2.0),
)

#: bipolar and -100..+73 V drives beside a unipolar sine: 17.8 s recorded at 2 kHz
BIPOLAR: tuple[dict[str, Any], ...] = (
    _around("triangle", 0.0, 120.0, frequency_hz=2.0, cycles=4),
    _around("triangle", -13.5, 86.5, frequency_hz=10.0, cycles=20, start="low"),
    {"kind": "sine", "amplitude_V": 100.0, "frequency_hz": 5.0, "cycles": 10},
    _around("offset_sine", 0.0, 140.0, frequency_hz=1.0, cycles=3, ramp_s=0.0, settle_s=0.2),
    _around("prbs", -20.0, 80.0, clock_hz=50.0, order=6, seed=7, transition_s=0.004, periods=2),
    _around(
        "offset_sine",
        -13.5,
        86.5,
        frequency_hz=20.0,
        cycles=40,
        envelope="growing",
        ramp_s=0.5,
        settle_s=0.5,
    ),
)

#: unipolar triangles 0..100 V from 0.5 to 40 Hz, sines at 1 and 40 Hz, a bipolar triangle:
#: 17 s recorded at 2 kHz, 23 s with the rests
RATES: tuple[dict[str, Any], ...] = (
    *(
        _around("triangle", 50.0, 50.0, frequency_hz=f, cycles=c, start="low")
        for f, c in ((0.5, 2), (5.0, 10), (20.0, 40), (40.0, 80))
    ),
    {"kind": "sine", "amplitude_V": 100.0, "frequency_hz": 1.0, "cycles": 3},
    {"kind": "sine", "amplitude_V": 100.0, "frequency_hz": 40.0, "cycles": 80},
    _around("triangle", 0.0, 100.0, frequency_hz=10.0, cycles=20),
)

#: the study's campaigns, all on the ``bipolar`` bench rig at 2 kHz
DRIVES: dict[str, Drive] = {
    "wideband": Drive(WIDEBAND, "bipolar", 2000.0),
    "bipolar_mix": Drive(BIPOLAR, "bipolar", 2000.0),
    "rates": Drive(RATES, "bipolar", 2000.0),
}

#: library effect -> (bench truth as rig-file effects, campaign)
CASES: dict[str, tuple[list[dict[str, Any]], str]] = {
    "amplifier_bandwidth": (
        [{"name": "amplifier_output_rc", "output_resistance_ohm": 250.0}],
        "wideband",
    ),
    "mechanical_resonance": ([{"name": "stack_resonance"}], "wideband"),
    "negative_field_asymmetry": ([{"name": "depoling"}], "bipolar_mix"),
    "rate_hysteresis": ([{"name": "viscous_slip"}], "rates"),
    "sensor_drift": ([{"name": "gauge_warmup", "zero_ue": 60.0, "tau_s": 30.0}], "rates"),
}

#: the drives the nulls (no structural truth on the bench) are run on
NULL_DRIVES = tuple(DRIVES)


def structural_campaign(
    case: str | None,
    seed: int = 0,
    *,
    drive: str | None = None,
    truth: str = "paper",
    effects: Sequence[dict[str, Any]] | None = None,
) -> list[Record]:
    """The campaign of ``case`` (a :data:`CASES` name; ``None``: the null, no effect) on its
    drive or ``drive`` (a :data:`DRIVES` name), with the bench truth ``truth`` (``paper`` or
    ``hybrid``); ``effects`` replaces the case's bench effects."""
    planted, own = CASES[case] if case is not None else ([], "wideband")
    d = DRIVES[drive or own]
    return bench_campaign(
        planted if effects is None else effects,
        truth=truth,
        seed=seed,
        entries=d.entries,
        rate_hz=d.rate_hz,
        rig=d.rig,
    )
