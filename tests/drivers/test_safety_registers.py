"""Signed 32-bit registers of the conditioner: decoded with their sign, end to end.

``OUTPUT`` (the conditioner's output voltage, 1 uV per count) and ``BALANCE`` (the nulled
imbalance, 0.001 ue per count) are int32 in two registers, high word first. A decode that loses
the sign reads -1 uV as +4294.967295 V. The reference here is Python's ``struct`` (big-endian
``>i`` split into two ``>H`` words), independent of the register map's code.
"""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st
from labrig.drivers import strain_registers as R
from labrig.drivers.sim.bench import BenchConfig, GaugePhysics, VirtualBench
from labrig.drivers.sim.modbus_server import ModbusConditionerServer
from labrig.drivers.strain_modbus import ModbusConditioner, StrainModbusSettings

pytestmark = pytest.mark.timeout(30)

SIGNED = [R.OUTPUT, R.BALANCE]
INT32 = st.integers(min_value=-(2**31), max_value=2**31 - 1)


def words_of(value: int) -> list[int]:
    """Two big-endian 16-bit words of a big-endian int32 (the reference encoding)."""
    return list(struct.unpack(">HH", struct.pack(">i", value)))


@pytest.mark.parametrize("reg", SIGNED, ids=lambda r: r.name)
@pytest.mark.parametrize("value", [-1, -2, -(2**31), -(2**16), -65535, 2**31 - 1, 0, 1, 65536])
def test_int32_boundaries(reg, value):
    assert R.from_registers(reg, words_of(value)) == value
    assert R.to_registers(reg, value) == words_of(value)


@given(value=INT32)
def test_int32_round_trip(value):
    for reg in SIGNED:
        assert R.from_registers(reg, words_of(value)) == value
        assert R.from_registers(reg, R.to_registers(reg, value)) == value


def test_uint32_stays_unsigned():
    """The unsigned 32-bit registers keep the top bit as magnitude (serial 0x80000001)."""
    words = list(struct.unpack(">HH", struct.pack(">I", 0x80000001)))
    assert R.from_registers(R.SERIAL, words) == 0x80000001


@pytest.fixture
def conditioner():
    bench = VirtualBench(BenchConfig(gauge=GaugePhysics(noise_ue=0.0)), seed=0)
    srv = ModbusConditionerServer(bench, "tcp").start()
    settings = StrainModbusSettings(address=srv.address, timeout_s=1.0)
    cond = ModbusConditioner(settings, srv.address)
    yield cond, bench
    cond.close()
    srv.stop()


@pytest.mark.parametrize("volts", [-1.234567, -0.000001, -10.5, 3.5])
def test_negative_output_voltage_reads_negative_through_the_driver(conditioner, volts):
    cond, bench = conditioner
    with bench.lock:
        bench.cond.output_V = volts
    assert cond.read_output_V() == pytest.approx(volts, abs=1e-6)


def test_negative_balance_reads_negative_through_the_driver(conditioner):
    cond, bench = conditioner
    with bench.lock:
        bench.cond.balance_ue = -123.456
    raw = int(cond.read(R.BALANCE))
    assert raw * R.BALANCE.scale == pytest.approx(-123.456, abs=1e-3)
