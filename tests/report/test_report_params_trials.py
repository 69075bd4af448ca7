"""``labrig report --params``: what an adversarial trial found in the parameter file's use.

- every section of the file the report uses is checked when the file is read: a hand-edited
  ``uncertainty``, ``correlation``, ``identifiability``, ``heldout_nrmse_pct`` (or ``method``,
  ``entries``, ``train_files``) is refused, exit 2, naming the file and the field, where it
  crashed the page (exit 1) and passed ``--json`` silently;
- the effects' parameters are checked against the bounds each library effect declares;
- a model identified on strain in ``ue`` does not predict records in ``raw`` units (as
  ``labrig validate`` refuses them);
- the peers are identified on the records our model was (the file's training file and its
  ``entries``), not on every entry of it, and the page says what its NRMSE is: in-sample on
  the entries every model was identified on, out-of-sample on the others;
- the drive amplitude of a vanishing entry is its whole span, not its last period's.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from labrig.analysis.records import Record
from labrig.commands.prepare import prepare
from labrig.commands.report import fit_report_models, report_data
from labrig.report.data import drive_of
from labrig.report.html import render

from helpers import invoke

#: the entries of helpers.TINY, in run order
FIRST, SECOND, THIRD = "sine_60V_2Hz", "sine_80V_2Hz", "sine_100V_2Hz"


def _quiet(*_: object) -> None:
    """A progress callback that says nothing."""


@pytest.fixture(scope="module")
def fits(tiny_run: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``labrig fit`` of the tiny run on every entry (``all``) and on its first one only
    (``first``)."""
    folder = tmp_path_factory.mktemp("trial_fits")
    out = {"all": folder / "all.json", "first": folder / "first.json"}
    res = invoke("fit", tiny_run, "--no-heldout", "--out", out["all"])
    assert res.exit_code == 0, res.output
    res = invoke("fit", tiny_run, "--no-heldout", "--entries", FIRST, "--out", out["first"])
    assert res.exit_code == 0, res.output
    return out


def _edited(src: Path, folder: Path, name: str, edit) -> Path:
    doc = json.loads(src.read_text())
    edit(doc)
    path = folder / f"{name}.json"
    path.write_text(json.dumps(doc))
    return path


def _report(run: Path, params: Path, *extra: object):
    return invoke("report", run, "--params", params, "--no-heldout", "--json", *extra)


EDITS = {
    "uncertainty.vc_V": (lambda d: d["uncertainty"].__setitem__("vc_V", "big"), "'big' is not"),
    "uncertainty": (lambda d: d.__setitem__("uncertainty", [1]), "is not an object"),
    "uncertainty.lam_t": (lambda d: d["uncertainty"].__setitem__("lam_t", -1.0), "negative"),
    "correlation": (lambda d: d.__setitem__("correlation", [1, 2]), "is not an object"),
    "correlation.vc_V.gamma_ue_per_V": (
        lambda d: d["correlation"]["vc_V"].__setitem__("gamma_ue_per_V", "x"),
        "'x' is not a number",
    ),
    "identifiability": (lambda d: d.__setitem__("identifiability", "x"), "is not an object"),
    "identifiability.loop.span_V": (
        lambda d: d["identifiability"]["loop"].__setitem__("span_V", "wide"),
        "voltage above 0 V",
    ),
    "heldout_nrmse_pct": (lambda d: d.__setitem__("heldout_nrmse_pct", "x"), "number >= 0"),
    "method": (lambda d: d.__setitem__("method", 5), "is not a string"),
    "entries": (lambda d: d.__setitem__("entries", [1, 2]), "list of distinct entry names"),
    "train_files": (lambda d: d.__setitem__("train_files", "run.h5"), "list of distinct run"),
}


@pytest.mark.parametrize("field", sorted(EDITS))
def test_a_hand_edited_section_is_refused_naming_file_and_field(
    tiny_run: Path, fits: dict[str, Path], tmp_path: Path, field: str
):
    edit, why = EDITS[field]
    bad = _edited(fits["all"], tmp_path, "q", edit)
    res = _report(tiny_run, bad, "--peers", "none")
    assert res.exit_code == 2, res.output
    assert f"{bad}: [{field}] " in res.stderr and why in res.stderr
    assert "Traceback" not in res.stderr and res.stdout == ""


def test_every_problem_of_the_file_is_named_at_once(
    tiny_run: Path, fits: dict[str, Path], tmp_path: Path
):
    def edit(d: dict) -> None:
        d["uncertainty"]["vc_V"] = "big"
        d["heldout_nrmse_pct"] = "x"

    res = _report(tiny_run, _edited(fits["all"], tmp_path, "q", edit), "--peers", "none")
    assert res.exit_code == 2
    assert "[uncertainty.vc_V]" in res.stderr and "[heldout_nrmse_pct]" in res.stderr


def test_effect_parameters_outside_their_declared_bounds_are_refused(
    tiny_run: Path, fits: dict[str, Path], tmp_path: Path
):
    """c = -5 and tau_s = -1 s for viscoelastic_creep (bounds -0.3..0.5 and 1 ms..30 s, as its
    Param declares them) predicted a strain of 489 % NRMSE; within them the file is used."""

    def creep(c: float, tau_s: float):
        effect = {"effect": "viscoelastic_creep", "params": {"c": c, "tau_s": tau_s}}
        return lambda d: d.__setitem__("effects", [effect])

    bad = _edited(fits["all"], tmp_path, "bad", creep(-5.0, -1.0))
    res = _report(tiny_run, bad, "--peers", "none")
    assert res.exit_code == 2, res.output
    text = " ".join(res.stderr.split())
    assert f"{bad}: [effects[0].params.tau_s] -1 is outside" in text
    assert "0.001 to 30 s" in text
    assert "[effects[0].params.c] -5 is outside" in text and "-0.3 to 0.5" in text
    good = _edited(fits["all"], tmp_path, "good", creep(0.01, 0.5))
    assert _report(tiny_run, good, "--peers", "none").exit_code == 0


@pytest.fixture(scope="module")
def imported(tiny_run: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The tiny run's first entry exported and imported again: as it is (``ue``) and with its
    strain declared ``raw``."""
    folder = tmp_path_factory.mktemp("trial_import")
    assert invoke("export", tiny_run, "--out", folder / "csv").exit_code == 0
    (csv,) = [p for p in (folder / "csv").glob("*.csv") if FIRST in p.name]
    out = {"ue": folder / "ue.h5", "raw": folder / "raw.h5"}
    assert invoke("import", csv, "--out", out["ue"]).exit_code == 0
    res = invoke("import", csv, "--out", out["raw"], "--strain-units", "raw")
    assert res.exit_code == 0, res.output
    return out


def test_a_model_in_ue_does_not_predict_raw_records(
    imported: dict[str, Path], fits: dict[str, Path]
):
    res = _report(imported["raw"], fits["all"], "--peers", "none")
    assert res.exit_code == 2, res.output
    text = " ".join(res.stderr.split())
    assert f"{fits['all']}: [train_files] its model was identified on strain in 'ue'" in text
    assert "the report's records are in 'raw'" in text and "/strain] in 'raw'" in text
    assert _report(imported["ue"], fits["all"], "--peers", "none").exit_code == 0


def _pi_nrmse(run: Path, params: Path) -> dict[str, float]:
    res = _report(run, params, "--peers", "prandtl_ishlinskii")
    assert res.exit_code == 0, res.output
    return {e: row["prandtl_ishlinskii.nrmse_pct"] for e, row in json.loads(res.stdout).items()}


def test_the_peers_are_identified_on_the_entries_our_model_was(
    tiny_run: Path, fits: dict[str, Path]
):
    """Our model fitted on the first entry only: the Prandtl-Ishlinskii baseline too, so its
    score on that entry is its in-sample score of a fit on that entry alone, and differs from
    the report with parameters fitted on every entry (they were equal: the peers were fitted
    on every entry of the training file whatever our model was fitted on)."""
    alone = invoke(
        "fit", tiny_run, "--model", "prandtl_ishlinskii", "--entries", FIRST, "--no-heldout",
        "--json",
    )  # fmt: skip
    assert alone.exit_code == 0, alone.output
    one = _pi_nrmse(tiny_run, fits["first"])
    assert one[FIRST] == pytest.approx(json.loads(alone.stdout)["per_entry"][FIRST], rel=1e-6)
    every = _pi_nrmse(tiny_run, fits["all"])
    assert one[FIRST] != pytest.approx(every[FIRST], rel=1e-3)


def test_on_another_file_the_peers_are_identified_on_the_entries_our_model_was(
    imported: dict[str, Path], fits: dict[str, Path]
):
    one = _pi_nrmse(imported["ue"], fits["first"])
    every = _pi_nrmse(imported["ue"], fits["all"])
    assert one[FIRST] != pytest.approx(every[FIRST], rel=1e-3)


def _page(run: Path, params: Path) -> str:
    """The report's page without figures (its text), every peer fitted."""
    doc = json.loads(params.read_text())
    setup = prepare(run)
    fitted = fit_report_models(setup, doc, params, "global", False, _quiet)
    return render(report_data(setup, fitted, False, True), None, {})


def _metrics_table(page: str) -> str:
    """The summary and the metrics table of a page."""
    return page[page.index('id="summary"') : page.index('id="frequency"')]


def _headings(page: str) -> set[str]:
    """The text at the start of every heading cell of ``page``."""
    return {h.strip() for h in re.findall(r"<th[^>]*>([^<]*)", page)}


def test_the_page_says_which_entries_are_in_sample(tiny_run: Path, fits: dict[str, Path]):
    """The training file is the report's: the entry the models were identified on is marked,
    the others are out-of-sample, and the heading does not call the column in-sample; the
    note says where every model was identified."""
    page = _metrics_table(_page(tiny_run, fits["first"]))
    assert {"NRMSE", "NRMSE (%)"} <= _headings(page)
    assert not any("in-sample" in h for h in _headings(page))
    assert f'{FIRST} <span class="small">(training)</span>' in page
    assert f"{SECOND} <span" not in page and f"{THIRD} <span" not in page
    assert (
        f"our model and the peers are identified on {FIRST} of {tiny_run.name} (the training "
        f"files of first.json) and predict the records of this report: in-sample on {FIRST}, "
        "out-of-sample on the others"
    ) in page
    whole = _metrics_table(_page(tiny_run, fits["all"]))
    assert "NRMSE in-sample (%)" in _headings(whole) and "(training)" not in whole


def test_with_parameters_from_another_file_the_column_is_out_of_sample(
    tiny_run: Path, imported: dict[str, Path], fits: dict[str, Path]
):
    page = _metrics_table(_page(imported["ue"], fits["first"]))
    assert {"NRMSE out-of-sample", "NRMSE out-of-sample (%)"} <= _headings(page)
    assert not any("in-sample" in h for h in _headings(page))
    assert (
        f"our model and the peers are identified on {FIRST} of {tiny_run.name} (the training "
        "files of first.json) and predict the records of this report, out-of-sample"
    ) in page


def test_a_vanishing_entry_states_its_whole_span_not_its_last_period():
    """A 5 Hz drive of 70 V fading out over 2 s: its last period spans a fraction of a volt
    (the page said 0.66 V for a drive up to 70 V)."""
    rate = 1000.0
    t = np.arange(3000) / rate
    envelope = np.where(t < 1.0, 70.0, 70.0 * np.exp(-(t - 1.0) / 0.3))
    v = envelope * 0.5 * (1.0 - np.cos(2 * np.pi * 5.0 * t))
    rec = Record.from_arrays("vanishing", rate, v, 0.8 * v, frequency_hz=5.0)
    f, periodic, amplitude = drive_of(rec)
    assert f == 5.0 and not periodic
    assert amplitude == pytest.approx(70.0, rel=1e-3)
