"""Every injected fault ends in a clear DeviceError and, through the Rig, 0 V at the amplifier.

The faults are injected in the simulators (the drivers under test are the real ones, talking
over their transports): a serial link dropped mid-command, missing and garbled GCS answers,
Modbus timeouts, exception responses and damaged frames, amplifier overload and
over-temperature, and a conditioner excitation fault. A driver leaves the output where it is
when it raises (no step to 0 V); the Rig ramps it down
(tests/runner/test_safety_ramp.py measures the ramp's slope).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
import yaml
from labrig.drivers import strain_registers as R

from labrig.core.errors import DeviceError
from labrig.runner.rigfile import DEFAULT_RIG_YAML, open_rig

pytestmark = pytest.mark.timeout(60)


@pytest.fixture
def rig(tmp_path: Path):
    data = yaml.safe_load(DEFAULT_RIG_YAML)
    data["amplifier"]["timeout_s"] = 0.2
    data["conditioner"]["timeout_s"] = 0.2
    p = tmp_path / "rig.yaml"
    p.write_text(yaml.safe_dump(data))
    r = open_rig(p, seed=0)
    r.amplifier.enable()
    r.daq.write_static(5.0)  # energised: 50 V on the stack
    assert r.sim.bench.amp.v_out == pytest.approx(50.0, abs=0.01)
    assert r.amplifier.status().overflow  # a 50 V step into 10 uF is current-limited
    assert r.amplifier.status().ok  # OVF? is latched until read
    yield r
    r.close()


def assert_zero(rig) -> None:
    amp = rig.sim.bench.amp
    assert amp.v_out == 0.0
    assert amp.online or rig.sim.bench.ao_level == 0.0  # and it stays there


GCS_FAULTS = [
    # (fault, command it hits, operation, expected words in the message)
    ("drop", "VOL?", lambda r: r.amplifier.read_voltage(), "read_voltage", "link lost"),
    ("silent", "*IDN?", lambda r: r.amplifier.identify(), "identify", "no answer within 0.2 s"),
    ("garble", "OVF?", lambda r: r.amplifier.status(), "status", "garbled answer"),
    ("garble", "VMA?", lambda r: r.amplifier.output_limits(), "output_limits", "garbled"),
    ("drop", "ONL", lambda r: r.amplifier.enable(), "enable", "link lost"),
    ("silent", "ERR?", lambda r: r.amplifier.enable(), "enable", "no answer"),
]


@pytest.mark.parametrize(("fault", "command", "op", "operation", "words"), GCS_FAULTS)
def test_gcs_faults(rig, fault, command, op, operation, words):
    rig.sim.gcs.inject(fault, command=command)
    with pytest.raises(DeviceError) as ei:
        op(rig)
    e = ei.value
    assert e.device.startswith("amplifier (PI E-503 at socket://127.0.0.1:")
    assert e.operation.startswith(operation)
    assert words in e.detail
    # the driver did not step the output to 0 V on its own: the Rig ramps it
    assert rig.sim.bench.amp.v_out == pytest.approx(50.0, abs=0.01)
    rig.safe_zero()
    assert_zero(rig)
    assert "E-503" in rig.amplifier.identify()  # and reconnects on the next call


def test_dropped_link_during_playback(rig):
    rig.daq.configure(1000.0, ["gauge", "amp_monitor"])
    with pytest.raises(DeviceError, match="read_voltage"), rig.zero_on_error():
        for blk in rig.daq.play(rig.volts_to_ao(np.full(2000, 80.0)), 250):
            if blk.start == 500:
                assert rig.sim.bench.amp.v_out == pytest.approx(80.0, abs=0.01)
                rig.sim.gcs.inject("drop")
                rig.amplifier.read_voltage()
    assert_zero(rig)
    assert rig.sim.bench.ao_level == 0.0


@pytest.mark.parametrize("flag", ["overload", "over_temperature"])
def test_amplifier_flags(rig, flag):
    rig.sim.bench.inject(flag)
    st = rig.amplifier.status()
    assert not st.ok
    assert (st.overflow, st.over_temperature) == (flag == "overload", flag == "over_temperature")
    with pytest.raises(DeviceError) as ei:
        rig.check()
    assert ei.value.device == "amplifier"
    assert ei.value.operation == "status check"
    assert ("overflow" if flag == "overload" else "over-temperature") in ei.value.detail
    assert_zero(rig)


def test_amplifier_driver_check_leaves_the_output_to_the_rig(rig):
    rig.sim.bench.inject("overload")
    with pytest.raises(DeviceError, match="overflow"):
        rig.amplifier.check()
    assert rig.sim.bench.amp.v_out == pytest.approx(50.0, abs=0.01)  # no step by the driver
    with pytest.raises(DeviceError, match="overflow"):
        rig.check()  # the Rig ramps to 0 V, then raises
    assert rig.sim.bench.amp.v_out == 0.0 and rig.sim.bench.amp.online


MODBUS_FAULTS = [
    ("timeout", {}, lambda r: r.conditioner.status(), "status", "no valid answer within 0.2 s"),
    ("garble", {}, lambda r: r.conditioner.identify(), "identify", "no valid answer"),
    (
        "exception",
        {"code": 4},
        lambda r: r.conditioner.zero(),
        "zero",
        "Modbus exception 4 (device failure)",
    ),
    (
        "exception",
        {"code": 6},
        lambda r: r.conditioner.configure(2.0, 1, 0),
        "configure",
        "Modbus exception 6 (device busy)",
    ),
]


@pytest.mark.parametrize(("fault", "kw", "op", "operation", "words"), MODBUS_FAULTS)
def test_modbus_faults(rig, fault, kw, op, operation, words):
    rig.sim.modbus_tcp.inject(fault, **kw)
    with pytest.raises(DeviceError) as ei, rig.zero_on_error():
        op(rig)
    e = ei.value
    assert e.device.startswith("conditioner (Modbus tcp 127.0.0.1:")
    assert e.operation.startswith(operation) and "register" in e.operation
    assert words in e.detail
    assert_zero(rig)
    assert rig.conditioner.status().ok  # reconnects on the next call


def test_modbus_illegal_value_is_reported(rig):
    with pytest.raises(DeviceError, match=r"illegal data value"), rig.zero_on_error():
        rig.conditioner.write(R.EXCITATION, 50)  # 50 mV: below the 500 mV minimum
    assert_zero(rig)


def test_modbus_rtu_timeout(tmp_path):
    data = yaml.safe_load(DEFAULT_RIG_YAML)
    # 1 s, not less: the timeout also bounds opening the rig, which a loaded machine can slow
    data["conditioner"].update(transport="rtu", timeout_s=1.0)
    p = tmp_path / "rig.yaml"
    p.write_text(yaml.safe_dump(data))
    with open_rig(p, seed=0) as r:
        r.amplifier.enable()
        r.daq.write_static(3.0)
        r.sim.modbus_rtu.inject("timeout")
        with pytest.raises(DeviceError, match="no valid answer"), r.zero_on_error():
            r.conditioner.status()
        assert r.sim.bench.amp.v_out == 0.0


def test_excitation_fault(rig):
    rig.sim.bench.inject("excitation_fault")
    st = rig.conditioner.status()
    assert st.excitation_fault and st.error_code == 1 and not st.ok
    with pytest.raises(DeviceError) as ei:
        rig.check()
    assert ei.value.device == "conditioner" and "excitation fault" in ei.value.detail
    assert_zero(rig)


def test_balance_failure(tmp_path):
    data = yaml.safe_load(DEFAULT_RIG_YAML)
    data["bench"]["gauge"]["bridge_offset_ue"] = 8000.0  # beyond the balance range
    p = tmp_path / "rig.yaml"
    p.write_text(yaml.safe_dump(data))
    with pytest.raises(DeviceError, match="balance failed"):
        open_rig(p, seed=0)


def test_safe_zero_never_raises_when_the_link_is_down(rig, caplog):
    rig.sim.gcs.stop()
    with caplog.at_level(logging.ERROR):
        rig.safe_zero()  # DAQ to 0 V works; the amplifier link is gone: logged, not raised
    assert rig.sim.bench.ao_level == 0.0
    assert rig.sim.bench.amp.v_out == 0.0  # OFFLINE: follows the DAQ's 0 V
    assert any("safe_zero" in r.getMessage() for r in caplog.records)
    with pytest.raises(DeviceError, match="cannot open the link"):
        rig.amplifier.identify()


def test_open_fails_cleanly_when_no_amplifier_answers(tmp_path):
    data = yaml.safe_load(DEFAULT_RIG_YAML)
    data["amplifier"]["url"] = "socket://127.0.0.1:9"  # discard port: nothing listens
    p = tmp_path / "rig.yaml"
    p.write_text(yaml.safe_dump(data))
    with pytest.raises(DeviceError) as ei:
        open_rig(p, seed=0)
    assert ei.value.device.startswith("amplifier")
