"""An input driven past the DAQ's range ends the run as a device fault (exit 3), the block
that showed it logged (labrig.rig.instruments.Rig.clipped_input, labrig.runner.execute).

A converter past its range returns its last code: the strain record then has a flat top where
the actuator went on, and a run said "complete" over it (a 1 mV input range, or mains pickup
of 1e10 mV, recorded as good data)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from labrig.rig.instruments import CLIP_FRACTION, Rig
from labrig.rig.limits import RigLimits

from helpers import invoke, rig_path


@dataclass
class Daq:
    def ai_range_V(self) -> tuple[float, float]:
        return (-10.0, 10.0)


def rig(daq: object) -> Rig:
    return Rig("t", daq, None, None, RigLimits(), (10.0, 1e5), "")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("value", "clipped"),
    [(9.9989, False), (9.9991, True), (-9.9989, False), (-9.9991, True), (10.0, True)],
)
def test_a_sample_at_the_end_of_the_range_is_clipped(value: float, clipped: bool):
    assert CLIP_FRACTION == 0.9999  # 9.999 V on a +-10 V range: the values above straddle it
    block = {"amp_monitor": np.zeros(5), "gauge": np.array([0.1, value, 0.2, 0.3, 0.0])}
    why = rig(Daq()).clipped_input(block)
    assert (why is not None) == clipped
    if clipped:
        assert why.startswith(f"the gauge input reached {value:g} V, the end of the DAQ's")
        assert "(-10 to 10 V), 1 times in a block" in why


def test_a_daq_that_does_not_say_its_range_is_not_checked():
    assert rig(object()).clipped_input({"gauge": np.full(3, 1e9)}) is None


def test_a_run_whose_gauge_clips_fails_with_the_block_logged(tmp_path: Path):
    proto = tmp_path / "p.yaml"
    proto.write_text(
        "name: c\nrate_hz: 500\nsteps:\n  - {kind: sine, amplitude_V: 60, frequency_hz: 2, "
        "cycles: 2}\n"
    )
    # at the top: about 550 ue, 0.6 V at the gauge; 60 V, 3.0 V at the amplifier's monitor
    # (0.05 V/V); an input range of +-0.4 V clips both, +-3.5 V neither
    narrow = rig_path(tmp_path, bench={"daq": {"ai_range_V": 0.4}})
    res = invoke("run", proto, "--rig", narrow, "--out", tmp_path / "r.h5", "--seed", 1)
    assert res.exit_code == 3, res.output
    said = " ".join(res.output.split())
    assert "daq: acquisition during sine_60V_2Hz failed: the amp_monitor input reached" in said
    assert "the end of the DAQ's input range (-0.4 to 0.4 V)" in said
    info = json.loads(invoke("info", tmp_path / "r.h5", "--json").stdout)
    (entry,) = info["entries"]
    assert entry["status"] == "failed" and "the signal is clipped" in entry["reason"]
    # the blocks up to the clipped one are in the file; the clipped samples at 0.4 V x 20
    assert 0 < entry["samples"] < 1000
    assert entry["max_amplifier_voltage_V"] == pytest.approx(8, rel=1e-4)
    wide = rig_path(tmp_path, bench={"daq": {"ai_range_V": 3.5}})
    res = invoke("run", proto, "--rig", wide, "--out", tmp_path / "ok.h5", "--seed", 1)
    assert res.exit_code == 0, res.output
