"""The structural study's campaigns (labrig.studies.structural): each plants its bench truth on
drives planned and preflighted as protocol steps, and one small campaign goes through diagnose
with ``--also negative_field_asymmetry`` (the full study is benchmarks/bench_structural_study.py;
the whole campaigns through diagnose are ``slow``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from labrig.analysis.diagnose import diagnose
from labrig.model.effects import EFFECT_NAMES, STRUCTURAL_EFFECT_NAMES
from labrig.protocol.check import load_plan
from labrig.studies.campaign import bench_campaign
from labrig.studies.structural import CASES, DRIVES, STRUCTURAL_NAMES, structural_campaign

#: a small bipolar campaign: a +-120 V triangle, a -100..+73 V triangle, a unipolar sine and a
#: PRBS down to -100 V (2.3 s recorded at 1 kHz)
SMALL = (
    {"kind": "triangle", "offset_V": 0.0, "amplitude_V": 120.0, "frequency_hz": 2.0, "cycles": 2},
    {
        "kind": "triangle",
        "offset_V": -13.5,
        "amplitude_V": 86.5,
        "frequency_hz": 10.0,
        "cycles": 5,
        "start": "low",
    },
    {"kind": "sine", "amplitude_V": 100.0, "frequency_hz": 5.0, "cycles": 3},
    {
        "kind": "prbs",
        "offset_V": -20.0,
        "amplitude_V": 80.0,
        "clock_hz": 50.0,
        "order": 4,
        "seed": 7,
        "transition_s": 0.004,
        "periods": 1,
    },
)
ASK = ("negative_field_asymmetry",)


def test_the_wideband_campaign_is_the_protocol_file():
    """experiments/wideband.yaml plans the samples the in-process campaign plays."""
    plan = load_plan(Path(__file__).parents[2] / "experiments" / "wideband.yaml")
    recs = structural_campaign(None, 1, drive="wideband")
    assert [s.name for s in plan.steps] == [r.name for r in recs]
    for step, rec in zip(plan.steps, recs, strict=True):
        np.testing.assert_array_equal(step.samples(), rec.voltage_V)


def test_every_structural_library_effect_has_a_case():
    assert set(CASES) == set(STRUCTURAL_NAMES)
    assert set(STRUCTURAL_NAMES) <= set(STRUCTURAL_EFFECT_NAMES)
    # opt-in, not tried by default; but negative_field_asymmetry, a default where the drive goes
    # below 0 V (tests/diagnose/test_poling_candidate.py)
    assert set(STRUCTURAL_NAMES) & set(EFFECT_NAMES) == {"negative_field_asymmetry"}
    # the truths are bench effects of other names than the library's
    assert not {e["name"] for eff, _ in CASES.values() for e in eff} & set(STRUCTURAL_NAMES)


@pytest.mark.parametrize("drive", sorted(DRIVES))
def test_campaigns_mix_the_drive_kinds(drive):
    recs = structural_campaign(None, 1, drive=drive)
    kinds = {r.meta["kind"] for r in recs}
    assert len(recs) >= 6 and len(kinds) >= 2 and kinds != {"sine"}
    v = np.concatenate([r.voltage_V for r in recs])
    assert v.min() < -50 and v.max() > 50  # bipolar or biased drives beside unipolar ones
    assert len({r.name for r in recs}) == len(recs)


@pytest.mark.parametrize("case", sorted(CASES))
def test_each_truth_changes_its_campaign(case):
    """Same seed, same noise: the planted truth is all that differs from the null."""
    _, drive = CASES[case]
    null = structural_campaign(None, 2, drive=drive)
    recs = structural_campaign(case, 2)
    diff = [
        np.sqrt(np.mean((a.strain_ue - b.strain_ue) ** 2)) for a, b in zip(recs, null, strict=True)
    ]
    assert max(diff) > 5.0  # ue: well above the 2 ue gauge noise
    assert [r.name for r in recs] == [r.name for r in null]


@pytest.mark.slow
def test_depoling_is_found_on_a_small_campaign():
    """With the library's one candidate asked for (the full library is the slow test's: on this
    small campaign ``quadratic_term`` takes the residual first)."""
    recs = bench_campaign([{"name": "depoling"}], seed=1, entries=SMALL, rig="bipolar")
    d = diagnose(recs, effects=ASK, always=ASK, max_effects=1)
    assert d.effects_added and d.effects_added[0]["effect"] == "negative_field_asymmetry"
    assert d.after["heldout_nrmse_pct"] < 0.5 * d.before["heldout_nrmse_pct"]


def test_the_null_of_the_small_campaign_stays_noise():
    """The default tier's run of a campaign through diagnose (the depoled one above is slow)."""
    recs = bench_campaign([], seed=1, entries=SMALL, rig="bipolar")
    d = diagnose(recs, effects=ASK, always=ASK, max_effects=1)
    assert not d.effects_added
    assert d.classification == "consistent_with_noise"


#: cases the study (docs/diagnose.md, "The structural study") does not find first, and why
#: (none since sensor_drift starts at the balanced zero and its span follows the zero; before,
#: the default offset_drift took the gauge's warm-up)
NOT_FIRST: dict[str, str] = {}


@pytest.mark.slow
@pytest.mark.parametrize(
    "case",
    [
        pytest.param(c, marks=pytest.mark.xfail(reason=NOT_FIRST[c], strict=False))
        if c in NOT_FIRST
        else c
        for c in sorted(CASES)
    ],
)
def test_each_case_is_named_first_on_its_campaign(case):
    d = diagnose(
        structural_campaign(case, 1),
        effects=EFFECT_NAMES + STRUCTURAL_NAMES,
        always=STRUCTURAL_NAMES,
        max_effects=3,
    )
    assert d.effects_added and d.effects_added[0]["effect"] == case
