"""``labrig batch`` and ``labrig sim fleet`` on small fleets (a 3-entry campaign, a few runs).

- the batch table and per-run documents equal the one-by-one ``labrig fit --json`` and
  ``labrig diagnose --json`` outputs (serially, and on a LocalCluster when Dask is installed);
- runs that cannot be read are failed rows with their error, the others complete, exit code 4;
- a rerun skips unchanged runs and recomputes a changed file, other options or another version;
- without Dask the batch runs serially with a note, without pyarrow the table is CSV;
- the robust z-score against scipy's MAD, the flag rule, the actuator identity, the simulated
  fleet's spread and defects.

Scheduler and workers as separate processes, a killed worker: tests/fleet/test_fleet_cluster.py.
"""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from labrig.analysis.simulate import PARAM_NAMES
from labrig.fleet.outliers import Z_LIMIT, flag_runs, robust_z
from labrig.fleet.simfleet import DEFECTS, SPREAD, TRUNCATE_SIGMA, draw_fleet, write_fleet
from labrig.fleet.table import read_table
from labrig.model import PAPER_TABLE1

from helpers import FLEET_CAMPAIGN, invoke


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> Path:
    """Three simulated actuators on the small campaign: A0001 healthy, A0002 depolarised and
    A0003 cracked."""
    d = tmp_path_factory.mktemp("fleet")
    proto = d / "small.yaml"
    proto.write_text(FLEET_CAMPAIGN)
    write_fleet(3, d / "runs", proto, seed=11, defect_fraction=0.67)
    return d / "runs"


def table(out: Path) -> list[dict]:
    f = out / "fleet.parquet"
    return read_table(f if f.exists() else out / "fleet.csv")


def by_file(rows: list[dict]) -> dict[str, dict]:
    return {Path(r["run_file"]).name: r for r in rows}


def check_equals_cli(rows: list[dict], out: Path, names: list[str], runs: Path) -> None:
    """Each named run's row and documents equal ``labrig fit --json`` / ``diagnose --json``."""
    rows_by = by_file(rows)
    for name in names:
        run = runs / name
        res = invoke("fit", run, "--json")
        assert res.exit_code == 0, res.stderr
        fit = json.loads(res.stdout)
        row = rows_by[name]
        for p in PARAM_NAMES:
            assert row[p] == fit["params"][p], (name, p)
            assert row[f"{p}_sd"] == fit["uncertainty"][p], (name, p)
        assert row["nrmse_pct"] == fit["nrmse_pct"]
        assert row["heldout_nrmse_pct"] == fit["heldout_nrmse_pct"]
        key = row["key"]
        assert json.loads((out / "runs" / key / "fit.json").read_text()) == fit
        if row["command"] != "diagnose":
            continue
        res = invoke("diagnose", run, "--json")
        assert res.exit_code == 0, res.stderr
        diag = json.loads(res.stdout)
        assert json.loads((out / "runs" / key / "diagnosis.json").read_text()) == diag
        assert row["effects"] == ",".join(e["effect"] for e in diag["effects_added"])
        assert row["verdict"] == diag["verdict"]
        assert row["diag_heldout_before_pct"] == diag["before"]["heldout_nrmse_pct"]
        assert row["diag_heldout_after_pct"] == diag["after"]["heldout_nrmse_pct"]
        page = (out / "runs" / key / "diagnosis.html").read_text()
        assert page.lower().startswith("<!doctype html>") and name in page


def without_fleet_page(monkeypatch: pytest.MonkeyPatch) -> None:
    """Leave the fleet page (``fleet.html``: a dozen figures, drawn again by each batch) out of
    a test that does not read it; the page has its own tests (here and
    tests/api/test_day_one.py)."""
    import labrig.fleet.fleet_report as fleet_report

    monkeypatch.setattr(fleet_report, "write_fleet_report", lambda path, *args: path)


def test_batch_diagnose_equals_the_one_by_one_commands(fleet, tmp_path, monkeypatch):
    without_fleet_page(monkeypatch)
    out = tmp_path / "out"
    run = sorted(fleet.glob("*.h5"))[1]
    res = invoke("batch", "diagnose", run, "--out", out, "--serial", "--json")
    assert res.exit_code == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["runs"] == 1 and summary["succeeded"] == 1 and summary["failed"] == []
    rows = table(out)
    check_equals_cli(rows, out, [run.name], fleet)
    # every value a task returns has a column (nothing dropped on the way to the table)
    result = json.loads((out / "runs" / run.stem / "result-diagnose.json").read_text())
    assert set(result["row"]) <= set(rows[0])
    entries = read_table(out / "fleet_entries.parquet")
    # the run's fit.json, which check_equals_cli found equal to ``labrig fit --json``
    fit = json.loads((out / "runs" / rows[0]["key"] / "fit.json").read_text())
    assert [e["entry"] for e in entries] == list(fit["per_entry"])
    assert set().union(*(e.keys() for e in result["entries"])) <= set(entries[0])


@pytest.mark.slow
def test_batch_diagnose_equals_the_one_by_one_commands_on_six_runs(tmp_path):
    proto = tmp_path / "small.yaml"
    proto.write_text(FLEET_CAMPAIGN)
    runs = tmp_path / "runs"
    write_fleet(6, runs, proto, seed=12, defect_fraction=0.5)
    out = tmp_path / "out"
    where = ["--workers", "2"] if importlib.util.find_spec("distributed") else ["--serial"]
    res = invoke("batch", "diagnose", runs, "--out", out, *where, "--json")
    assert res.exit_code == 0, res.stderr
    rows = table(out)
    assert sorted(by_file(rows)) == sorted(p.name for p in runs.glob("*.h5"))
    check_equals_cli(rows, out, sorted(by_file(rows)), runs)
    truth = json.loads((runs / "truth.json").read_text())
    for a in truth["actuators"]:
        r = by_file(rows)[a["run_file"]]
        assert (r["actuator"], r["rig"]) == (a["id"], a["rig"])
    page = (out / "fleet.html").read_text()
    assert "Control charts" in page and "data:image/png;base64," in page


@pytest.mark.slow  # a local Dask cluster; the serial batch tests stay in the default tier
def test_batch_fit_on_a_local_cluster_equals_serial(fleet, tmp_path):
    pytest.importorskip("distributed")
    serial, dask = tmp_path / "serial", tmp_path / "dask"
    files = sorted(str(p) for p in fleet.glob("*.h5"))
    a = invoke("batch", "fit", *files, "--out", serial, "--serial")
    b = invoke("batch", "fit", *files, "--out", dask, "--workers", 2, "--json")
    assert a.exit_code == 0 and b.exit_code == 0, (a.stderr, b.stderr)
    assert json.loads(b.stdout)["scheduler"] == "local"
    ra, rb = by_file(table(serial)), by_file(table(dask))
    assert sorted(ra) == sorted(rb) == sorted(Path(f).name for f in files)
    for name in ra:
        for col in [*PARAM_NAMES, "nrmse_pct", "heldout_nrmse_pct", "creep_pct_per_decade"]:
            assert ra[name][col] == rb[name][col], (name, col)
    check_equals_cli(list(rb.values()), dask, [sorted(rb)[0]], fleet)
    page = (dask / "fleet.html").read_text()
    assert page.count("data:image/png;base64,") >= 9  # distributions + 8 control charts
    assert "Flagged runs" in page and "Verdicts" in page


def test_unreadable_runs_fail_alone_with_their_error(fleet, tmp_path):
    good = sorted(fleet.glob("*.h5"))[0]
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "truncated.h5").write_bytes(good.read_bytes()[:5000])
    (bad / "text.h5").write_text("time,voltage\n0,1\n")
    with h5py.File(bad / "other.h5", "w") as f:
        f["x"] = np.arange(3)
    out = tmp_path / "out"
    res = invoke("batch", "fit", good, f"{bad}/*.h5", "--out", out, "--serial", "--no-heldout")
    assert res.exit_code == 4, res.output
    rows = by_file(table(out))
    assert len(rows) == 4
    assert rows[good.name]["status"] == "ok" and rows[good.name]["error"] == ""
    assert "truncated" in rows["truncated.h5"]["error"]
    assert "not a readable HDF5 run file" in rows["text.h5"]["error"]
    assert "not a labrig run file" in rows["other.h5"]["error"]
    for n in ("truncated.h5", "text.h5", "other.h5"):
        assert rows[n]["status"] == "failed" and rows[n]["alpha0_ue_per_V"] is None
    assert "Failed runs" in (out / "fleet.html").read_text()


def test_bad_input_is_exit_2(fleet, tmp_path):
    res = invoke("batch", "fit", f"{tmp_path}/nothing/*.h5", "--out", tmp_path / "o")
    assert res.exit_code == 2 and "no file matches" in res.output
    other = tmp_path / "other"
    other.mkdir()
    (other / "mine.txt").write_text("keep me")
    res = invoke("batch", "fit", fleet, "--out", other, "--serial")
    assert res.exit_code == 2 and "holds other files" in res.output
    assert (other / "mine.txt").read_text() == "keep me"
    res = invoke("batch", "fit", fleet, "--out", tmp_path / "o", "--serial", "--workers", 2)
    assert res.exit_code == 2


@pytest.mark.slow
def test_rerun_skips_only_unchanged_runs(fleet, tmp_path):
    runs = tmp_path / "runs"
    shutil.copytree(fleet, runs, ignore=shutil.ignore_patterns("setup", "truth.json"))
    files = sorted(runs.glob("*.h5"))[:3]
    out = tmp_path / "out"
    args = ["batch", "fit", *files, "--out", out, "--serial", "--no-heldout", "--json"]
    first = invoke(*args)
    assert first.exit_code == 0, first.stderr
    before = by_file(table(out))
    second = json.loads(invoke(*args).stdout)
    assert second["skipped"] == 3
    again = by_file(table(out))
    assert all(r["skipped"] for r in again.values())
    assert {n: r["alpha0_ue_per_V"] for n, r in again.items()} == {
        n: r["alpha0_ue_per_V"] for n, r in before.items()
    }
    # new content in one file (another actuator's run): only that one is fitted again
    shutil.copyfile(files[2], files[0])
    third = json.loads(invoke(*args).stdout)
    assert third["skipped"] == 2
    rows = by_file(table(out))
    assert not rows[files[0].name]["skipped"]
    assert rows[files[0].name]["alpha0_ue_per_V"] == rows[files[2].name]["alpha0_ue_per_V"]
    # a result written by another labrig version is not reused
    res_file = out / "runs" / rows[files[1].name]["key"] / "result-fit.json"
    doc = json.loads(res_file.read_text())
    doc["identity"]["labrig_version"] = "0.0.1"
    res_file.write_text(json.dumps(doc))
    assert json.loads(invoke(*args).stdout)["skipped"] == 2
    # other options: nothing reused
    other = invoke("batch", "fit", *files, "--out", out, "--serial", "--json")
    assert json.loads(other.stdout)["skipped"] == 0


def test_rerun_skips_an_unchanged_run_and_refits_a_changed_one(fleet, tmp_path, monkeypatch):
    """The default tier's twin of the test above: one run, fitted, skipped, then its content
    replaced by another actuator's run and fitted again. The fleet page (``fleet.html``, drawn
    again by each batch and about two thirds of its CPU here) is left out: the skips are read
    from the JSON summary."""
    without_fleet_page(monkeypatch)
    runs = tmp_path / "runs"
    shutil.copytree(fleet, runs, ignore=shutil.ignore_patterns("setup", "truth.json"))
    first, other = sorted(runs.glob("*.h5"))[:2]
    out = tmp_path / "out"
    args = ["batch", "fit", first, "--out", out, "--serial", "--no-heldout", "--json"]
    assert json.loads(invoke(*args).stdout)["skipped"] == 0
    assert json.loads(invoke(*args).stdout)["skipped"] == 1
    shutil.copyfile(other, first)
    assert json.loads(invoke(*args).stdout)["skipped"] == 0


def test_without_dask_serial_with_a_note_and_without_pyarrow_csv(fleet, tmp_path):
    """In a fresh interpreter where ``distributed`` and ``pyarrow`` cannot be imported. The
    fleet page (not read here; drawing it and importing matplotlib for it were two thirds of
    the child's CPU) is left out as in :func:`without_fleet_page`, its module a stand-in."""
    out = tmp_path / "out"
    code = (
        "import sys, types; sys.modules['distributed'] = None; sys.modules['pyarrow'] = None; "
        "page = types.ModuleType('labrig.fleet.fleet_report'); "
        "page.write_fleet_report = lambda path, *args: path; sys.modules[page.__name__] = page; "
        "from labrig.cli import app; app()"
    )
    files = sorted(str(p) for p in fleet.glob("*.h5"))[:1]
    cmd = [sys.executable, "-c", code, "batch", "fit", *files, "--out", str(out), "--no-heldout"]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=240)
    assert p.returncode == 0, p.stderr
    said = " ".join(p.stderr.split())
    assert "Dask is not installed (pip install 'labrig[fleet]')" in said
    assert "one after another" in said
    assert not (out / "fleet.parquet").exists()
    rows = by_file(read_table(out / "fleet.csv"))
    fit = json.loads(invoke("fit", files[0], "--json", "--no-heldout").stdout)
    assert float(rows[Path(files[0]).name]["alpha0_ue_per_V"]) == fit["params"]["alpha0_ue_per_V"]


def test_robust_z_against_scipy_mad():
    from scipy import stats  # here, not for every worker's collection

    rng = np.random.default_rng(3)
    x = rng.normal(10.0, 2.0, 101)
    ref = (x - np.median(x)) / stats.median_abs_deviation(x, scale="normal")
    np.testing.assert_allclose(robust_z(x), ref, rtol=2e-4)
    # more than half equal: MAD is 0, the mean absolute deviation takes over
    y = np.array([1.0] * 6 + [2.0, 3.0, 11.0])
    dev = np.mean(np.abs(y - 1.0))
    np.testing.assert_allclose(robust_z(y), (y - 1.0) / (1.2533 * dev))


def test_flag_rule():
    rng = np.random.default_rng(5)
    rows = [
        {
            "status": "ok",
            "alpha0_ue_per_V": 8.9 * (1 + 0.03 * g),
            "effects": "",
            "verdict_class": "",
        }
        for g in rng.standard_normal(40)
    ]
    rows[3]["alpha0_ue_per_V"] = 8.9 * 0.8
    rows[7]["effects"] = "sensor_lowpass"
    rows[9]["verdict_class"] = "unexplained"
    rows.append({"status": "failed", "alpha0_ue_per_V": None})
    assert flag_runs(rows) == ["alpha0_ue_per_V"]
    flagged = [i for i, r in enumerate(rows) if r["flagged"]]
    assert flagged == [3, 7, 9]
    assert rows[3]["z_alpha0_ue_per_V"] < -Z_LIMIT
    assert rows[3]["named_effect"] == "alpha0_ue_per_V low"
    assert rows[7]["named_effect"] == "sensor_lowpass"
    assert rows[-1]["flagged"] is None


def test_actuator_identity_from_the_file(fleet, tmp_path):
    from labrig.fleet.identity import run_identity, sample_from_hdf5, sample_from_protocol

    run = sorted(fleet.glob("*.h5"))[0]
    assert run_identity(run)["actuator"] == run.stem  # from the protocol's description
    assert sample_from_hdf5(run) == ""
    # a NeXus NXsample group (as a writer with sample metadata would add it)
    nexus = tmp_path / "sample.h5"
    with h5py.File(nexus, "w") as f:
        g = f.create_group("run").create_group("sample")
        g.attrs["NX_class"] = "NXsample"
        g["serial_number"] = "P-888 #3"
    assert sample_from_hdf5(nexus) == "P-888 #3"
    assert sample_from_protocol("name: x\nmetadata: {sample: stack 12}\n") == "stack 12"
    assert sample_from_protocol("name: x\ndescription: no id here\n") == ""
    # a recorded text is read with the protocol files' bounds: a nesting bomb is no identity
    assert sample_from_protocol("a: " + "[" * 50_000 + "]" * 50_000) == ""


def test_simulated_fleet_truth_and_run_files(fleet):
    truth = json.loads((fleet / "truth.json").read_text())
    assert [a["run_file"] for a in truth["actuators"]] == [f"A000{k}.h5" for k in range(1, 4)]
    defects = [a["defect"] for a in truth["actuators"] if a["defect"]]
    assert sorted(defects) == ["cracked", "depolarised"]
    from labrig.store import read_run

    for a in truth["actuators"]:
        run = read_run(fleet / a["run_file"], load_data=False)
        rig = yaml.safe_load(run.rig_text)
        assert rig["name"] == a["rig"]
        assert rig["bench"]["truth"]["paper_overrides"] == a["params"]
        assert rig["bench"]["effects"] == a["bench_effects"]
        assert run.seed == a["seed"] and run.status == "complete"
        assert f"actuator {a['id']}" in yaml.safe_load(run.protocol_text)["description"]


def test_manufacturing_spread_and_defect_mix():
    from scipy import stats  # here, not for every worker's collection

    fleet = draw_fleet(3000, seed=1, defect_fraction=0.05)
    # a standard normal truncated at +-3 has standard deviation 0.98658 (independent value)
    trunc_sd = float(stats.truncnorm(-TRUNCATE_SIGMA, TRUNCATE_SIGMA).std())
    healthy = [a for a in fleet if a.defect is None]
    for p, s in SPREAD.items():
        rel = np.array([a.params[p] for a in healthy]) / getattr(PAPER_TABLE1, p) - 1
        assert abs(rel.std() / (s * trunc_sd) - 1) < 0.06, p
        assert np.abs(rel).max() <= s * TRUNCATE_SIGMA + 1e-12
    kinds = [a.defect for a in fleet if a.defect]
    assert len(kinds) == 150
    assert {k: kinds.count(k) for k in DEFECTS} == {
        "depolarised": 50,
        "cracked": 50,
        "loose_gauge": 50,
    }
    assert all(a.bench_effects[0]["name"] == "log_creep" for a in fleet if a.defect == "cracked")


def test_sim_fleet_refuses_to_overwrite(tmp_path):
    proto = tmp_path / "small.yaml"
    # one of the campaign's three sines (the run's length is not what is checked)
    proto.write_text(FLEET_CAMPAIGN.replace("[1, 10, 40]", "[40]"))
    out = tmp_path / "f"
    assert invoke("sim", "fleet", 1, "--out", out, "--protocol", proto).exit_code == 0
    before = (out / "A0001.h5").read_bytes()
    res = invoke("sim", "fleet", 1, "--out", out, "--protocol", proto, "--seed", 4)
    assert res.exit_code == 2 and "--overwrite" in res.output
    assert (out / "A0001.h5").read_bytes() == before


def test_batch_report_equals_labrig_report(fleet, tmp_path, monkeypatch):
    without_fleet_page(monkeypatch)
    run = sorted(fleet.glob("*.h5"))[0]
    out = tmp_path / "out"
    res = invoke("batch", "report", run, "--out", out, "--serial", "--no-heldout")
    assert res.exit_code == 0, res.output
    one = invoke("report", run, "--out", tmp_path / "one.html", "--no-heldout", "--json")
    assert one.exit_code == 0, one.stderr
    metrics = json.loads(one.stdout)
    assert json.loads((out / "runs" / run.stem / "report.json").read_text()) == metrics
    row = table(out)[0]
    for model in ("prandtl_ishlinskii", "bouc_wen"):
        mean = np.mean([m[f"{model}.nrmse_pct"] for m in metrics.values()])
        assert row[f"report_{model}_nrmse_pct"] == pytest.approx(mean, rel=1e-12)
    assert (out / "runs" / run.stem / "report.html").read_text().lower().startswith("<!doctype")
