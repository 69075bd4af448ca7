"""Exact-byte tests of the conditioner's Modbus register map (TCP and RTU framing).

Frames are built by hand here (not by pymodbus) so the bytes on the wire are what is checked.
"""

from __future__ import annotations

import socket
import struct

import pytest
from labrig.drivers import strain_registers as R
from labrig.drivers.sim.bench import BenchConfig, GaugePhysics, VirtualBench
from labrig.drivers.sim.modbus_server import ModbusConditionerServer

pytestmark = pytest.mark.timeout(30)


def crc16(data: bytes) -> bytes:
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return struct.pack("<H", crc)


def make_bench() -> VirtualBench:
    cfg = BenchConfig(gauge=GaugePhysics(noise_ue=0.0, bridge_offset_ue=40.0))
    return VirtualBench(cfg, seed=0)


@pytest.fixture
def tcp():
    bench = make_bench()
    srv = ModbusConditionerServer(bench, "tcp").start()
    sock = socket.create_connection(("127.0.0.1", srv.port), timeout=2.0)
    yield _TcpLink(sock), bench, srv
    sock.close()
    srv.stop()


class _TcpLink:
    def __init__(self, sock):
        self.sock, self.tid = sock, 0

    def exchange(self, pdu: bytes, unit: int = 1) -> tuple[bytes, bytes]:
        """Send a PDU in an MBAP frame; return (request frame, response frame)."""
        self.tid += 1
        req = struct.pack(">HHHB", self.tid, 0, len(pdu) + 1, unit) + pdu
        self.sock.sendall(req)
        head = self._recv(7)
        (length,) = struct.unpack(">H", head[4:6])
        return req, head + self._recv(length - 1)

    def _recv(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            assert chunk, "connection closed"
            buf += chunk
        return buf


def test_read_device_id_exact_bytes(tcp):
    link, _, _ = tcp
    req, resp = link.exchange(bytes.fromhex("04 0000 0001"))
    assert req == bytes.fromhex("0001 0000 0006 01 04 0000 0001")
    assert resp == bytes.fromhex("0001 0000 0005 01 04 02 3840")


@pytest.mark.parametrize(
    ("reg", "words"),
    [
        (R.DEVICE_ID, "3840"),
        (R.FIRMWARE, "0100"),
        (R.SERIAL, "003A 9801"),  # 3840001
        (R.MODEL, "4448 3338 3430 2D53 494D 2020 2020 2020"),  # "DH3840-SIM      "
        (R.STATUS, "0000"),
        (R.ERROR, "0000"),
        (R.SENSITIVITY, "0010 8E48"),  # 1 085 000 nV/ue = 1.085 mV/ue
        (R.BALANCE, "0000 0000"),
        (R.OUTPUT, "0000 0000"),
    ],
)
def test_input_registers_exact_bytes(tcp, reg, words):
    link, _, _ = tcp
    data = bytes.fromhex(words)
    _, resp = link.exchange(struct.pack(">BHH", 4, reg.address, reg.count))
    assert resp[7:] == bytes([4, 2 * reg.count]) + data
    assert len(data) == 2 * reg.count


def test_whole_input_block(tcp):
    link, _, _ = tcp
    _, resp = link.exchange(bytes.fromhex("04 0000 0018"))
    words = struct.unpack(">24H", resp[9:])
    assert words[0] == 0x3840
    assert R.from_registers(R.MODEL, list(words[4:12])) == "DH3840-SIM      "
    assert R.from_registers(R.SENSITIVITY, list(words[18:20])) == 1085000


@pytest.mark.parametrize(
    ("reg", "value", "wire"),
    [(R.EXCITATION, 5000, "1388"), (R.GAIN, 10, "000A"), (R.FILTER, 1000, "03E8")],
)
def test_write_single_holding_register_exact_bytes(tcp, reg, value, wire):
    link, bench, _ = tcp
    pdu = struct.pack(">BH", 6, reg.address) + bytes.fromhex(wire)
    _, resp = link.exchange(pdu)
    assert resp[7:] == pdu  # function 06 echoes the request
    _, resp = link.exchange(struct.pack(">BHH", 3, reg.address, 1))
    assert resp[7:] == b"\x03\x02" + bytes.fromhex(wire)
    assert {
        "EXCITATION": bench.cond.excitation_V * 1000,
        "GAIN": bench.cond.gain,
        "FILTER": bench.cond.filter_hz,
    }[reg.name] == value


def test_read_holding_block_power_on(tcp):
    link, _, _ = tcp
    _, resp = link.exchange(bytes.fromhex("03 0100 0004"))
    assert resp[7:] == bytes.fromhex("03 08 07D0 0001 0000 0000")  # 2 V, gain 1, off, cmd 0


def test_write_multiple_registers_exact_bytes(tcp):
    link, bench, _ = tcp
    pdu = bytes.fromhex("10 0100 0003 06 0FA0 0002 0064")  # 4 V, gain 2, 100 Hz
    _, resp = link.exchange(pdu)
    assert resp[7:] == bytes.fromhex("10 0100 0003")
    assert (bench.cond.excitation_V, bench.cond.gain, bench.cond.filter_hz) == (4.0, 2, 100)
    _, resp = link.exchange(bytes.fromhex("04 0012 0002"))  # sensitivity doubles with 4 V
    assert resp[7:] == bytes.fromhex("04 04 0021 1C90")  # 2 170 000
    _, resp = link.exchange(bytes.fromhex("04 0010 0001"))
    assert resp[7:] == bytes.fromhex("04 02 0008")  # STATUS bit 3: filter on


def test_balance_command(tcp):
    link, bench, _ = tcp
    bench.settle()
    _, resp = link.exchange(bytes.fromhex("06 0103 0001"))
    assert resp[7:] == bytes.fromhex("06 0103 0001")
    _, resp = link.exchange(bytes.fromhex("04 0014 0002"))
    assert resp[7:] == bytes.fromhex("04 04 0000 9C40")  # 40 000 milli-ue nulled
    _, resp = link.exchange(bytes.fromhex("03 0103 0001"))
    assert resp[7:] == bytes.fromhex("03 02 0001")  # the last command written


@pytest.mark.parametrize(
    ("pdu", "answer"),
    [
        ("06 0100 0064", "86 03"),  # excitation 100 mV: below 500 mV
        ("06 0101 0003", "86 03"),  # gain 3: not a gain step
        ("06 0102 7530", "86 03"),  # filter 30 kHz: above 20 kHz
        ("06 0103 0009", "86 03"),  # unknown command
        ("04 0064 0001", "84 02"),  # unmapped input register
        ("03 0000 0001", "83 02"),  # input registers are not holding registers
        ("06 0000 0001", "86 02"),  # ... and cannot be written
        ("04 0016 0003", "84 02"),  # read past the end of the map
    ],
)
def test_exception_responses_exact_bytes(tcp, pdu, answer):
    link, _, _ = tcp
    _, resp = link.exchange(bytes.fromhex(pdu))
    assert resp[6:] == bytes.fromhex("01") + bytes.fromhex(answer)


def test_invalid_setting_sets_error_register(tcp):
    link, _, _ = tcp
    link.exchange(bytes.fromhex("06 0101 0003"))
    _, resp = link.exchange(bytes.fromhex("04 0010 0002"))
    assert resp[7:] == bytes.fromhex("04 04 8000 0003")  # fault bit, error 3 (invalid setting)
    link.exchange(bytes.fromhex("06 0103 0002"))  # clear error
    _, resp = link.exchange(bytes.fromhex("04 0010 0002"))
    assert resp[7:] == bytes.fromhex("04 04 0000 0000")


def test_injected_exception_response(tcp):
    link, _, srv = tcp
    srv.inject("exception", code=4)
    _, resp = link.exchange(bytes.fromhex("04 0000 0001"))
    assert resp[7:] == bytes.fromhex("84 04")
    _, resp = link.exchange(bytes.fromhex("04 0000 0001"))
    assert resp[7:] == bytes.fromhex("04 02 3840")


def test_rtu_framing_exact_bytes():
    bench = make_bench()
    srv = ModbusConditionerServer(bench, "rtu").start()
    try:
        assert srv.address.startswith("socket://127.0.0.1:")
        sock = socket.create_connection(("127.0.0.1", srv.port), timeout=2.0)
        req = bytes.fromhex("01 04 0000 0001")
        req += crc16(req)
        assert req == bytes.fromhex("01 04 0000 0001 31CA")
        sock.sendall(req)
        want = bytes.fromhex("01 04 02 3840")
        want += crc16(want)
        buf = b""
        while len(buf) < len(want):
            chunk = sock.recv(64)
            assert chunk
            buf += chunk
        assert buf == want
        sock.close()
    finally:
        srv.stop()
