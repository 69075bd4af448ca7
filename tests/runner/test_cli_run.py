"""`labrig run / info / export / check` end to end on the simulated rig.

The paper's campaign (experiments/paper.yaml, 11 entries) runs once (in-process, typer's
CliRunner); the tests read its file: statuses, the NeXus layout, and loops that look like the
paper's (about 1000 ue at 100 V, hysteresis, a positive strain at 0 V after the first cycle).
Device faults and bad --out paths go through the CLI in-process (typer's CliRunner).
"""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from labrig.cli import app
from labrig.store import read_run

from helpers import arm

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "experiments" / "paper.yaml"
SEED = 1
ENTRIES = [
    *(f"sine_{a}V_{f}Hz" for a in (50, 100) for f in (1, 5, 10, 20, 40)),
    "vanishing_100V_1Hz",
]
CHANNELS = {
    "time": "s",
    "command_voltage": "V",
    "gauge_raw": "V",
    "strain": "um/m",  # microstrain as pint and UDUNITS read it (in memory: ue)
    "amplifier_voltage": "V",
}

pytestmark = pytest.mark.timeout(180)


def labrig_cmd() -> list[str]:
    exe = Path(sys.executable).parent / "labrig"
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "labrig.cli"]


@pytest.fixture(scope="module")
def paper_run(tmp_path_factory) -> tuple[Path, SimpleNamespace]:
    """``labrig run`` of the paper's campaign, in-process (typer's CliRunner) from a folder of
    its own; its exit code and outputs as a finished process's (``returncode``, ``stdout``,
    ``stderr``). The signals tests run ``labrig`` as a process (tests/runner/
    test_runner_signals.py)."""
    d = tmp_path_factory.mktemp("paper")
    out = d / "paper.h5"
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(d)
        res = CliRunner().invoke(
            app, ["run", str(PAPER), "--out", str(out), "--seed", str(SEED)], env={"COLUMNS": "80"}
        )
    assert isinstance(res.exception, SystemExit | None), repr(res.exception)
    return out, SimpleNamespace(returncode=res.exit_code, stdout=res.stdout, stderr=res.stderr)


@pytest.fixture(scope="module")
def paper(paper_run):
    out, proc = paper_run
    assert proc.returncode == 0, proc.stderr
    return read_run(out)


def test_paper_run_completes(paper_run, paper):
    out, proc = paper_run
    assert proc.stdout.strip().splitlines()[-1] == str(out)  # prints the run file's path
    assert "Traceback" not in proc.stderr
    assert "run complete: 11 entries" in proc.stderr
    assert paper.status == "complete" and not paper.incomplete and paper.reason == ""
    assert paper.seed == SEED
    assert paper.planned_entries == ENTRIES
    assert list(paper.entries) == ENTRIES
    for e in paper:
        assert e.status == "complete", e.name
        assert e.rate_hz == 1000.0
        assert e.n_samples == e.step["n_samples"] > 0
        assert not e.trimmed
    assert paper.protocol_text == PAPER.read_text()
    assert paper.start_time and paper.end_time
    with h5py.File(out, "r") as f:
        assert float(f["run/final_amplifier_voltage_V"][()]) == 0.0


def _cycles(e, skip_s: float = 1.0):
    """Command voltage, strain and the sign of dV for t >= skip_s (the first cycle skipped)."""
    t, v, s = e.time, e["command_voltage"], e["strain"]
    m = t >= skip_s
    return v[m], s[m], np.sign(np.gradient(v))[m]


def test_loops_look_like_the_seeds(paper):
    # about 1000 ue at 100 V at every frequency
    for f in (1, 5, 10, 20, 40):
        e = paper[f"sine_100V_{f}Hz"]
        v, s, _ = _cycles(e)
        peak = s[v >= v.max() - 1.0].mean()
        assert 800 <= peak <= 1300, (e.name, peak)
        half = paper[f"sine_50V_{f}Hz"]
        hv, hs, _ = _cycles(half)
        assert 0.3 * peak <= hs[hv >= hv.max() - 0.5].mean() <= 0.6 * peak, half.name

    e = paper["sine_100V_1Hz"]
    v, s, dv = _cycles(e)
    span = s.max() - s.min()
    # visible hysteresis: at mid-voltage the falling branch lies well above the rising one
    mid = np.abs(v - 50.0) < 1.0
    gap = s[mid & (dv < 0)].mean() - s[mid & (dv > 0)].mean()
    assert gap > 0.08 * span, (gap, span)
    # and the loop encloses an area (one steady cycle, t in [3, 4) s)
    c = (e.time >= 3.0) & (e.time < 4.0)
    area = -np.trapezoid(e["strain"][c], e["command_voltage"][c])
    assert area > 0.05 * 100.0 * span, area

    # positive strain at 0 V after the first cycle, also in the first entry (from rest)
    first = paper["sine_50V_1Hz"]
    assert abs(first["strain"][:50].mean()) < 10.0  # starts at 0 after the zero balance
    for name in ("sine_50V_1Hz", "sine_100V_1Hz"):
        v, s, _ = _cycles(paper[name])
        assert s[v < 0.5].mean() > 15.0, name  # well above the 2 ue noise

    # the amplifier follows the command (monitor channel, a few quantisation steps)
    amp = e["amplifier_voltage"] - e["command_voltage"]
    assert np.sqrt(np.mean(amp**2)) < 0.5


def test_run_file_is_nexus_self_describing(paper_run):
    out, _ = paper_run
    with h5py.File(out, "r") as f:
        assert f.attrs["NX_class"] == "NXroot"
        default = f.attrs["default"]
        assert default in ENTRIES and f[default].attrs["NX_class"] == "NXentry"
        for name in ENTRIES:
            g = f[name]
            assert g.attrs["NX_class"] == "NXentry"
            assert g.attrs["default"] == "data"
            d = g["data"]
            assert d.attrs["NX_class"] == "NXdata"
            assert d.attrs["signal"] == "strain"
            assert [str(a) for a in d.attrs["axes"]] == ["time"]
            assert set(d) == set(CHANNELS)
            for ch, units in CHANNELS.items():
                ds = d[ch]
                assert ds.attrs["units"] == units, (name, ch)
                assert str(ds.attrs["long_name"]).strip(), (name, ch)
            for key in ("sample_rate", "duration"):
                assert g[key].attrs["units"] in ("Hz", "s")
                assert str(g[key].attrs["long_name"]).strip()
            assert g["status"][()].decode() == "complete"
            for note in ("protocol", "rig"):
                assert g[note].attrs["NX_class"] == "NXnote"
            assert g["instrument"].attrs["NX_class"] == "NXinstrument"
        run = f["run"]
        assert run["status"][()].decode() == "complete"
        assert run["protocol/data"][()].decode() == PAPER.read_text()
        inst = run["instrument"]
        for dev in ("daq", "amplifier", "conditioner"):
            assert dev in inst
        assert "E-503" in inst["amplifier/identity"][()].decode()


def test_info_and_export(paper_run, paper, tmp_path):
    out, _ = paper_run
    res = CliRunner().invoke(app, ["info", str(out)], env={"COLUMNS": "160"})
    assert res.exit_code == 0, res.output
    assert "status: complete" in res.output
    assert "entries: 11 of 11 planned" in res.output
    for name in ENTRIES:
        assert name in res.output

    csv_dir = tmp_path / "csv"
    res = CliRunner().invoke(app, ["export", str(out), "--csv", str(csv_dir)])
    assert res.exit_code == 0, res.output
    files = sorted(csv_dir.glob("*.csv"))
    assert sorted(p.stem for p in files) == sorted(ENTRIES)
    e = paper["sine_100V_40Hz"]
    with open(csv_dir / "sine_100V_40Hz.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    header = rows[0]
    assert {"time_s", "command_voltage_V", "strain_ue", "amplifier_voltage_V"} <= set(header)
    table = np.array(rows[1:], dtype=float)
    assert table.shape == (e.n_samples, len(header))
    strain = table[:, header.index("strain_ue")]
    np.testing.assert_allclose(strain, e["strain"], rtol=1e-9, atol=1e-9)


def test_check_prints_the_plan():
    res = CliRunner().invoke(app, ["check", str(PAPER)], env={"COLUMNS": "160"})
    assert res.exit_code == 0, res.output
    for name in ENTRIES:
        assert name in res.output
    assert f"{PAPER}: OK, 11 entries, 87.5 s" in res.output


def test_same_seed_same_data(tmp_path):
    """`--seed` makes a simulated run reproducible: same seed, identical data; another seed,
    other noise."""
    proto = tmp_path / "p.yaml"
    proto.write_text(
        "name: seeded\nrate_hz: 1000\nrest_s: 0.5\nsteps:\n"
        "  - {kind: sine, amplitude_V: 60, frequency_hz: 5, cycles: 5}\n"
        "  - {kind: hold, voltage_V: 0, duration_s: 0.5}\n"
    )
    runs = {}
    for name, seed in (("a", 11), ("b", 11), ("c", 12)):
        out = tmp_path / f"{name}.h5"
        res = CliRunner().invoke(app, ["run", str(proto), "--out", str(out), "--seed", str(seed)])
        assert res.exit_code == 0, res.output
        assert f"(seed {seed})" in res.output
        runs[name] = read_run(out)
    a, b, c = runs["a"], runs["b"], runs["c"]
    assert (a.seed, b.seed, c.seed) == (11, 11, 12)
    assert len(a) == 2
    for e in a:
        for ch in e.channels:
            np.testing.assert_array_equal(e[ch], b[e.name][ch], err_msg=f"{e.name}/{ch}")
    assert not np.array_equal(a["sine_60V_5Hz"]["strain"], c["sine_60V_5Hz"]["strain"])


def test_a_rig_whose_devices_are_absent_exits_3(tmp_path):
    """The lab rig file (NI DAQ, serial amplifier) on a machine without them: a device error
    naming the device, exit 3, no file, no traceback."""
    out = tmp_path / "run.h5"
    lab = ROOT / "experiments" / "rigs" / "lab-example.yaml"
    res = CliRunner().invoke(
        app,
        ["run", str(ROOT / "experiments" / "envelope.yaml"), "--rig", str(lab), "--out", str(out)],
    )
    assert res.exit_code == 3, res.output
    assert isinstance(res.exception, SystemExit)
    assert "error: daq" in res.output or "error: amplifier" in res.output, res.output
    assert not out.exists()


# -- device faults and --out through the CLI ----------------------------------------------------


def test_device_fault_exits_3_with_the_device_named(tmp_path, monkeypatch):
    rigs = arm(monkeypatch, 2500, lambda: rigs[0].sim.bench.inject("over_temperature"))
    out = tmp_path / "run.h5"
    res = CliRunner().invoke(app, ["run", str(PAPER), "--out", str(out), "--seed", "2"])
    assert res.exit_code == 3, res.output
    assert "Traceback" not in res.output
    assert "run failed" in res.output
    assert "amplifier" in res.output and "over-temperature" in res.output
    assert res.output.strip().splitlines()[-1] == str(out)
    f = read_run(out)
    assert f.status == "failed" and "over-temperature" in f.reason
    assert [e.status for e in f] == ["failed"]
    assert rigs[0].sim.bench.amp.v_out == 0.0


def test_bad_out_paths_are_refused_without_traceback(tmp_path):
    proto = tmp_path / "p.yaml"
    proto.write_text(
        "name: p\nrate_hz: 1000\nsteps:\n  - {kind: hold, voltage_V: 5, duration_s: 0.2}\n"
    )
    d = tmp_path / "adir"
    d.mkdir()
    existing = tmp_path / "old.h5"
    existing.write_bytes(b"keep me")
    cases = [
        (["--out", str(d)], "is a directory"),
        (["--out", str(d), "--overwrite"], "is a directory"),
        (["--out", str(existing)], "exists"),
        (["--out", "/proc/no/such/place/run.h5"], "cannot create the run file"),
    ]
    for extra, words in cases:
        res = CliRunner().invoke(app, ["run", str(proto), *extra])
        assert res.exit_code == 2, (extra, res.output)
        assert isinstance(res.exception, SystemExit), (extra, repr(res.exception))
        assert words in res.output, (extra, res.output)
    assert existing.read_bytes() == b"keep me"
    assert list(d.iterdir()) == []


def test_export_to_an_unwritable_place_is_a_message(paper_run):
    out, _ = paper_run
    res = CliRunner().invoke(app, ["export", str(out), "--csv", "/proc/no/such/dir"])
    assert res.exit_code != 0
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.output.startswith("error: ")


def test_protocol_name_with_brackets_runs(tmp_path):
    """Rich markup in a protocol's name is printed as text, not parsed."""
    proto = tmp_path / "p.yaml"
    proto.write_text(
        'name: "shots [/b] and [red]"\nrate_hz: 1000\n'
        "steps:\n  - {kind: hold, voltage_V: 5, duration_s: 0.2}\n"
    )
    out = tmp_path / "run.h5"
    res = CliRunner().invoke(app, ["run", str(proto), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "shots [/b] and [red]" in res.output
    assert read_run(out).status == "complete"


def test_check_protocol_name_with_brackets(tmp_path):
    proto = tmp_path / "p.yaml"
    proto.write_text(
        'name: "shots [/b]"\nrate_hz: 1000\n'
        "steps:\n  - {kind: hold, voltage_V: 5, duration_s: 0.2}\n"
    )
    res = CliRunner().invoke(app, ["check", str(proto)])
    assert res.exit_code == 0 and res.exception is None, res.output


@pytest.mark.slow
def test_realtime_run_keeps_to_the_clock(tmp_path):
    """`--realtime` paces the simulated rig: the 15.5 s envelope takes 15.5 s, not less and
    not much more (the runner keeps up at 1 kHz with its health checks and flushes)."""
    import time

    out = tmp_path / "env.h5"
    proto = ROOT / "experiments" / "envelope.yaml"
    t0 = time.monotonic()
    proc = subprocess.run(
        [*labrig_cmd(), "run", str(proto), "--realtime", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    wall = time.monotonic() - t0
    assert proc.returncode == 0, proc.stderr
    (e,) = list(read_run(out))
    assert e.status == "complete" and e.n_samples == e.step["n_samples"]
    assert 15.5 <= wall <= 15.5 + 6.0  # start-up (imports, simulators) included
