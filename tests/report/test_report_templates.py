"""The report, diagnosis and fleet pages are jinja2 templates in the package: they ship as
package data, escape every text (a run file's names cannot inject markup), refuse a value
they are not given, can be restyled from a folder of templates, and show every number of the
metrics table."""

from __future__ import annotations

import fnmatch
import tomllib
from pathlib import Path

import jinja2
import numpy as np
import pytest

from labrig.analysis.records import Record
from labrig.report.data import METRICS, PARAM_ROWS, Fitted, Provenance, build_report
from labrig.report.html import fmt, render
from labrig.report.templating import TEMPLATES_ENV
from labrig.report.templating import render as render_template

ROOT = Path(__file__).resolve().parents[2]
TEMPLATES = ROOT / "labrig" / "report" / "templates"
HOSTILE = "<script>alert(1)</script>"


def test_templates_are_package_data() -> None:
    """Every template file matches a package-data pattern of labrig.report (a wheel carries
    them), and every page the code renders is among them."""
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    patterns = conf["package-data"]["labrig.report"]
    files = sorted(p.relative_to(TEMPLATES.parent).as_posix() for p in TEMPLATES.iterdir())
    assert {"templates/report.html.j2", "templates/diagnosis.html.j2", "templates/fleet.html.j2",
            "templates/control.html.j2", "templates/style.css"} <= set(files)  # fmt: skip
    for f in files:
        assert any(fnmatch.fnmatch(f, p) for p in patterns), (f, patterns)
    assert "labrig.report" in conf["packages"]


def sine_records(names: list[str]) -> list[Record]:
    t = np.arange(2000) / 1000.0
    out = []
    for k, name in enumerate(names):
        v = 50 * (1 - np.cos(2 * np.pi * (5 + 5 * k) * t))
        out.append(Record.from_arrays(name, 1000.0, v, 1.1 * v + 3 * np.sin(v / 20)))
    return out


def page_of(names: list[str], run_file: str = "run.h5") -> tuple[str, object]:
    recs = sine_records(names)
    params = {n: 1.0 + i for i, (n, _, _) in enumerate(PARAM_ROWS)}
    params.update(shape="exponential", memory="return_point")
    models = {
        "dynamic": Fitted(
            "dynamic",
            {r.name: 1.1 * r.voltage_V for r in recs},
            {r.name: 2.0 for r in recs},
            params=params,
            uncertainty={n: 0.1 for n, _, _ in PARAM_ROWS},
            method="global",
        ),
        "bouc_wen": Fitted("bouc_wen", None, note=f"cannot fit {HOSTILE}"),
    }
    data = build_report(
        f"Model versus measurement: {HOSTILE}",
        recs,
        models,
        0.0,
        Provenance(run_file=run_file, protocol_text=HOSTILE, instrument={"name": HOSTILE}),
        {"entries": names},
        notes=[f"a note {HOSTILE}"],
        generated="2026-01-01T00:00:00+00:00",
        labrig_version="0.1.0",
    )
    return render(data, None, {}), data


def test_every_text_is_escaped() -> None:
    page, _ = page_of([f"e{HOSTILE}", "plain"], run_file=f"/runs/{HOSTILE}.h5")
    assert "<script>" not in page
    assert page.count("&lt;script&gt;alert(1)&lt;/script&gt;") >= 6  # title, names, notes, ...


def test_the_page_shows_every_number_of_the_metrics() -> None:
    names = ["sine_a", "sine_b", "sine_c"]
    page, data = page_of(names)
    for e in data.entries:
        assert f">{e.name}</td>" in page
        for metric, _, _ in METRICS:
            v = e.metrics["dynamic"].get(metric)
            text = fmt(v, metric)
            assert text is None or f">{text}</td>" in page, (e.name, metric, text)
    for key in ("summary", "metrics", "frequency", "parameters", "entries", "provenance"):
        assert f'id="{key}"' in page
    assert "Bouc-Wen: not fitted (cannot fit &lt;script&gt;" in page
    assert "1 entry scored" in page_of(["only"])[0]  # plurals


def test_a_missing_value_is_an_error() -> None:
    """A value the page does not give is an error, not a blank (StrictUndefined)."""
    from labrig.report.html import report_context

    _, data = page_of(["sine_a"])
    context = report_context(data, None, {})
    del context["version"]
    with pytest.raises(jinja2.UndefinedError, match="version"):
        render_template("report.html.j2", **context)


def test_a_lab_restyles_from_a_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "style.css").write_text("body { color: #123456; }  /* our lab */\n")
    monkeypatch.setenv(TEMPLATES_ENV, str(tmp_path))
    page, _ = page_of(["sine_a"])
    assert "color: #123456" in page and "--ours: #b8302a" not in page
    monkeypatch.delenv(TEMPLATES_ENV)
    page, _ = page_of(["sine_a"])
    assert "--ours: #b8302a" in page


def test_diagnosis_and_fleet_pages_escape(tmp_path: Path) -> None:
    from labrig.analysis.diagnose import Diagnosis, Evidence
    from labrig.fleet.fleet_report import render_fleet
    from labrig.fleet.schedule import ScheduleInfo
    from labrig.report.diagnose_html import render_diagnosis

    recs = sine_records(["a", "b", "c"])
    score = {"nrmse_pct": 1.0, "heldout_nrmse_pct": 1.2, "per_entry": {r.name: 1.0 for r in recs}}
    evidence = Evidence({}, 1.0, 1.0, 1.0, {}, [f"evidence {HOSTILE}"])
    d = Diagnosis(
        score, score, [{"effect": "creep", "params": {"c": 0.01}, "evidence": HOSTILE}],
        [{"effect": "creep", "heldout_nrmse_pct": 0.5, "evidence": HOSTILE}],
        f"verdict {HOSTILE}", "explained", evidence, evidence,
        {r.name: r.strain_ue for r in recs}, {r.name: r.strain_ue for r in recs},
    )  # fmt: skip
    page = render_diagnosis(d, recs, title=HOSTILE)
    assert "<script>" not in page and page.count("&lt;script&gt;") >= 5
    rows = [{"run_file": HOSTILE, "key": "k", "status": "failed", "command": "fit",
             "error": HOSTILE}]  # fmt: skip
    page = render_fleet(rows, [], ScheduleInfo("serial", 1), tmp_path)
    assert "<script>" not in page and "&lt;script&gt;" in page
    assert "on 1 worker ·" in " ".join(page.split())
