"""``labrig sim serve``: the simulators run standalone, real clients reach them, the rig's
limits hold from the first command, and a port in use is a clear error."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import serial
import yaml
from pymodbus.client import ModbusTcpClient

from labrig.runner.rigfile import DEFAULT_RIG_YAML

from helpers import invoke

pytestmark = pytest.mark.timeout(60)


def labrig_cmd() -> list[str]:
    exe = Path(sys.executable).parent / "labrig"
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "labrig.cli"]


def start_serve() -> tuple[subprocess.Popen, list[str]]:
    """``serve(None)`` in a subprocess; its lines up to "Press Ctrl-C"."""
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
    lines: list[str] = []
    deadline = time.monotonic() + 30
    while not any("Ctrl-C" in x for x in lines):
        if time.monotonic() > deadline:
            proc.kill()
            raise AssertionError(lines)
        line = proc.stdout.readline()
        if not line:
            proc.kill()
            raise AssertionError(proc.stderr.read())
        lines.append(line)
    return proc, lines


def stop_serve(proc: subprocess.Popen, sig: int = signal.SIGTERM) -> str:
    proc.send_signal(sig)
    try:
        out, _ = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    return out


def gcs_url(lines: list[str]) -> str:
    return next(w for x in lines if "GCS" in x for w in x.split() if w.startswith("socket://"))


def ask(s: serial.SerialBase, line: bytes) -> bytes:
    s.write(line)
    return s.read_until(b"\n")


def check_the_rigs_limits(lines: list[str], s: serial.SerialBase) -> None:
    """The default rig allows -20..100 V: the standalone amplifier starts with VMI/VMA there
    (not at its hardware -30..130 V) and refuses SVA beyond them, before any labrig driver
    has configured it (the first commands of a new server)."""
    assert "-20 to 100 V" in "".join(lines)
    assert ask(s, b"VMA? 1\n") == b"1=100.0000\n"
    assert ask(s, b"VMI? 1\n") == b"1=-20.0000\n"
    s.write(b"ONL 1 1\n")
    assert ask(s, b"ERR?\n") == b"0\n"
    for cmd, err in ((b"SVA A 130\n", b"17\n"), (b"VMA 1 130\n", b"17\n")):
        s.write(cmd)
        assert ask(s, b"ERR?\n") == err, cmd
    s.write(b"SVA A 1_0\n")  # not a number in GCS (Python's float() would say 10)
    assert ask(s, b"ERR?\n") == b"1\n"
    time.sleep(0.2)
    assert ask(s, b"VOL? 1\n") == b"1=0.0000\n"  # the output never moved
    assert ask(s, b"SVA? A\n") == b"A=0.0000\n"


@pytest.mark.parametrize(
    "stop",
    # the default tier stops it by Ctrl-C; the other three signals take the same path (one
    # handler, the same exception) and run in the slow tier, and in the default tier's
    # in-process test below
    [
        signal.SIGINT,
        pytest.param(signal.SIGTERM, marks=pytest.mark.slow),
        pytest.param(signal.SIGHUP, marks=pytest.mark.slow),
        pytest.param(signal.SIGQUIT, marks=pytest.mark.slow),
    ],
    ids=["ctrl-c", "sigterm", "sighup", "sigquit"],
)
def test_serve_prints_addresses_and_answers_until_stopped(stop):
    """The server holds the rig's limits from its first command, answers real clients, and
    stops cleanly on the signal (one server for all three: starting one, numba's kernels
    loaded, costs more than its checks).

    Fast equivalent in the default tier: tests/drivers/test_sim_serve.py::test_serve_stops_on_every_stop_signal_as_on_ctrl_c
    """  # noqa: E501
    proc, lines = start_serve()
    try:
        text = "".join(lines)
        tcp = next(x for x in lines if "Modbus TCP" in x).split()[-3]
        assert "Modbus RTU" in text
        with serial.serial_for_url(gcs_url(lines), timeout=2) as s:
            check_the_rigs_limits(lines, s)
            s.write(b"ONL 1 1\nSVA A 10\n")
            time.sleep(0.3)  # the bench clock runs in real time
            s.write(b"VOL? 1\n")
            assert s.read_until(b"\n") == b"1=10.0000\n"
        host, port = tcp.rsplit(":", 1)
        client = ModbusTcpClient(host, port=int(port), timeout=2, retries=0)
        assert client.read_input_registers(0, count=1, device_id=1).registers == [0x3840]
        client.close()
    finally:
        out = stop_serve(proc, stop)
    assert "stopping the simulators" in out  # stopped cleanly, not killed by the signal
    assert proc.returncode == 0


class _StubSimulators:
    """Stands in for the servers in :func:`test_serve_stops_on_every_stop_signal_as_on_ctrl_c`."""

    stopped = 0

    def __init__(self, *args, **kwargs):
        pass

    def start(self):
        return self

    def run_clock(self):
        pass

    def stop(self):
        type(self).stopped += 1


@pytest.mark.parametrize(
    "stop", [signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT], ids=["sigterm", "sighup", "sigquit"]
)
def test_serve_stops_on_every_stop_signal_as_on_ctrl_c(stop, monkeypatch, capsys):
    """``serve``'s own path, in-process with its servers stood in for: a SIGTERM, SIGHUP or
    SIGQUIT while it serves is caught as the Ctrl-C of the test above (the process's, in the
    default tier): it says it stops, stops the simulators and returns (exit 0)."""
    import labrig.drivers.sim.serve as serve_mod

    def addresses(name, sims):
        # the signal's handler is serve's (never the default, which would end this process)
        assert signal.getsignal(stop) not in (signal.SIG_DFL, signal.SIG_IGN, None)
        os.kill(os.getpid(), stop)
        time.sleep(5)  # the handler raises here
        raise AssertionError("the signal was not raised in serve")

    monkeypatch.setattr(serve_mod, "kernels", lambda: None)
    monkeypatch.setattr(serve_mod, "Simulators", _StubSimulators)
    monkeypatch.setattr(serve_mod, "_print_addresses", addresses)
    monkeypatch.setattr(_StubSimulators, "stopped", 0)
    before = signal.getsignal(stop)
    serve_mod.serve(None)  # returns: the signal did not escape as an exception
    assert "stopping the simulators" in capsys.readouterr().out
    assert _StubSimulators.stopped == 1
    assert signal.getsignal(stop) == before


@pytest.fixture
def busy_port():
    """A port on 127.0.0.1 that something else listens on."""
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    yield s.getsockname()[1]
    s.close()


@pytest.mark.parametrize(
    ("command", "kind"),
    # each command and each port in the default tier; the other two pairs in the slow tier
    [
        ("sim-serve", "modbus_tcp_port"),
        ("run", "gcs_port"),
        pytest.param("sim-serve", "gcs_port", marks=pytest.mark.slow),
        pytest.param("run", "modbus_tcp_port", marks=pytest.mark.slow),
    ],
    ids=["sim-serve-modbus_tcp_port", "run-gcs_port", "sim-serve-gcs_port", "run-modbus_tcp_port"],
)
def test_a_fixed_port_in_use_is_exit_2_naming_the_field(tmp_path, busy_port, kind, command):
    data = yaml.safe_load(DEFAULT_RIG_YAML)
    data["simulator"] = {kind: busy_port}
    rig = tmp_path / "rig.yaml"
    rig.write_text(yaml.safe_dump(data))
    if command == "sim-serve":
        args = ["sim", "serve", "--rig", str(rig)]
    else:
        proto = tmp_path / "p.yaml"
        proto.write_text(
            "name: p\nrate_hz: 1000\nsteps:\n  - {kind: hold, voltage_V: 5, duration_s: 0.2}\n"
        )
        args = ["run", str(proto), "--rig", str(rig), "--out", str(tmp_path / "run.h5")]
    # in-process (the message and the exit code are the command's, not the process's; the
    # process of ``sim serve`` is the tests' above)
    res = invoke(*args)
    assert res.exit_code == 2, res.output
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert "Traceback" not in res.output
    assert str(rig) in res.stderr and f"simulator.{kind}" in res.stderr
    assert f"127.0.0.1:{busy_port}" in res.stderr and "in use" in res.stderr
    assert not (tmp_path / "run.h5").exists()
