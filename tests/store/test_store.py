"""HDF5 run files: round trip, NeXus attributes, units, info and CSV export."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from rich.console import Console

from labrig.core.errors import InputFileError
from labrig.core.version import __version__
from labrig.store import (
    STANDARD_CHANNELS,
    Channel,
    RunWriter,
    export_csv,
    read_run,
    run_info,
    run_summary,
)
from labrig.store.format import stored_units

CHANNELS = ["command_voltage", "amplifier_voltage", "gauge_raw", "strain", "temperature"]
DESCRIBE = {
    "amplifier": {
        "identity": {"vendor": "PI", "model": "E-503", "serial": "sim-0001"},
        "settings": {"gain": 10.0, "i_peak_A": 0.18, "enabled": True, "ranges_V": [-20, 100]},
    },
    "conditioner": {
        "identity": {"model": "DH3840"},
        "settings": {"sensitivity_mV_per_ue": 1.085, "filter_hz": 300, "note": None},
    },
    "daq": {"identity": {"model": "sim"}, "settings": {"rate_hz": 1000, "channels": ["ai0"]}},
}


def block(k0: int, n: int, amp: float = 100.0) -> dict[str, np.ndarray]:
    k = np.arange(k0, k0 + n)
    v = amp / 2 * (1 - np.cos(2 * np.pi * k / 1000))
    return {
        "command_voltage": v,
        "amplifier_voltage": v * 0.99,
        "gauge_raw": v * 1.085e-2,
        "strain": v * 10.0,
        "temperature": np.full(n, 23.5),
    }


def write_run(path: Path, n_blocks=(3, 2), finish=True) -> RunWriter:
    w = RunWriter(
        path,
        "name: test\nrate_hz: 1000\n",
        "kind: simulated\n",
        DESCRIBE,
        seed=42,
        protocol_name="test",
        protocol_file="p.yaml",
        rig_file="r.yaml",
        planned_entries=["sine_100V_1Hz", "sine_50V_1Hz", "never_run"],
    )
    for name, amp, nb in [
        ("sine_100V_1Hz", 100.0, n_blocks[0]),
        ("sine_50V_1Hz", 50.0, n_blocks[1]),
    ]:
        e = w.begin_entry(name, {"kind": "sine", "amplitude_V": amp}, 1000.0, CHANNELS)
        for b in range(nb):
            e.append(block(b * 250, 250, amp))
        if finish or name == "sine_100V_1Hz":
            e.finish("complete")
    if finish:
        w.finish("complete")
    w.close()
    return w


def test_round_trip(tmp_path):
    p = tmp_path / "run.h5"
    write_run(p)
    run = read_run(p)
    assert run.status == "complete" and not run.incomplete and run.reason == ""
    assert run.seed == 42 and run.software_version == __version__
    assert run.protocol_text.startswith("name: test") and run.rig_text == "kind: simulated\n"
    assert run.protocol_file == "p.yaml" and run.rig_file == "r.yaml"
    assert run.instrument == DESCRIBE
    assert run.planned_entries == ["sine_100V_1Hz", "sine_50V_1Hz", "never_run"]
    assert list(run.entries) == ["sine_100V_1Hz", "sine_50V_1Hz"]
    e = run["sine_100V_1Hz"]
    assert e.status == "complete" and e.rate_hz == 1000 and e.index == 0
    assert e.step == {"kind": "sine", "amplitude_V": 100.0}
    assert e.channels == ["time", *CHANNELS]
    assert e.n_samples == 750 and e.duration_s == pytest.approx(0.749)
    np.testing.assert_allclose(e.time, np.arange(750) / 1000)
    ref = block(0, 750)
    for c in CHANNELS:
        np.testing.assert_array_equal(e[c], ref[c])
    assert e.units["strain"] == "ue" and e.units["time"] == "s"
    assert e.start_time <= e.end_time
    assert run["sine_50V_1Hz"].n_samples == 500


def test_nexus_structure_and_units(tmp_path):
    p = tmp_path / "run.h5"
    write_run(p)
    with h5py.File(p, "r") as f:
        assert f.attrs["NX_class"] == "NXroot"
        assert f.attrs["default"] == "sine_100V_1Hz"
        assert f.attrs["creator"] == "labrig" and f.attrs["creator_version"] == __version__
        for key in ("file_name", "file_time", "HDF5_Version", "h5py_version"):
            assert key in f.attrs
        assert f["run"].attrs["NX_class"] == "NXcollection"
        assert f["run/protocol"].attrs["NX_class"] == "NXnote"
        assert f["run/rig"].attrs["NX_class"] == "NXnote"
        assert f["run/instrument"].attrs["NX_class"] == "NXinstrument"
        assert f["run/instrument/amplifier/identity/model"][()] == b"E-503"
        assert f["run/instrument/amplifier/settings/i_peak_A"].attrs["units"] == "A"
        assert f["run/status"][()] == b"complete"
        for name in ("sine_100V_1Hz", "sine_50V_1Hz"):
            g = f[name]
            assert g.attrs["NX_class"] == "NXentry" and g.attrs["default"] == "data"
            for fld in ("title", "start_time", "end_time", "status", "step_definition"):
                assert fld in g, fld
            assert json.loads(g["step_definition"][()])["kind"] == "sine"
            assert g["sample_rate"].attrs["units"] == "Hz"
            # instrument and notes are links to the run-level groups, not copies
            assert g["instrument"] == f["run/instrument"]
            assert g["protocol"] == f["run/protocol"]
            d = g["data"]
            assert d.attrs["NX_class"] == "NXdata"
            assert d.attrs["signal"] == "strain"
            assert list(d.attrs["axes"]) == ["time"]
            assert "temperature" in list(d.attrs["auxiliary_signals"])
            for ds_name, ds in d.items():
                assert isinstance(ds, h5py.Dataset)
                assert ds.attrs["units"] and ds.attrs["long_name"], ds_name
                if ds_name in STANDARD_CHANNELS:  # as stored: microstrain as pint reads it
                    assert ds.attrs["units"] == stored_units(STANDARD_CHANNELS[ds_name][0])
                assert ds.chunks is not None and ds.maxshape == (None,)


def test_statuses_and_context_manager(tmp_path):
    p = tmp_path / "failed.h5"
    with pytest.raises(RuntimeError), RunWriter(p, "", "", {}, seed=None) as w:
        e = w.begin_entry("a", {}, 100.0, [Channel("x", "V", "x signal")])
        e.append({"x": np.ones(5)})
        raise RuntimeError("amplifier over temperature")
    run = read_run(p)
    assert run.status == "failed" and "over temperature" in run.reason
    assert run["a"].status == "failed" and run.seed is None
    np.testing.assert_allclose(run["a"].time, np.arange(5) / 100)  # time filled in

    p = tmp_path / "aborted.h5"
    with pytest.raises(KeyboardInterrupt), RunWriter(p, "", "", {}, seed=1) as w:
        w.begin_entry("a", {}, 100.0, ["strain"]).append({"strain": np.ones(3)})
        raise KeyboardInterrupt
    run = read_run(p)
    assert run.status == "aborted" and run["a"].status == "aborted"

    p = tmp_path / "explicit.h5"
    with RunWriter(p, "", "", {}, seed=1) as w:
        e = w.begin_entry("a", {}, 100.0, ["strain"])
        e.finish("aborted", "user asked")
        w.finish("aborted", "user asked")
    run = read_run(p)
    assert run.status == "aborted" and run["a"].reason == "user asked"


def test_writer_refuses_misuse(tmp_path):
    p = tmp_path / "x.h5"
    with RunWriter(p, "", "", {}, seed=1) as w:
        e = w.begin_entry("a", {}, 100.0, ["strain"])
        with pytest.raises(ValueError, match="missing"):
            e.append({"command_voltage": np.ones(3)})
        with pytest.raises(ValueError, match="length"):
            e.append({"strain": np.ones(3), "time": np.ones(2)})
        with pytest.raises(RuntimeError, match="still running"):
            w.begin_entry("b", {}, 100.0, ["strain"])
        e.finish()
        with pytest.raises(ValueError, match="exists"):
            w.begin_entry("a", {}, 100.0, ["strain"])
        with pytest.raises(ValueError):
            w.begin_entry("bad name", {}, 100.0, ["strain"])
        with pytest.raises(RuntimeError):
            e.append({"strain": np.ones(3)})
    with pytest.raises(FileExistsError):
        RunWriter(p, "", "", {}, seed=1)


def test_unfinished_run_reads_as_incomplete(tmp_path):
    p = tmp_path / "run.h5"
    write_run(p, finish=False)
    run = read_run(p)
    assert run.status == "running" and run.incomplete
    assert run["sine_100V_1Hz"].status == "complete"
    assert run["sine_50V_1Hz"].status == "running"
    console = Console(width=150, record=True)
    console.print(run_info(p))
    assert "incomplete" in console.export_text()


def test_info_and_summary(tmp_path):
    p = tmp_path / "run.h5"
    write_run(p)
    s = run_summary(p)
    assert s["status"] == "complete" and s["planned_entries"] == 3
    e0 = s["entries"][0]
    assert e0["samples"] == 750 and e0["rate_hz"] == 1000
    assert e0["max_command_voltage_V"] == pytest.approx(100, rel=1e-3)
    assert e0["max_strain_ue"] == pytest.approx(1000, rel=1e-3)
    json.dumps(s)
    console = Console(width=150, record=True)
    console.print(run_info(p))
    out = console.export_text()
    assert "sine_100V_1Hz" in out and "complete" in out and "2 of 3 planned" in out


def test_export_csv(tmp_path):
    p = tmp_path / "run.h5"
    write_run(p)
    paths = export_csv(p, tmp_path / "csv")
    assert [q.name for q in paths] == ["sine_100V_1Hz.csv", "sine_50V_1Hz.csv"]
    lines = paths[0].read_text().splitlines()
    assert lines[0] == (
        "time_s,command_voltage_V,amplifier_voltage_V,gauge_raw_V,strain_ue,temperature_degC"
    )
    assert len(lines) == 751
    table = np.loadtxt(paths[0], delimiter=",", skiprows=1)
    e = read_run(p)["sine_100V_1Hz"]
    np.testing.assert_allclose(table[:, 0], e.time, rtol=1e-9)
    np.testing.assert_allclose(table[:, 4], e["strain"], rtol=1e-9)


def test_reading_non_run_files_is_an_input_error(tmp_path):
    with pytest.raises(InputFileError):
        read_run(tmp_path / "missing.h5")
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5 at all")
    with pytest.raises(InputFileError, match="HDF5"):
        read_run(junk)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = 1
    with pytest.raises(InputFileError, match="labrig"):
        read_run(other)


def test_instrument_units_from_key_names(tmp_path):
    p = tmp_path / "u.h5"
    desc = {"amp": {"gain_V_per_V": 10.0, "i_peak_A": 0.18, "rate_hz": 1000, "foo_per_bar": 1}}
    with RunWriter(p, "", "", desc, seed=1) as w:
        w.begin_entry("a", {}, 100.0, ["strain"], title="a title").finish()
    with h5py.File(p, "r") as f:
        g = f["run/instrument/amp"]
        assert g["gain_V_per_V"].attrs["units"] == "V/V"
        assert g["i_peak_A"].attrs["units"] == "A"
        assert g["rate_hz"].attrs["units"] == "Hz"
        assert "units" not in g["foo_per_bar"].attrs
    assert read_run(p)["a"].title == "a title"


def test_signal_falls_back_without_strain(tmp_path):
    p = tmp_path / "s.h5"
    with RunWriter(p, "", "", {}, seed=1) as w:
        w.begin_entry("a", {}, 100.0, [("force", "N", "force")]).append({"force": [1.0, 2.0]})
    with h5py.File(p, "r") as f:
        assert f["a/data"].attrs["signal"] == "force"
    e = read_run(p)["a"]
    assert e.signal == "force" and e.units["force"] == "N"
