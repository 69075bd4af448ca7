"""``labrig validate TRAIN --on TEST`` and ``labrig.validate``: every model identified on the
training records only, every model scored on the test records by one rule.

Data: the first 5 s (1 000 rows) of the two real micromanipulator records (yan9a, MIT licence,
tests/data/real), imported as ``labrig import`` does; small enough for the default tier. The
scores are recomputed here from each model's exported prediction with numpy (the offset of
imported data fitted as the mean of measured minus predicted over the scored samples, or over
their first half for the second-half score), and the parameters of the models are checked to
be those ``labrig fit`` finds on the training file alone.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

import labrig
from labrig.analysis.baselines import fit_baseline
from labrig.analysis.load import records_from_run
from labrig.cli.validate import print_scores
from labrig.commands.prepare import prepare, training_setup
from labrig.commands.report import fit_report_models, report_data
from labrig.commands.validate import check_unseen, score_entry
from labrig.core.errors import InputFileError
from labrig.report.html import render

from helpers import TINY, invoke, run_protocol

REAL = Path(__file__).resolve().parents[1] / "data" / "real" / "yan9a-micromanipulator"
FILES = ("Model_Vi_Do.dat", "Test_Vi_Do_Di.dat")
ROWS = 1000
WARMUP_S = 1.25  # what fit's automatic warm-up gives these cuts (two periods, capped)

pytestmark = pytest.mark.skipif(
    not all((REAL / f).is_file() for f in FILES), reason=f"real data not found in {REAL}"
)


def import_cut(src: Path, dst_dir: Path, name: str, rows: int = ROWS) -> Path:
    text = src.read_text().splitlines()[:rows]
    cut = dst_dir / f"{name}.dat"
    cut.write_text("\n".join(text) + "\n")
    out = dst_dir / f"{name}.h5"
    res = invoke("import", cut, "--out", out, "--voltage", "1", "--strain", "5",
                 "--rate-hz", "200", "--strain-units", "raw")  # fmt: skip
    assert res.exit_code == 0, res.output
    return out


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("validate")
    return import_cut(REAL / FILES[0], d, "ident"), import_cut(REAL / FILES[1], d, "valid")


@pytest.fixture(scope="module")
def result(files):
    train, test = files
    return labrig.validate(train, on=test)


def test_scores_recomputed_from_the_exported_predictions(files, result) -> None:
    _, test = files
    doc = labrig.as_json(result)
    (rec,) = records_from_run(test)
    i0 = round(WARMUP_S * rec.rate_hz)
    assert result.tests[0].warmup_s == pytest.approx(WARMUP_S)
    m = rec.strain_ue[i0:]
    span = m.max() - m.min()
    assert set(doc["models"]) == {"dynamic", "prandtl_ishlinskii", "bouc_wen", "sindy"}
    for key, model in result.models.items():
        p = model.predictions[(str(test), rec.name)][i0:]
        assert p.shape == m.shape
        whole = p + np.mean(m - p)
        w = 100 * np.sqrt(np.mean((m - whole) ** 2)) / span
        h = m.size // 2
        second = p + np.mean(m[:h] - p[:h])
        s = 100 * np.sqrt(np.mean((m[h:] - second[h:]) ** 2)) / span
        got = doc["models"][key]
        assert got["whole_nrmse_pct"] == pytest.approx(w, rel=1e-9), key
        assert got["second_half_nrmse_pct"] == pytest.approx(s, rel=1e-9), key
    # our model predicts the other record better than every peer, and not below the floor
    ours = doc["models"]["dynamic"]["whole_nrmse_pct"]
    assert doc["noise_floor_pct"] < ours < 1.5
    for k in ("prandtl_ishlinskii", "bouc_wen", "sindy"):
        assert ours < doc["models"][k]["whole_nrmse_pct"]


def test_models_are_identified_on_the_training_file_only(files, result) -> None:
    train, _ = files
    fit = labrig.open(train).fit(heldout=False)
    got = result.models["dynamic"].params
    for k, v in fit.params.model_dump().items():
        assert got[k] == (pytest.approx(v, rel=1e-9) if isinstance(v, float) else v), k
    recs = records_from_run(train)
    pi = fit_baseline(recs, "prandtl_ishlinskii", heldout=False, warmup_s=WARMUP_S, offset=True)
    assert result.models["prandtl_ishlinskii"].params["weights_ue_per_V"] == pytest.approx(
        pi.params["weights_ue_per_V"], rel=1e-9
    )


def test_cli_json_table_and_page(files, result, tmp_path: Path, capsys) -> None:
    train, test = files
    page = tmp_path / "v.html"
    res = invoke("validate", train, "--on", test, "--json", "--out", page)
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    api = labrig.as_json(result)
    for k, m in api["models"].items():
        assert doc["models"][k]["whole_nrmse_pct"] == pytest.approx(m["whole_nrmse_pct"], rel=1e-6)
    html = page.read_text(encoding="utf-8")
    assert html.count("<img ") == 1  # one figure per test entry, a row per model in it
    for label in ("ours", "Prandtl-Ishlinskii", "Bouc-Wen", "SINDy", "noise floor"):
        assert label in html
    assert "http" not in html
    # the table: every model and the floor, with the numbers of the JSON
    print_scores(doc)
    shown = capsys.readouterr().out
    for m in doc["models"].values():
        assert f"{m['whole_nrmse_pct']:.3g}" in shown
        assert f"{m['second_half_nrmse_pct']:.3g}" in shown
    assert f"{doc['noise_floor_pct']:.3g}" in shown


def test_effects_from_a_diagnosis(files, tmp_path: Path) -> None:
    """``--effects-from``: our model refitted on the training records with the accepted
    effects (a library effect and empirical terms), scored by the same rule."""
    train, test = files
    diag = tmp_path / "diagnosis.json"
    added = [
        {"effect": "field_saturation", "params": {"s": 0.01, "s_sd": 0.001}, "evidence": ""},
    ]
    diag.write_text(json.dumps({"effects_added": added}))
    v = labrig.validate(train, on=test, effects_from=diag)
    m = v.models["dynamic+effects"]
    assert v.effects == ["field_saturation"]
    assert m.params["effects"][0]["effect"] == "field_saturation"
    (rec,) = records_from_run(test)
    i0 = round(WARMUP_S * rec.rate_hz)
    meas = rec.strain_ue[i0:]
    p = m.predictions[(str(test), rec.name)][i0:]
    w = 100 * np.std(meas - p) / np.ptp(meas)  # offset = mean: the residual's std
    assert m.mean("whole_nrmse_pct") == pytest.approx(w, rel=1e-9)
    # saturation helps this stack out of sample (measured: 0.72 -> 0.41 % on these cuts)
    assert m.mean("whole_nrmse_pct") < 0.8 * v.models["dynamic"].mean("whole_nrmse_pct")


def test_bad_input_exits_2_naming_the_file(files, tmp_path: Path) -> None:
    train, test = files
    cases = [
        (["validate", train, "--on", train], "given both as training and as test data"),
        (["validate", train, "--on", Path(os.path.relpath(train))], "both as training"),
        (["validate", train, train, "--on", test], "given twice as training data"),
        (["validate", train, "--on", tmp_path / "nope.h5"], "nope.h5"),
        (["validate", train, "--on", test, "--out", test], "--out"),
    ]
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    cases.append((["validate", train, "--on", test, "--effects-from", bad], "bad.json"))
    nolist = tmp_path / "nolist.json"
    nolist.write_text('{"effects": []}')
    cases.append((["validate", train, "--on", test, "--effects-from", nolist], "effects_added"))
    unknown = tmp_path / "unknown.json"
    unknown.write_text('{"effects_added": [{"effect": "gremlins", "params": {}}]}')
    cases.append((["validate", train, "--on", test, "--effects-from", unknown], "gremlins"))
    cases.append(
        (["validate", train, "--on", test, "--effects-from", nolist, "--diagnose"], "not both")
    )
    for args, words in cases:
        res = invoke(*args)
        assert res.exit_code == 2, (args, res.output)
        assert "Traceback" not in res.output
        assert words in res.output, (args, res.output)
    existing = tmp_path / "exists.html"
    existing.write_text("keep")
    res = invoke("validate", train, "--on", test, "--out", existing)
    assert res.exit_code == 2 and "--overwrite" in res.output
    assert existing.read_text() == "keep"


def test_a_test_record_held_by_a_training_file_is_refused(files, tmp_path: Path) -> None:
    """The test capture imported again under another name, or gathered with another capture in
    one training file, is the data a model would be scored on: exit 2 naming the test file and
    the training record, before anything is fitted. The same capture with one sample changed
    by 1e-9 of its value is another record and passes the check."""
    train, test = files
    d = tmp_path / "again"
    d.mkdir()
    copy = import_cut(REAL / FILES[1], d, "copy")
    both = tmp_path / "both.h5"
    cuts = [tmp_path / "a.dat", tmp_path / "b.dat"]
    for src, cut in zip(FILES, cuts, strict=True):
        cut.write_text("\n".join((REAL / src).read_text().splitlines()[:ROWS]) + "\n")
    res = invoke("import", *cuts, "--out", both, "--voltage", "1", "--strain", "5",
                 "--rate-hz", "200", "--strain-units", "raw")  # fmt: skip
    assert res.exit_code == 0, res.output
    for args, record in [([train, copy], "copy"), ([both], "b")]:
        res = invoke("validate", *args, "--on", test)
        assert res.exit_code == 2, (args, res.output)
        assert "Traceback" not in res.output
        assert str(test) in res.output and "holds the same samples" in res.output
        assert f"training record {record!r}" in res.output
    res = invoke("validate", "--leave-one-out", train, copy, test)
    assert res.exit_code == 2 and "holds the same samples" in res.output, res.output
    # one sample changed: not the same record (the check itself, without the fits)
    lines = (REAL / FILES[1]).read_text().splitlines()[:ROWS]
    cols = lines[500].split()
    cols[4] = repr(float(cols[4]) * (1 + 1e-9))
    lines[500] = "\t".join(cols)
    near = tmp_path / "near.dat"
    near.write_text("\n".join(lines) + "\n")
    near_h5 = tmp_path / "near.h5"
    res = invoke("import", near, "--out", near_h5, "--voltage", "1", "--strain", "5",
                 "--rate-hz", "200", "--strain-units", "raw")  # fmt: skip
    assert res.exit_code == 0, res.output
    check_unseen(training_setup([train, near_h5]), [prepare(test)])
    with pytest.raises(InputFileError, match="holds the same samples"):
        check_unseen(training_setup([train, copy]), [prepare(test)])


def test_several_training_files_are_fitted_together(files, tmp_path: Path) -> None:
    """Two imported files with the same entry name: fitted together, the names made unique."""
    train, test = files
    d = tmp_path / "other"
    d.mkdir()
    second = import_cut(REAL / FILES[0], d, "ident", rows=1200)
    v = labrig.validate([train, second], on=test)
    assert v.train_setup.scored == [f"{train}:ident", f"{second}:ident"]
    assert not v.train_setup.chain and v.train_setup.offset
    assert v.models["dynamic"].mean("whole_nrmse_pct") < 1.5


def test_score_entry_rule() -> None:
    """The rule on synthetic numbers: a constant offset costs nothing, either way; a drift is
    scored on the second half from the first half's offset."""
    m = np.sin(np.linspace(0, 20, 1000)) * 10.0
    C = np.ones((m.size, 1))
    w, h = score_entry(m, m + 3.0, C)
    assert w == pytest.approx(0.0, abs=1e-12) and h == pytest.approx(0.0, abs=1e-12)
    ramp = np.linspace(0.0, 1.0, m.size)
    w, h = score_entry(m, m + ramp, C)
    r_whole = ramp - ramp.mean()
    assert w == pytest.approx(100 * np.sqrt(np.mean(r_whole**2)) / np.ptp(m), rel=1e-12)
    half = m.size // 2
    r_half = ramp[half:] - ramp[:half].mean()
    assert h == pytest.approx(100 * np.sqrt(np.mean(r_half**2)) / np.ptp(m), rel=1e-12)
    w0, h0 = score_entry(m, m + 3.0, np.zeros((m.size, 0)))  # no nuisance: the offset counts
    assert w0 == pytest.approx(300 / np.ptp(m)) and h0 == pytest.approx(300 / np.ptp(m))


def test_report_with_params_from_elsewhere_says_what_it_compares(
    files, result, tmp_path: Path
) -> None:
    """``labrig report TEST --params TRAIN.json``: our model identified on TRAIN, the peers
    fitted on TEST itself; the table, the page and the notes say so and point to validate."""
    _, test = files
    params = tmp_path / "train.json"
    doc = {"params": result.models["dynamic"].params, "method": "global", "entries": ["ident"]}
    params.write_text(json.dumps(doc))
    res = invoke("report", test, "--params", params, "--no-heldout", columns=400)
    assert res.exit_code == 0, res.output
    table = " ".join(res.stdout.split())
    assert "Not a like-for-like comparison" in table
    assert "identified on ident" in table and "scored in-sample" in table
    assert f"labrig validate TRAIN.h5 --on {test.name}" in table
    # the page (its text; the figures are the report's own): the same, in the summary
    setup = prepare(test)
    fitted = fit_report_models(setup, doc, params, "global", False, lambda *a: None)
    page = render(report_data(setup, fitted, False, True), None, {})
    summary = page[page.index('id="summary"') : page.index('id="metrics"')]
    assert "What this page compares" in summary and "scored in-sample" in summary


def test_report_fits_the_peers_on_the_training_files_the_params_name(
    files, result, tmp_path: Path
) -> None:
    """A parameter file that names its training files (``train_files``, as ``labrig fit``
    writes it): the report identifies the peers on those files too, predicts its own records
    with them (one offset per entry over the scored samples) and has nothing to warn about."""
    train, test = files
    params = tmp_path / "train.json"
    doc = {
        "params": result.models["dynamic"].params,
        "method": "global",
        "entries": ["ident"],
        "train_files": [str(train)],
    }
    params.write_text(json.dumps(doc))
    setup = prepare(test)
    fitted = fit_report_models(setup, doc, params, "global", False, lambda *a: None)
    assert fitted.caveat is None and fitted.peers_on == [train]
    (rec,) = records_from_run(train)
    pi = fit_baseline([rec], "prandtl_ishlinskii", heldout=False, warmup_s=WARMUP_S, offset=True)
    fm = fitted.models["prandtl_ishlinskii"]
    assert fm.params["weights_ue_per_V"] == pytest.approx(pi.params["weights_ue_per_V"], rel=1e-9)
    # its prediction of the test record: the training fit's model run on the test voltage
    (trec,) = records_from_run(test)
    raw = pi.model.predict(trec.voltage_V, rest_V=trec.rest_V)
    i0 = round(WARMUP_S * trec.rate_hz)
    expected = raw + np.mean(trec.strain_ue[i0:] - raw[i0:])
    assert fm.predictions[trec.name] == pytest.approx(expected, rel=1e-9, abs=1e-9)
    # the same scores as validate's whole-record rule
    m = trec.strain_ue[i0:]
    got = 100 * np.sqrt(np.mean((m - fm.predictions[trec.name][i0:]) ** 2)) / np.ptp(m)
    assert got == pytest.approx(result.models["prandtl_ishlinskii"].mean("whole_nrmse_pct"))
    assert "What this page compares" not in render(
        report_data(setup, fitted, False, True), None, {}
    )
    # training files that are gone: back to the in-sample peers, said plainly
    doc["train_files"] = [str(tmp_path / "gone.h5")]
    fitted = fit_report_models(setup, doc, params, "global", False, lambda *a: None)
    assert fitted.peers_on is None and "Not a like-for-like" in (fitted.caveat or "")
    assert any("not found" in n and "gone.h5" in n for n in fitted.notes)


@pytest.mark.slow
def test_report_page_with_params_from_a_fit_of_another_file(files, tmp_path: Path) -> None:
    """End to end: ``labrig fit TRAIN`` writes its training file; ``labrig report TEST
    --params`` fits the peers on it (no caveat); the same report on the training file itself
    keeps its peers in-sample, like our model (no caveat either)."""
    train, test = files
    params = tmp_path / "train.json"
    assert invoke("fit", train, "--no-heldout", "--out", params).exit_code == 0
    assert json.loads(params.read_text())["train_files"] == [str(train.resolve())]
    page = tmp_path / "r.html"
    res = invoke("report", test, "--params", params, "--no-heldout", "--out", page)
    assert res.exit_code == 0, res.output
    html = page.read_text(encoding="utf-8")
    assert "What this page compares" not in html and "training files of" in html
    res = invoke("report", train, "--params", params, "--no-heldout", "--json")
    assert res.exit_code == 0 and "like-for-like" not in res.stderr


def test_report_without_params_says_nothing_of_the_kind(files) -> None:
    """Every model fitted on the same records: no caveat (the fitted-now path sets none)."""
    _, test = files
    setup = prepare(test)
    fitted = fit_report_models(setup, None, None, "global", False, lambda *a: None)
    assert fitted.caveat is None
    assert "What this page compares" not in render(
        report_data(setup, fitted, False, False), None, {}
    )


@pytest.mark.slow
def test_diagnose_now_equals_effects_from_the_diagnosis_file(files, tmp_path: Path) -> None:
    """``--diagnose`` carries what ``labrig diagnose`` of the training file accepts: the same
    effects and the same scores as ``--effects-from`` its diagnosis.json (about 45 s of CPU)."""
    train, test = files
    res = invoke("diagnose", train, "--out", tmp_path / "diag")
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "diag" / "diagnosis.json").read_text())
    names = [e["effect"] for e in doc["effects_added"]]
    now = labrig.validate(train, on=test, diagnose=True)
    given = labrig.validate(train, on=test, effects_from=tmp_path / "diag" / "diagnosis.json")
    assert now.effects == given.effects == names
    for key in now.models:
        a, b = now.models[key], given.models[key]
        assert a.mean("whole_nrmse_pct") == pytest.approx(b.mean("whole_nrmse_pct"), rel=1e-9)


@pytest.fixture(scope="module")
def rig_runs(tiny_run: Path, tmp_path_factory) -> tuple[Path, Path]:
    """The shared run of TINY (seed 1) and another (seed 2)."""
    return tiny_run, run_protocol(TINY, tmp_path_factory.mktemp("rig"), seed=2)


def test_recorded_runs_are_chained_and_scored_without_offset(rig_runs, files) -> None:
    """Two recorded runs of the simulated rig: each simulated as a chain of its entries with
    their rests, no offset (the conditioner is zeroed at rest), so the whole-record NRMSE is
    the plain NRMSE of the exported prediction; a recorded run with another training file is
    refused (exit 2 naming it)."""
    a, b = rig_runs
    v = labrig.validate(a, on=b)
    assert v.tests[0].chain and not v.tests[0].offset
    recs = records_from_run(b)
    assert [r.name for r in recs] == v.tests[0].scored
    for key, m in v.models.items():
        for r in recs:
            p = m.predictions[(str(b), r.name)]
            e = r.strain_ue - p
            ref = 100 * np.sqrt(np.mean(e**2)) / np.ptp(r.strain_ue)
            sc = next(s for s in m.scores if s.entry == r.name)
            assert sc.whole_nrmse_pct == pytest.approx(ref, rel=1e-9), (key, r.name)
            h = r.n // 2
            ref_h = 100 * np.sqrt(np.mean(e[h:] ** 2)) / np.ptp(r.strain_ue)
            assert sc.second_half_nrmse_pct == pytest.approx(ref_h, rel=1e-9), (key, r.name)
    # the truth is our model: it predicts the other run near the noise floor, the peers do not
    ours = v.models["dynamic"].mean("whole_nrmse_pct")
    assert ours < 2 * v.noise_floor_pct
    assert ours < min(
        v.models[k].mean("whole_nrmse_pct") for k in ("prandtl_ishlinskii", "bouc_wen")
    )
    res = invoke("validate", a, b, "--on", b)  # b on both sides: refused first
    assert res.exit_code == 2 and "both as training and as test" in res.output
    res = invoke("validate", a, files[0], "--on", b)
    assert res.exit_code == 2 and "only training file" in res.output and str(a) in res.output


def test_report_out_never_replaces_a_training_file_the_params_name(files, tmp_path: Path) -> None:
    """The training files a parameter file names are inputs of ``labrig report``: ``--out``
    onto one is exit 2 naming it, even with ``--overwrite``, and the file is left as it was;
    a parameter file naming other files does not refuse the same ``--out``."""
    train, test = files
    before = train.read_bytes()
    params = tmp_path / "train.json"
    params.write_text(json.dumps({"params": {}, "train_files": [str(train)]}))
    res = invoke("report", test, "--params", params, "--out", train, "--overwrite")
    assert res.exit_code == 2 and str(train.name) in res.output, res.output
    assert "Traceback" not in res.output and train.read_bytes() == before
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"params": {}, "train_files": [str(tmp_path / "elsewhere.h5")]}))
    from labrig.commands.report import named_training_files

    assert named_training_files(other) == [tmp_path / "elsewhere.h5"]
    assert named_training_files(tmp_path / "missing.json") == []


@pytest.mark.slow
def test_leave_one_out_predicts_each_file_from_the_others(files, tmp_path: Path) -> None:
    """``--leave-one-out A B C``: fold k is ``validate`` of the other two on file k (the same
    scores as that call), the summary the mean over the folds; the table names every file."""
    train, test = files
    d = tmp_path / "third"
    d.mkdir()
    third = import_cut(REAL / FILES[1], d, "valid2", rows=800)
    loo = labrig.commands.validate.validate_leave_one_out([train, test, third])
    assert [v.test for v in loo.folds] == [[train], [test], [third]]
    assert [v.train for v in loo.folds] == [[test, third], [train, third], [train, test]]
    alone = labrig.validate([train, test], on=third)
    for key, m in alone.models.items():
        assert loo.folds[2].models[key].mean("whole_nrmse_pct") == m.mean("whole_nrmse_pct")
    doc = loo.to_json()
    for key in ("dynamic", "prandtl_ishlinskii", "bouc_wen", "sindy"):
        per = [v.models[key].mean("second_half_nrmse_pct") for v in loo.folds]
        assert doc["models"][key]["second_half_nrmse_pct"] == pytest.approx(sum(per) / 3)
        assert list(doc["models"][key]["per_file"]) == [str(train), str(test), str(third)]
    res = invoke("validate", "--leave-one-out", train, test, third)
    assert res.exit_code == 0, res.output
    assert all(p.stem in res.output for p in (train, test, third))


def test_leave_one_out_folds(monkeypatch, tmp_path: Path) -> None:
    """The fast tier's check of ``--leave-one-out`` (the slow test above runs the fits): fold
    k trains on every file but k and tests on k, with the options passed on; the summary is
    the mean over the folds of each fold's mean."""
    from types import SimpleNamespace

    import labrig.commands.validate as cv

    calls = []

    def fake(train, on, **kw):
        calls.append((list(train), list(on), kw))
        k = len(calls)
        m = cv.ValidatedModel("dynamic", "ours")
        m.scores = [cv.EntryScore(str(on[0]), "e", float(k), 10.0 * k)]
        return SimpleNamespace(
            test=list(on), models={"dynamic": m}, noise_floor_pct=0.1 * k, to_json=lambda: {}
        )

    monkeypatch.setattr(cv, "validate_runs", fake)
    paths = [tmp_path / f"{c}.h5" for c in "abcd"]
    loo = cv.validate_leave_one_out(paths, run_diagnosis=True, method="staged")
    assert [c[1] for c in calls] == [[p] for p in paths]
    assert [c[0] for c in calls] == [[q for q in paths if q != p] for p in paths]
    assert all(c[2]["run_diagnosis"] and c[2]["method"] == "staged" for c in calls)
    doc = loo.to_json()
    assert doc["models"]["dynamic"]["whole_nrmse_pct"] == pytest.approx(2.5)
    assert doc["models"]["dynamic"]["second_half_nrmse_pct"] == pytest.approx(25.0)
    assert doc["models"]["dynamic"]["per_file"] == {str(p): k + 1.0 for k, p in enumerate(paths)}
    assert doc["noise_floor_pct"] == pytest.approx(0.25)


def test_leave_one_out_bad_usage(files) -> None:
    train, test = files
    res = invoke("validate", "--leave-one-out", train, test)
    assert res.exit_code == 2 and "at least 3 files" in res.output, res.output
    res = invoke("validate", "--leave-one-out", train, test, train)
    assert res.exit_code == 2 and "twice" in res.output, res.output
    res = invoke("validate", "--leave-one-out", train, test, "--on", test)
    assert res.exit_code == 64 and "--on" in res.output, res.output
    res = invoke("validate", "--leave-one-out", train, test, test, "--overwrite")
    assert res.exit_code == 64 and "takes no --overwrite" in res.output, res.output
    res = invoke("validate", train)
    assert res.exit_code == 64 and "--leave-one-out" in res.output, res.output


def test_leave_one_out_table_names_files_apart(capsys) -> None:
    """Two files of one name in different folders: the table's columns are their paths, not
    their names twice; distinct names stay short."""
    from labrig.cli.validate import print_leave_one_out

    def doc(files: list[str]) -> dict:
        per = {f: 0.5 + k for k, f in enumerate(files)}
        model = {"label": "ours", "per_file": per, "whole_nrmse_pct": 1.0}
        model["second_half_nrmse_pct"] = 1.1
        return {"leave_one_out": files, "models": {"dynamic": model}, "noise_floor_pct": 0.1}

    print_leave_one_out(doc(["a/run.h5", "b/run.h5", "c/other.h5"]))
    out = capsys.readouterr().out
    assert "a/run.h5" in out and "b/run.h5" in out and "c/other.h5" in out
    print_leave_one_out(doc(["a/run.h5", "b/third.h5", "c/other.h5"]))
    out = capsys.readouterr().out
    assert "run" in out and "third" in out and "a/run.h5" not in out
