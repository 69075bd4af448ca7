"""Import, fit and report on real measurements (skipped when the data are absent).

The yan9a-micromanipulator data set (:data:`REAL`; its README describes it): a piezo
micromanipulator at 1 Hz, 200 Hz sampling, no time column; column 1 the command at DAQ level
(V), column 5 a capacitive sensor in raw units. The raw reading rises with the voltage and its
loop runs counter-clockwise (rising branch below the falling one), the orientation of a piezo's
strain lagging its voltage, so it is imported as it is (no sign flip) and fitted in raw units
per DAQ volt. Both files start mid-stroke (not at rest) and the sensor's zero is arbitrary: the fit
uses its automatic two-period warm-up and one offset per entry.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from labrig.analysis.load import records_from_run
from labrig.analysis.metrics import loop_area

from helpers import invoke

REAL = Path(__file__).resolve().parents[1] / "data" / "real" / "yan9a-micromanipulator"
FILES = ("Model_Vi_Do.dat", "Test_Vi_Do_Di.dat")

pytestmark = pytest.mark.skipif(
    not all((REAL / f).is_file() for f in FILES), reason=f"real data not found in {REAL}"
)


def test_import_fit_report_on_real_data(tmp_path: Path) -> None:
    run = tmp_path / "real.h5"
    res = invoke("import", *(REAL / f for f in FILES), "--out", run, "--voltage", "1",
                 "--strain", "5", "--rate-hz", "200", "--strain-units", "raw")  # fmt: skip
    assert res.exit_code == 0, res.stderr
    records = records_from_run(run)
    assert [r.name for r in records] == ["Model_Vi_Do", "Test_Vi_Do_Di"]
    for r in records:  # the piezo's loop orientation: imported without a sign flip
        assert loop_area(r.voltage_V, r.strain_ue, r.rate_hz, 1.0) > 0
    # the sensor's numbers are labelled raw wherever a unit is shown, not ue
    info = invoke("info", run)
    assert info.exit_code == 0 and "max raw" in info.stdout and "max ue" not in info.stdout
    # the fit's table (its JSON in --out, what --json prints: tests/cli/test_cli_fit.py)
    params = tmp_path / "params.json"
    res = invoke("fit", run, "--out", params)
    assert res.exit_code == 0, res.stderr
    assert "raw/V" in res.stdout and "ue/V" not in res.stdout
    fit = json.loads(params.read_text())
    assert "do not start at rest" in res.stderr and "offset per entry" in res.stderr
    assert fit["nrmse_pct"] < 1.0 and fit["heldout_nrmse_pct"] < 1.0
    assert fit["uncertainty"]["lam_d"] is None  # 1 Hz only: G_d fixed, said in a note

    out = tmp_path / "real.html"
    res = invoke("report", run, "--params", params, "--out", out, "--json")
    assert res.exit_code == 0, res.stderr
    table = json.loads(res.stdout)
    page = out.read_text(encoding="utf-8")
    assert "imported data" in page and "http" not in page
    assert page.count("<img ") == 2  # one per entry; no frequency figure (1 Hz only)
    for model in ("prandtl_ishlinskii", "bouc_wen"):
        ours = [row["dynamic.nrmse_pct"] for row in table.values()]
        theirs = [row[f"{model}.nrmse_pct"] for row in table.values()]
        held = [row[f"{model}.heldout_nrmse_pct"] for row in table.values()]
        assert sum(ours) < sum(theirs)
        assert fit["heldout_nrmse_pct"] < sum(held) / len(held)
