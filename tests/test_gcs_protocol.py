"""Exact-byte tests of the GCS subset spoken by the simulated E-503 (docs/instruments.md)."""

from __future__ import annotations

import socket

import pytest
from labrig.drivers.sim.bench import BenchConfig, VirtualBench
from labrig.drivers.sim.gcs_server import IDN, GCSServer

pytestmark = pytest.mark.timeout(30)


@pytest.fixture
def gcs():
    bench = VirtualBench(BenchConfig.ideal(), seed=0)
    srv = GCSServer(bench).start()
    sock = socket.create_connection(("127.0.0.1", srv.port), timeout=2.0)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    yield srv, sock, bench
    sock.close()
    srv.stop()


def ask(sock: socket.socket, data: bytes) -> bytes:
    """Send ``data``; return the answer up to the final line (a line not ending in ' \\n')."""
    sock.sendall(data)
    buf = b""
    while not (buf.endswith(b"\n") and not buf.endswith(b" \n")):
        chunk = sock.recv(4096)
        assert chunk, "connection closed"
        buf += chunk
    return buf


def tell(sock: socket.socket, data: bytes) -> None:
    """Send a command without answer, then make sure ERR? is 0."""
    sock.sendall(data)
    assert ask(sock, b"ERR?\n") == b"0\n"


def test_idn(gcs):
    _, s, _ = gcs
    assert ask(s, b"*IDN?\n") == IDN.encode() + b"\n"


def test_err_reports_and_clears(gcs):
    _, s, _ = gcs
    assert ask(s, b"ERR?\n") == b"0\n"
    s.sendall(b"XYZ 1\n")
    assert ask(s, b"ERR?\n") == b"2\n"  # unknown command
    assert ask(s, b"ERR?\n") == b"0\n"  # cleared by reading
    s.sendall(b"SVA B 1\n")
    assert ask(s, b"ERR?\n") == b"15\n"  # invalid axis
    s.sendall(b"SVA A\n")
    assert ask(s, b"ERR?\n") == b"1\n"  # syntax
    s.sendall(b"SVA A abc\n")
    assert ask(s, b"ERR?\n") == b"1\n"
    s.sendall(b"SVA A 500\n")
    assert ask(s, b"ERR?\n") == b"17\n"  # beyond VMA


def test_onl_and_query(gcs):
    _, s, bench = gcs
    assert ask(s, b"ONL? 1\n") == b"1=0\n"  # powers up OFFLINE (analog control)
    assert ask(s, b"ONL?\n") == b"1=0\n"
    tell(s, b"ONL 1 1\n")
    assert bench.amp.online
    assert ask(s, b"ONL? 1\n") == b"1=1\n"
    s.sendall(b"ONL 1 2\n")
    assert ask(s, b"ERR?\n") == b"17\n"
    tell(s, b"ONL 1 0\n")
    assert ask(s, b"ONL? 1\n") == b"1=0\n"


def test_sva_sets_output_in_online_mode(gcs):
    _, s, bench = gcs
    tell(s, b"ONL 1 1\n")
    tell(s, b"SVA A 12.5\n")
    assert ask(s, b"SVA? A\n") == b"A=12.5000\n"
    assert ask(s, b"SVA?\n") == b"A=12.5000\n"
    assert ask(s, b"VOL? 1\n") == b"1=12.5000\n"  # ideal bench: no slew limit
    assert bench.amp.v_out == pytest.approx(12.5)
    tell(s, b"SVA A -5\n")
    assert ask(s, b"VOL?\n") == b"1=-5.0000\n"


def test_vol_follows_analog_input_offline(gcs):
    _, s, bench = gcs
    bench.ao_level = 3.0
    bench.settle()
    assert ask(s, b"VOL? 1\n") == b"1=30.0000\n"  # gain 10
    tell(s, b"ONL 1 1\n")  # ONLINE: analog input ignored, SVA = 0
    assert ask(s, b"VOL? 1\n") == b"1=0.0000\n"


def test_vma_vmi(gcs):
    _, s, _ = gcs
    assert ask(s, b"VMA? 1\n") == b"1=130.0000\n"
    assert ask(s, b"VMI? 1\n") == b"1=-30.0000\n"
    tell(s, b"VMA 1 100\n")
    tell(s, b"VMI 1 -20\n")
    assert ask(s, b"VMA?\n") == b"1=100.0000\n"
    assert ask(s, b"VMI?\n") == b"1=-20.0000\n"
    s.sendall(b"VMA 1 200\n")  # beyond the amplifier's range
    assert ask(s, b"ERR?\n") == b"17\n"
    s.sendall(b"VMI 1 150\n")  # not below VMA
    assert ask(s, b"ERR?\n") == b"17\n"
    s.sendall(b"VMA 2 50\n")
    assert ask(s, b"ERR?\n") == b"15\n"


def test_vma_clamps_output(gcs):
    _, s, bench = gcs
    tell(s, b"VMA 1 50\n")
    bench.ao_level = 8.0
    bench.settle()
    assert ask(s, b"VOL? 1\n") == b"1=50.0000\n"
    assert ask(s, b"OVF? A\n") == b"A=1\n"  # clipped: overflow


def test_ovf_latch_and_srg(gcs):
    _, s, bench = gcs
    assert ask(s, b"OVF? A\n") == b"A=0\n"
    assert ask(s, b"OVF?\n") == b"A=0\n"
    assert ask(s, b"SRG? A 1\n") == b"A 1=0x0\n"
    bench.inject("overload")
    assert ask(s, b"SRG? A 1\n") == b"A 1=0x1\n"
    assert ask(s, b"OVF? A\n") == b"A=1\n"
    bench.inject("overload", on=False)
    bench.settle()
    assert ask(s, b"OVF? A\n") == b"A=1\n"  # latched until read
    assert ask(s, b"OVF? A\n") == b"A=0\n"
    tell(s, b"ONL 1 1\n")
    assert ask(s, b"SRG? A 1\n") == b"A 1=0x4\n"
    bench.inject("over_temperature")
    assert ask(s, b"SRG? A 1\n") == b"A 1=0x6\n"
    s.sendall(b"SRG? A 2\n")
    assert ask(s, b"ERR?\n") == b"1\n"


def test_over_temperature_shuts_output_down(gcs):
    _, s, bench = gcs
    bench.ao_level = 5.0
    bench.settle()
    assert ask(s, b"VOL? 1\n") == b"1=50.0000\n"
    bench.inject("over_temperature")
    assert ask(s, b"VOL? 1\n") == b"1=0.0000\n"


def test_multiline_help(gcs):
    _, s, _ = gcs
    ans = ask(s, b"HLP?\n")
    lines = ans.split(b"\n")[:-1]
    assert len(lines) > 5
    assert all(line.endswith(b" ") for line in lines[:-1])
    assert not lines[-1].endswith(b" ")
    assert lines[0] == b"*IDN? - identification "


def test_two_commands_in_one_packet(gcs):
    _, s, _ = gcs
    assert ask(s, b"ONL 1 1\nSVA A 7\nSVA? A\n") == b"A=7.0000\n"


def test_received_log(gcs):
    srv, s, _ = gcs
    ask(s, b"*IDN?\n")
    assert srv.received[-1] == b"*IDN?\n"
