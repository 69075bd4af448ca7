"""``labrig report --params FILE`` keeps the held-out column: the parameters file gives only the
mean held-out NRMSE, so each entry's is measured now, leave-one-entry-out as ``labrig fit``
does (it was ``null`` for our model on every entry, the column empty)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from helpers import invoke


@pytest.fixture(scope="module")
def params(tiny_run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("params") / "params.json"
    res = invoke("fit", tiny_run, "--out", out)
    assert res.exit_code == 0, res.output
    return out


def test_report_with_params_has_our_held_out_column(tiny_run: Path, params: Path):
    res = invoke("report", tiny_run, "--params", params, "--json")
    assert res.exit_code == 0, res.output
    metrics = json.loads(res.stdout)
    fit = json.loads(params.read_text())
    held = [row["dynamic.heldout_nrmse_pct"] for row in metrics.values()]
    assert all(isinstance(h, float) for h in held), held
    # the same leave-one-entry-out as `labrig fit`: the same mean
    assert sum(held) / len(held) == pytest.approx(fit["heldout_nrmse_pct"], rel=1e-6)


def test_without_heldout_the_column_stays_empty(tiny_run: Path, params: Path):
    res = invoke("report", tiny_run, "--params", params, "--json", "--no-heldout")
    assert res.exit_code == 0, res.output
    metrics = json.loads(res.stdout)
    assert all(row["dynamic.heldout_nrmse_pct"] is None for row in metrics.values())
