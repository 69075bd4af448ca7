"""One library function diagnoses a run file for the command, the Python API and the batch
(:func:`labrig.commands.diagnose.diagnose_run_file`): ``--mains-hz`` reaches the
diagnosis from each of them, the outputs are refused before any work when they exist, and the
diagnosis module no longer sits below ``prepare`` (imports go one way).

The diagnosis itself is replaced by a recorder here (its numbers are
tests/diagnose/test_diagnose.py's): these tests are about what reaches it and what is written."""

from __future__ import annotations

import ast
import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from typer.testing import CliRunner

import labrig
import labrig.analysis.diagnose as diagnosis
import labrig.analysis.load as load
import labrig.commands.diagnose as run_file
from labrig.analysis.diagnose import Diagnosis, Evidence
from labrig.cli import app
from labrig.cli.typer_app import EXIT_USAGE
from labrig.core.errors import InputFileError
from labrig.model.effects import EFFECT_NAMES
from labrig.studies.campaign import bench_campaign

pytestmark = pytest.mark.timeout(120)
ROOT = Path(__file__).resolve().parents[2]


def stub_diagnosis() -> Diagnosis:
    per = {"a": 1.0, "b": 1.0, "c": 1.0}
    score = {"nrmse_pct": 1.0, "heldout_nrmse_pct": 1.1, "per_entry": per}
    evidence = Evidence({}, 1.0, 1.0, 1.0, {}, ["a sentence of evidence"])
    return Diagnosis(
        before=score,
        after=score,
        effects_added=[],
        candidates=[],
        verdict="consistent with noise: a stub standing in for the diagnosis in this test",
        classification="consistent_with_noise",
        evidence_before=evidence,
        evidence_after=evidence,
    )


@pytest.fixture
def recorded(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    """Records of a small bench campaign for any run file; the diagnosis' keyword arguments
    recorded and a stub returned."""
    recs = bench_campaign([], seed=6)
    monkeypatch.setattr(load, "records_from_run", lambda path, entries=None: recs)
    calls: list[dict[str, Any]] = []

    def fake(records, params=None, **kw):
        calls.append({"records": records, "params": params, **kw})
        return stub_diagnosis()

    monkeypatch.setattr(diagnosis, "diagnose", fake)
    return calls


def test_mains_hz_reaches_the_diagnosis_from_the_command(recorded, tmp_path: Path) -> None:
    res = CliRunner().invoke(
        app, ["diagnose", str(tmp_path / "run.h5"), "--mains-hz", "60", "--json"]
    )
    assert res.exit_code == 0, res.output
    (call,) = recorded
    assert call["mains_hz"] == 60.0
    assert call["effects"] == EFFECT_NAMES
    assert json.loads(res.stdout) == stub_diagnosis().to_json()
    res = CliRunner().invoke(app, ["diagnose", str(tmp_path / "run.h5"), "--json"])
    assert res.exit_code == 0 and recorded[1]["mains_hz"] is None  # default: detected


def test_mains_hz_reaches_the_diagnosis_from_batch_and_api(
    recorded, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from labrig.fleet.tasks import TaskOptions, TaskResult, diagnose_part

    out = TaskResult("diagnose", "r.h5", "r", ok=False)
    diagnose_part(tmp_path / "r.h5", TaskOptions(also=("remanence",), mains_hz=50.0), out)
    assert recorded[-1]["mains_hz"] == 50.0
    assert recorded[-1]["effects"] == (*EFFECT_NAMES, "remanence")
    assert set(out.documents) == set(run_file.OUTPUT_NAMES)
    assert json.loads(out.documents["diagnosis.json"]) == stub_diagnosis().to_json()

    seen: dict[str, Any] = {}

    def spy(path, params_file=None, **kw):
        seen.update(kw)
        return SimpleNamespace(diagnosis=stub_diagnosis())

    monkeypatch.setattr(run_file, "diagnose_run_file", spy)
    fake_run = labrig.Run.__new__(labrig.Run)
    fake_run.path = tmp_path / "r.h5"
    assert fake_run.diagnose(mains_hz=60.0).verdict == stub_diagnosis().verdict
    assert seen["mains_hz"] == 60.0


@pytest.mark.parametrize("hz", ["0", "-50", "2000", "fifty"])
def test_a_bad_mains_frequency_is_a_usage_error(tmp_path: Path, hz: str) -> None:
    res = CliRunner().invoke(app, ["diagnose", str(tmp_path / "run.h5"), "--mains-hz", hz])
    assert res.exit_code == EXIT_USAGE, res.output
    assert "--mains-hz" in res.stderr


def test_existing_outputs_are_refused_before_the_work(recorded, tmp_path: Path) -> None:
    out = tmp_path / "d"
    out.mkdir()
    (out / "diagnosis.json").write_text("{}")
    with pytest.raises(InputFileError, match="--overwrite"):
        run_file.diagnose_run_file(tmp_path / "run.h5", out=out)
    assert recorded == []  # refused before the diagnosis
    assert (out / "diagnosis.json").read_text() == "{}"
    res = CliRunner().invoke(app, ["diagnose", str(tmp_path / "run.h5"), "--out", str(out)])
    assert res.exit_code == 2 and recorded == []
    assert "exists already; pass --overwrite" in " ".join(res.stderr.split())


def test_api_refuses_existing_outputs_without_overwrite(recorded, tmp_path: Path) -> None:
    """``Run.diagnose(out=...)`` goes through the same staged outputs: an existing file is a
    ``FileExistsError`` before any work; with ``overwrite=True`` both files are replaced."""
    out = tmp_path / "d"
    out.mkdir()
    (out / "diagnosis.html").write_text("old")
    fake_run = labrig.Run.__new__(labrig.Run)
    fake_run.path = tmp_path / "r.h5"
    with pytest.raises(FileExistsError, match="overwrite=True"):
        fake_run.diagnose(out=out)
    assert recorded == [] and (out / "diagnosis.html").read_text() == "old"
    result = run_file.diagnose_run_file(tmp_path / "r.h5", out=out, overwrite=True)
    assert result.written == [out / n for n in run_file.OUTPUT_NAMES]
    assert json.loads((out / "diagnosis.json").read_text()) == stub_diagnosis().to_json()
    assert "a stub standing in for the diagnosis" in (out / "diagnosis.html").read_text()


def test_prepare_does_not_import_the_diagnosis() -> None:
    """``commands/diagnose.py`` imports ``prepare``; ``prepare`` (also read by ``fit`` and
    ``report``) never imports the diagnosis package, not even inside a function."""
    tree = ast.parse((ROOT / "labrig" / "commands" / "prepare.py").read_text())
    imported = {
        node.module
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and node.module is not None
    }
    imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert not [m for m in imported if m.startswith("labrig.analysis.diagnose")], imported
