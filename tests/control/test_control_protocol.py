"""Strain-command protocol steps: planning, preflight, recording, and control on the hybrid rig.

The threshold tests run the paper's control example (experiments/control.yaml) on the simulated
rig with the ``hybrid`` truth. ``test_control_thresholds_fast`` uses the committed parameters
(experiments/hybrid-params.json, fitted by ``labrig fit`` on a paper.yaml run of that rig) and a
shortened protocol; the slow test redoes the whole chain: campaign run, fit, control run.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from labrig.analysis.load import records_from_run
from labrig.control import check_drive, compute_drive, entry_metrics, load_control_model
from labrig.core.errors import InputFileError
from labrig.model import PAPER_TABLE1
from labrig.protocol.check import check_protocol, load_plan
from labrig.protocol.preflight import preflight_checks
from labrig.rig.limits import RigLimits
from labrig.runner.execute import execute
from labrig.store import read_run

ROOT = Path(__file__).resolve().parents[2]
EXP = ROOT / "experiments"
PARAMS = EXP / "hybrid-params.json"
FREQS = (1, 5, 10, 20, 40)


def write_protocol(tmp_path: Path, steps: list[dict], **top) -> Path:
    shutil.copy(PARAMS, tmp_path / "params.json")
    doc = {"name": "control test", "rate_hz": 1000, "params": "params.json"}
    doc.update(top)
    doc["steps"] = steps
    p = tmp_path / "protocol.yaml"
    p.write_text(yaml.safe_dump(doc, sort_keys=False))
    return p


def issues_of(exc: pytest.ExceptionInfo) -> list:
    return exc.value.issues


# -- planning ----------------------------------------------------------------------------------


def test_strain_steps_expand_with_names_definitions_and_command(tmp_path):
    p = write_protocol(
        tmp_path,
        [
            {"kind": "strain_sine", "amplitude_ue": 500, "frequency_hz": 10, "cycles": 20,
             "control": "compensated"},
            {"kind": "strain_sine", "amplitude_ue": 500, "frequency_hz": 10, "cycles": 20,
             "control": "direct"},
            {"kind": "strain_vanishing", "amplitude_ue": 800, "frequency_hz": 1, "decay_s": 2,
             "hold_s": 1, "control": "compensated"},
        ],
    )  # fmt: skip
    plan = check_protocol(p)
    names = [s.name for s in plan.steps]
    assert names == [
        "strain_sine_500ue_10Hz_compensated",
        "strain_sine_500ue_10Hz_direct",
        "strain_vanishing_800ue_1Hz_compensated",
    ]
    cm = load_control_model(PARAMS)  # the model and the creep fitted with it
    params = cm.params
    for s in plan.steps:
        d = s.definition
        assert d["control"] in ("direct", "compensated") and d["frequency_hz"] == s.frequency_hz
        assert d["amplitude_ue"] in (500, 800)
        assert d["model_params"] == params.model_dump()
        assert d["model_creep"] == {"c": cm.creep[0], "tau_s": cm.creep[1]}
        A, beta, gam = cm.remanence
        assert d["model_remanence"] == {"A_ue_per_V": A, "beta_per_V": beta, "gamma_per_V": gam}
        assert d["params_file"] == "params.json"
        units, _, cmd = s.aux["command_strain"]
        assert units == "ue" and cmd.size == s.n_samples
        i0, i1 = d["command_start_index"], d["command_stop_index"]
        # the entry: a 0 V rest sample, then drive[n] at sample n + 1, then a ramp to 0 V
        v = s.samples()
        assert v[0] == 0.0 and v[-1] == 0.0
        strain = cmd[i0:i1]
        drive = compute_drive(strain, cm, 1000.0, d["control"])
        assert np.allclose(v[1 : 1 + drive.size], drive, atol=1e-9)
        assert strain[0] == 0.0 and cmd[0] == 0.0
        # the model (with its creep and remanence) fed the entry's voltage follows the recorded
        # command (compensated)
        if d["control"] == "compensated":
            pred = cm.predict(v, 1000.0)[i0:i1]
            assert np.max(np.abs(pred[100:] - strain[100:])) < 1e-3
            assert d["drive_min_V"] < 0  # drift cancelled with negative volts (allowed)
    sine = plan.steps[0]
    assert sine.definition["cycles"] == 20 and sine.duration_s == pytest.approx(2.0, abs=0.01)
    assert "strain sine 500 ue, 10 Hz, 20 cycles, compensated control" in sine.title
    van = plan.steps[2].definition
    assert van["hold_s"] == 1 and van["envelope_end_s"] == pytest.approx(2.5)
    assert plan.checks is not None and all(c.v_min_V >= -20 for c in plan.checks)


def test_strain_csv_step_and_step_level_params(tmp_path):
    shutil.copy(PARAMS, tmp_path / "fit.json")
    t = np.arange(0, 2.0, 0.002)
    s = 300 * np.sin(np.pi * t / 2.0) ** 2 + 50  # does not start at 0: a strain edge is added
    np.savetxt(tmp_path / "cmd.csv", np.c_[t, s], delimiter=",", header="t,strain", comments="")
    p = tmp_path / "p.yaml"
    p.write_text(
        "name: csv\nrate_hz: 1000\nsteps:\n"
        "  - {kind: strain_csv, path: cmd.csv, time_column: t, column: strain,\n"
        "     control: compensated, params: fit.json}\n"
    )
    plan = check_protocol(p)
    (st,) = plan.steps
    assert st.name == "strain_csv_cmd_compensated" and st.kind == "strain_csv"
    d = st.definition
    assert d["strain_edge_ramps"] == 2 and d["params_file"] == "fit.json"
    cmd = st.aux["command_strain"][2]
    assert cmd[0] == 0.0 and cmd.max() == pytest.approx(350, abs=1)


def test_params_missing_unreadable_or_invalid(tmp_path):
    step = {"kind": "strain_sine", "amplitude_ue": 500, "frequency_hz": 5, "cycles": 5,
            "control": "direct"}  # fmt: skip
    p = tmp_path / "p.yaml"
    p.write_text(yaml.safe_dump({"name": "x", "rate_hz": 1000, "steps": [step]}))
    with pytest.raises(InputFileError) as e:
        load_plan(p)
    assert "needs model parameters: params: FILE" in str(e.value)
    assert issues_of(e)[0].field == "steps[0]"
    p.write_text(
        yaml.safe_dump({"name": "x", "rate_hz": 1000, "steps": [{**step, "params": "no.json"}]})
    )
    with pytest.raises(InputFileError) as e:
        load_plan(p)
    (issue,) = issues_of(e)
    assert issue.field == "steps[0].params" and "parameter file not found" in issue.message
    assert issue.line is not None
    (tmp_path / "bad.json").write_text('{"params": {"alpha0_ue_per_V": 1}}')
    p.write_text(
        yaml.safe_dump({"name": "x", "rate_hz": 1000, "params": "bad.json", "steps": [step]})
    )
    with pytest.raises(InputFileError) as e:
        load_plan(p)
    (issue,) = issues_of(e)
    assert issue.field == "params" and "invalid model parameters" in issue.message
    # schema: control is required, and only direct | compensated
    p.write_text(
        yaml.safe_dump({"name": "x", "rate_hz": 1000, "params": "bad.json",
                        "steps": [{**step, "control": "feedback"}]})
    )  # fmt: skip
    with pytest.raises(InputFileError) as e:
        load_plan(p)
    assert issues_of(e)[0].field == "steps[0].control"


def test_preflight_and_check_drive_measure_a_drive_alike(tmp_path):
    """The protocol preflight (on the step's waveform) and ``check_drive`` (on the drive array)
    use one measurement: the same peak and cycle-mean current for the same drive, with the peak
    found at the same time (``check_drive`` counts from the drive's first sample, one sample
    after the entry's 0 V rest sample). The independent reference is the unipolar-sine formula
    of a direct drive, ``pi C_eff A f`` and ``2 C_eff A f`` (A the drive's amplitude, V)."""
    p = write_protocol(
        tmp_path,
        [{"kind": "strain_sine", "amplitude_ue": 900, "frequency_hz": 20, "cycles": 10,
          "control": "direct"}],
    )  # fmt: skip
    plan = check_protocol(p)
    (step,), (pf,) = plan.steps, plan.checks
    d = step.definition
    drive = step.samples(d["command_start_index"], d["command_stop_index"])
    lim = RigLimits()
    chk = check_drive(drive, 1000.0, lim, 20.0)
    assert chk.peak_current_A == pytest.approx(pf.peak_current_A, rel=1e-12)
    assert chk.mean_current_A == pytest.approx(pf.mean_current_A, rel=1e-9)
    assert chk.window_s == pf.window_s == pytest.approx(1 / 20)
    assert chk.peak_time_s + 1e-3 == pytest.approx(pf.peak_time_s, abs=1e-12)
    # one record: the entry's, and the drive's (its own samples' range and duration)
    assert type(chk) is type(pf) and pf.name == step.name and chk.name == "the drive"
    assert chk.duration_s == pytest.approx(drive.size / 1000.0)
    assert (chk.v_min_V, chk.v_max_V) == (float(drive.min()), float(drive.max()))
    # 50 samples per cycle played linearly between samples: the peak slope is a chord's, 0.3 %
    # below the sine's
    c_eff, amp = lim.effective_capacitance_F, float(np.max(drive))
    assert chk.peak_current_A == pytest.approx(np.pi * c_eff * amp * 20, rel=5e-3)
    assert chk.mean_current_A == pytest.approx(2 * c_eff * amp * 20, rel=5e-3)


def test_preflight_names_the_strain_step_when_infeasible(tmp_path):
    p = write_protocol(
        tmp_path,
        [
            {"kind": "strain_sine", "amplitude_ue": 2000, "frequency_hz": 1, "cycles": 2,
             "control": "compensated"},
            {"kind": "strain_sine", "amplitude_ue": 1000, "frequency_hz": 80, "cycles": 40,
             "control": "direct"},
        ],
        rate_hz=2000,
    )  # fmt: skip
    with pytest.raises(InputFileError) as e:
        check_protocol(p)
    msgs = {(i.field, i.line is not None): i.message for i in issues_of(e)}
    volt = msgs[("steps[0].amplitude_ue", True)]
    assert "compensated drive for 2000 ue at 1 Hz reaches" in volt and "-20 to 100 V" in volt
    cur = [m for (f, _), m in msgs.items() if f == "steps[1].amplitude_ue"]
    assert any("A peak" in m or "on average" in m for m in cur)
    assert volt.endswith("lower amplitude_ue")
    assert all(m.endswith("lower amplitude_ue or frequency_hz") for m in cur)
    # a narrower negative range refuses the drift-cancelling drive, naming why
    q = write_protocol(
        tmp_path,
        [{"kind": "strain_sine", "amplitude_ue": 1000, "frequency_hz": 20, "cycles": 20,
          "control": "compensated"}],
    )  # fmt: skip
    plan = load_plan(q)
    with pytest.raises(InputFileError, match="below 0 V to cancel the drift"):
        preflight_checks(plan, RigLimits(v_min_V=-1.0))


def test_runner_records_the_command_strain(tmp_path):
    """On the default simulated rig (its truth: the model with PAPER_TABLE1) compensation with
    the truth's own parameters tracks to the noise: the whole chain (plan, timing of the 0 V
    first sample, DAQ, runner, recorded command) lines up."""
    p = write_protocol(
        tmp_path,
        [{"kind": "strain_sine", "amplitude_ue": 400, "frequency_hz": 5, "cycles": 5,
          "control": "compensated"}],
    )  # fmt: skip
    (tmp_path / "params.json").write_text(json.dumps({"params": PAPER_TABLE1.model_dump()}))
    plan = check_protocol(p)
    out = execute(plan, None, tmp_path / "run.h5", seed=1)
    assert out.status == "complete"
    (entry,) = read_run(tmp_path / "run.h5")
    assert entry.units["command_strain"] == "ue"
    (st,) = plan.steps
    assert np.array_equal(entry["command_strain"], st.aux["command_strain"][2])
    (rec,) = records_from_run(tmp_path / "run.h5")
    assert "command_strain" in rec.aux and rec.meta["control"] == "compensated"
    mt = entry_metrics(rec)
    assert mt["control"] == "compensated" and mt["frequency_hz"] == 5
    # 2 ue rms gauge noise on a 400 ue command: 0.5 %; DAQ quantisation and amplifier aside
    assert mt["tracking_nrmse_pct"] < 1.0 and mt["hysteresis_width_pct"] < 2.0
    assert abs(mt["zero_command_strain_ue"]) < 3.0


# -- the control example on the hybrid rig -------------------------------------------------------


def run_metrics(run_file: Path) -> dict[str, dict]:
    """``labrig.control.entry_metrics`` of every strain-command entry of a run (plus, for the
    vanishing command, the gauge noise from the last second)."""
    out = {}
    for r in records_from_run(run_file):
        mt = entry_metrics(r)
        if mt["kind"] != "strain_sine":
            mt["noise_ue"] = float(np.std(np.diff(r.strain_ue[-1000:])) / np.sqrt(2))
        out[r.name] = mt
    return out


def assert_thresholds(met: dict, amp: str, freqs) -> None:
    for f in freqs:
        d = met[f"strain_sine_{amp}ue_{f}Hz_direct"]
        c = met[f"strain_sine_{amp}ue_{f}Hz_compensated"]
        need = 2.0 if f == 40 else 4.0
        assert d["hysteresis_width_pct"] >= need * c["hysteresis_width_pct"], (f, d, c)
        assert d["tracking_nrmse_pct"] >= need * c["tracking_nrmse_pct"], (f, d, c)
        # the strain bias at zero command is suppressed
        assert abs(c["zero_command_strain_ue"]) < 0.25 * abs(d["zero_command_strain_ue"])


def shortened_control(tmp_path: Path, freqs, cycles_per_hz: float, vanishing: bool = False) -> Path:
    doc = yaml.safe_load((EXP / "control.yaml").read_text())
    doc["rig"] = str(EXP / "rigs" / "hybrid.yaml")
    doc["params"] = str(PARAMS)
    steps = []
    for st in doc["steps"]:
        if st["kind"] == "strain_sine" and st["frequency_hz"] in freqs:
            steps.append({**st, "cycles": max(3, round(cycles_per_hz * st["frequency_hz"]))})
        elif st["kind"] == "strain_vanishing" and vanishing:
            steps.append(st)
    doc["steps"] = steps
    p = tmp_path / "control_short.yaml"
    p.write_text(yaml.safe_dump(doc, sort_keys=False))
    return p


@pytest.mark.timeout(300)
def test_control_thresholds_fast(tmp_path):
    """5-40 Hz on the hybrid rig with the committed fit: at least 4x (2x at 40 Hz)."""
    p = shortened_control(tmp_path, (5, 20, 40), 2.0)
    plan = check_protocol(p, RigLimits())
    out = execute(plan, plan.rig_path, tmp_path / "control.h5", seed=5)
    assert out.status == "complete"
    assert_thresholds(run_metrics(tmp_path / "control.h5"), "1000", (5, 20, 40))


@pytest.mark.timeout(300)
def test_control_threshold_1hz(tmp_path):
    """1 Hz: the fit's viscoelastic creep (the hybrid plant's slow Eq. 11 mode) makes it."""
    p = shortened_control(tmp_path, (1,), 5.0)
    plan = check_protocol(p, RigLimits())
    out = execute(plan, plan.rig_path, tmp_path / "control.h5", seed=5)
    assert out.status == "complete"
    assert_thresholds(run_metrics(tmp_path / "control.h5"), "1000", (1,))


@pytest.mark.timeout(300)
def test_control_vanishing_returns_within_noise_of_zero(tmp_path):
    """The hybrid plant keeps a Bouc-Wen remanence at 0 V after the vanishing command (about
    8 ue with direct control); the fit's remanence effect lets the compensation cancel it."""
    p = shortened_control(tmp_path, (), 1.0, vanishing=True)
    plan = check_protocol(p, RigLimits())
    assert execute(plan, plan.rig_path, tmp_path / "control.h5", seed=5).status == "complete"
    met = run_metrics(tmp_path / "control.h5")
    c = met["strain_vanishing_1000ue_1Hz_compensated"]
    d = met["strain_vanishing_1000ue_1Hz_direct"]
    assert abs(c["final_strain_ue"]) < 0.5 * abs(d["final_strain_ue"])
    assert abs(c["final_strain_ue"]) < c["noise_ue"]


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_control_example_end_to_end(tmp_path):
    """The documented chain with the CLI: paper.yaml on the hybrid rig (another seed than the
    committed fit's), ``labrig fit --effect viscoelastic_creep --effect remanence``,
    control.yaml: the issue's thresholds at 1-40 Hz and the vanishing command's return to within
    noise of zero (docs/control.md)."""
    from labrig.drivers.sim.hybrid import HYBRID_DEFAULT
    from typer.testing import CliRunner

    from labrig.cli import app

    rig = EXP / "rigs" / "hybrid.yaml"
    check = check_protocol(EXP / "paper.yaml", RigLimits())
    assert execute(check, rig, tmp_path / "hybrid.h5", seed=11).status == "complete"
    fit = CliRunner().invoke(
        app,
        ["fit", str(tmp_path / "hybrid.h5"), "--effect", "viscoelastic_creep", "--effect",
         "remanence", "--no-heldout", "--out", str(tmp_path / "params.json")],
    )  # fmt: skip
    assert fit.exit_code == 0, fit.output
    creep, rem = json.loads((tmp_path / "params.json").read_text())["effects"]
    # the hybrid plant's slow mode: Eq. 11's pole/zero pair at -3.50/-3.75 rad/s (0.285 s)
    assert 0.2 < creep["params"]["tau_s"] < 0.4 and 0.03 < creep["params"]["c"] < 0.2
    # and its Bouc-Wen block's gain (the fit never sees it)
    assert rem["params"]["A_ue_per_V"] == pytest.approx(HYBRID_DEFAULT.bw_A_ue_per_V, rel=0.2)
    doc = yaml.safe_load((EXP / "control.yaml").read_text())
    doc["rig"], doc["params"] = str(rig), "params.json"
    p = tmp_path / "control.yaml"
    p.write_text(yaml.safe_dump(doc, sort_keys=False))
    plan = check_protocol(p, RigLimits())
    assert execute(plan, rig, tmp_path / "control.h5", seed=12).status == "complete"
    met = run_metrics(tmp_path / "control.h5")
    assert_thresholds(met, "1000", (1, 5, 10, 20, 40))
    vd = met["strain_vanishing_1000ue_1Hz_direct"]
    vc = met["strain_vanishing_1000ue_1Hz_compensated"]
    assert vc["tracking_nrmse_pct"] < 0.5 * vd["tracking_nrmse_pct"]
    assert abs(vd["final_strain_ue"]) > 2 * vd["noise_ue"]  # the plant's remanence
    assert abs(vc["final_strain_ue"]) < vc["noise_ue"]
