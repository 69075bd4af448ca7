"""``labrig batch report --peers``: the baselines each run's report fits, as ``labrig report
--peers``; a batch with other peers is not taken for the one already made."""

from __future__ import annotations

import json
from pathlib import Path

from labrig.fleet.table import read_table

from helpers import invoke


def report_columns(out: Path) -> set[str]:
    f = out / "fleet.parquet"
    (row,) = read_table(f if f.exists() else out / "fleet.csv")
    return {k for k in row if k.startswith("report_") and k.endswith("_nrmse_pct")}


def test_batch_report_fits_the_peers_asked_for(tiny_run: Path, tmp_path: Path):
    out = tmp_path / "out"
    args = ("batch", "report", tiny_run, "--out", out, "--serial", "--no-heldout", "--json")
    res = invoke(*args, "--peers", "bouc_wen")
    assert res.exit_code == 0, res.stderr
    assert report_columns(out) == {"report_bouc_wen_nrmse_pct"}
    res = invoke(*args, "--peers", "none")
    assert res.exit_code == 0, res.stderr
    assert json.loads(res.stdout)["skipped"] == 0  # other options: made again
    assert report_columns(out) == set()
    assert invoke(*args, "--peers", "bw").exit_code != 0
