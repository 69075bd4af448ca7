"""labrig import: text and .mat inputs, column choice, scaling, aux channels, bad files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.io import savemat
from typer.testing import CliRunner

from labrig.analysis.load import records_from_run
from labrig.cli import app
from labrig.store import read_run

runner = CliRunner()
REAL = Path(__file__).resolve().parents[1] / "data" / "real" / "yan9a-micromanipulator"


def _csv(path: Path, header: str | None, cols: list[np.ndarray], delim: str = ",") -> Path:
    lines = [header] if header else []
    lines += [delim.join(f"{x:.9g}" for x in row) for row in np.column_stack(cols)]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_header_needs_no_options(tmp_path: Path) -> None:
    t = np.arange(500) / 1000.0
    v = 50 * (1 - np.cos(2 * np.pi * 5 * t))
    s = 9.0 * v + 3.0
    temp = 25 + t
    f = _csv(tmp_path / "my-run 1.csv", "time_s,voltage_V,strain_ue,temperature_C", [t, v, s, temp])
    out = tmp_path / "r.h5"
    res = runner.invoke(app, ["import", str(f), "--out", str(out)])  # temperature: kept unasked
    assert res.exit_code == 0, res.output
    run = read_run(out)
    (entry,) = list(run)
    assert entry.name == "my_run_1"  # named after the file stem, made HDF5-safe
    assert entry.rate_hz == pytest.approx(1000.0)
    np.testing.assert_allclose(entry["strain"], s, rtol=1e-8)
    np.testing.assert_allclose(entry["temperature"], temp, rtol=1e-8)
    assert entry.units["temperature"] == "degC"  # C is degC, the run file's unit
    rec = records_from_run(out)[0]
    assert rec.hold == "linear"  # a measured voltage, not a DAQ's ZOH drive
    np.testing.assert_allclose(rec.voltage_V, v, rtol=1e-8, atol=1e-9)


def test_no_header_indices_rate_and_scale(tmp_path: Path) -> None:
    n = 300
    v = np.linspace(0, 3, n)
    raw = -2.0 * v
    f = _csv(tmp_path / "a.dat", None, [v, np.zeros(n), raw], delim="\t")
    g = _csv(tmp_path / "b.dat", None, [v, np.zeros(n), 1.5 * raw], delim=" ")  # other data
    out = tmp_path / "r.h5"
    args = ["import", str(f), str(g), "--out", str(out), "--voltage", "1", "--strain", "3"]
    args += ["--rate-hz", "200", "--strain-scale", "-1", "--voltage-scale", "10"]
    args += ["--strain-units", "ue"]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    run = read_run(out)
    assert [e.name for e in run] == ["a", "b"]  # in the order given
    e = run["a"]
    np.testing.assert_allclose(e["command_voltage"], 10 * v, rtol=1e-8)
    np.testing.assert_allclose(e["strain"], 2.0 * v, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(e.time, np.arange(n) / 200.0)


def test_mat_file(tmp_path: Path) -> None:
    t = np.arange(100) / 50.0
    f = tmp_path / "m.mat"
    savemat(f, {"t": t[:, None], "V": (5 * t)[:, None], "S": (40 * t)[:, None]})
    out = tmp_path / "r.h5"
    args = ["import", str(f), "--out", str(out), "--time", "t", "--voltage", "V", "--strain", "S"]
    res = runner.invoke(app, [*args, "--strain-units", "ue"])
    assert res.exit_code == 0, res.output
    e = next(iter(read_run(out)))
    np.testing.assert_allclose(e["strain"], 40 * t)
    assert e.rate_hz == pytest.approx(50.0)


@pytest.mark.parametrize(
    ("content", "args", "needle"),
    [
        ("1,2,3\n4,5\n6,7,8\n", ["--voltage", "1", "--strain", "3", "--rate-hz", "10"], ":2:"),
        ("1,2,3\n4,5,6,7\n", ["--voltage", "1", "--strain", "3", "--rate-hz", "10"], ":2:"),
        ("1,2\n3,abc\n", ["--voltage", "1", "--strain", "2", "--rate-hz", "10"], "not a number"),
        ("1,2\n3,4\n", ["--voltage", "1", "--strain", "2"], "--rate-hz"),
        ("1,2\n3,4\n", ["--rate-hz", "10"], "which column is the voltage"),
        ("1,2\n3,4\n", ["--voltage", "1", "--strain", "9", "--rate-hz", "10"], "'9'"),
        ("time_s,voltage_V,strain_ue\n0,1,2\n0,1,2\n", [], "does not increase"),
        ("", ["--voltage", "1", "--strain", "2", "--rate-hz", "10"], "no data"),
        (b"\x00\x01\x02junk", ["--voltage", "1", "--strain", "2", "--rate-hz", "10"], "binary"),
        ("x;y\n1;2\n3;4\n".encode("utf-16"), ["--voltage", "x", "--strain", "y"], "--rate-hz"),
    ],
)
def test_bad_files_clear_error_nothing_written(tmp_path: Path, content, args, needle) -> None:
    # (a good file read before a bad one: tests/importers/test_import_safety.py)
    bad = tmp_path / "bad.csv"
    bad.write_bytes(content if isinstance(content, bytes) else content.encode())
    out = tmp_path / "r.h5"
    res = runner.invoke(app, ["import", str(bad), "--out", str(out), *args])
    assert res.exit_code == 2, res.output
    assert needle in res.output and "bad.csv" in res.output
    assert "Traceback" not in res.output
    assert not out.exists()


def test_real_micromanipulator_data(tmp_path: Path) -> None:
    out = tmp_path / "yan.h5"
    args = ["import", str(REAL / "Model_Vi_Do.dat"), str(REAL / "Test_Vi_Do_Di.dat")]
    args += ["--out", str(out), "--voltage", "1", "--strain", "5", "--rate-hz", "200"]
    args += ["--strain-scale", "-1", "--strain-units", "raw"]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    recs = records_from_run(out)
    assert [r.name for r in recs] == ["Model_Vi_Do", "Test_Vi_Do_Di"]
    assert recs[0].voltage_V.size == 8027 and recs[1].voltage_V.size == 14155
    assert recs[0].voltage_V.min() >= 0 and recs[0].voltage_V.max() <= 3.7


SMART = Path(__file__).resolve().parents[1] / "data" / "real" / "chandratue-SmartHysteresis"


def test_real_smart_hysteresis_record_reads_as_written(tmp_path: Path) -> None:
    """The headerless SmartHysteresis rows (an empty first field, then time s, displacement um,
    voltage V) import with column numbers; the numbers are the file's, independently parsed."""
    src = SMART / "hysteresis_v_150_1hz_2cycles_1khz.csv"
    out = tmp_path / "smart.h5"
    args = ["import", str(src), "--out", str(out), "--time", "2", "--voltage", "4"]
    args += ["--strain", "3", "--strain-units", "raw"]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    (rec,) = records_from_run(out)
    rows = [line.split(",") for line in src.read_text().splitlines()]
    assert len(rows) == 2000 and all(r[0] == "" and len(r) == 4 for r in rows)
    np.testing.assert_array_equal(rec.voltage_V, [float(r[3]) for r in rows])
    np.testing.assert_array_equal(rec.strain_ue, [float(r[2]) for r in rows])
    assert rec.rate_hz == pytest.approx(1000.0, rel=1e-4)
    # a displacement in um is not a strain: refused without a stack length or raw
    bad = runner.invoke(app, [*args[:-2], "--strain-units", "um", "--overwrite"])
    assert bad.exit_code == 2 and "stack-length-mm" in bad.output
