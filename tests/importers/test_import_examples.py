"""Every format of docs/import.md imports from its committed example, with the options the doc
gives, and its broken variant is refused (exit 2) naming the file, the line or variable, and
what was expected. The examples come from tests/data/import/make_examples.py, whose
``signals()`` is the reference here."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from labrig.analysis.load import records_from_run
from labrig.store import read_run

from helpers import invoke as run_cli

DATA = Path(__file__).resolve().parents[1] / "data" / "import"
_spec = importlib.util.spec_from_file_location("make_examples", DATA / "make_examples.py")
assert _spec and _spec.loader
examples = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(examples)
SIG = examples.signals()
UE_PER_UM = 1e3 / examples.STACK_MM  # 1 um over 18 mm is 1e-6 m / 18e-3 m = 55.6 ue

# file, options, channels expected besides time/voltage/strain, strain reference
GOOD = [
    ("header.csv", [], {"temperature": "degC"}, "strain"),
    ("headerless_index.csv", ["--time", "2", "--voltage", "3", "--strain", "4",
                              "--strain-units", "ue"], {}, "strain"),
    ("units_row.csv", ["--stack-length-mm", "18"], {}, "displacement_um"),
    ("semicolon_decimal_comma.csv", [], {}, "strain"),
    ("cp1252.csv", ["--time", "Zeit", "--voltage", "Spannung", "--strain", "Dehnung"],
     {"temperature": "degC"}, "strain"),
    ("utf16.csv", [], {}, "strain"),
    ("bom.csv", [], {}, "strain"),
    ("tab_empty_first.tsv", ["--time", "2", "--voltage", "3", "--strain", "4",
                             "--strain-units", "ue"], {}, "strain"),
    ("plain_v5.mat", [], {"temperature": "degC"}, "strain"),
    ("rows_v5.mat", ["--time", "data:1", "--voltage", "data:2", "--strain", "data:3",
                     "--strain-units", "ue"], {}, "strain"),
    ("plain_v73.mat", ["--time", "t", "--strain-units", "ue"], {}, "strain"),
    ("logical_v5.mat", [], {}, "strain"),  # its logical enabled_V left out
    ("controldesk_v73.mat", [], {}, "strain"),
]  # fmt: skip

# broken file, options, what the message must contain (file is always checked)
BAD = [
    ("header_bad.csv", [], ["header_bad.csv:22:", "column 3", "'12.5.1'", "expected a number"]),
    ("headerless_index_bad.csv", ["--time", "2", "--voltage", "3", "--strain", "4",
                                  "--strain-units", "ue"],
     ["headerless_index_bad.csv:31:", "5 fields, expected 4"]),
    ("units_row_bad.csv", ["--stack-length-mm", "18"],
     ["units_row_bad.csv:13:", "column 1 (time)", "not a number", "time is needed"]),
    ("semicolon_decimal_comma_bad.csv", [],
     ["semicolon_decimal_comma_bad.csv:41:", "'1.234,5'",
      "expected a number with a decimal comma"]),
    ("cp1252_bad.csv", ["--time", "Zeit", "--voltage", "Spannung", "--strain", "Dehnung"],
     ["cp1252_bad.csv:27:", "column 1 (Zeit)", "does not increase"]),
    ("utf16_bad.csv", [], ["utf16_bad.csv:65:", "column 3 (strain)", "strain is needed"]),
    ("bom_bad.csv", [], ["bom_bad.csv:1:", "no line of numbers", "expected delimited numbers"]),
    ("tab_empty_first_bad.tsv", ["--time", "2", "--voltage", "3", "--strain", "4",
                                 "--strain-units", "ue"],
     ["tab_empty_first_bad.tsv:34:", "column 2", "not uniformly sampled"]),
    ("plain_v5_bad.mat", [], ["plain_v5_bad.mat:", "variable time_s", "has 64 samples",
                              "voltage (variable voltage_V) has 59"]),
    ("rows_v5_bad.mat", ["--time", "data:1", "--voltage", "data:2", "--strain", "data:3",
                         "--strain-units", "ue"],
     ["rows_v5_bad.mat:", "variable data, row 2", "sample 17", "voltage is needed"]),
    ("plain_v73_bad.mat", ["--time", "t", "--strain-units", "ue"],
     ["plain_v73_bad.mat:", "variable t, sample 6", "does not increase"]),
    ("controldesk_bad.mat", ["--voltage", "Amplifier", "--strain", "Sensor",
                             "--stack-length-mm", "18"],
     ["controldesk_bad.mat:", "capture capture_1, Y(2)", "has 50 samples",
      "voltage (Y(1) (Model Root/Amplifier/Out1)) has 64"]),
    ("controldesk_v73_bad.mat", [], ["controldesk_v73_bad.mat:", "capture capture_1, Y(2)",
                                     "sample 41", "strain is needed"]),
]  # fmt: skip


def invoke(*args: object):
    return run_cli(*args, columns=None)


@pytest.mark.parametrize(("name", "options", "aux", "strain_key"), GOOD, ids=[g[0] for g in GOOD])
def test_example_imports(tmp_path: Path, name: str, options: list, aux: dict, strain_key: str):
    out = tmp_path / "run.h5"
    res = invoke("import", DATA / name, "--out", out, *options)
    assert res.exit_code == 0, res.output
    (entry,) = list(read_run(out))
    assert entry.rate_hz == pytest.approx(examples.RATE_HZ, rel=1e-9)
    np.testing.assert_allclose(entry.time, SIG["time"], atol=1e-12)
    np.testing.assert_allclose(entry["command_voltage"], SIG["voltage"], atol=1e-9)
    factor = UE_PER_UM if strain_key == "displacement_um" else 1.0
    np.testing.assert_allclose(entry["strain"], SIG[strain_key] * factor, rtol=1e-9, atol=1e-9)
    assert entry.units["strain"] == "ue" and entry.units["command_voltage"] == "V"
    assert {k: entry.units[k] for k in entry.channels if k not in
            ("time", "command_voltage", "strain")} == aux  # fmt: skip
    for k in aux:  # the temperature of the examples, in degC
        np.testing.assert_allclose(entry[k], SIG["temperature"], atol=1e-9)
    (record,) = records_from_run(out)
    assert record.meta["kind"] == "import" and record.hold == "linear"


def test_controldesk_captures_one_entry_each_or_one_picked(tmp_path: Path) -> None:
    out = tmp_path / "dspace.h5"
    options = ["--voltage", "Amplifier", "--strain", "2", "--stack-length-mm", "18"]
    res = invoke("import", DATA / "controldesk.mat", "--out", out, *options)
    assert res.exit_code == 0, res.output
    run = read_run(out)
    assert [e.name for e in run] == ["controldesk_capture_1", "controldesk_capture_2"]
    for e, shift in zip(run, (0.0, 10.0), strict=True):  # the generator shifts capture 2 by 10 V
        np.testing.assert_allclose(e["command_voltage"], SIG["voltage"] + shift, atol=1e-9)
        np.testing.assert_allclose(e["strain"], SIG["displacement_um"] * UE_PER_UM, rtol=1e-9)
        np.testing.assert_allclose(e["temperature"], SIG["temperature"], atol=1e-9)
        step = e.step
        assert (
            step["capture"] in e.name and step["format"]["format"] == "dSPACE ControlDesk capture"
        )
        assert "Revision 2.0" in step["format"]["description"]
        assert step["channels"]["strain"]["conversion"] == "um / 18 mm stack -> ue"
    res = invoke("import", DATA / "controldesk.mat", "--out", out, "--overwrite", "--capture",
                 "capture_2", *options)  # fmt: skip
    assert res.exit_code == 0, res.output
    (only,) = list(read_run(out))
    assert only.name == "controldesk_capture_2"
    np.testing.assert_allclose(only["command_voltage"], SIG["voltage"] + 10.0, atol=1e-9)


def test_list_shows_channels_units_and_lengths() -> None:
    res = invoke("import", DATA / "controldesk.mat", "--list")
    assert res.exit_code == 0, res.output
    for text in ("capture_1", "capture_2", "Model Root/Sensor/Out1 (Sensor)", "um", "degC",
                 "X(1)", "Time", " 64 "):  # fmt: skip
        assert text in res.output
    res = invoke("import", DATA / "units_row.csv", "--list")
    assert res.exit_code == 0, res.output
    assert "units line 2" in res.output and "strain" in res.output and "um" in res.output
    res = invoke("import", DATA / "rows_v5.mat", "--list")
    assert "one signal per row" in res.output and "data:3" in res.output


@pytest.mark.parametrize(("name", "options", "needles"), BAD, ids=[b[0] for b in BAD])
def test_broken_example_names_file_place_and_expectation(
    tmp_path: Path, name: str, options: list, needles: list[str]
) -> None:
    out = tmp_path / "run.h5"
    res = invoke("import", DATA / name, "--out", out, *options)
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    for needle in needles:
        assert needle in res.output
    assert not out.exists()


def test_window_crops_and_is_stated(tmp_path: Path) -> None:
    out = tmp_path / "w.h5"
    res = invoke("import", DATA / "header.csv", "--out", out, "--window", "0.05:0.15")
    assert res.exit_code == 0, res.output
    (e,) = list(read_run(out))
    inside = (SIG["time"] >= 0.05) & (SIG["time"] <= 0.15)
    np.testing.assert_allclose(e["command_voltage"], SIG["voltage"][inside], atol=1e-9)
    np.testing.assert_allclose(e.time, SIG["time"][inside] - 0.05, atol=1e-12)
    assert e.step["window_s"] == [0.05, 0.15]
    assert e.step["window_first_sample_s"] == pytest.approx(0.05)
    json.dumps(e.step)  # the metadata is plain JSON
    res = invoke("import", DATA / "header.csv", "--out", out, "--overwrite", "--window", "5:6")
    assert (
        res.exit_code == 2 and "fewer than 2 samples" in res.output and "0 to 0.315" in res.output
    )
