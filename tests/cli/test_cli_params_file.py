"""Parameter files (``report --params``, ``diagnose --params``) go through one reader
(labrig.analysis.params_file): the same problem gets the same message from both commands, naming the
file, the field and what would be valid; and the one JSON sanitizer (labrig.core.jsonsafe)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from labrig.analysis.params_file import read_fit_output, read_params_file, start_params
from labrig.core.errors import InputFileError
from labrig.core.jsonsafe import json_safe
from labrig.model import PAPER_TABLE1


def _message(read, path: Path) -> str:
    with pytest.raises(InputFileError) as e:
        read(path)
    return str(e.value)


def _both(path: Path) -> tuple[str, str]:
    return _message(read_fit_output, path), _message(lambda p: start_params(p, print), path)


def test_a_missing_file(tmp_path: Path) -> None:
    report, diagnose = _both(tmp_path / "nope.json")
    assert report == diagnose == f"{tmp_path / 'nope.json'}: parameter file not found"


def test_not_json(tmp_path: Path) -> None:
    path = tmp_path / "notes.txt"
    path.write_text("not json\n")
    report, diagnose = _both(path)
    assert report == diagnose
    assert report.startswith(f"{path}: not a JSON parameter file (")


def test_invalid_parameters_name_each_field(tmp_path: Path) -> None:
    path = tmp_path / "bad.json"
    doc = {"params": {**PAPER_TABLE1.model_dump(), "alpha0_ue_per_V": -1.0, "vc_V": "ten"}}
    path.write_text(json.dumps(doc))
    report, diagnose = _both(path)
    assert report == diagnose
    assert report.startswith(f"{path}: [params] invalid model parameters: ")
    assert "alpha0_ue_per_V: Input should be greater than 0" in report
    assert "vc_V: " in report


def test_a_baseline_file_is_refused_by_both(tmp_path: Path) -> None:
    path = tmp_path / "pi.json"
    path.write_text(json.dumps({"method": "bouc_wen", "params": {"A": 1.0}}))
    report, diagnose = _both(path)
    assert "[method] holds a bouc_wen baseline; the report needs" in report
    assert "[method] holds a bouc_wen baseline; diagnose needs" in diagnose


def test_a_bare_model_params_object_is_for_diagnose_only(tmp_path: Path) -> None:
    path = tmp_path / "bare.json"
    path.write_text(PAPER_TABLE1.model_dump_json())
    assert start_params(path, print) == PAPER_TABLE1
    assert "no 'params' object" in _message(read_fit_output, path)
    pf = read_params_file(path, "diagnose", bare_ok=True)
    assert pf.doc is None and pf.params == PAPER_TABLE1


def test_a_fit_file_is_read_whole(tmp_path: Path) -> None:
    doc = {"params": PAPER_TABLE1.model_dump(), "method": "global", "nrmse_pct": 0.5}
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(doc))
    assert read_fit_output(path) == doc
    said: list[str] = []
    assert start_params(path, said.append) == PAPER_TABLE1
    assert said == []  # no effects: nothing to announce


def test_json_safe_gives_strict_json() -> None:
    raw = {
        "a": math.nan,
        "b": [math.inf, 1.5, (2.0, -math.inf)],
        "c": {"d": None, "e": "x"},
        3: 1,
    }
    safe = json_safe(raw)
    assert safe == {"a": None, "b": [None, 1.5, [2.0, None]], "c": {"d": None, "e": "x"}, "3": 1}
    json.dumps(safe, allow_nan=False)  # raises on NaN or infinity
    with pytest.raises(ValueError):
        json.dumps(raw, allow_nan=False)
