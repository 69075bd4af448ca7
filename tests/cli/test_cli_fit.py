"""``labrig fit`` end to end on the simulated rig: run a protocol, fit the run file.

The simulated rig's truth is ``DynamicHysteresisModel(PAPER_TABLE1)`` behind the real drivers
(current limit, 16-bit DAQ, 2 ue rms gauge noise). The must-show criteria of the fit issue: alpha0,
gamma, Vc within 2 %, the orders within 0.03, the time constants within 25 %, and a mean NRMSE
within 1.2 times the noise floor. The noise floor is taken from the run file's instrument
description (the bench's configured gauge noise, with the ADC's quantisation) and cross-checked
against the strain's scatter during the envelope's 0 V hold.

A reduced campaign (a 2-cycle sweep at 50/100 V, 1-40 Hz, and a short envelope, 1 s rests)
exercises the command line, with and without the held-out scores; ``experiments/paper.yaml``
itself (about 15 s: run, fit and leave-one-out) checks the criteria on the paper's campaign in
the slow tier.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
import pytest

from labrig.analysis.load import records_from_run
from labrig.model import PAPER_TABLE1
from labrig.store import read_run

from helpers import BASELINE_JSON_KEYS, FIT_JSON_KEYS, SMALL_CAMPAIGN, invoke, run_protocol
from reference.noise_ref import configured_noise_ue, hold_noise_ue

ROOT = Path(__file__).resolve().parents[2]
JSON_KEYS = list(FIT_JSON_KEYS)
SMALL_ENTRIES = [
    "sine_50V_1Hz",
    "sine_50V_5Hz",
    "sine_50V_20Hz",
    "sine_50V_40Hz",
    "sine_100V_1Hz",
    "sine_100V_5Hz",
    "sine_100V_20Hz",
    "sine_100V_40Hz",
    "vanishing_100V_1Hz",
]


@pytest.fixture(scope="module")
def small_run(tmp_path_factory) -> Path:
    return run_protocol(SMALL_CAMPAIGN, tmp_path_factory.mktemp("small"), seed=5)


@functools.cache
def noise_floor_pct(run_file: Path) -> float:
    """The run file's noise floor (percent), from its configured noise, checked against the
    scatter in the envelope's 0 V hold. Read once per run file (the files are read-only)."""
    records = records_from_run(run_file)
    run = read_run(run_file, load_data=False)
    sigma = configured_noise_ue(run.instrument)
    assert sigma is not None
    # the configured noise agrees with the scatter in the envelope's 0 V hold
    hold = hold_noise_ue(
        [r.voltage_V for r in records], [r.strain_ue for r in records], [r.rate_hz for r in records]
    )
    assert hold == pytest.approx(sigma, rel=0.1)
    return float(np.mean([100 * sigma / np.ptp(r.strain_ue) for r in records]))


def check_must_show(params: dict, nrmse: float, run_file: Path) -> float:
    """The issue's criteria; returns the noise floor (percent)."""
    t = PAPER_TABLE1
    for k in ("alpha0_ue_per_V", "gamma_ue_per_V", "vc_V"):
        assert params[k] == pytest.approx(getattr(t, k), rel=0.02), k
    for k in ("lam_t", "lam_d"):
        assert params[k] == pytest.approx(getattr(t, k), abs=0.03), k
    for k in ("tau_t_s", "tau_d_s"):
        assert params[k] == pytest.approx(getattr(t, k), rel=0.25), k
    floor_pct = noise_floor_pct(run_file)
    assert nrmse <= 1.2 * floor_pct
    return floor_pct


@pytest.fixture(scope="module")
def base_fit(small_run: Path, tmp_path_factory) -> tuple:
    """``labrig fit --json --no-heldout --out``: the result and the parameter file."""
    out = tmp_path_factory.mktemp("base") / "sub" / "params.json"
    return invoke("fit", small_run, "--json", "--no-heldout", "--out", out), out


def test_fit_json_recovers_the_truth(small_run: Path, base_fit: tuple) -> None:
    res, out = base_fit
    assert res.exit_code == 0, res.stderr
    j = json.loads(res.stdout)  # stdout is the JSON and nothing else
    assert list(j) == JSON_KEYS
    assert json.loads(out.read_text()) == j
    assert set(j["params"]) == set(PAPER_TABLE1.model_dump())
    assert j["method"] == "global"
    assert j["entries"] == SMALL_ENTRIES
    assert list(j["per_entry"]) == SMALL_ENTRIES
    assert j["heldout_nrmse_pct"] is None
    assert all(j["uncertainty"][k] > 0 for k in ("alpha0_ue_per_V", "lam_t", "tau_d_s"))
    assert j["correlation"]["alpha0_ue_per_V"]["alpha0_ue_per_V"] == pytest.approx(1.0)
    check_must_show(j["params"], j["nrmse_pct"], small_run)
    assert "chained as one run" in res.stderr


def test_fit_with_an_effect_the_rig_does_not_have(
    small_run: Path, base_fit: tuple, tmp_path: Path
) -> None:
    """--effect viscoelastic_creep on the default rig (its truth is the model, no creep): the
    fitted creep is negligible and the model's parameters stay the truth's. (Measured: c =
    -0.33 % +- 0.07 %: 5 formal sigma, because c trades off against G_t's slow tail; the formal
    uncertainty does not carry that, so the bound is physical: below 1 % of the strain.)"""
    out = tmp_path / "p.json"
    res = invoke("fit", small_run, "--effect", "viscoelastic_creep", "--no-heldout", "--json",
                 "--out", out)  # fmt: skip
    assert res.exit_code == 0, res.stderr
    j = json.loads(res.stdout)
    assert json.loads(out.read_text()) == j
    (e,) = j["effects"]
    assert e["effect"] == "viscoelastic_creep" and "tau" in e["description"]
    assert abs(e["params"]["c"]) < 0.01, e
    check_must_show(j["params"], j["nrmse_pct"], small_run)
    # the fit minimises the sum of squared per-entry NRMSE, not their mean: the nested model
    # (the effect's null is the base) is never worse in that objective
    base = json.loads(base_fit[0].stdout)  # the fit without the effect

    def objective(per_entry: dict[str, float]) -> float:
        return float(np.sum(np.square(list(per_entry.values()))))

    assert objective(j["per_entry"]) <= objective(base["per_entry"]) * (1 + 1e-9)
    assert j["nrmse_pct"] == pytest.approx(j["without_effects"]["nrmse_pct"], abs=1e-3)
    assert j["heldout_nrmse_pct"] is None


def test_fit_table_with_heldout_on_chosen_entries(small_run: Path, tmp_path: Path) -> None:
    """--entries fits a subset; the other entries still drive the run's history."""
    chosen = ["sine_100V_1Hz", "sine_50V_20Hz", "sine_100V_40Hz"]
    out = tmp_path / "p.json"
    res = invoke("fit", small_run, "--entries", ",".join(chosen), "--out", out)
    assert res.exit_code == 0, res.stderr
    for name in ("alpha0_ue_per_V", "tau_d_s", "± 1σ", "held-out", "mean", *chosen):
        assert name in res.stdout
    assert "sine_50V_1Hz" not in res.stdout
    assert "noise floor" in res.stdout
    assert "not scored, simulated as history" in res.stderr
    j = json.loads(out.read_text())
    assert j["entries"] == ["sine_50V_20Hz", "sine_100V_1Hz", "sine_100V_40Hz"]  # run order
    assert 0 < j["nrmse_pct"] < j["heldout_nrmse_pct"] < 1.0


@pytest.mark.parametrize("model", ["prandtl_ishlinskii", "bouc_wen"])
def test_fit_baselines(small_run: Path, model: str) -> None:
    res = invoke("fit", small_run, "--model", model, "--json", "--no-heldout")
    assert res.exit_code == 0, res.stderr
    j = json.loads(res.stdout)
    assert list(j) == list(BASELINE_JSON_KEYS)
    assert j["method"] == model
    assert j["nrmse_pct"] > 1.0  # rate-independent: far from the noise floor on this campaign


def test_fit_staged(small_run: Path) -> None:
    res = invoke("fit", small_run, "--method", "staged", "--json", "--no-heldout")
    assert res.exit_code == 0, res.stderr
    j = json.loads(res.stdout)
    assert j["method"] == "staged"
    assert j["params"]["alpha0_ue_per_V"] == pytest.approx(8.9, rel=0.1)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["fit", "{missing}"], "run file not found"),
        (["fit", "{text}"], "not a readable HDF5 run file"),
        (["fit", "{run}", "--entries", "sine_50V_1Hz,nope"], "no entry 'nope'"),
        (["fit", "{run}", "--warmup-s", "100"], "leaves 0 of its"),
        (["fit", "{run}", "--out", "{dir}"], "is a directory"),
        (["fit", "{run}", "--effect", "creep", "--effect", "creep"], "given twice"),
        (["fit", "{run}", "--model", "bouc_wen", "--effect", "creep"], "applies to the dynamic"),
        (["report", "{missing}", "--out", "{dir}/r.html"], "run file not found"),
        (["fit", "{dir}"], "is a folder, not a run file"),
        (["diagnose", "{dir}"], "`labrig runs FOLDER` lists the runs"),
        (["watch", "{dir}"], "is a folder, not a run file"),
        (["report", "{run}", "--out", "{dir}/r.html", "--params", "{text}"], "not a JSON"),
    ],
)
def test_bad_input_exits_2_without_traceback(
    small_run: Path, tmp_path: Path, args: list[str], message: str
) -> None:
    text = tmp_path / "notes.txt"
    text.write_text("not hdf5\n")
    subs = {"missing": tmp_path / "nope.h5", "text": text, "run": small_run, "dir": tmp_path}
    res = invoke(*[a.format(**subs) for a in args])
    assert res.exit_code == 2, (res.stdout, res.stderr)
    assert message in res.stderr
    assert res.stderr.startswith("error:")
    assert "Traceback" not in res.stderr + res.stdout
    assert res.stdout == ""


@pytest.mark.parametrize("value", ["-1", "nan", "inf"])
def test_a_bad_warmup_is_a_usage_error_naming_the_option(small_run: Path, value: str) -> None:
    res = invoke("fit", small_run, "--warmup-s", value)
    assert res.exit_code == 64, (res.stdout, res.stderr)
    assert res.stderr.startswith("error: --warmup-s: ") and "expected seconds >= 0" in res.stderr
    assert str(small_run) not in res.stderr  # the run file is not what is wrong
    if value == "-1":  # just inside the bound, once: 0 s is accepted
        assert invoke("fit", small_run, "--warmup-s", "0", "--no-heldout").exit_code == 0


def test_heldout_fit_criteria(small_run: Path) -> None:
    """``labrig fit --json`` with its held-out scores (the default) on the reduced campaign:
    the issue's criteria, and the held-out NRMSE within 1.3 times the noise floor (the paper
    campaign's check below, on 9 entries)."""
    res = invoke("fit", small_run, "--json")
    assert res.exit_code == 0, res.stderr
    j = json.loads(res.stdout)
    assert j["entries"] == SMALL_ENTRIES
    floor = check_must_show(j["params"], j["nrmse_pct"], small_run)
    assert j["nrmse_pct"] <= j["heldout_nrmse_pct"] <= 1.3 * floor
    assert np.isfinite(list(j["uncertainty"].values())).all()


@pytest.mark.slow
def test_paper_campaign_on_the_simulated_rig(tmp_path: Path) -> None:
    """experiments/paper.yaml (11 entries, 1 kHz) on the simulated rig, then labrig fit.

    Fast equivalent in the default tier: tests/cli/test_cli_fit.py::test_heldout_fit_criteria
    """
    run = run_protocol((ROOT / "experiments" / "paper.yaml").read_text(), tmp_path, seed=7)
    res = invoke("fit", run, "--json")
    assert res.exit_code == 0, res.stderr
    j = json.loads(res.stdout)
    assert len(j["entries"]) == 11
    floor = check_must_show(j["params"], j["nrmse_pct"], run)
    assert j["heldout_nrmse_pct"] <= 1.3 * floor
    assert np.isfinite(list(j["uncertainty"].values())).all()


def test_baselines_fit_one_offset_per_entry() -> None:
    """Imported data have an arbitrary sensor zero: with ``offset=True`` the baselines (like our
    model) fit one constant per entry, in-sample and held out."""
    from labrig.analysis.baselines import PrandtlIshlinskii, fit_baseline
    from labrig.analysis.records import Record

    r = tuple(100.0 * np.arange(16) / 16)
    w = np.zeros(16)
    w[[0, 3, 7]] = [6.0, 2.0, 1.0]
    truth = PrandtlIshlinskii(r, tuple(w))
    t = np.arange(3000) / 1000.0
    recs = []
    for k, (amp, c) in enumerate([(100.0, -120.0), (60.0, 35.0), (80.0, 7.5)]):
        v = amp / 2 * (1 - np.cos(2 * np.pi * (1 + k) * t))
        recs.append(Record.from_arrays(f"e{k}", 1000.0, v, truth.predict(v) + c, hold="linear"))
    plain = fit_baseline(recs, "prandtl_ishlinskii", heldout=False)
    assert plain.nrmse_pct > 5.0  # the offsets spoil a fit without them
    for kind in ("prandtl_ishlinskii", "bouc_wen"):
        res = fit_baseline(recs, kind, heldout=True, offset=True)
        assert res.offsets_ue is not None and set(res.offsets_ue) == {"e0", "e1", "e2"}
        if kind == "prandtl_ishlinskii":
            assert res.nrmse_pct < 1e-6 and res.heldout_nrmse_pct < 0.1  # other grid held out
            assert res.offsets_ue["e0"] == pytest.approx(-120.0, abs=1e-6)
            np.testing.assert_allclose(res.predict(recs[1]), recs[1].strain_ue, atol=1e-6)
        else:
            assert res.nrmse_pct < 5.0
