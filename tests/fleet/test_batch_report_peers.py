"""``labrig batch report --peers``: the baselines each run's report fits, as ``labrig report
--peers``; other peers are other options (a batch with them is not taken for one made)."""

from __future__ import annotations

import json
from pathlib import Path

from labrig.fleet.table import read_table
from labrig.fleet.tasks import TaskOptions

from helpers import invoke


def report_columns(out: Path) -> set[str]:
    f = out / "fleet.parquet"
    (row,) = read_table(f if f.exists() else out / "fleet.csv")
    return {k for k in row if k.startswith("report_") and k.endswith("_nrmse_pct")}


def test_batch_report_fits_the_peers_asked_for(tiny_run: Path, tmp_path: Path, monkeypatch):
    import labrig.fleet.fleet_report as fleet_report

    # not the fleet page (a dozen figures; tested in test_fleet.py and test_day_one.py)
    monkeypatch.setattr(fleet_report, "write_fleet_report", lambda path, *args: path)
    out = tmp_path / "out"
    args = ("batch", "report", tiny_run, "--out", out, "--serial", "--no-heldout", "--json")
    res = invoke(*args, "--peers", "bouc_wen")
    assert res.exit_code == 0, res.stderr
    assert report_columns(out) == {"report_bouc_wen_nrmse_pct"}
    assert invoke(*args, "--peers", "bw").exit_code != 0


def test_other_peers_are_other_options():
    """The options are the batch cache's identity (a batch with other options is made again:
    test_fleet.py): each choice of peers is its own."""
    chosen = [TaskOptions(), TaskOptions(peers=()), TaskOptions(peers=("bouc_wen",))]
    assert len({json.dumps(o.to_json(), sort_keys=True) for o in chosen}) == 3
    # every peer (the default): the options of a batch made before there was a choice
    assert "peers" not in TaskOptions().to_json()
