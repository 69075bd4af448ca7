"""A protocol at exactly the rig's voltage limits runs (labrig.rig.instruments.Rig.volts_to_ao).

The DAQ's converter rounds each AO sample to its nearest code (half a code: 0.15 mV at the DAQ,
1.5 mV at the actuator on the default rig). The amplifier is set to the rig's limits; a sample
asked for at -20 V came out at -20.001 V, and the simulated E-503 clamped it and reported an
overflow: `check` said OK and `run` failed with a device fault. Samples within one code of a
limit are now drawn in to one code inside it, every other sample is as asked."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from labrig.rig.instruments import Rig
from labrig.rig.limits import RigLimits

from helpers import invoke

GAIN = 10.0
STEP = 20.0 / 2**16  # one code of a 16-bit +-10 V converter (V at the DAQ)


@dataclass
class Amp:
    gain: float = GAIN


@dataclass
class Daq:
    step: float | None

    def ao_step_V(self) -> float | None:
        return self.step


def rig(step: float | None) -> Rig:
    return Rig("t", Daq(step), Amp(), None, RigLimits(), (10.0, 1e5), "")  # type: ignore[arg-type]


def test_samples_at_the_limits_are_drawn_in_by_one_code():
    lo, hi = -20.0 / GAIN, 100.0 / GAIN  # the default limits at the DAQ
    asked = np.array([-20.0, 100.0, 0.0, 55.5, -19.0, 99.0])
    ao = rig(STEP).volts_to_ao(asked)
    assert ao[0] == lo + STEP and ao[1] == hi - STEP
    assert np.array_equal(ao[2:], asked[2:] / GAIN)  # the rest as asked, bit for bit
    # the converter's nearest-code rounding keeps them inside the limits, the asked ones not
    codes = np.round(asked[:2] / GAIN / STEP) * STEP
    assert codes[0] < lo  # -2.0 V is not a code: the nearest lies past the limit
    assert lo <= np.round(ao[0] / STEP) * STEP and np.round(ao[1] / STEP) * STEP <= hi


def test_one_code_inside_is_kept_and_just_past_it_is_drawn_in():
    lo = -20.0 / GAIN
    inside = (lo + STEP) * GAIN  # exactly one code inside: kept
    past = np.nextafter(lo + STEP, -np.inf) * GAIN  # a hair nearer the limit: drawn in
    ao = rig(STEP).volts_to_ao([inside, past])
    assert ao[0] == inside / GAIN and ao[1] == lo + STEP
    assert past / GAIN < lo + STEP


def test_without_a_known_step_every_sample_is_as_asked():
    asked = np.array([-20.0, 100.0, 3.0])
    assert np.array_equal(rig(None).volts_to_ao(asked), asked / GAIN)


@pytest.mark.parametrize("volts", [-20, 100])
def test_a_hold_at_a_limit_of_the_simulated_rig_runs(tmp_path: Path, volts: int):
    proto = tmp_path / "p.yaml"
    proto.write_text(
        "name: edge\nrate_hz: 500\nsteps:\n"
        f"  - {{kind: hold, voltage_V: {volts}, duration_s: 0.2}}\n"
    )
    assert invoke("check", proto).exit_code == 0
    res = invoke("run", proto, "--out", tmp_path / "r.h5", "--seed", 3)
    assert res.exit_code == 0, res.output
    info = invoke("info", tmp_path / "r.h5", "--json")
    assert '"status": "complete"' in info.stdout, info.stdout
