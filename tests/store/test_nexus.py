"""A run file is valid NeXus for a NeXus validator (nexusformat: the base classes, with no
errors) and its default plot resolves: root @default -> entry @default -> NXdata with @signal
strain and @axes time."""

from __future__ import annotations

from pathlib import Path

import h5py
import pytest
import yaml
from typer.testing import CliRunner

from labrig.cli import app

nexus = pytest.importorskip("nexusformat.nexus", reason="the test extra installs nexusformat")

pytestmark = pytest.mark.timeout(180)


@pytest.fixture(scope="module")
def run_file(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("nexus")
    proto = d / "p.yaml"
    proto.write_text(
        yaml.safe_dump(
            {
                "name": "nexus test",
                "rate_hz": 1000,
                "steps": [
                    {"kind": "sine", "amplitude_V": 80, "frequency_hz": 5, "cycles": 2},
                    {"kind": "hold", "voltage_V": 20, "duration_s": 0.3},
                ],
            }
        )
    )
    out = d / "run.h5"
    args = ["run", str(proto), "--out", str(out), "--seed", "1", "--operator", "alice"]
    args += ["--sample", "P-888 #3", "--meta", "actuator_model=P-888.51"]
    args += ["--meta", "actuator_serial=123"]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    return out


def test_the_validator_finds_no_errors(run_file: Path, capsys):
    from nexusformat.nexus.validate import validate_file

    _warnings, errors = validate_file(str(run_file))
    report = capsys.readouterr().out
    assert errors == 0, report
    # it did walk our groups (the NXuser and NXsample of each entry)
    assert "NXuser: /sine_80V_5Hz/user" in report


def test_nexusformat_resolves_the_default_plot(run_file: Path):
    root = nexus.nxload(str(run_file))
    try:
        assert root.nxclass == "NXroot"
        data = root.plottable_data  # root @default -> entry @default -> NXdata
        assert data is not None and data.nxclass == "NXdata"
        assert data.nxpath == "/sine_80V_5Hz/data"
        assert data.nxsignal.nxname == "strain"
        assert [a.nxname for a in data.nxaxes] == ["time"]
        assert data.nxsignal.shape == data.nxaxes[0].shape and data.nxsignal.shape[0] > 100
        entry = root["sine_80V_5Hz"]
        assert entry.nxclass == "NXentry"
        assert entry["definition"].nxvalue == "NXlabrig"
        assert entry["program_name"].nxvalue == "labrig"
        assert entry["user/name"].nxvalue == "alice"
        assert entry["sample/name"].nxvalue == "P-888 #3"
        assert entry["sample/serial_number"].nxvalue == "123"
        assert root["run/metadata/actuator_model"].nxvalue == "P-888.51"
        # every entry has its own default plot
        for name in [n for n in root if n != "run"]:
            d = root[name].plottable_data
            assert d.nxsignal.nxname == "strain" and d.nxaxes[0].nxname == "time"
    finally:
        root.nxfile.close()


def test_a_missing_default_is_caught(run_file: Path, tmp_path: Path):
    """The check above can fail: without @default the plot does not resolve to our NXdata."""
    broken = tmp_path / "nodefault.h5"
    broken.write_bytes(run_file.read_bytes())
    with h5py.File(broken, "a") as f:
        del f.attrs["default"]
        for name in f:
            if "default" in f[name].attrs:
                del f[name].attrs["default"]
        del f["sine_80V_5Hz/data"].attrs["signal"]
    root = nexus.nxload(str(broken))
    try:
        d = root.plottable_data
        assert d is None or d.nxpath != "/sine_80V_5Hz/data" or d.nxsignal is None
    finally:
        root.nxfile.close()
