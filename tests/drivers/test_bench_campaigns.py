"""The bipolar and biased campaigns: the protocol files run on the simulated rig, and the
in-process campaigns play the same drives on the same bench."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from labrig.drivers.sim.bench import BenchConfig

from labrig.analysis.load import records_from_run
from labrig.core.errors import InputFileError
from labrig.protocol.check import check_protocol
from labrig.rig.rigspec import load_rig
from labrig.studies.campaign import (
    BENCH_RIGS,
    BIASED_ENTRIES,
    BIPOLAR_ENTRIES,
    DRIVES,
    STUDY_CASES,
    STUDY_DRIVES,
    bench_campaign,
    study_campaign,
)

from helpers import invoke

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[2]
EXP = ROOT / "experiments"
BIPOLAR_RIG = EXP / "rigs" / "bipolar.yaml"
FILES = {"bipolar": EXP / "bipolar.yaml", "biased": EXP / "biased-envelope.yaml"}


@pytest.mark.parametrize("drive", ["bipolar", pytest.param("biased", marks=pytest.mark.slow)])
def test_labrig_run_plays_the_protocol_file_on_the_bipolar_rig(tmp_path, drive):
    """``labrig run`` (in-process: the file the command writes is the claim, not its process)
    exits 0; the run file holds every entry, its voltage is the plan's (ramp-in, settle and
    ramp back to 0 V included) and the amplifier followed it to -150 V."""
    out = tmp_path / "run.h5"
    res = invoke("run", FILES[drive], "--out", out, "--seed", 3)
    assert res.exit_code == 0, res.output
    plan = check_protocol(FILES[drive], load_rig(BIPOLAR_RIG).limits)
    records = records_from_run(out)
    assert [r.name for r in records] == [s.name for s in plan.steps]
    for r, s in zip(records, plan.steps, strict=True):
        assert np.array_equal(r.voltage_V, s.samples())
        assert r.voltage_V[0] == 0.0 and r.voltage_V[-1] == 0.0
        assert r.frequency_hz == s.frequency_hz and r.meta["offset_V"] == s.definition["offset_V"]
        monitor = r.aux["amplifier_voltage"]
        assert np.max(np.abs(monitor - r.voltage_V)) < 0.5  # monitor noise and quantisation
    assert min(np.min(r.aux["amplifier_voltage"]) for r in records) < -149.0


@pytest.mark.parametrize("drive", ["bipolar", "biased"])
def test_the_in_process_campaign_plays_the_protocol_files_entries(drive):
    plan = check_protocol(FILES[drive], load_rig(BIPOLAR_RIG).limits)
    d = DRIVES[drive]
    assert d.rig == "bipolar" and d.rate_hz == plan.rate_hz
    recs = bench_campaign(entries=d.entries, rig=d.rig, rate_hz=d.rate_hz, seed=1)
    assert [r.name for r in recs] == [s.name for s in plan.steps]
    for r, s in zip(recs, plan.steps, strict=True):
        assert np.array_equal(r.voltage_V, s.samples())
        assert r.meta == {**s.definition, "rest_after_s": 1.0}
        assert r.rate_hz == plan.rate_hz and r.hold == "zoh"


def test_the_bipolar_bench_is_the_bipolar_rig_file():
    """:data:`BENCH_RIGS` ``bipolar`` = experiments/rigs/bipolar.yaml's limits and amplifier;
    the file's bench adds field saturation (a campaign gives it as an effect)."""
    rig = load_rig(BIPOLAR_RIG)
    ours = BENCH_RIGS["bipolar"]
    assert rig.limits == ours.limits
    amp = rig.bench_config.amplifier
    for key, value in ours.bench["amplifier"].items():
        assert getattr(amp, key) == value, key
    assert [e.name for e in rig.bench_config.effects] == ["field_saturation"]
    assert rig.settings["amplifier"].gain_V_per_V == amp.gain_V_per_V  # calibration = truth
    assert amp.out_min_V <= rig.limits.v_min_V and rig.limits.v_max_V <= amp.out_max_V


def test_campaign_entries_are_short():
    """A diagnose on them must take minutes: at most ~20 s recorded, 25 000 samples."""
    for name, entries in (("bipolar", BIPOLAR_ENTRIES), ("biased", BIASED_ENTRIES)):
        d = DRIVES[name]
        recs = bench_campaign(entries=entries, rig=d.rig, rate_hz=d.rate_hz, noise_ue=0.0)
        assert sum(r.duration_s for r in recs) < 20.0
        assert sum(r.n for r in recs) < 25_000


def test_tuples_and_protocol_steps_mix_with_unique_names():
    step = {"kind": "offset_sine", "offset_V": 20.0, "amplitude_V": 20.0, "frequency_hz": 5.0,
            "cycles": 2.0, "ramp_s": 0.1, "settle_s": 0.1}  # fmt: skip
    recs = bench_campaign(entries=[(50.0, 5.0, 0.4), step, step, (50.0, 5.0, 0.4)], seed=2)
    assert [r.name for r in recs] == [
        "sine_50V_5Hz",
        "offset_sine_20V_20V_5Hz_constant",
        "offset_sine_20V_20V_5Hz_constant_2",
        "sine_50V_5Hz_2",
    ]
    assert recs[0].meta["kind"] == "sine" and recs[1].meta["kind"] == "offset_sine"
    assert recs[1].meta["sine_start_s"] == pytest.approx(0.2)


def test_an_entry_beyond_the_rigs_limits_is_refused():
    with pytest.raises(InputFileError, match="offset_V -90 V is out of range"):
        bench_campaign(entries=BIASED_ENTRIES[:1], rate_hz=2000.0)  # the built-in rig


def test_study_cases_and_their_drives():
    for case, effects in STUDY_CASES.items():
        BenchConfig.model_validate({"effects": effects})
        assert all(d in DRIVES for d in STUDY_DRIVES.get(case, ("short",)))
    assert STUDY_DRIVES["field_saturation"][0] == "bipolar"
    assert STUDY_DRIVES["none"] == ("short", "bipolar", "biased")
    recs = study_campaign("field_saturation", seed=4)
    plan = check_protocol(FILES["bipolar"], BENCH_RIGS["bipolar"].limits)
    assert [r.name for r in recs] == [s.name for s in plan.steps]
    biased = study_campaign("field_saturation", seed=4, drive="biased")
    assert all(r.rate_hz == 2000.0 and r.meta["envelope"] == "growing" for r in biased)


def test_field_saturation_takes_strain_off_the_bipolar_campaign():
    """The same seed with and without the bench's saturation: less strain at 150 V, about the
    5 % the effect takes off the drive (more, as the hysteresis amplifies it), less at 75 V."""
    plain = study_campaign("none", seed=5, drive="bipolar")
    sat = study_campaign("field_saturation", seed=5, drive="bipolar")
    loss = {}
    for p, s in zip(plain, sat, strict=True):
        loss[p.name] = 1 - np.ptp(s.strain_ue) / np.ptp(p.strain_ue)
    assert 0.04 < loss["offset_sine_0V_150V_1Hz_constant"] < 0.08
    assert 0.005 < loss["offset_sine_0V_75V_1Hz_constant"] < 0.03
