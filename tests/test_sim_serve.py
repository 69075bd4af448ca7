"""``labrig sim serve``: the simulators run standalone and real clients reach them."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest
import serial
from pymodbus.client import ModbusTcpClient

pytestmark = pytest.mark.timeout(60)


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_serve_prints_addresses_and_answers_until_stopped(stop):
    code = "from labrig.drivers.sim.serve import serve; serve(None)"
    proc = subprocess.Popen(
        [sys.executable, "-c", code],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # as from a terminal: a shell starts background jobs (a CI script run with `&`) with
        # SIGINT ignored, and Python then installs no KeyboardInterrupt handler, so Ctrl-C would
        # never arrive (the test hung in such runs)
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        lines = []
        deadline = time.monotonic() + 30
        while not any("Ctrl-C" in x for x in lines):
            assert time.monotonic() < deadline, lines
            line = proc.stdout.readline()
            assert line, proc.stderr.read()
            lines.append(line)
        text = "".join(lines)
        gcs = next(w for x in lines if "GCS" in x for w in x.split() if w.startswith("socket://"))
        tcp = next(x for x in lines if "Modbus TCP" in x).split()[-3]
        assert "Modbus RTU" in text
        with serial.serial_for_url(gcs, timeout=2) as s:
            s.write(b"ONL 1 1\nSVA A 10\n")
            time.sleep(0.3)  # the bench clock runs in real time
            s.write(b"VOL? 1\n")
            assert s.read_until(b"\n") == b"1=10.0000\n"
        host, port = tcp.rsplit(":", 1)
        client = ModbusTcpClient(host, port=int(port), timeout=2, retries=0)
        assert client.read_input_registers(0, count=1, device_id=1).registers == [0x3840]
        client.close()
    finally:
        proc.send_signal(stop)
        try:
            out, _ = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
    assert "stopping the simulators" in out  # stopped cleanly, not killed by the signal
    assert proc.returncode == 0
