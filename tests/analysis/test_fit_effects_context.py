"""Effects fitted with the model (``labrig fit --effect``) are configured for the run they were
fitted on, saved with that configuration, and used by ``labrig report --params``.

- ``quadratic_term`` is relative to the run's full-scale voltage: on a 0-3.6 V drive (a DAQ-level
  command, as in the real micromanipulator data) an electrostrictive 5 % at full scale is found
  as 5 % (with the library's default 100 V reference it would need 139 %, beyond its bound).
- The report of a run with a ``--effect viscoelastic_creep`` parameter file predicts with the
  creep: its first entry (from rest) equals an independent evaluation,
  :meth:`labrig.control.ControlModel.predict` (the dynamic model's ``predict`` followed by the
  Kelvin-Voigt filter, not the fit engine's simulation), and its NRMSE per entry is the fit's.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np
import pytest

from labrig.analysis.fit import fit_model
from labrig.analysis.fit_effects import fit_effects
from labrig.analysis.params_file import fitted_effects
from labrig.analysis.records import Record
from labrig.analysis.signals import sine
from labrig.commands.prepare import prepare
from labrig.commands.report import predict_entries
from labrig.control import load_control_model
from labrig.model import PAPER_TABLE1, DynamicHysteresisModel

from helpers import invoke

ROOT = Path(__file__).resolve().parents[2]
RATE = 1000.0


def test_quadratic_term_is_relative_to_the_runs_full_scale():
    v_full, c2 = 3.6, 0.05  # V at the DAQ; 5 % of full scale at full scale
    # the paper's model seen from a 0-3.6 V command (gain folded into alpha0 and gamma, Vc)
    g = 100.0 / v_full
    p = PAPER_TABLE1.model_copy(
        update={
            "alpha0_ue_per_V": PAPER_TABLE1.alpha0_ue_per_V * g,
            "gamma_ue_per_V": PAPER_TABLE1.gamma_ue_per_V * g,
            "vc_V": PAPER_TABLE1.vc_V / g,
        }
    )
    model = DynamicHysteresisModel(p)
    rng = np.random.default_rng(3)
    records = []
    for a, f in ((v_full, 1.0), (v_full, 10.0), (v_full / 2, 1.0), (v_full / 2, 10.0)):
        v = sine(a, f, 2.0, RATE)
        s = model.predict(v + c2 * v * v / v_full, RATE) + rng.normal(0.0, 2.0, v.size)
        records.append(Record(f"s{a:g}_{f:g}", RATE, np.arange(v.size) / RATE, v, s))
    base = fit_model(records, heldout=False)
    res = fit_effects(records, base, ["quadratic_term"], chain=False, heldout=False)
    assert res.context["v_ref"] == pytest.approx(v_full)
    assert res.effects[0]["params"]["c2"] == pytest.approx(c2, rel=0.1)
    assert res.to_json()["effects_context"] == res.context


#: 500 Hz and 0.5 s rests (half the samples of 1 kHz and 1 s rests: the fit's CPU halves); the
#: creep is as clear (measured: c = 8 %, NRMSE 0.47 times the fit's without it)
SWEEP_RATE = 500.0
SWEEP = """\
name: creep check
rig: {rig}
rate_hz: 500
rest_s: 0.5
steps:
  - kind: sweep
    amplitudes_V: [100]
    frequencies_hz: [1, 20]
    cycles: 3
    min_duration_s: 2
"""


@pytest.mark.timeout(600)
def test_report_with_a_fit_effect_file_predicts_with_the_effect(tmp_path: Path):
    proto = tmp_path / "p.yaml"
    proto.write_text(SWEEP.format(rig=ROOT / "experiments" / "rigs" / "hybrid.yaml"))
    run = tmp_path / "run.h5"
    assert invoke("run", proto, "--seed", 3, "--out", run).exit_code == 0
    params = tmp_path / "params.json"
    res = invoke("fit", run, "--effect", "viscoelastic_creep", "--no-heldout", "--out", params)
    assert res.exit_code == 0, res.stderr
    doc = json.loads(params.read_text())
    assert set(doc["effects_context"]) == {
        "temperature",
        "amplifier_voltage",
        "mains_hz",
        "v_ref",
        "rate_hz",
    }

    setup = prepare(run, None, None, None)
    cm = load_control_model(params)
    pred = predict_entries(cm.params, setup, fitted_effects(doc, params, setup.records))
    first = setup.records[0]
    want = cm.predict(first.voltage_V, SWEEP_RATE)
    np.testing.assert_allclose(pred[first.name], want, rtol=0, atol=1e-6 * np.ptp(want))
    # without the creep the first entry differs clearly (the fit found c of several %)
    assert first.rate_hz == SWEEP_RATE
    plain = DynamicHysteresisModel(cm.params).predict(first.voltage_V, SWEEP_RATE)
    assert np.max(np.abs(plain - want)) > 5.0

    # our model only: the peers are not what this checks (test_report_peers.py)
    res = invoke("report", run, "--params", params, "--out", tmp_path / "r.html", "--json",
                 "--no-heldout", "--peers", "none")  # fmt: skip
    assert res.exit_code == 0, res.stderr
    table = json.loads(res.stdout)
    for name, nrmse in doc["per_entry"].items():
        assert table[name]["dynamic.nrmse_pct"] == pytest.approx(nrmse, rel=1e-6)
    assert doc["nrmse_pct"] < 0.8 * doc["without_effects"]["nrmse_pct"]
    # the page says what the effect was fitted to, as the fit described it
    (creep,) = doc["effects"]
    page = (tmp_path / "r.html").read_text()
    assert creep["effect"] == "viscoelastic_creep" and creep["description"]
    assert f"viscoelastic_creep ({creep['description']})" in html.unescape(page)


def test_a_fit_file_without_its_effects_context_is_read_and_configured_from_the_run(tmp_path):
    """Files written before ``effects_context`` existed: the names are checked when the file is
    read, the parameters once the run's records say how the effects are configured (a
    temperature channel gives thermal_drift its ``k_per_K`` form)."""
    from labrig.analysis.params_file import read_fit_output as read_params
    from labrig.core.errors import InputFileError

    doc = {
        "params": PAPER_TABLE1.model_dump(),
        "effects": [{"effect": "thermal_drift", "params": {"k_per_K": 0.004}}],
    }
    path = tmp_path / "old.json"
    path.write_text(json.dumps(doc))
    assert read_params(path)["effects"] == doc["effects"]
    t = np.arange(100) / RATE
    rec = Record("e", RATE, t, np.zeros(100), np.zeros(100), {"temperature": 23 + t})
    effects, values = fitted_effects(doc, path, [rec])
    assert [e.name for e in effects] == ["thermal_drift"] and values == {
        "thermal_drift": {"k_per_K": 0.004}
    }
    # without a temperature channel the same file does not fit the run: a clear error
    bare = Record("e", RATE, t, np.zeros(100), np.zeros(100))
    with pytest.raises(InputFileError, match="thermal_drift needs numeric params"):
        fitted_effects(doc, path, [bare])
    # an unknown effect is refused when the file is read
    path.write_text(json.dumps({**doc, "effects": [{"effect": "gremlins", "params": {}}]}))
    with pytest.raises(InputFileError, match="gremlins"):
        read_params(path)


def test_an_effects_context_written_before_rate_hz_is_read(tmp_path):
    """A context without ``rate_hz`` (files written before the field existed) is accepted and
    leaves mechanical_resonance without a sampling limit; a context missing an original field,
    or holding an unknown one, is refused with the field named."""
    from labrig.core.errors import InputFileError

    old_context = {"temperature": False, "amplifier_voltage": False, "mains_hz": 50.0}
    old_context["v_ref"] = 100.0
    p = {"tau_r_s": 1.0 / (2 * np.pi * 7351.0), "zeta": 0.05, "internal": 0.5}
    doc = {
        "params": PAPER_TABLE1.model_dump(),
        "effects": [{"effect": "mechanical_resonance", "params": p}],
        "effects_context": old_context,
    }
    path = tmp_path / "old.json"
    (eff,), values = fitted_effects(doc, path)
    assert eff.refusals(values["mechanical_resonance"], {}) == []  # no rate: no limit
    (eff,), _ = fitted_effects(
        {**doc, "effects_context": {**old_context, "rate_hz": 10_000.0}}, path
    )
    assert "alias" in eff.refusals(values["mechanical_resonance"], {})[0]  # 7.35 kHz at 10 kHz
    for bad in ({k: v for k, v in old_context.items() if k != "v_ref"}, {**old_context, "x": 1.0}):
        with pytest.raises(InputFileError, match="effects_context"):
            fitted_effects({**doc, "effects_context": bad}, path)
