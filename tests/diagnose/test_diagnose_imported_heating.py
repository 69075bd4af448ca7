"""A self-heated campaign measured elsewhere: CSV files with a temperature column, imported with
no options (the temperature column is kept as ``temperature``, degC), diagnosed: thermal_drift
is named first with its coefficient, and the model is left at the noise floor.

The bench: +0.5 %/K of strain per kelvin, the stack heating by up to 20 K over the campaign
(loss factor 0.1, 0.04 J/K, 300 K/W)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

import labrig
from labrig.cli import app
from labrig.studies.campaign import bench_campaign

K_PER_K = 0.005
HEATING = {
    "name": "self_heating",
    "heat_capacity_J_per_K": 0.04,
    "tan_delta": 0.1,
    "strain_coeff_per_K": K_PER_K,
    "thermal_resistance_K_per_W": 300.0,
}


@pytest.mark.slow  # a minute; thermal_drift's recovery on a short campaign: tests/diagnose
@pytest.mark.timeout(600)
def test_thermal_drift_is_found_in_imported_csv_files(tmp_path):
    import pandas as pd  # here: the only test of the module to write CSV (slow tier)

    recs = bench_campaign([HEATING], seed=3)
    rise = max(float(r.aux["temperature"].max()) for r in recs) - recs[0].aux["temperature"][0]
    assert 15.0 < rise < 25.0  # the campaign heats the stack by up to about 20 K
    files = []
    for k, r in enumerate(recs):
        f = tmp_path / f"{k + 1:02d}_{r.name}.csv"
        pd.DataFrame(
            {
                "time_s": r.time_s,
                "voltage_V": r.voltage_V,
                "strain_ue": r.strain_ue,
                "temperature_C": r.aux["temperature"],
            }
        ).to_csv(f, index=False)
        files.append(str(f))
    out = tmp_path / "heated.h5"
    res = CliRunner().invoke(app, ["import", *files, "--out", str(out)])
    assert res.exit_code == 0, res.output
    d = labrig.open(out).diagnose()
    added = [e["effect"] for e in d.effects_added]
    assert added and added[0] == "thermal_drift", d.verdict
    assert d.effects_added[0]["params"]["k_per_K"] == pytest.approx(K_PER_K, rel=0.2)
    assert d.evidence_after.ratio <= 1.3, d.verdict
