"""``labrig diagnose`` on campaigns generated on the virtual bench (drivers/sim) with one of its
optional effects switched on; the fitted model is never told which.

Fast tests: the JSON contract, a null campaign (2 seeds), mains pickup and the conditioner
low-pass, the CLI function. The many-seed and every-effect studies are ``@pytest.mark.slow``
(``pytest -m slow tests/diagnose/test_diagnose.py``);
``python -m labrig.studies.campaign`` prints the confusion table.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from labrig.analysis.diagnose import diagnose
from labrig.model.effects import library
from labrig.studies.campaign import (
    HOLD_ENTRIES,
    SHORT_ENTRIES,
    STUDY_CASES,
    bench_campaign,
    study_campaign,
    truth_campaign,
)

#: bench effect (as in a rig file) -> the library effect diagnose should name; strengths are
#: clear (the effect dominates the residual), forms differ from the library's (2nd-order
#: Butterworth vs a fitted section, peak/average fold-back vs a slew limit, mode bank vs log
#: kernel, instantaneous loss power vs a measured temperature)
CASES = {k: v for k, v in STUDY_CASES.items() if k not in ("none", "cubic_term")}

KEYS = {"before", "after", "effects_added", "candidates", "headline", "verdict", "messages"}


def _check_contract(doc: dict) -> None:
    assert set(doc) == KEYS
    for k in ("before", "after"):
        assert set(doc[k]) == {"nrmse_pct", "heldout_nrmse_pct", "per_entry"}
        assert all(isinstance(v, float) for v in doc[k]["per_entry"].values())
    for e in doc["effects_added"]:
        assert set(e) == {"effect", "params", "evidence"}
        assert isinstance(e["evidence"], str) and e["evidence"]
    for c in doc["candidates"]:
        assert set(c) == {"effect", "round", "heldout_nrmse_pct", "evidence"}
        assert isinstance(c["round"], int) and c["round"] >= 1
    assert isinstance(doc["verdict"], str) and len(doc["verdict"]) > 40
    assert doc["headline"] and "\n" not in doc["headline"]
    assert all(isinstance(m, str) and m for m in doc["messages"])
    json.dumps(doc)


def _found(expected: str, seed: int = 11, truth: str = "paper"):
    recs = study_campaign(expected, seed, truth=truth)
    d = diagnose(recs)
    doc = d.to_json()
    _check_contract(doc)
    return d, doc


# the default tier's null is tests/diagnose/test_attribution_fast.py's "none" row
@pytest.mark.slow
@pytest.mark.parametrize("seed", [3, 4])
def test_null_campaign_adds_nothing(seed):
    d = diagnose(bench_campaign([], seed=seed))
    doc = d.to_json()
    _check_contract(doc)
    assert doc["effects_added"] == []
    assert d.classification == "consistent_with_noise"
    assert "consistent with noise" in doc["verdict"]
    assert doc["after"] == doc["before"]


def named_first_and_halves_heldout(doc: dict, expected: str) -> None:
    assert doc["effects_added"], doc["verdict"]
    assert doc["effects_added"][0]["effect"] == expected
    assert doc["after"]["heldout_nrmse_pct"] <= 0.5 * doc["before"]["heldout_nrmse_pct"]
    # evidence in words, with numbers
    ev = doc["effects_added"][0]["evidence"]
    assert "held-out NRMSE" in ev and any(ch.isdigit() for ch in ev)


# the default tier's case (mains pickup) is the command's, below
@pytest.mark.slow
@pytest.mark.parametrize("expected", ["mains_pickup", "sensor_lowpass"])
def test_effect_is_named_first_and_halves_heldout(expected):
    _, doc = _found(expected)
    named_first_and_halves_heldout(doc, expected)


def test_cli_function_writes_json_and_html(tmp_path, monkeypatch, capsys):
    """The command on a mains-pickup campaign: the document and the page written, the effect
    named first and the held-out error at least halved (the library's own test of that claim,
    above, runs in the slow tier)."""
    import labrig.analysis.load as load
    from labrig.cli.diagnose import diagnose_command

    recs = study_campaign("mains_pickup", 11)
    monkeypatch.setattr(load, "records_from_run", lambda path, entries=None: recs)
    code = diagnose_command(tmp_path / "run.h5", None, tmp_path / "out", True)
    assert code == 0
    out = capsys.readouterr().out
    doc = json.loads(out)
    _check_contract(doc)
    named_first_and_halves_heldout(doc, "mains_pickup")
    assert json.loads((tmp_path / "out" / "diagnosis.json").read_text()) == doc
    html = (tmp_path / "out" / "diagnosis.html").read_text()
    assert '<img src="data:image/png;base64,' in html and "Verdict" in html


def test_params_file_is_validated(tmp_path, monkeypatch):
    import labrig.analysis.load as load
    from labrig.cli.diagnose import diagnose_command
    from labrig.core.errors import InputFileError

    monkeypatch.setattr(load, "records_from_run", lambda path, entries=None: [])
    bad = tmp_path / "p.json"
    bad.write_text('{"alpha0_ue_per_V": -1}')
    with pytest.raises(InputFileError):
        diagnose_command(tmp_path / "run.h5", bad, None, True)


def test_params_from_a_baseline_fit_are_refused(tmp_path, monkeypatch):
    import labrig.analysis.load as load
    from labrig.cli.diagnose import diagnose_command
    from labrig.core.errors import InputFileError

    monkeypatch.setattr(load, "records_from_run", lambda path, entries=None: [])
    f = tmp_path / "pi.json"
    f.write_text(json.dumps({"method": "prandtl_ishlinskii", "params": {"n": 10}}))
    with pytest.raises(InputFileError, match="baseline"):
        diagnose_command(tmp_path / "run.h5", f, None, True)


def test_params_with_fitted_effects_use_the_base_and_say_so(tmp_path):
    """A ``labrig fit --effect`` file: its base parameters are the start, its effects are named
    as not assumed (diagnose tests every effect itself)."""
    from labrig.analysis.params_file import start_params
    from labrig.model import PAPER_TABLE1

    doc = {
        "params": PAPER_TABLE1.model_dump(),
        "effects": [{"effect": "viscoelastic_creep", "params": {"c": 0.05, "tau_s": 0.3}}],
    }
    f = tmp_path / "fit.json"
    f.write_text(json.dumps(doc))
    said: list[str] = []
    assert start_params(f, said.append) == PAPER_TABLE1
    assert len(said) == 1 and "viscoelastic_creep" in said[0] and "not assumed" in said[0]


# -- slow studies ------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("expected", sorted(n for n in CASES if n != "creep"))
def test_every_effect_is_named_first(expected):
    _d, doc = _found(expected, seed=21)
    assert doc["effects_added"], doc["verdict"]
    assert doc["effects_added"][0]["effect"] == expected, doc["verdict"]
    assert doc["after"]["heldout_nrmse_pct"] <= 0.5 * doc["before"]["heldout_nrmse_pct"]
    if expected == "thermal_drift":  # with a temperature channel: k within 10 % of the bench's
        k = doc["effects_added"][0]["params"]["k_per_K"]
        assert k == pytest.approx(CASES[expected][0]["strain_coeff_per_K"], rel=0.1)


@pytest.mark.slow
@pytest.mark.timeout(900)
@pytest.mark.parametrize("entries", ["short", "hold"])
def test_log_creep_is_absorbed_by_the_models_transient_relaxor(entries):
    """Logarithmic creep (4 %/decade, the bench's mode bank) on the default gauge (2 ue) is
    within the model family's reach: the paper's ``G_t`` with a small order creeps almost
    logarithmically, and the converged base fit shifts lam_t, tau_t and alpha0 to follow it
    (measured: in-sample NRMSE at the noise floor for 2-8 %/decade, also with a 100 V step held
    300 s and 300 s back at 0 V; what G_t misses, 0.083 % of the span, is a quarter of the
    floor: creep gains 3.0 % in-sample, not enough to be cross-validated). Nothing is
    attributed and the verdict says so; the model still predicts held-out entries at the floor.
    On a quiet gauge the remainder shows and creep is found (the test below).
    (With the last-reversal memory the base fit stalled and ``creep`` was "found": an
    artefact.)"""
    recs = truth_campaign(
        "paper", CASES["creep"], 21, entries=HOLD_ENTRIES if entries == "hold" else SHORT_ENTRIES
    )
    d = diagnose(recs)
    doc = d.to_json()
    _check_contract(doc)
    assert doc["effects_added"] == [], doc["verdict"]
    assert d.classification == "consistent_with_noise", doc["verdict"]
    floor = d.evidence_before.floor_pct
    assert doc["before"]["heldout_nrmse_pct"] < 1.3 * floor
    assert d.base_params["alpha0_ue_per_V"] > 1.1 * 8.9  # the creep went into the base
    # ... and is measured there: the creep the base model describes after a 100 V step equals
    # the bench's own (noise-free step on the bench, no model involved) within 0.5 %/decade
    # (measured on seed 21: 9.65 against 9.85 %/decade extrapolated from the 3 s entries, 9.86
    # against 9.85 with the 300 s hold), well apart from the same bench without creep (6.1)
    with_creep, without = (
        _bench_creep_pct_per_decade(CASES["creep"]),
        _bench_creep_pct_per_decade([]),
    )
    assert with_creep - without > 3.0
    assert d.base_creep_pct_per_decade == pytest.approx(with_creep, abs=0.5), doc["verdict"]
    assert "creep by" in doc["verdict"] and "not added as a separate effect" in doc["verdict"]


#: gauge noise (ue rms) at which a 4 %/decade log creep stands clear of the noise: the base's
#: G_t follows all but 0.083 % of the span of it (noise-free campaign, seed 21), and halving a
#: held-out NRMSE (the issue's test) needs that remainder above sqrt(3) times the floor, i.e.
#: noise below 0.26 ue (the 15 % rule alone adds creep up to about 1 ue: docs/diagnose.md)
#: (the default gauge's 2 ue gives a floor of 0.33 %)
QUIET_GAUGE_UE = 0.2


@pytest.mark.slow  # twin: test_modelled_creep_matches_the_relaxor_step_response_by_superposition
def test_log_creep_on_a_quiet_gauge_is_named_first_and_measured():
    """The bench's log creep (4 %/decade, a mode bank from 10 ms to 1e4 s) on a quiet gauge,
    seed 61 (not used while the creep effect was developed): creep is added, nothing else,
    the held-out NRMSE at least halves, the fitted rate is the bench's within 10 %, and the
    whole model's creep after a 100 V step matches the bench's own noise-free step (no model
    involved) within 0.5 %/decade."""
    recs = bench_campaign(CASES["creep"], seed=61, noise_ue=QUIET_GAUGE_UE)
    d = diagnose(recs)
    doc = d.to_json()
    _check_contract(doc)
    assert [e["effect"] for e in doc["effects_added"]] == ["creep"], doc["verdict"]
    assert doc["after"]["heldout_nrmse_pct"] <= 0.5 * doc["before"]["heldout_nrmse_pct"]
    c = doc["effects_added"][0]["params"]["c_per_decade"]
    assert c == pytest.approx(CASES["creep"][0]["per_decade"], rel=0.1)
    bench = _bench_creep_pct_per_decade(CASES["creep"])
    assert d.after_creep_pct_per_decade == pytest.approx(bench, abs=0.5), doc["verdict"]
    assert "from its slow relaxor G_t without creep" in doc["verdict"]


@pytest.mark.slow
def test_quiet_gauge_null_campaigns_add_nothing():
    """The acceptance rule on a quiet gauge (floor 0.037 %), where the base's own small
    mismatches are 10x closer to the floor than at the default noise: nothing added in 10
    seeds."""
    added = [
        [
            e["effect"]
            for e in diagnose(bench_campaign([], seed=s, noise_ue=QUIET_GAUGE_UE)).to_json()[
                "effects_added"
            ]
        ]
        for s in range(100, 110)
    ]
    assert added == [[]] * 10


def _bench_creep_pct_per_decade(effects) -> float:
    """Creep of the bench's strain (%/decade, 1-100 s after a 100 V step, noise-free)."""
    rec = bench_campaign(
        effects, seed=1, entries=[(100.0, 0.0, 400.0)], rate_hz=100.0, noise_ue=0.0
    )[0]
    t = rec.time_s - 0.2  # from the end of step_hold's 0.2 s ramp
    s1, s100 = (float(np.interp(x, t, rec.strain_ue)) for x in (1.0, 100.0))
    return 100.0 * ((s100 / s1) ** 0.5 - 1.0)


@pytest.mark.slow
@pytest.mark.parametrize("expected", ["mains_pickup", "sensor_lowpass", "thermal_drift"])
def test_slightly_imperfect_base_effect_found_nothing_spurious(expected):
    """The bench's truth is the paper's model with the Gaussian hysteresis shape, fitted with the
    exponential one (base residual 1.6x the floor with no effect): one effect is added, nothing
    beside it. It is the bench's, or (measured for the low-pass on seeds 1 and 2, not on this
    one) its documented confusable twin with the bench's effect named in the verdict as fitting
    almost as well (the low-pass and a delay differ by 1-2 % in held-out NRMSE here)."""
    _d, doc = _found(expected, seed=51, truth="paper_gaussian")
    names = [e["effect"] for e in doc["effects_added"]]
    assert len(names) == 1, doc["verdict"]
    if names[0] != expected:
        assert names[0] in library()[expected].confusable, doc["verdict"]
        assert f"{expected} fits almost as well" in doc["verdict"]


@pytest.fixture(scope="module")
def clean_heldout_seed21() -> float:
    """Held-out NRMSE (%) of the base on the seed-21 campaign without effects."""
    return diagnose(truth_campaign("paper", [], 21)).before["heldout_nrmse_pct"]


@pytest.mark.slow
@pytest.mark.parametrize(
    "pair",
    [
        ("mains_pickup", "sensor_lowpass"),
        ("thermal_drift", "offset_drift"),
        ("amplifier_current_limit", "mains_pickup"),
    ],
    ids="+".join,
)
def test_two_effects_at_once_are_both_found(pair, clean_heldout_seed21):
    """Two of the bench's effects at once (spec residuals.md, "testing the diagnosis"): both are
    added, in either order, nothing else, and together they bring the held-out NRMSE to within
    1.3x the held-out NRMSE of the same campaign without effects (0.35 % on seed 21)."""
    recs = truth_campaign("paper", CASES[pair[0]] + CASES[pair[1]], 21)
    d = diagnose(recs)
    doc = d.to_json()
    _check_contract(doc)
    assert sorted(e["effect"] for e in doc["effects_added"]) == sorted(pair), doc["verdict"]
    assert doc["after"]["heldout_nrmse_pct"] < 1.3 * clean_heldout_seed21, doc["verdict"]
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
        "sensor_lowpass",
        pytest.param(
            "thermal_drift",
            marks=pytest.mark.xfail(
                reason="known: thermal_drift is found first (k 0.55 %/K against the bench's "
                "1 %/K: the hybrid base takes part of the heating), then creep is added for "
                "the rest (held-out gain 17 %, t0 43 ms; on the same plant without heating "
                "creep gains 10 % and is rejected); the verdict says partially explained",
                strict=True,
            ),
        ),
    ],
)
def test_hybrid_truth_effect_found_nothing_spurious(expected):
    """The paper's section-4 plant (further from the family: base residual 2x the floor)."""
    _d, doc = _found(expected, seed=31, truth="hybrid")
    names = [e["effect"] for e in doc["effects_added"]]
    assert names and names[0] == expected, doc["verdict"]
    assert names == [expected], doc["verdict"]
    assert not doc["verdict"].startswith("Explained")  # the base's own mismatch stays


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


@pytest.mark.slow  # twins: tests/model/test_empirical.py, tests/diagnose/test_sparse_ode.py
def test_an_effect_outside_the_library_is_found_as_an_empirical_term():
    """A gain rising with field (the bench's ``+c3 (V/V_ref)^3`` on the strain, a bipolar
    drive): no named effect passes (a quadratic term is even, field saturation has the other
    sign), so the sparse regression of the residual runs; it selects V^3 with the positive sign,
    reports it as empirical, and the held-out NRMSE is at least halved."""
    d = diagnose(study_campaign("cubic_term", 1))
    doc = d.to_json()
    _check_contract(doc)
    assert [e["effect"] for e in doc["effects_added"]] == ["empirical_terms"], doc["verdict"]
    params = doc["effects_added"][0]["params"]
    # the bench's 40 ue at 100 V, at the campaign's full scale of 150 V: 40 * 1.5^3 = 135 ue
    assert params["c_V3"] == pytest.approx(40.0 * 1.5**3, rel=0.1)
    assert "EMPIRICAL" in doc["verdict"] and "not a physical attribution" in doc["verdict"]
    assert "cf. field_saturation" not in doc["verdict"].split("V^3:")[1].split(";")[0]
    assert d.classification == "partially_explained"
    assert doc["after"]["heldout_nrmse_pct"] <= 0.5 * doc["before"]["heldout_nrmse_pct"]


def test_verdict_says_what_became_of_each_usual_confusion():
    """Found on the hybrid bench: the verdict said creep "was tested and fit clearly worse" while
    creep had been added second. Each confusion is reported as it happened."""
    from labrig.analysis.diagnose import Candidate
    from labrig.analysis.diagnose.verdict import confusions_sentence

    lib = library(temperature=True)
    assert set(lib["thermal_drift"].confusable) == {"creep", "offset_drift"}
    first = Candidate("thermal_drift", 0, 0.3, tried=True, heldout_nrmse_pct=0.7)
    worse = Candidate("offset_drift", 0, 0.1, tried=True, heldout_nrmse_pct=0.9)
    low = Candidate("creep", 0, 0.0)
    s = confusions_sentence(first, [first, worse, low], ["thermal_drift", "creep"], lib)
    assert "(offset_drift) were cross-validated and fit clearly worse" in s
    assert "creep (usually confused with thermal_drift) was added after it" in s
    assert "creep" not in s.split("fit clearly worse")[0]
    s = confusions_sentence(first, [first, worse, low], ["thermal_drift"], lib)
    assert "creep (usually confused with thermal_drift) explained too little" in s
    assert "added" not in s


def test_modelled_creep_matches_the_relaxor_step_response_by_superposition():
    """With ``gamma = 0`` the model is linear, ``S = alpha0 G_d G_t V``; with ``G_d`` ~ 1 the
    strain after the ramped step is the superposition of ``G_t``'s closed-form step response
    (Mittag-Leffler, the paper's Eq. 9) over the held voltage increments (zoh: ``S[n] = sum_k dV_k
    g((n - k) dt)``), independent of the modal filter ``predict`` uses. Tolerance 1e-6."""
    from labrig.analysis.diagnose import modelled_creep_per_decade
    from labrig.analysis.signals import step_hold
    from labrig.model import ModelParams
    from labrig.model.mittag_leffler import relaxor_step

    lam_t, tau_t = 0.15, 1.55e-4
    p = ModelParams(
        alpha0_ue_per_V=10.0,
        gamma_ue_per_V=0.0,
        vc_V=65.0,
        lam_t=lam_t,
        tau_t_s=tau_t,
        lam_d=1.0,
        tau_d_s=1e-7,
    )
    rate, ramp = 100.0, 0.2
    v = step_hold(80.0, 400.0, rate, ramp_s=ramp)
    dv = np.diff(np.concatenate(([0.0], v[:40])))  # the ramp's increments, then constant
    t1, t2 = 1.0 + ramp, 100.0 + ramp
    s1, s2 = (
        float(np.sum(dv * relaxor_step(t - np.arange(40) / rate, tau_t, lam_t))) for t in (t1, t2)
    )
    expected = (s2 / s1) ** 0.5 - 1.0
    assert modelled_creep_per_decade(p, 80.0) == pytest.approx(expected, abs=1e-6)
    assert 0.03 < expected < 0.1  # the paper's G_t creeps several %/decade by itself
    assert np.isnan(modelled_creep_per_decade(p, 0.0))  # no strain, no creep figure


def test_modelled_creep_includes_an_added_creep_effect():
    """With ``gamma = 0`` and both relaxors a fraction of a microsecond fast the base strain
    is ``alpha0 V`` one sample late (a relaxor's zoh step response is 0 at the step and 1 a
    sample later) with no creep of its own; with the library's creep effect the strain is the
    direct sum ``S[n] = sum_k alpha0 dV_k (1 + c log10(1 + (n - k - 1) dt / t0))`` over the
    ramp's increments (no convolution code involved). Tolerance 1e-6."""
    from labrig.analysis.diagnose import modelled_creep_per_decade
    from labrig.analysis.signals import step_hold
    from labrig.model import ModelParams

    p = ModelParams(
        alpha0_ue_per_V=10.0,
        gamma_ue_per_V=0.0,
        vc_V=65.0,
        lam_t=1.0,
        tau_t_s=1e-7,
        lam_d=1.0,
        tau_d_s=1e-7,
    )
    assert modelled_creep_per_decade(p, 80.0) == pytest.approx(0.0, abs=1e-9)
    c, t0, rate, ramp = 0.03, 0.004, 100.0, 0.2
    dv = np.diff(np.concatenate(([0.0], step_hold(80.0, 400.0, rate, ramp_s=ramp)[:40])))

    def strain(t: float) -> float:
        lag = t - (np.arange(40) + 1) / rate
        return float(np.sum(10.0 * dv * (1.0 + c * np.log10(1.0 + lag / t0))))

    expected = (strain(100.0 + ramp) / strain(1.0 + ramp)) ** 0.5 - 1.0
    creep = library()["creep"]
    got = modelled_creep_per_decade(
        p, 80.0, creep_effects=[(creep, {"c_per_decade": c, "t0_s": t0})]
    )
    assert got == pytest.approx(expected, abs=1e-6)
    assert got == pytest.approx(c, rel=0.1)  # c per decade, for t >> t0


def test_a_time_constant_is_poorly_determined_relative_to_its_value():
    """Found in review: t0 = 43 +- 8 ms was called "poorly determined" because its spread was
    compared with its distance from the start value (50 ms), which means nothing for a
    log-scaled parameter."""
    from labrig.analysis.diagnose import accept
    from labrig.analysis.extended import FitOutcome

    eff = library()["creep"]
    held_ref = {f"e{i}": 1.0 for i in range(6)}
    held = {k: 0.7 for k in held_ref}

    def suspicious(sd_t0: float) -> list[str]:
        fo = FitOutcome(
            base={},
            effects={"creep": {"c_per_decade": 0.04, "t0_s": 0.043}},
            sd={"creep": {"c_per_decade": 0.002, "t0_s": sd_t0}},
            base_sd={},
            per_entry={},
            cost=0.0,
        )
        verdict = accept(eff, fo, held, held_ref)
        assert verdict.accepted
        return verdict.suspicious

    assert suspicious(0.008) == []
    assert any("t0_s is poorly determined" in x for x in suspicious(0.03))


def test_runner_up_gets_the_experiment_written_for_the_pair():
    """Found on the hybrid bench: offset_drift won with remanence as runner-up and the verdict
    proposed offset_drift's test against creep ("drift continues, creep does not")."""
    from labrig.analysis.diagnose import tell_apart

    lib = library()
    assert "remanence stays put" in tell_apart(lib["offset_drift"], lib["remanence"])
    assert tell_apart(lib["sensor_lowpass"], lib["time_delay"]) == lib["sensor_lowpass"].tell_apart
    both = tell_apart(lib["thermal_drift"], lib["quadratic_term"])
    assert lib["thermal_drift"].tell_apart in both and lib["quadratic_term"].tell_apart in both


def test_also_accepts_only_structural_effects(tmp_path):
    from typer.testing import CliRunner

    from labrig.cli import app
    from labrig.cli.typer_app import EXIT_USAGE

    res = CliRunner().invoke(app, ["diagnose", str(tmp_path / "run.h5"), "--also", "mains"])
    assert res.exit_code == EXIT_USAGE
    assert "viscoelastic_creep, remanence" in res.output  # the registry's order
    res = CliRunner().invoke(app, ["diagnose", str(tmp_path / "run.h5"), "--max-effects", "9"])
    assert res.exit_code == EXIT_USAGE


# two diagnoses of a hybrid campaign: 93 s on an idle machine, over 300 s with both cores busy
@pytest.mark.slow  # the default tier's twin: test_also_accepts_only_structural_effects
@pytest.mark.timeout(900)
def test_also_adds_the_structural_effect_to_the_candidates(tmp_path, monkeypatch, capsys):
    import labrig.analysis.load as load
    from labrig.cli.diagnose import diagnose_command

    recs = bench_campaign([], seed=6, truth="hybrid")
    monkeypatch.setattr(load, "records_from_run", lambda path, entries=None: recs)
    assert diagnose_command(tmp_path / "run.h5", None, None, True, (), 1) == 0
    out = capsys.readouterr()
    cands = {c["effect"] for c in json.loads(out.out)["candidates"]}
    assert "remanence" not in cands and "viscoelastic_creep" in cands  # a default where slow
    assert "--also remanence" in out.err  # the hint: not explained, not tried
    assert "--also viscoelastic_creep" not in out.err
    code = diagnose_command(tmp_path / "run.h5", None, None, True, ("remanence",), 1)
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert "remanence" in {c["effect"] for c in doc["candidates"]}
    assert len(doc["effects_added"]) <= 1


@pytest.mark.slow
@pytest.mark.timeout(1500)
def test_hybrid_rig_structure_is_found_with_the_structural_effects(tmp_path):
    """The paper's campaign (experiments/paper.yaml) on the simulated hybrid rig, no effect
    injected: by default offset_drift stands in for the plant's remanence ("partially
    explained"); with ``--also remanence --also viscoelastic_creep --max-effects 3`` diagnose
    finds the plant's own two blocks the paper's model lacks, each against the plant's values
    (drivers/sim/hybrid.py, never given to the fit): its Bouc-Wen gain A = 1.5 ue/V (within
    15 %) and Eq. 11's slow mode, 7 % with 0.285 s (within 10 %); measured on seed 1:
    A 1.60, c 6.71 %, tau 0.274 s, held-out 0.965 -> 0.283 %, "explained"."""
    from pathlib import Path

    from typer.testing import CliRunner

    from labrig.cli import app

    root = Path(__file__).resolve().parents[2]
    run = tmp_path / "hybrid.h5"
    res = CliRunner().invoke(
        app,
        [
            "run",
            str(root / "experiments" / "paper.yaml"),
            "--rig",
            str(root / "experiments" / "rigs" / "hybrid.yaml"),
            "--seed",
            "1",
            "--out",
            str(run),
        ],
    )
    assert res.exit_code == 0, res.output
    args = ["diagnose", str(run), "--json", "--max-effects", "3"]
    res = CliRunner().invoke(app, [*args, "--also", "remanence", "--also", "viscoelastic_creep"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    _check_contract(doc)
    added = {e["effect"]: e["params"] for e in doc["effects_added"]}
    assert set(added) == {"remanence", "viscoelastic_creep"}, doc["verdict"]
    assert added["remanence"]["A_ue_per_V"] == pytest.approx(1.5, rel=0.15)
    assert added["viscoelastic_creep"]["c"] == pytest.approx(0.07, rel=0.1)
    assert added["viscoelastic_creep"]["tau_s"] == pytest.approx(0.285, rel=0.1)
    assert doc["verdict"].startswith("Explained"), doc["verdict"]
    assert doc["after"]["heldout_nrmse_pct"] <= 0.5 * doc["before"]["heldout_nrmse_pct"]


def test_viscoelastic_creep_is_left_out_where_unidentifiable_unless_asked_for():
    """Fast sines only (10-40 Hz): a slow mode would look like a gain, so the default
    candidates leave ``viscoelastic_creep`` out and say why; ``always`` (``--also``) tries it."""
    records = bench_campaign(entries=((100.0, 10.0, 2.0), (50.0, 20.0, 2.0), (100.0, 40.0, 2.0)))
    default = diagnose(records, effects=("viscoelastic_creep",), max_effects=1)
    assert not default.candidates
    assert any("viscoelastic_creep not tried" in m for m in default.messages)
    asked = diagnose(
        records, effects=("viscoelastic_creep",), max_effects=1, always=("viscoelastic_creep",)
    )
    assert [c["effect"] for c in asked.candidates] == ["viscoelastic_creep"]
    assert any("tried as asked" in m for m in asked.messages)
