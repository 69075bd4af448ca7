"""The Python API at the package top: ``labrig.run`` and ``labrig.open`` give a ``Run`` whose
fields and tables match the file (read here with h5py), whose reprs stay short, whose analysis
results are what the command line prints with ``--json``, and whose run stops at 0 V on
Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
from pathlib import Path

import h5py
import numpy as np
import pytest
from test_catalogue import write_run
from typer.testing import CliRunner

import labrig
from labrig.cli import app
from labrig.core.errors import InputFileError
from labrig.store.format import memory_units

PROTOCOL = """\
name: api test
rate_hz: 1000
rest_s: 0.2
steps:
  - kind: sweep
    amplitudes_V: [100]
    frequencies_hz: [5, 10, 20]
    cycles: 2
"""
#: the entries the sweep expands to (names as docs/protocol.md gives them)
ENTRIES = ["sine_100V_5Hz", "sine_100V_10Hz", "sine_100V_20Hz"]


@pytest.fixture(scope="module")
def seeded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("api")
    (d / "sweep.yaml").write_text(PROTOCOL)
    run = labrig.run(d / "sweep.yaml", out=d / "run.h5", seed=4, progress=False)
    assert isinstance(run, labrig.Run)
    return d / "run.h5"


def cli_json(*args: str) -> dict:
    result = CliRunner().invoke(app, list(args))
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def test_open_reads_what_the_file_holds(seeded: Path):
    run = labrig.open(seeded)
    assert (run.status, run.protocol, run.seed, run.rig) == ("complete", "api test", 4, "")
    assert list(run.entries) == ENTRIES and len(run) == 3 and "sine_100V_5Hz" in run
    assert run.protocol_text == PROTOCOL
    assert run.start_time is not None and run.end_time is not None
    assert run.start_time <= run.end_time
    with h5py.File(seeded) as f:
        for name, e in run.entries.items():
            n = f[name]["data/time"].shape[0]
            assert e.samples == n and e.kind == "sine" and e.rate_hz == 1000.0
            assert e.duration_s == pytest.approx((n - 1) / 1000.0)
            assert e.step["amplitude_V"] == 100.0
        assert run.metadata["instrument/name"] == f["run/instrument/name"][()].decode()


def test_to_pandas_has_units_in_names_and_the_file_values(seeded: Path):
    run = labrig.open(seeded)
    df = run.to_pandas()
    with h5py.File(seeded) as f:
        channels = list(f[ENTRIES[0]]["data"])
        # as labrig names units in memory (microstrain stored as um/m reads as ue)
        units = {c: memory_units(f[ENTRIES[0]]["data"][c].attrs["units"]) for c in channels}
        expected = ["entry", *(f"{c}_{units[c]}" for c in channels)]
        # the channels, then the step definition's scalar keys (tests/api/test_day_one.py)
        assert list(df.columns)[: len(expected)] == expected
        step = json.loads(f[ENTRIES[0]]["step_definition"][()])
        assert set(df.columns[len(expected) :]) <= {k for k in step} | {
            k for e in ENTRIES for k in json.loads(f[e]["step_definition"][()])
        }
        assert list(df["entry"].cat.categories) == ENTRIES
        for name in ENTRIES:
            rows = df[df["entry"] == name]
            for c in channels:
                np.testing.assert_array_equal(
                    rows[f"{c}_{units[c]}"].to_numpy(), f[name]["data"][c][()]
                )
    assert len(df) == sum(e.samples for e in run.entries.values())
    assert df.attrs["units"]["strain_ue"] == "ue" and df.attrs["units"]["time_s"] == "s"
    one = run.to_pandas("sine_100V_10Hz")
    assert set(one["entry"]) == {"sine_100V_10Hz"}


def test_to_xarray_has_entry_and_sample_dimensions(seeded: Path):
    pytest.importorskip("xarray")
    run = labrig.open(seeded)
    ds = run.to_xarray()
    assert ds.sizes["entry"] == 3
    assert ds["strain"].attrs["units"] == "ue" and ds["time"].attrs["units"] == "s"
    with h5py.File(seeded) as f:
        for name in ENTRIES:
            strain = f[name]["data/strain"][()]
            row = ds["strain"].sel(entry=name).to_numpy()
            np.testing.assert_array_equal(row[: strain.size], strain)
            assert np.isnan(row[strain.size :]).all()
    assert list(ds["frequency_hz"].to_numpy()) == [5.0, 10.0, 20.0]


def test_to_xarray_without_xarray_says_how_to_install_it(
    seeded: Path, monkeypatch: pytest.MonkeyPatch
):
    run = labrig.open(seeded)
    monkeypatch.setitem(sys.modules, "xarray", None)  # import xarray now fails
    with pytest.raises(ImportError, match=r"pip install 'labrig\[xarray\]'"):
        run.to_xarray()


def test_reprs_stay_short_for_a_run_of_many_entries(tmp_path: Path):
    # 21 entries: more than either repr lists (8 lines of text, 20 rows of HTML), so both cut,
    # the HTML just past its 20 rows (each entry written costs the writer ~0.1 s of CPU)
    steps = [("sine", 10.0 + i, 1.0) for i in range(21)]
    path = write_run(tmp_path / "many.h5", "long campaign", steps, samples=5)
    run = labrig.open(path)
    text = repr(run)
    assert len(text) < 1500 and len(text.splitlines()) <= 12
    assert "21 entries" in text and "sine_10V_1Hz" in text and "sine_30V_1Hz" in text
    assert "... 14 more ..." in text and "sine_20V_1Hz" not in text
    page = run._repr_html_()
    assert len(page) < 6000 and "sine_10V_1Hz" in page and "... 1 more</td>" in page
    assert "sine_29V_1Hz" in page and "sine_30V_1Hz" not in page


def test_fit_is_what_fit_json_prints(seeded: Path):
    cli = cli_json("fit", str(seeded), "--json", "--no-heldout")
    result = labrig.open(seeded).fit(heldout=False)
    assert labrig.as_json(result) == cli
    assert result.params.alpha0_ue_per_V == cli["params"]["alpha0_ue_per_V"]


def test_report_is_what_report_json_prints(seeded: Path, tmp_path: Path):
    # the table without a page drawn (the same table as with one: tests/cli/
    # test_outputs_convention.py); the page is the API's, drawn once
    cli = cli_json("report", str(seeded), "--json")
    out = tmp_path / "api.html"
    built = labrig.open(seeded).report(out)
    assert labrig.as_json(built) == cli
    assert out.read_text(encoding="utf-8") == built.page
    with pytest.raises(FileExistsError):
        labrig.open(seeded).report(out)


def test_diagnose_is_what_diagnose_json_prints(seeded: Path):
    cli = cli_json("diagnose", str(seeded), "--json")
    result = labrig.open(seeded).diagnose()
    assert labrig.as_json(result) == cli
    assert result.verdict == cli["verdict"]


def test_run_refuses_to_overwrite(seeded: Path):
    before = seeded.read_bytes()
    with pytest.raises(FileExistsError):
        labrig.run(seeded.parent / "sweep.yaml", out=seeded, seed=1, progress=False)
    assert seeded.read_bytes() == before


def test_open_of_a_damaged_file_names_it(tmp_path: Path):
    bad = tmp_path / "bad.h5"
    bad.write_bytes(b"not a run file")
    with pytest.raises(InputFileError, match=r"bad\.h5") as e:
        labrig.open(bad)
    assert e.value.exit_code == 2


def test_runs_lists_a_folder_as_a_table(seeded: Path):
    df = labrig.runs(seeded.parent, where=["frequency_hz>=10"])
    assert list(df["path"]) == [str(seeded)]
    assert df.loc[0, "matching_entries"] == ENTRIES[1:]
    assert df.loc[0, "amplitudes_V"] == [100.0] and df.loc[0, "status"] == "complete"


@pytest.mark.timeout(60)
def test_ctrl_c_during_run_ramps_to_0V_then_raises(tmp_path: Path):
    """SIGINT while ``labrig.run`` runs in real time: the runner ramps to 0 V and records the
    abort; then the API raises KeyboardInterrupt."""
    (tmp_path / "p.yaml").write_text(PROTOCOL.replace("cycles: 2", "cycles: 20"))
    out = tmp_path / "run.h5"
    stop = threading.Event()

    def ctrl_c_once_writing() -> None:
        for _ in range(600):  # the run file exists once the rig is open and energised
            if stop.wait(0.05) or out.exists():
                break
        if not stop.wait(0.5):
            os.kill(os.getpid(), signal.SIGINT)

    thread = threading.Thread(target=ctrl_c_once_writing)
    thread.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            labrig.run(tmp_path / "p.yaml", out=out, seed=1, progress=False, realtime=True)
    finally:
        stop.set()
        thread.join()
    run = labrig.open(out)
    assert run.status == "aborted"
    with h5py.File(out) as f:
        assert float(f["run/final_amplifier_voltage_V"][()]) == 0.0
        assert int(f["run/exit_code"][()]) == 130
