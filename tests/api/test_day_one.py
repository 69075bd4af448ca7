"""What a lab meets on day one (labrig issue 26): labrig.open without the POSIX-only
``resource`` module (Windows), the shipped example protocols by name from any folder, whole file
names in ``labrig runs``, ``labrig.Run`` as a context manager, ``fit(...).predict(run)``, the
step columns of ``to_pandas()``, and the fleet page of a small fleet."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import labrig

from helpers import invoke


def test_open_works_without_the_resource_module(tiny_run: Path):
    code = (
        "import sys, signal\n"
        "sys.modules['resource'] = None\n"  # import resource raises ImportError, as on Windows
        "for name in ('SIGHUP', 'SIGQUIT'):\n"
        "    delattr(signal, name)\n"  # nor these signals
        "import labrig\n"
        f"run = labrig.open({str(tiny_run)!r})\n"
        "print(run.status, len(run), float(run['sine_60V_2Hz']['strain'].max()) > 0)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["complete", "3", "True"]


def test_shipped_protocols_by_name_from_any_folder(tmp_path: Path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no experiments/ folder here
    res = invoke("check", "sweep", "--json")
    assert res.exit_code == 0, res.output
    assert '"name": "harmonic sweep' in res.stdout or '"entries"' in res.stdout
    res = invoke("check", "control")  # its rig file is found beside it, in the package
    assert res.exit_code == 0, res.output
    res = invoke("check", "nosuch")
    assert res.exit_code == 2 and "examples: " in res.stderr and "paper" in res.stderr
    # a misspelled shipped rig is named with the rigs there are (not only "no such file")
    res = invoke("check", "sweep", "--rig", "hybrd")
    assert res.exit_code == 2 and "rigs: " in res.stderr, res.output
    assert "hybrid" in res.stderr and "bipolar" in res.stderr and "Traceback" not in res.output
    assert invoke("check", "sweep", "--rig", "hybrid").exit_code == 0
    # a file of that name in the working folder wins over the shipped one
    (tmp_path / "paper").write_text("name: mine\nrate_hz: 1000\nsteps: []\n")
    assert "[steps]" in invoke("check", "paper").stderr


def test_runs_lists_whole_file_names(tiny_run: Path, tmp_path: Path):
    name = "paper_campaign__sweep___vanishing_envelope_-20261126-120959.h5"
    (tmp_path / name).write_bytes(tiny_run.read_bytes())
    res = invoke("runs", tmp_path, columns=None)
    assert res.exit_code == 0, res.output
    assert str(tmp_path / name) in res.stdout


def test_run_is_a_context_manager_and_predicts(tiny_run: Path):
    with labrig.open(tiny_run) as run:
        fit = run.fit(heldout=False)
        whole = fit.predict(run)
        assert list(whole) == list(run.entries)
        for name, strain in whole.items():
            assert strain.shape == run[name]["strain"].shape
            span = np.ptp(run[name]["strain"])
            nrmse = 100 * np.sqrt(np.mean((strain - run[name]["strain"]) ** 2)) / span
            assert nrmse == pytest.approx(fit.per_entry[name], abs=0.05)  # as the fit scored
        one = fit.predict(run["sine_80V_2Hz"])
        assert one.shape == run["sine_80V_2Hz"]["strain"].shape
        assert fit.predict(run.records("sine_80V_2Hz")[0]) == pytest.approx(one)
        with pytest.raises(TypeError, match="cannot predict a str"):
            fit.predict("sine_80V_2Hz")
    assert run._full is None  # the samples let go; the metadata stays
    assert run.status == "complete"


def test_to_pandas_carries_the_step_definition(tiny_run: Path):
    df = labrig.open(tiny_run).to_pandas()
    for col in ("entry", "time_s", "strain_ue", "kind", "amplitude_V", "frequency_hz"):
        assert col in df.columns, col
    first = df[df.entry == "sine_60V_2Hz"]
    assert set(first.amplitude_V) == {60} and set(first.frequency_hz) == {2}
    assert set(df.kind) == {"sine"}
    assert df.amplitude_V.dtype.kind in "if"  # numbers, not objects


def test_fleet_page_of_a_small_fleet_shows_its_runs(tiny_run: Path, tmp_path: Path):
    runs = tmp_path / "runs"
    runs.mkdir()
    for k in range(2):
        (runs / f"r{k}.h5").write_bytes(tiny_run.read_bytes())
    out = tmp_path / "batch"
    res = invoke("batch", "fit", runs, "--out", out, "--serial", "--no-heldout")
    assert res.exit_code == 0, res.output
    page = (out / "fleet.html").read_text()
    assert "r0.h5" in page and "r1.h5" in page and "alpha0_ue_per_V" in page
    assert "No parameters to show" not in page
    assert page.count("data:image/png;base64,") >= 2  # distributions and a control chart


@pytest.mark.skipif(os.name != "posix", reason="the example data is read from the package")
def test_the_examples_ship_in_the_package():
    from labrig.runner.examples import example_names, examples_folder

    folder = examples_folder()
    assert folder is not None and (folder / "paper.yaml").is_file()
    assert {"paper", "sweep", "envelope"} <= set(example_names())
    assert "hybrid" in example_names("rig")
