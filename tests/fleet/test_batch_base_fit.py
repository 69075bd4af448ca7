"""``batch diagnose`` fits the base model once per run: the diagnosis takes the fit the task's
``fit`` part made (``diagnose(base_fit=...)``, checked by ``base_fit_reusable``), and its
document is the one ``labrig diagnose`` writes for the same file."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

import labrig.analysis.diagnose.procedure as procedure
from labrig.analysis.diagnose.procedure import base_fit_reusable
from labrig.analysis.diagnose.state import Settings
from labrig.analysis.fit import fit_model
from labrig.analysis.load import records_from_run
from labrig.model.params import PAPER_TABLE1

from helpers import invoke


def _settings(**kw) -> Settings:
    base = {"chain": True, "offset": False, "warmup_s": 0.0, "top_k": 4, "min_gain": 0.15}
    return Settings(**{**base, **kw})


@pytest.fixture(scope="module")
def tiny_fit(tiny_run: Path):
    records = records_from_run(tiny_run)
    return records, fit_model(records, heldout=False, chain=True)


def test_a_fit_made_as_the_diagnosis_would_make_it_is_reused(tiny_fit):
    records, fr = tiny_fit
    assert base_fit_reusable(fr, records, _settings())


@pytest.mark.parametrize(
    "change",
    [
        {"chain": False},
        {"offset": True},
        {"warmup_s": 0.1},
        {"memory": "last_reversal"},
        {"shape": "gaussian"},
        {"initial": PAPER_TABLE1},  # a start the diagnosis' own fit would also try
    ],
    ids=lambda d: next(iter(d)),
)
def test_a_fit_made_otherwise_is_not_reused(tiny_fit, change):
    records, fr = tiny_fit
    assert not base_fit_reusable(fr, records, _settings(**change))


def test_a_fit_of_other_entries_or_method_is_not_reused(tiny_fit):
    records, fr = tiny_fit
    assert not base_fit_reusable(fr, records[:2], _settings())
    assert not base_fit_reusable(dataclasses.replace(fr, method="staged"), records, _settings())
    assert not base_fit_reusable(dataclasses.replace(fr, chain=False), records, _settings())


class StopError(Exception):
    """Raised by a stand-in to end a call once what the test checks has happened."""


def test_diagnose_takes_a_reusable_base_fit_instead_of_fitting(tiny_fit, monkeypatch):
    records, fr = tiny_fit
    fits: list[int] = []
    seen: list[object] = []

    def no_fit(recs, **kw):
        fits.append(len(recs))
        raise StopError

    def after_the_fit(recs, chain):  # fit_base's next step: stop there
        raise StopError

    monkeypatch.setattr(procedure, "fit_model", no_fit)
    monkeypatch.setattr(procedure, "build_sequences", after_the_fit)
    real_fit_base = procedure.fit_base

    def spy(*a, **kw):
        seen.append(a[-1] if len(a) == 8 else kw.get("base_fit"))
        return real_fit_base(*a, **kw)

    monkeypatch.setattr(procedure, "fit_base", spy)
    with pytest.raises(StopError):
        procedure.diagnose(records, base_fit=fr)
    assert fits == [] and seen == [fr]  # taken, not refitted
    with pytest.raises(StopError):
        procedure.diagnose(records, base_fit=dataclasses.replace(fr, chain=False))
    assert fits == [3] and seen[-1] is None  # not the diagnosis' fit: fitted again
    with pytest.raises(StopError):
        procedure.diagnose(records)
    assert fits == [3, 3]


def test_the_batch_task_gives_its_fit_to_the_diagnosis(tiny_run: Path, monkeypatch):
    import labrig.commands.diagnose as diagnose_command
    from labrig.fleet.tasks import Snapshot, TaskOptions, TaskResult, diagnose_part, fit_part

    got: dict[str, object] = {}

    def capture(path, **kw):
        got.update(kw)
        raise StopError

    snap = Snapshot(tiny_run, None)
    fit_part(snap, TaskOptions(heldout=False), TaskResult("diagnose", str(tiny_run), "k", False))
    assert snap.fit is not None
    monkeypatch.setattr(diagnose_command, "diagnose_run_file", capture)
    with pytest.raises(StopError):
        diagnose_part(snap, TaskOptions(), TaskResult("diagnose", str(tiny_run), "k", False))
    assert got["base_fit"] is snap.fit.result
    snap.fit = None  # a part called on its own: no fit to give
    with pytest.raises(StopError):
        diagnose_part(snap, TaskOptions(), TaskResult("diagnose", str(tiny_run), "k", False))
    assert got["base_fit"] is None


@pytest.mark.slow  # the default tier's twins: the two tests above
def test_batch_diagnose_fits_once_and_writes_what_diagnose_writes(
    tiny_run: Path, tmp_path: Path, monkeypatch
):
    calls: list[int] = []
    real = procedure.fit_model

    def counted(records, **kw):
        calls.append(len(records))
        return real(records, **kw)

    monkeypatch.setattr(procedure, "fit_model", counted)
    res = invoke("diagnose", tiny_run, "--json", "--workers", "1")
    assert res.exit_code == 0, res.output
    alone = json.loads(res.stdout)
    assert calls == [3]  # labrig diagnose fits its base itself
    out = tmp_path / "out"
    res = invoke("batch", "diagnose", tiny_run, "--out", out, "--serial")
    assert res.exit_code == 0, res.output
    assert calls == [3]  # the batch task's diagnosis took the fit its fit part made
    docs = list(out.rglob("diagnosis.json"))
    assert len(docs) == 1
    assert json.loads(docs[0].read_text()) == alone
