"""What ``labrig import`` refuses to guess: a strain whose unit nobody stated, MATLAB logical
values taken for a signal, and the same data given twice (two entries of one record, and a
leave-one-entry-out score that has seen the entry it scores)."""

from __future__ import annotations

import importlib.util
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.io import savemat

from labrig.store import read_run

from helpers import DATA, invoke

EXAMPLES = DATA / "import"
_spec = importlib.util.spec_from_file_location("make_examples", EXAMPLES / "make_examples.py")
assert _spec and _spec.loader
examples = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(examples)


def _csv(path: Path, header: str | None, n: int = 100, shift: float = 0.0) -> Path:
    t = np.arange(n) / 100.0
    v = 50.0 + 40.0 * np.sin(2 * np.pi * t) + shift
    lines = [header] if header else []
    lines += [f"{a:.6g},{b:.6g},{9 * b:.6g}" for a, b in zip(t, v, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    return path


def run_import(*args: object):
    return invoke("import", *args, columns=None)


# -- a strain without a unit ------------------------------------------------------------------


def test_a_strain_without_a_unit_is_refused_naming_the_column_and_the_option(tmp_path: Path):
    f = _csv(tmp_path / "raw.csv", None)
    out = tmp_path / "r.h5"
    res = run_import(f, "--out", out, "--time", "1", "--voltage", "2", "--strain", "3")
    assert res.exit_code == 2, res.output
    assert "raw.csv: [column 3] the strain states no unit" in res.stderr
    assert "--strain-units" in res.stderr and "Traceback" not in res.output
    assert not out.exists()


@pytest.mark.parametrize(
    ("header", "options", "unit"),
    [
        (None, ["--strain-units", "ue"], "ue"),  # stated on the command line
        (None, ["--strain-units", "raw"], "raw"),  # kept as numbers, labelled raw
        ("time_s,voltage_V,strain_ue", [], "ue"),  # stated by the header
        ("time_s,voltage_V,strain [raw]", [], "raw"),
    ],
)
def test_a_stated_strain_unit_is_the_one_stored(tmp_path: Path, header, options, unit):
    f = _csv(tmp_path / "x.csv", header)
    out = tmp_path / "r.h5"
    cols = [] if header else ["--time", "1", "--voltage", "2", "--strain", "3"]
    res = run_import(f, "--out", out, *cols, *options)
    assert res.exit_code == 0, res.output
    (entry,) = read_run(out)
    assert entry.units["strain"] == unit


# -- MATLAB logical values --------------------------------------------------------------------


def test_a_v5_logical_is_left_out_and_listed(tmp_path: Path):
    out = tmp_path / "r.h5"
    res = run_import(EXAMPLES / "logical_v5.mat", "--out", out)
    assert res.exit_code == 0, res.output
    (entry,) = read_run(out)
    assert set(entry.channels) == {"time", "command_voltage", "strain"}  # no 0/1 "enabled"
    assert "variable enabled_V: logical values" in entry.step["skipped"]
    listed = run_import(EXAMPLES / "logical_v5.mat", "--list")
    assert "logical" in listed.output
    refused = run_import(EXAMPLES / "logical_v5.mat", "--out", out, "--overwrite",
                         "--voltage", "enabled_V")  # fmt: skip
    assert refused.exit_code == 2 and "enabled_V" in refused.stderr


def test_v5_and_v73_leave_logical_values_out_alike(tmp_path: Path):
    """A logical named like a voltage (``u``), at the top and inside a struct, in a v5 file
    (scipy stores it as uint8 with a logical flag) and in a v7.3 file (``MATLAB_class``
    logical): left out of both alike, the double ``voltage_V`` taken."""
    import h5py

    n = 50
    t = np.arange(n) / 100.0
    v = 50 + 40 * np.sin(2 * np.pi * t)
    flag = np.arange(n) % 2 == 0
    signals = {"time_s": t, "voltage_V": v, "strain_ue": 9 * v}
    savemat(tmp_path / "v5.mat", {**signals, "u": flag, "s": {"ok": flag}})
    examples.write_v73(tmp_path / "v73.mat", signals)
    with h5py.File(tmp_path / "v73.mat", "a") as f:
        ds = f.create_dataset("u", data=flag[None, :].astype(np.uint8))
        ds.attrs["MATLAB_class"] = np.bytes_("logical")
    skipped = {}
    for name in ("v5.mat", "v73.mat"):
        out = tmp_path / f"{name}.h5"
        res = run_import(tmp_path / name, "--out", out)
        assert res.exit_code == 0, res.output
        (entry,) = read_run(out)
        np.testing.assert_allclose(entry["command_voltage"], v)  # not the logical 'u'
        assert set(entry.channels) == {"time", "command_voltage", "strain"}
        skipped[name] = [x for x in entry.step["skipped"] if "logical" in x]
    assert skipped["v5.mat"] == ["variable u: logical values", "variable s.ok: logical values"]
    assert skipped["v73.mat"] == ["variable u: logical values"]


# -- the same data twice ----------------------------------------------------------------------


def test_the_same_file_twice_is_refused_naming_it(tmp_path: Path):
    f = _csv(tmp_path / "a.csv", "time_s,voltage_V,strain_ue")
    out = tmp_path / "r.h5"
    res = run_import(f, f, "--out", out)
    assert res.exit_code == 2, res.output
    assert f"{f}: given twice (the same path)" in res.stderr and not out.exists()


def test_two_paths_to_one_file_are_refused(tmp_path: Path):
    f = _csv(tmp_path / "a.csv", "time_s,voltage_V,strain_ue")
    (tmp_path / "sub").mkdir()
    link = tmp_path / "sub" / "b.csv"
    os.symlink(f, link)
    res = run_import(f, link, "--out", tmp_path / "r.h5")
    assert res.exit_code == 2, res.output
    assert f"{link}: given twice (the same file as {f})" in res.stderr


def test_two_files_of_the_same_content_are_refused_naming_both(tmp_path: Path):
    f = _csv(tmp_path / "a.csv", "time_s,voltage_V,strain_ue")
    g = Path(shutil.copy(f, tmp_path / "copy of a.csv"))
    other = _csv(tmp_path / "b.csv", "time_s,voltage_V,strain_ue", shift=1.0)
    assert other.stat().st_size == f.stat().st_size  # same size, other data: allowed
    res = run_import(f, other, g, "--out", tmp_path / "r.h5")
    assert res.exit_code == 2, res.output
    assert f"{g}: the same content as {f}" in res.stderr
    assert str(other) not in res.stderr
    ok = run_import(f, other, "--out", tmp_path / "r.h5")
    assert ok.exit_code == 0, ok.output
    assert [e.name for e in read_run(tmp_path / "r.h5")] == ["a", "b"]


def test_the_same_samples_in_files_of_other_bytes_are_refused(tmp_path: Path):
    """Line ends, a byte-order mark, another header or units that convert to the same values:
    the files differ, the records do not. One sample changed: two records."""
    f = _csv(tmp_path / "a.csv", "time_s,voltage_V,strain_ue")
    text = f.read_text()
    crlf = tmp_path / "a_crlf.csv"
    crlf.write_bytes(text.replace("\n", "\r\n").encode())
    bom = tmp_path / "a_bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + text.replace("time_s,", "t [s],").encode())
    res = run_import(f, crlf, bom, "--out", tmp_path / "r.h5")
    assert res.exit_code == 2, res.output
    said = " ".join(res.stderr.split())
    assert f"{crlf}: holds the same voltage and strain samples as {f}" in said
    assert f"{bom}: holds the same voltage and strain samples as {f}" in said
    assert not (tmp_path / "r.h5").exists()
    lines = text.splitlines()
    *head, last = lines
    cells = last.split(",")
    cells[2] = repr(float(cells[2]) + 1e-3)  # one strain sample differs
    changed = tmp_path / "changed.csv"
    changed.write_text("\n".join([*head, ",".join(cells)]) + "\n")
    ok = run_import(f, changed, "--out", tmp_path / "r.h5")
    assert ok.exit_code == 0, ok.output
