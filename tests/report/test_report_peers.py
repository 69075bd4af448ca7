"""``labrig report --peers``: which baselines are fitted beside our model (default: all).

Our model's numbers do not depend on the peers chosen; the page and the metrics show only the
peers fitted and say when none was; an unknown name is refused before any work, naming the
valid ones.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

import labrig
from labrig.analysis.baselines import KINDS
from labrig.cli.common import PEERS
from labrig.commands.report import checked_peers
from labrig.report.html import peers_and_rate

from helpers import invoke


def models_in(metrics: dict) -> set[str]:
    """The models of a ``report --json`` table (keys ``model.metric``)."""
    return {
        k.split(".")[0]
        for row in metrics.values()
        for k in row
        if k.endswith(".nrmse_pct") and not k.startswith("measured")
    }


def report_json(run: Path, *extra: object) -> dict:
    res = invoke("report", run, "--json", "--no-heldout", *extra)
    assert res.exit_code == 0, res.stderr
    return json.loads(res.stdout)


def test_the_cli_names_the_peers_the_report_fits():
    assert PEERS == KINDS


def test_our_model_is_the_same_whichever_peers_are_fitted(tiny_run: Path):
    one = report_json(tiny_run, "--peers", "bouc_wen")
    alone = report_json(tiny_run, "--peers", "none")
    assert models_in(one) == {"dynamic", "bouc_wen"}
    assert models_in(alone) == {"dynamic"}
    assert one.keys() == alone.keys()
    for name, row in one.items():
        ours = {k: v for k, v in row.items() if k.startswith("dynamic.")}
        assert ours and {k: alone[name][k] for k in ours} == ours


def test_a_page_without_peers_says_so_and_shows_none(tiny_run: Path, tmp_path: Path):
    out = tmp_path / "r.html"
    res = invoke("report", tiny_run, "--no-heldout", "--peers", "none", "--out", out)
    assert res.exit_code == 0, res.stderr
    text = re.sub(r"data:image/png;base64,[^\"']+", "", out.read_text())
    assert "no peers fitted (peers: none)" in text
    assert "(model)" in text and "model and baselines" not in text
    assert "Bold: the best" not in text  # one model: no best
    for label in ("Prandtl", "Bouc-Wen", "SINDy"):
        assert label not in text


@pytest.mark.parametrize("given", ["foo", "bouc_wen,foo", "", " , ", "BOUC_WEN"])
def test_an_unknown_peer_is_refused_naming_the_valid_ones(tiny_run: Path, given: str):
    res = invoke("report", tiny_run, "--json", "--peers", given)
    assert res.exit_code != 0 and res.stdout == ""
    assert "prandtl_ishlinskii, bouc_wen, sindy" in res.stderr and "Traceback" not in res.stderr


def test_the_library_call_takes_peers_in_any_order_and_refuses_unknown_ones(tiny_run: Path):
    assert checked_peers(None) == KINDS
    assert checked_peers(["sindy", "prandtl_ishlinskii", "sindy"]) == (
        "prandtl_ishlinskii",
        "sindy",
    )
    assert checked_peers("sindy") == ("sindy",)
    assert checked_peers(k for k in ["bouc_wen", "sindy"]) == ("bouc_wen", "sindy")
    assert checked_peers([]) == ()
    with pytest.raises(ValueError, match=r"'bw'.*choose from prandtl_ishlinskii"):
        labrig.open(tiny_run).report(peers=["bw"])


def test_the_frequency_caption_speaks_of_the_peers_shown():
    assert peers_and_rate({"dynamic": 0}) == ""
    assert peers_and_rate({"bouc_wen": 0}) == (
        "Bouc-Wen is rate-independent: its loops do not change with frequency."
    )
    both = peers_and_rate(dict.fromkeys(KINDS, 0))
    assert both.startswith("Prandtl-Ishlinskii and Bouc-Wen are rate-independent: their loops")
    assert both.endswith("; SINDy's sparse ODE does depend on the rate.")


def test_the_in_sample_caveat_names_the_peers_fitted(tiny_run: Path, tmp_path: Path):
    """A parameter file that does not name its training files: the peers are fitted on the
    report's own records, and the caveat says which (none: no caveat, nothing is compared)."""
    params = tmp_path / "p.json"
    assert invoke("fit", tiny_run, "--no-heldout", "--out", params).exit_code == 0
    doc = json.loads(params.read_text())
    del doc["train_files"]
    params.write_text(json.dumps(doc))
    base = ("report", tiny_run, "--params", params, "--no-heldout", "--json")
    one = invoke(*base, "--peers", "bouc_wen")
    assert one.exit_code == 0, one.stderr
    assert "the peers (Bouc-Wen) are fitted now" in " ".join(one.stderr.split())
    alone = invoke(*base, "--peers", "none")
    assert alone.exit_code == 0, alone.stderr
    assert "like-for-like" not in alone.stderr
