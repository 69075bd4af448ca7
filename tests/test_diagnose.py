"""``labrig diagnose`` on campaigns generated on the virtual bench (drivers/sim) with one of its
optional effects switched on; the fitted model is never told which.

Fast tests: the JSON contract, a null campaign (2 seeds), mains pickup and the conditioner
low-pass, the CLI function. The many-seed and every-effect studies are ``@pytest.mark.slow``
(``pytest -m slow tests/test_diagnose.py``); ``benchmarks/diagnose_attribution.py`` prints the
confusion table.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from labrig.analysis.diagnose import diagnose
from labrig.analysis.diagnose_campaign import bench_campaign

#: bench effect (as in a rig file) -> the library effect diagnose should name; strengths are
#: clear (the effect dominates the residual), forms differ from the library's (2nd-order
#: Butterworth vs a fitted section, peak/average fold-back vs a slew limit, mode bank vs log
#: kernel, instantaneous loss power vs a measured temperature)
CASES = {
    "sensor_lowpass": [{"name": "conditioner_lowpass", "cutoff_hz": 150.0, "order": 2}],
    "mains_pickup": [{"name": "mains_pickup", "amplitude_mV": 20.0}],
    "amplifier_current_limit": [{"name": "amplifier_current_limit"}],
    "thermal_drift": [
        {
            "name": "self_heating",
            "heat_capacity_J_per_K": 0.2,
            "tan_delta": 0.1,
            "strain_coeff_per_K": 0.01,
        }
    ],
    "offset_drift": [
        {"name": "offset_drift", "rate_ue_per_s": 1.5, "random_walk_ue_per_sqrt_s": 0.5}
    ],
    "creep": [{"name": "log_creep", "per_decade": 0.04}],
}

KEYS = {"before", "after", "effects_added", "candidates", "verdict"}


def _check_contract(doc: dict) -> None:
    assert set(doc) == KEYS
    for k in ("before", "after"):
        assert set(doc[k]) == {"nrmse_pct", "heldout_nrmse_pct", "per_entry"}
        assert all(isinstance(v, float) for v in doc[k]["per_entry"].values())
    for e in doc["effects_added"]:
        assert set(e) == {"effect", "params", "evidence"}
        assert isinstance(e["evidence"], str) and e["evidence"]
    for c in doc["candidates"]:
        assert set(c) == {"effect", "heldout_nrmse_pct", "evidence"}
    assert isinstance(doc["verdict"], str) and len(doc["verdict"]) > 40
    json.dumps(doc)


def _found(expected: str, seed: int = 11, truth: str = "paper"):
    recs = bench_campaign(CASES[expected], seed=seed, truth=truth)
    d = diagnose(recs)
    doc = d.to_json()
    _check_contract(doc)
    return d, doc


@pytest.mark.parametrize("seed", [3, 4])
def test_null_campaign_adds_nothing(seed):
    d = diagnose(bench_campaign([], seed=seed))
    doc = d.to_json()
    _check_contract(doc)
    assert doc["effects_added"] == []
    assert d.classification == "consistent_with_noise"
    assert "consistent with noise" in doc["verdict"]
    assert doc["after"] == doc["before"]


@pytest.mark.parametrize("expected", ["mains_pickup", "sensor_lowpass"])
def test_effect_is_named_first_and_halves_heldout(expected):
    _, doc = _found(expected)
    assert doc["effects_added"], doc["verdict"]
    assert doc["effects_added"][0]["effect"] == expected
    assert doc["after"]["heldout_nrmse_pct"] <= 0.5 * doc["before"]["heldout_nrmse_pct"]
    # evidence in words, with numbers
    ev = doc["effects_added"][0]["evidence"]
    assert "held-out NRMSE" in ev and any(ch.isdigit() for ch in ev)


def test_cli_function_writes_json_and_html(tmp_path, monkeypatch, capsys):
    import labrig.analysis.load as load
    from labrig.cli_diagnose import diagnose_command

    recs = bench_campaign(CASES["mains_pickup"], seed=5)
    monkeypatch.setattr(load, "records_from_run", lambda path, entries=None: recs)
    code = diagnose_command(tmp_path / "run.h5", None, tmp_path / "out", True)
    assert code == 0
    out = capsys.readouterr().out
    doc = json.loads(out)
    _check_contract(doc)
    assert json.loads((tmp_path / "out" / "diagnosis.json").read_text()) == doc
    html = (tmp_path / "out" / "diagnosis.html").read_text()
    assert '<img src="data:image/png;base64,' in html and "Verdict" in html


def test_params_file_is_validated(tmp_path, monkeypatch):
    import labrig.analysis.load as load
    from labrig.cli_diagnose import diagnose_command
    from labrig.errors import InputFileError

    monkeypatch.setattr(load, "records_from_run", lambda path, entries=None: [])
    bad = tmp_path / "p.json"
    bad.write_text('{"alpha0_ue_per_V": -1}')
    with pytest.raises(InputFileError):
        diagnose_command(tmp_path / "run.h5", bad, None, True)


# -- slow studies ------------------------------------------------------------------------------


_THERMAL_XFAIL = pytest.mark.xfail(
    reason="known: the refit of base + thermal_drift stalls in a local optimum (k about half "
    "the truth) because the single-memory operator makes the cost jump at tiny V* reversals; "
    "held-out gain 41 % but only 3 of 6 folds better (docs/diagnose.md, known limits)",
    strict=False,
)


@pytest.mark.slow
@pytest.mark.parametrize(
    "expected",
    [pytest.param(n, marks=_THERMAL_XFAIL) if n == "thermal_drift" else n for n in sorted(CASES)],
)
def test_every_effect_is_named_first(expected):
    _, doc = _found(expected, seed=21)
    assert doc["effects_added"], doc["verdict"]
    assert doc["effects_added"][0]["effect"] == expected, doc["verdict"]
    assert doc["after"]["heldout_nrmse_pct"] <= 0.5 * doc["before"]["heldout_nrmse_pct"]


@pytest.mark.slow
def test_null_campaigns_over_ten_seeds():
    added, noise = 0, 0
    for seed in range(100, 110):
        d = diagnose(bench_campaign([], seed=seed))
        added += bool(d.effects_added)
        noise += d.classification == "consistent_with_noise"
    # at least 95 % of the campaigns add nothing (here: all ten)
    assert added == 0
    assert noise == 10


@pytest.mark.slow
@pytest.mark.parametrize(
    "expected",
    [
        "mains_pickup",
        pytest.param(
            "sensor_lowpass",
            marks=pytest.mark.xfail(
                reason="known: with the hybrid truth, creep (which describes the hybrid plant's "
                "slow Eq. 11 pole) is added first",
                strict=False,
            ),
        ),
        pytest.param("thermal_drift", marks=_THERMAL_XFAIL),
    ],
)
def test_hybrid_truth_effect_found_nothing_spurious(expected):
    d, doc = _found(expected, seed=31, truth="hybrid")
    names = [e["effect"] for e in doc["effects_added"]]
    assert names and names[0] == expected, doc["verdict"]
    # measured: a second effect (creep, describing the hybrid plant's slow Eq. 11 pole that the
    # paper model lacks) is often added; then the verdict must not claim a full explanation
    assert len(names) == 1 or d.classification == "partially_explained", doc["verdict"]


@pytest.mark.slow
def test_effect_outside_the_library_is_not_claimed_as_certain():
    # soft saturation of the strain (not in the library): S -> S0 tanh(S / S0)
    recs = bench_campaign([], seed=41)
    s0 = 2500.0
    for r in recs:
        r.strain_ue = s0 * np.tanh(r.strain_ue / s0)
    d = diagnose(recs)
    assert d.classification in ("unexplained", "partially_explained"), d.verdict
    assert not d.verdict.startswith("Explained")
