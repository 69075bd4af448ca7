"""Real hardware without the hardware: ``labrig drivers`` lists what is installed, ``labrig check
--rig`` loads a rig's drivers without opening anything, and every driver failure (a missing
package, NI's runtime missing, the device not found, the device lost during a run) exits 3
naming the device and the operation, with no traceback and no exception class name, and says
"DAQ stop failed" at most once.

The real ``nidaqmx`` is not installed here; tests/data/fake_nidaqmx stands in for it (it imports
like the real package; its calls fail as without NI's runtime, or as LABRIG_FAKE_NIDAQMX
says)."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest
from typer.testing import CliRunner

from labrig.cli import app

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[2]
STAND_IN = ROOT / "tests" / "data" / "fake_nidaqmx"
LAB_RIG = ROOT / "experiments" / "rigs" / "lab-example.yaml"
PROTOCOL = ROOT / "experiments" / "paper.yaml"
#: what a message must not show: a traceback, or the class of the exception behind it
LEAKS = ("Traceback", "DaqNotFoundError", "DaqError", "ModuleNotFoundError", "Exception")

ONE_SINE = "name: one\nrate_hz: 1000\nsteps:\n  - kind: sine\n    amplitude_V: 10\n"
ONE_SINE += "    frequency_hz: 5\n    cycles: 2\n"


@pytest.fixture
def stand_in(monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    """``labrig ARGS`` in this process (typer's CliRunner) in ``tmp_path``, with the stand-in
    nidaqmx importable as on a child's path and LABRIG_FAKE_NIDAQMX at ``mode``; the stand-in
    forgotten after (the other tests see nidaqmx missing, as it is here)."""
    monkeypatch.syspath_prepend(str(STAND_IN))
    monkeypatch.chdir(tmp_path)

    def invoke(*args: object, mode: str):
        monkeypatch.setenv("LABRIG_FAKE_NIDAQMX", mode)
        # as in a labrig process, where no handler is configured: log records reach stderr
        # through logging's last resort (pytest's capturing handlers set aside meanwhile)
        root = logging.getLogger()
        handlers = root.handlers[:]
        root.handlers.clear()
        try:
            return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "160"})
        finally:
            root.handlers[:] = handlers

    try:
        yield invoke
    finally:
        for name in [m for m in sys.modules if m == "nidaqmx" or m.startswith("nidaqmx.")]:
            del sys.modules[name]


def assert_no_leak(text: str) -> None:
    for leak in LEAKS:
        assert leak not in text, text


def sim_backed_rig(tmp_path: Path) -> Path:
    """The lab rig with its amplifier and conditioner on the simulated bench (so a run gets as
    far as the DAQ's playback), its DAQ the NI driver."""
    text = LAB_RIG.read_text()
    text = text.replace("url: /dev/ttyUSB0 ", "url: sim ").replace(
        "transport: rtu", "transport: tcp"
    )
    text = text.replace("address: /dev/ttyUSB1 ", "address: sim ")
    assert "url: sim" in text and "address: sim" in text
    rig = tmp_path / "ni-sim.yaml"
    rig.write_text(text)
    return rig


def test_drivers_lists_roles_and_packages() -> None:
    res = CliRunner().invoke(app, ["drivers", "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["entry_point_group"] == "labrig.drivers"
    by_name = {d["name"]: d for d in doc["drivers"]}
    assert {n: d["role"] for n, d in by_name.items()} == {
        "nidaqmx": "daq",
        "sim_daq": "daq",
        "pi_e503": "amplifier",
        "strain_modbus": "conditioner",
    }
    (ni,) = by_name["nidaqmx"]["packages"]
    assert (ni["distribution"], ni["version"], ni["install"]) == (
        "nidaqmx",
        None,  # not installed here
        "pip install 'labrig[nidaq]'",
    )
    assert not by_name["nidaqmx"]["ok"] and "ni.com" in by_name["nidaqmx"]["runtime"]
    (serial,) = by_name["pi_e503"]["packages"]
    assert serial["version"] == metadata.version("pyserial")
    (modbus,) = by_name["strain_modbus"]["packages"]
    assert modbus["version"] == metadata.version("pymodbus")
    assert all(d["provided_by"].startswith("labrig ") for d in doc["drivers"])
    text = CliRunner().invoke(app, ["drivers"])
    assert text.exit_code == 0
    assert "daq: nidaqmx" in text.stdout and "nidaqmx missing (pip install 'labrig[nidaq]')" in (
        text.stdout
    )
    assert "4 drivers (3 usable" in text.stderr


def test_check_loads_the_drivers_and_opens_nothing(stand_in) -> None:
    """With the stand-in (every call into NI's driver would fail) and serial ports that do not
    exist, check still passes: it imports and validates, and calls nothing. (In-process, with
    ``--json`` then as text: neither is about the process.)"""
    args = ["check", PROTOCOL, "--rig", LAB_RIG]
    res = stand_in(*args, "--json", mode="no_runtime")
    assert res.exit_code == 0, (res.stderr, repr(res.exception))
    doc = json.loads(res.stdout)
    drivers = {d["role"]: d for d in doc["drivers"]}
    assert [drivers[r]["name"] for r in ("daq", "amplifier", "conditioner")] == [
        "nidaqmx",
        "pi_e503",
        "strain_modbus",
    ]
    assert drivers["daq"]["packages"][0]["version"] == "0.0.0+labrig.stand-in"
    assert doc["rig_name"] == "lab-p888" and doc["simulated"] is False
    text = stand_in(*args, mode="no_runtime")
    assert text.exit_code == 0, text.stderr
    assert "loaded, no device opened" in text.stdout
    assert "daq: nidaqmx (labrig" in text.stdout


def test_check_without_the_package_exits_3() -> None:
    res = CliRunner().invoke(app, ["check", str(PROTOCOL), "--rig", str(LAB_RIG)])
    assert res.exit_code == 3, res.output
    msg = " ".join(res.stderr.split())
    assert "daq (nidaqmx driver): load driver failed" in msg
    assert "the Python package 'nidaqmx' is not installed (pip install 'labrig[nidaq]')" in msg
    assert_no_leak(res.output)


#: ``labrig check`` then ``labrig run`` in one child with pymodbus blocked (typer's CliRunner)
PYMODBUS_BLOCKED = """
import json, sys
sys.modules["pymodbus"] = None
from typer.testing import CliRunner
from labrig.cli import app
commands = (["check", "one.yaml"], ["run", "one.yaml", "--out", "r.h5"])
done = [CliRunner().invoke(app, a) for a in commands]
print(json.dumps([(r.exit_code, r.output, r.stderr, repr(r.exception)) for r in done]))
"""


def test_a_package_missing_at_driver_import_exits_3(tmp_path: Path) -> None:
    """pymodbus blocked (``sys.modules["pymodbus"] = None``) in a new interpreter: the
    conditioner's driver module does not import; check and run say so as a device fault
    before anything is opened. (Both commands from one child: the block is on the process, the
    exit codes and messages are the commands'.)"""
    (tmp_path / "one.yaml").write_text(ONE_SINE)
    child = subprocess.run(
        [sys.executable, "-c", PYMODBUS_BLOCKED],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=60,
    )
    assert child.returncode == 0, child.stderr
    for code, output, stderr, exc in json.loads(child.stdout):
        assert code == 3 and exc.startswith("SystemExit("), (stderr, exc)
        msg = " ".join(stderr.split())
        assert "conditioner (strain_modbus driver): load driver failed" in msg, msg
        assert "'pymodbus' is not installed (pip install 'pymodbus>=3.16,<3.17')" in msg
        assert_no_leak(output)
    assert not (tmp_path / "r.h5").exists()


@pytest.mark.parametrize(
    ("mode", "detail"),
    [
        ("no_runtime", "NI's NI-DAQmx runtime is not installed"),
        ("no_device", "device 'Dev1' not found (devices: Dev7)"),
    ],
)
def test_run_without_runtime_or_device_exits_3(
    tmp_path: Path, stand_in, mode: str, detail: str
) -> None:
    """In-process (the exit code and the message are the command's, not the process's)."""
    (tmp_path / "one.yaml").write_text(ONE_SINE)
    res = stand_in("run", "one.yaml", "--rig", LAB_RIG, "--out", "r.h5", mode=mode)
    assert res.exit_code == 3, res.output
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    msg = " ".join(res.stderr.split())
    assert f"daq (NI-DAQmx Dev1): open failed: {detail}" in msg, msg
    assert_no_leak(res.output)
    assert "DAQ stop failed" not in res.stderr  # nothing was energised, nothing to stop
    assert not (tmp_path / "r.h5").exists()


def test_a_device_lost_in_the_run_exits_3_and_says_stop_failed_once(
    tmp_path: Path, stand_in
) -> None:
    """The device answers at open, then every task fails: the run fails at its first playback,
    the ramp to 0 V falls back to the amplifier's setpoint, the file records the failure.
    (In-process: the exit code and the messages are the command's.)"""
    rig = sim_backed_rig(tmp_path)
    (tmp_path / "one.yaml").write_text(ONE_SINE)
    res = stand_in("run", "one.yaml", "--rig", rig, "--out", "r.h5", mode="unplugged")
    assert res.exit_code == 3, res.output
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    msg = " ".join(res.stderr.split())
    assert "run failed: daq (NI-DAQmx Dev1): play failed: Device cannot be accessed." in msg
    assert "(DAQmx status -201003)" in msg
    assert res.stderr.count("DAQ stop failed") == 1, res.stderr
    assert "ramping the amplifier's setpoint" in msg
    assert_no_leak(res.output)
    info = CliRunner().invoke(app, ["info", str(tmp_path / "r.h5"), "--json"])
    assert info.exit_code == 0, info.output
    assert json.loads(info.stdout)["status"] == "failed"


def test_failure_text_names_no_class() -> None:
    """The words of a failure: the runtime missing in words, else the driver's first line with
    its status code, never the exception's class."""
    sys.path.insert(0, str(STAND_IN))
    try:
        import nidaqmx
        from labrig.drivers.ni_daqmx import failure_text

        assert "install NI-DAQmx from ni.com" in failure_text(
            nidaqmx.errors.DaqNotFoundError("Could not find an installation"), nidaqmx
        )
        text = failure_text(
            nidaqmx.errors.DaqError("Device identifier is invalid.", -200220), nidaqmx
        )
        assert text == "Device identifier is invalid. (DAQmx status -200220)"
        assert failure_text(RuntimeError(""), nidaqmx) == (
            "the NI-DAQmx driver failed without a message"
        )
    finally:
        sys.path.remove(str(STAND_IN))
        for name in [m for m in sys.modules if m == "nidaqmx" or m.startswith("nidaqmx.")]:
            del sys.modules[name]
