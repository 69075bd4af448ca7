"""Exact-byte tests of the GCS subset spoken by the simulated E-503 (docs/instruments.md)."""

from __future__ import annotations

import socket
import threading
import time

import pytest
from labrig.drivers.sim.bench import BenchConfig, VirtualBench
from labrig.drivers.sim.gcs_server import IDN, MAX_CONNECTIONS, GCSServer

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
    """VMI/VMA start at the rig's limits (-20..100 V by default), not at the amplifier's
    hardware range (-30..130 V), and cannot be widened beyond them."""
    _, s, _ = gcs
    assert ask(s, b"VMA? 1\n") == b"1=100.0000\n"
    assert ask(s, b"VMI? 1\n") == b"1=-20.0000\n"
    tell(s, b"VMA 1 80\n")
    tell(s, b"VMI 1 -10\n")
    assert ask(s, b"VMA?\n") == b"1=80.0000\n"
    assert ask(s, b"VMI?\n") == b"1=-10.0000\n"
    tell(s, b"VMA 1 100\n")  # back up to the rig's limit: allowed
    tell(s, b"VMI 1 -20\n")
    for cmd in (b"VMA 1 100.001\n", b"VMA 1 130\n", b"VMA 1 200\n", b"VMI 1 -20.001\n"):
        s.sendall(cmd)  # beyond the rig's range (or the amplifier's)
        assert ask(s, b"ERR?\n") == b"17\n", cmd
    assert ask(s, b"VMA?\n") == b"1=100.0000\n"
    assert ask(s, b"VMI?\n") == b"1=-20.0000\n"
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


def test_sva_beyond_the_rigs_range_is_refused_from_the_start(gcs):
    """The rig allows -20..100 V: SVA 130 (inside the hardware range) is refused with error 17
    and the output does not move, from the first command on."""
    _, s, bench = gcs
    tell(s, b"ONL 1 1\n")
    for value in (b"130", b"100.01", b"-20.01", b"-30"):
        s.sendall(b"SVA A " + value + b"\n")
        assert ask(s, b"ERR?\n") == b"17\n", value
        assert bench.amp.v_out == 0.0
    tell(s, b"SVA A 100\n")  # the limits themselves are allowed
    assert ask(s, b"VOL? 1\n") == b"1=100.0000\n"
    tell(s, b"SVA A -20\n")
    assert ask(s, b"VOL? 1\n") == b"1=-20.0000\n"


@pytest.mark.parametrize(
    "value", [b"1_0", b"_10", b"1e1_0", b"nan", b"inf", b"-inf", b"0x10", b"1e999", b"10V", b"+"]
)
def test_numbers_are_plain_decimals(gcs, value):
    """Python's float() takes '1_0' as 10 and 'nan'/'inf'; the GCS number syntax does not:
    each is a syntax error (1) and the setpoint does not change."""
    _, s, _ = gcs
    tell(s, b"ONL 1 1\n")
    tell(s, b"SVA A 5\n")
    s.sendall(b"SVA A " + value + b"\n")
    assert ask(s, b"ERR?\n") == b"1\n"
    assert ask(s, b"SVA? A\n") == b"A=5.0000\n"


@pytest.mark.parametrize("value", [b"10", b"+10", b"10.", b".5", b"1e1", b"1.5E+1", b"-0.5"])
def test_plain_decimals_are_accepted(gcs, value):
    _, s, _ = gcs
    tell(s, b"ONL 1 1\n")
    tell(s, b"SVA A " + value + b"\n")
    assert ask(s, b"SVA? A\n") == b"A=%.4f\n" % float(value)


def test_connections_are_bounded(gcs):
    """One thread per client, at most MAX_CONNECTIONS at once: a further client is
    disconnected at once, the others keep working, and a freed slot is reused."""
    srv, s, _ = gcs
    extra = []
    try:
        for _ in range(MAX_CONNECTIONS - 1):  # the fixture holds one
            c = socket.create_connection(("127.0.0.1", srv.port), timeout=2.0)
            assert ask(c, b"ERR?\n") == b"0\n"
            extra.append(c)
        late = socket.create_connection(("127.0.0.1", srv.port), timeout=2.0)
        with late:
            try:
                late.sendall(b"ERR?\n")
                reply = late.recv(100)
            except ConnectionResetError:
                reply = b""
            assert reply == b""  # closed by the server, never answered
        assert ask(s, b"ERR?\n") == b"0\n"
        live = [t for t in threading.enumerate() if t.name == "gcs-conn"]
        assert len(live) <= MAX_CONNECTIONS
        extra.pop().close()
        deadline = time.monotonic() + 5
        while True:  # the server notices the close within its 0.2 s poll
            again = socket.create_connection(("127.0.0.1", srv.port), timeout=2.0)
            try:
                again.sendall(b"ERR?\n")
                reply = again.recv(100)
            except ConnectionResetError:
                reply = b""
            again.close()
            if reply == b"0\n" or time.monotonic() > deadline:
                break
            time.sleep(0.1)
        assert reply == b"0\n"
    finally:
        for c in extra:
            c.close()


def test_a_line_without_end_is_bounded(gcs):
    """A client that sends more than MAX_LINE bytes without a line end is disconnected (the
    simulator does not buffer without limit); the other clients keep working."""
    from labrig.drivers.sim.gcs_server import MAX_LINE

    srv, s, _ = gcs
    c = socket.create_connection(("127.0.0.1", srv.port), timeout=2.0)
    with c:
        try:
            for _ in range(2 * MAX_LINE // 1024 + 2):
                c.sendall(b"X" * 1024)
            reply = c.recv(100)
        except (ConnectionResetError, BrokenPipeError):
            reply = b""
        assert reply == b""  # closed by the server
    assert ask(s, b"ERR?\n") == b"0\n"
