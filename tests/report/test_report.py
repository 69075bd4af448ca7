"""``labrig report``: one self-contained HTML file and the metrics table as JSON.

The run is a reduced campaign on the simulated rig (see test_cli_fit.py); the report either
fits first (held-out on a few chosen entries, to stay fast) or takes ``labrig fit --out``
parameters.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from labrig.analysis.noise_floor import noise_floor, residual_noise
from labrig.analysis.records import Record
from labrig.report.data import METRICS, MODEL_KEYS

from helpers import SMALL_CAMPAIGN, invoke, run_protocol

SECTIONS = ("summary", "metrics", "frequency", "parameters", "entries", "provenance")
CHOSEN = ["sine_50V_1Hz", "sine_100V_5Hz", "sine_50V_40Hz", "vanishing_100V_1Hz"]
CHOSEN_RUN_ORDER = ["sine_50V_1Hz", "sine_50V_40Hz", "sine_100V_5Hz", "vanishing_100V_1Hz"]


@pytest.fixture(scope="module")
def small_run(tmp_path_factory) -> Path:
    return run_protocol(SMALL_CAMPAIGN, tmp_path_factory.mktemp("report"), seed=6)


@pytest.fixture(scope="module")
def fitted_report(small_run: Path, tmp_path_factory) -> tuple[Path, dict, str]:
    """Report that fits first, on chosen entries, with held-out NRMSE, and --json."""
    out = tmp_path_factory.mktemp("html") / "report.html"
    res = invoke("report", small_run, "--out", out, "--entries", ",".join(CHOSEN), "--json")
    assert res.exit_code == 0, res.stderr
    return out, json.loads(res.stdout), res.stderr


def assert_self_contained(page: str) -> None:
    assert page.startswith("<!DOCTYPE html>")
    low = page.lower()
    for bad in ("http://", "https://", "<script", "<link", "@import", "url(", "<iframe"):
        assert bad not in low, bad
    srcs = re.findall(r"""src\s*=\s*["']([^"']*)""", page)
    assert srcs and all(s.startswith("data:image/png;base64,") for s in srcs)


def test_report_is_one_self_contained_file(fitted_report) -> None:
    out, _, stderr = fitted_report
    page = out.read_text(encoding="utf-8")
    assert_self_contained(page)
    for sec in SECTIONS:
        assert f'id="{sec}"' in page
    # one figure per entry plus the frequency figure (periodic entries at 1, 5 and 40 Hz)
    assert page.count("<img ") == len(CHOSEN) + 1
    for name in CHOSEN:
        assert f"<h3>{name}</h3>" in page
    for text in ("Prandtl-Ishlinskii", "Bouc-Wen", "fractional-order model", "NRMSE held-out",
                 "loop-area error", "strain-shift error", "max error", "± 1σ", "alpha0_ue_per_V",
                 "small campaign", "labrig 0.1.0", "Noise floor", "Protocol file",
                 "Instrument description", "seed</dt><dd>6"):  # fmt: skip
        assert text in page, text
    # the envelope is not periodic: said in the notes
    assert "not computed for vanishing_100V_1Hz" in page
    assert "wrote" in stderr


def test_report_json_metrics_table(fitted_report) -> None:
    _, table, _ = fitted_report
    assert list(table) == CHOSEN_RUN_ORDER
    for name, row in table.items():
        for model in MODEL_KEYS:
            for metric, _, _ in METRICS:
                key = f"{model}.{metric}"
                assert key in row, key
                assert row[key] is None or isinstance(row[key], float)
        assert row["dynamic.nrmse_pct"] < 1.0
        assert row["dynamic.heldout_nrmse_pct"] is not None
        # our model beats both rate-independent baselines on the simulated rig
        assert row["dynamic.nrmse_pct"] < row["prandtl_ishlinskii.nrmse_pct"]
        assert row["dynamic.nrmse_pct"] < row["bouc_wen.nrmse_pct"]
        periodic = not name.startswith("vanishing")
        assert (row["dynamic.loop_area_error_pct"] is not None) == periodic
        assert (row["measured.strain_shift_ue"] is not None) == periodic
    assert abs(table["sine_50V_40Hz"]["dynamic.loop_area_error_pct"]) < 5.0


def test_report_from_params_file(small_run: Path, tmp_path: Path) -> None:
    params = tmp_path / "params.json"
    res = invoke("fit", small_run, "--no-heldout", "--json", "--out", params)
    assert res.exit_code == 0, res.stderr
    out = tmp_path / "r.html"
    # two entries and our model only: each entry drawn costs a figure, and the peers are not
    # what this checks (test_report_json_metrics_table; every entry of a run is drawn by
    # default with --params too: test_report_real.py)
    res = invoke("report", small_run, "--params", params, "--out", out, "--no-heldout",
                 "--peers", "none", "--entries", "sine_50V_1Hz,sine_100V_40Hz")  # fmt: skip
    assert res.exit_code == 0, res.stderr
    assert res.stdout.strip() == str(out)
    page = out.read_text(encoding="utf-8")
    assert_self_contained(page)
    assert page.count("<img ") == 2 + 1  # the entries and the frequency figure
    assert "<h3>sine_50V_1Hz</h3>" in page and "<h3>sine_100V_40Hz</h3>" in page
    assert f"from {params}" in page
    assert "held-out NRMSE not computed" in page


def test_report_refuses_baseline_params(small_run: Path, tmp_path: Path) -> None:
    params = tmp_path / "pi.json"
    res = invoke("fit", small_run, "--model", "prandtl_ishlinskii", "--no-heldout", "--out", params)
    assert res.exit_code == 0, res.stderr
    res = invoke("report", small_run, "--params", params, "--out", tmp_path / "r.html")
    assert res.exit_code == 2
    assert "baseline" in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "r.html").exists()


# -- noise floor -----------------------------------------------------------------------------------


def test_residual_noise_cancels_errors_locked_to_the_drive() -> None:
    """A periodic model error 20x the noise repeats every period and cancels; a smooth
    error of a non-periodic record cancels in the second difference. Noise: 1.5 ue rms, the
    estimate within 5 % (4 000 and 20 000 samples: standard error about 2 % and 1 %)."""
    rng = np.random.default_rng(1)
    period = 200
    locked = 30.0 * np.sin(2 * np.pi * np.arange(20 * period) / period) ** 3
    noisy = locked + rng.normal(0, 1.5, locked.size)
    assert residual_noise(noisy, period) == pytest.approx(1.5, rel=0.05)
    t = np.linspace(0.0, 1.0, 20000)
    smooth = 40.0 * np.exp(-3 * t) + 10 * t**2
    assert residual_noise(smooth + rng.normal(0, 1.5, t.size), None) == pytest.approx(1.5, rel=0.05)


def test_noise_floor_is_the_noise_over_each_span() -> None:
    """Two periodic entries of spans 200 and 400 ue with 2 ue of noise: floors 1 % and 0.5 %,
    mean 0.75 %; an entry without a prediction is left out."""
    rng = np.random.default_rng(2)
    rate, f = 1000.0, 5.0
    t = np.arange(4000) / rate
    v = 50 * (1 - np.cos(2 * np.pi * f * t))
    recs, preds = [], {}
    for name, gain in (("a", 2.0), ("b", 4.0)):
        clean = gain * v
        recs.append(Record.from_arrays(name, rate, v, clean + rng.normal(0, 2.0, t.size)))
        preds[name] = clean + 3.0 * np.sin(2 * np.pi * f * t)  # a model error locked to the drive
    recs.append(Record.from_arrays("c", rate, v, 3 * v))
    nf = noise_floor(recs, preds)
    assert nf is not None
    assert nf.noise_ue == pytest.approx(2.0, rel=0.05)
    assert nf.nrmse_pct == pytest.approx(0.75, rel=0.05)
    assert noise_floor(recs, {}) is None
