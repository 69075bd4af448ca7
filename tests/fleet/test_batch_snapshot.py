"""One snapshot per batch result (labrig.fleet.tasks.read_snapshot).

- a run file that changes between the fit and the diagnosis of a task (a writer appending, a
  resume renaming its copy over it) does not mix two versions in one row: the diagnosis gets the
  records the fit got, and the row's SHA-256 is of the bytes read;
- a run file still being written is not analysed: its row says ``being written`` and the batch
  exits 4, the other runs are analysed;
- ``batch report`` fits our model once per run (it fitted it twice: once for the fit columns,
  once inside the report).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

import labrig.analysis.diagnose as diagnosis_module
import labrig.commands.fit as fit_module
from labrig.fleet.table import read_table

from helpers import TINY, invoke, run_protocol, start_writer, stop_writer

#: four entries: what the run file becomes between the two reads of the old code
FOUR = TINY + "  - kind: sine\n    amplitude_V: 40\n    frequency_hz: 2\n    cycles: 2\n"


def rows(out: Path) -> dict[str, dict]:
    f = out / "fleet.parquet"
    return {Path(r["run_file"]).name: r for r in read_table(f if f.exists() else out / "fleet.csv")}


@pytest.fixture
def run_copy(tiny_run: Path, tmp_path: Path) -> Path:
    p = tmp_path / "runs" / "a.h5"
    p.parent.mkdir()
    p.write_bytes(tiny_run.read_bytes())
    return p


def test_fit_and_diagnosis_of_a_row_see_one_snapshot(run_copy: Path, tmp_path: Path, monkeypatch):
    bigger = run_protocol(FOUR, tmp_path, seed=2)
    original = run_copy.read_bytes()
    real_fit = fit_module.fit_model
    seen: dict[str, list[str]] = {}

    def fit_then_the_file_changes(records, **kw):
        res = real_fit(records, **kw)
        seen["fit"] = list(kw.get("scored") or [r.name for r in records])
        run_copy.write_bytes(bigger.read_bytes())  # the file grows between the two reads
        return res

    def diagnose_records(records, *a, **kw):
        seen["diagnose"] = [r.name for r in records]
        raise RuntimeError("stop after the records were seen")

    monkeypatch.setattr(fit_module, "fit_model", fit_then_the_file_changes)
    monkeypatch.setattr(diagnosis_module, "diagnose", diagnose_records)
    out = tmp_path / "out"
    res = invoke("batch", "diagnose", run_copy, "--out", out, "--serial")
    assert res.exit_code == 4, res.output  # the fake diagnosis stops the task
    assert len(seen["fit"]) == 3
    assert "diagnose" in seen, rows(out)["a.h5"]["error"]
    assert seen["diagnose"] == seen["fit"]  # not the 4 entries of the file as it is now
    row = rows(out)["a.h5"]
    assert row["input_sha256"] == hashlib.sha256(original).hexdigest()
    assert row["n_entries"] == 3


@pytest.mark.slow  # the default tier's twin: test_fit_and_diagnosis_of_a_row_see_one_snapshot
def test_a_run_file_being_written_is_not_analysed(run_copy: Path, tmp_path: Path):
    live = run_copy.parent / "live.h5"
    writer = start_writer(live)
    try:
        out = tmp_path / "out"
        res = invoke(
            "batch", "fit", run_copy, live, "--out", out, "--serial", "--no-heldout", "--json"
        )
    finally:
        stop_writer(writer)
    assert res.exit_code == 4, res.output
    summary = json.loads(res.stdout)
    assert summary["succeeded"] == 1 and len(summary["failed"]) == 1
    assert "is being written now" in summary["failed"][0]["error"]
    by = rows(out)
    assert by["live.h5"]["status"] == "being written"
    assert by["a.h5"]["status"] == "ok"
    # once the run has ended, the next batch analyses it (the refusal was not cached)
    res = invoke("batch", "fit", run_copy, live, "--out", out, "--serial", "--no-heldout")
    assert res.exit_code in (0, 4), res.output
    assert rows(out)["live.h5"]["status"] != "being written"


def test_batch_report_fits_our_model_once(run_copy: Path, tmp_path: Path, monkeypatch):
    # the fleet page (its figures, most of this batch's CPU) is not read here; its own tests:
    # tests/fleet/test_fleet.py, tests/api/test_day_one.py
    import labrig.fleet.fleet_report as fleet_report

    monkeypatch.setattr(fleet_report, "write_fleet_report", lambda path, *args: path)
    real_fit = fit_module.fit_model
    calls = []

    def counted(records, **kw):
        calls.append(1)
        return real_fit(records, **kw)

    monkeypatch.setattr(fit_module, "fit_model", counted)
    out = tmp_path / "out"
    res = invoke("batch", "report", run_copy, "--out", out, "--serial", "--no-heldout")
    assert res.exit_code == 0, res.output
    assert len(calls) == 1
    key = rows(out)["a.h5"]["key"]
    fit_doc = json.loads((out / "runs" / key / "fit.json").read_text())
    report = json.loads((out / "runs" / key / "report.json").read_text())
    # the report scores the fit the row reports
    for entry, nrmse in fit_doc["per_entry"].items():
        assert report[entry]["dynamic.nrmse_pct"] == pytest.approx(nrmse, rel=1e-9)
