"""Bad input never touches hardware: `labrig run` / `labrig check` on the bad-file corpora.

Two corpora, each with a manifest of where labrig must point (file:line, field, message):

- ``tests/data/bad/`` (protocol files; manifest ``EXPECTED.yaml``; owned by the protocol work),
- ``tests/data/bad_rigs/`` (rig files; manifest ``EXPECTED.yaml``; entries with an ``xfail``
  key are known bugs, run as strict xfails).

Every file must give exit code 2, print ``FILE:LINE:`` and the field, no traceback, write no
run file, and never open the rig: the CLI runs in-process (typer's CliRunner) with
``labrig.runner.execute.open_rig``, ``labrig.runner.rigfile.open_rig``, the simulators' start and
the transports' constructors replaced by functions that record the call and raise. A few files
also go through a real ``labrig`` process, to see exactly what a person sees on stderr.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from labrig.runner import execute as runner
from labrig.runner import rigfile

from helpers import invoke as run_cli

ROOT = Path(__file__).resolve().parents[2]
BAD_PROTOCOLS = ROOT / "tests" / "data" / "bad"
BAD_RIGS = ROOT / "tests" / "data" / "bad_rigs"
EXPECTED_PROTOCOLS: dict = yaml.safe_load((BAD_PROTOCOLS / "EXPECTED.yaml").read_text())
EXPECTED_RIGS: dict = yaml.safe_load((BAD_RIGS / "EXPECTED.yaml").read_text())
GOOD_PROTOCOL = ROOT / "experiments" / "envelope.yaml"

pytestmark = pytest.mark.timeout(120)


class DeviceOpenedError(AssertionError):
    pass


@pytest.fixture
def no_hardware(monkeypatch) -> list:
    """Every way to a device raises (and is recorded): opening a rig, starting the
    simulators, opening a serial/socket link or a Modbus client."""
    import serial
    from labrig.drivers import strain_modbus
    from labrig.drivers.sim import serve

    calls: list = []

    def refuse(what):
        def f(*args, **kwargs):
            calls.append((what, args))
            raise DeviceOpenedError(f"{what} was called for a bad input file")

        return f

    monkeypatch.setattr(runner, "open_rig", refuse("labrig.runner.execute.open_rig"))
    monkeypatch.setattr(rigfile, "open_rig", refuse("labrig.runner.rigfile.open_rig"))
    monkeypatch.setattr(serve.Simulators, "start", refuse("Simulators.start"))
    monkeypatch.setattr(serial, "serial_for_url", refuse("serial.serial_for_url"))
    monkeypatch.setattr(strain_modbus, "ModbusTcpClient", refuse("ModbusTcpClient"))
    monkeypatch.setattr(strain_modbus, "ModbusSerialClient", refuse("ModbusSerialClient"))
    return calls


def invoke(args: list[str]):
    return run_cli(*args, columns=None)


def assert_refused(res, calls: list, out_dir: Path | None = None) -> str:
    """Exit 2, a message and no traceback, nothing opened, nothing written."""
    text = res.output
    assert calls == [], f"a device was opened: {calls}"
    assert not isinstance(res.exception, DeviceOpenedError)
    # SystemExit(2) from typer.Exit; anything else escaped the `friendly` wrapper
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code == 2, text
    assert "Traceback" not in text
    assert text.startswith("error: "), text
    if out_dir is not None:
        assert list(out_dir.iterdir()) == [], "a run file was written for a bad input"
    return text


def _params(expected: dict) -> list:
    out = []
    for name in sorted(expected):
        why = expected[name].get("xfail")
        marks = [pytest.mark.xfail(reason=why, strict=True)] if why else []
        out.append(pytest.param(name, marks=marks, id=name))
    return out


def test_rig_corpus_is_complete():
    files = {p.name for p in BAD_RIGS.iterdir()} - {"EXPECTED.yaml"}
    assert files == set(EXPECTED_RIGS), "every bad rig file needs an EXPECTED.yaml entry and back"
    assert len(files) >= 10
    for name, exp in EXPECTED_RIGS.items():
        assert {"line", "field", "message"} <= set(exp), name


@pytest.mark.parametrize("name", _params(EXPECTED_PROTOCOLS))
def test_run_refuses_bad_protocol(name, tmp_path, no_hardware):
    exp = EXPECTED_PROTOCOLS[name]
    path = BAD_PROTOCOLS / name
    out_dir = tmp_path / "runs"
    out_dir.mkdir()
    res = invoke(["run", str(path), "--out", str(out_dir / "run.h5")])
    text = assert_refused(res, no_hardware, out_dir)
    assert f"{path}:{exp['line']}:" in text
    if exp["field"]:
        assert f"[{exp['field']}" in text
    assert exp["message"].lower() in text.lower()


@pytest.mark.parametrize("command", ["run", "check"])
@pytest.mark.parametrize("name", _params(EXPECTED_RIGS))
def test_bad_rig_is_refused_at_its_line(name, command, tmp_path, no_hardware):
    exp = EXPECTED_RIGS[name]
    path = BAD_RIGS / name
    out_dir = tmp_path / "runs"
    out_dir.mkdir()
    args = [command, str(GOOD_PROTOCOL), "--rig", str(path)]
    if command == "run":
        args += ["--out", str(out_dir / "run.h5")]
    res = invoke(args)
    text = assert_refused(res, no_hardware, out_dir)
    assert f"{path}:{exp['line']}:" in text, text
    if exp["field"]:
        assert f"[{exp['field']}" in text, text
    assert exp["message"].lower() in text.lower(), text


def test_bad_rig_named_by_the_protocol(tmp_path, no_hardware):
    """The rig can come from the protocol's `rig:` key; the error names the rig file."""
    rig = tmp_path / "rigs" / "vmin_ge_vmax.yaml"
    rig.parent.mkdir()
    rig.write_bytes((BAD_RIGS / "vmin_ge_vmax.yaml").read_bytes())
    proto = tmp_path / "p.yaml"
    proto.write_text(
        "name: p\nrig: rigs/vmin_ge_vmax.yaml\nrate_hz: 1000\n"
        "steps:\n  - kind: hold\n    voltage_V: 10\n    duration_s: 1\n"
    )
    out_dir = tmp_path / "runs"
    out_dir.mkdir()
    res = invoke(["run", str(proto), "--out", str(out_dir / "run.h5")])
    text = assert_refused(res, no_hardware, out_dir)
    line = EXPECTED_RIGS["vmin_ge_vmax.yaml"]["line"]
    assert f"{rig}:{line}: [limits]" in text


def test_sine_too_fast_for_the_current_limit_is_refused_by_check_and_run(tmp_path, no_hardware):
    proto = tmp_path / "fast.yaml"
    proto.write_text(
        "name: too fast\nrate_hz: 5000\nsteps:\n"
        "  - kind: sine\n    amplitude_V: 100\n    frequency_hz: 80\n    cycles: 10\n"
    )
    for args in (["check", str(proto)], ["run", str(proto), "--out", str(tmp_path / "r.h5")]):
        res = invoke(args)
        text = assert_refused(res, no_hardware)
        # file:line and field of the frequency, the current it needs, what the amplifier gives
        # and what would be valid
        assert f"{proto}:6: [steps[0].frequency_hz] 100 V at 80 Hz needs 0.26 A peak" in text
        assert "the amplifier gives 0.18 A" in text
        assert "max frequency at 100 V is 56.1 Hz" in text
        assert "max amplitude at 80 Hz is 70.2 V" in text
        assert "average limit is 0.12 A" in text
    assert not (tmp_path / "r.h5").exists()


def test_what_a_person_sees(tmp_path):
    """Real processes (the real entry point, real stderr): one bad protocol, two bad rigs."""
    exe = Path(sys.executable).parent / "labrig"
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "labrig.cli"]
    cases = [
        (BAD_PROTOCOLS / "sine_too_fast_for_current.yaml", None, EXPECTED_PROTOCOLS),
        (GOOD_PROTOCOL, BAD_RIGS / "binary_junk.yaml", EXPECTED_RIGS),
        (GOOD_PROTOCOL, BAD_RIGS / "syntax_tab_indent.yaml", EXPECTED_RIGS),
    ]
    procs = []
    for i, (proto, rig, expected) in enumerate(cases):
        out = tmp_path / f"run{i}.h5"
        args = [*cmd, "run", str(proto), "--out", str(out)] + (["--rig", str(rig)] if rig else [])
        p = subprocess.Popen(args, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        bad = rig or proto
        procs.append((p, out, bad, expected[bad.name]["line"]))
    for p, out, bad, line in procs:
        stdout, stderr = p.communicate(timeout=60)
        err = stderr.decode()
        assert p.returncode == 2, err
        assert "Traceback" not in err and stdout == b""
        assert err.startswith(f"error: {bad}:{line}:"), err
        assert not out.exists()
