"""The pieces under ``labrig import``: text layouts found from the first bytes, labels split into
name and unit, units converted to the run file's (checked against hand-written factors), and
auxiliary columns kept with their names and units, a temperature as ``temperature`` in degC."""

from __future__ import annotations

import codecs
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from labrig.analysis.load import records_from_run
from labrig.cli import app
from labrig.importers.labels import entry_name, short_channel_name, split_label
from labrig.importers.sniff import LayoutError, find_layout
from labrig.importers.units import convert, parse_unit
from labrig.store import read_run


def layout(text: str | bytes, **kw):
    data = text.encode() if isinstance(text, str) else text
    return find_layout(data, True, **kw)


def test_tab_file_with_empty_first_field_keeps_its_columns() -> None:
    lay = layout("\t0.0002\t-1.72\t0.0\n\t0.0004\t-1.70\t0.1\n")
    assert (lay.separator, lay.width, lay.names) == ("\t", 4, None)


def test_comma_file_with_empty_index_column() -> None:
    lay = layout(",0.0002,-1.72,0.0\n,0.0004,-1.70,0.1\n")
    assert (lay.separator, lay.decimal, lay.width) == (",", ".", 4)


def test_semicolon_with_decimal_comma_and_units_row() -> None:
    lay = layout("Messung 3\ntime;voltage;strain\ns;mV;um\n0,001;1,5;2,5\n0,002;1,6;2,7\n")
    assert (lay.separator, lay.decimal, lay.first_data_line) == (";", ",", 4)
    assert (lay.header_line, lay.units_line) == (2, 3)
    assert lay.names == ["time", "voltage", "strain"] and lay.units == ["s", "mV", "um"]
    assert any("skipped lines 1" in n for n in lay.notes)


def test_header_units_in_brackets_suffixes_and_commented_header() -> None:
    lay = layout("Time [s]\tVoltage (mV)\ttemperature_C\tstrain_raw\n0\t1\t20\t3\n1\t2\t21\t4\n")
    assert lay.names == ["Time", "Voltage", "temperature", "strain_raw"]
    assert lay.units == ["s", "mV", "C", ""]
    lay = layout("# time_s,voltage_V,strain_ue\n0,1,2\n1,2,3\n")
    assert lay.names == ["time", "voltage", "strain"] and lay.header_line == 1


def test_header_one_short_names_columns_after_an_index() -> None:
    lay = layout("time,voltage,strain\n0,0.0,1,2\n1,0.1,2,3\n")
    assert lay.names == ["", "time", "voltage", "strain"]


@pytest.mark.parametrize(
    ("encoding", "bom"),
    [("utf-8-sig", b""), ("utf-16", b""), ("utf-16-le", b""), ("cp1252", b"")],
)
def test_encodings(encoding: str, bom: bytes) -> None:
    text = "Zeit [s];Temperatur [°C];Dehnung [µm/m]\n0,0;20,5;1,0\n0,1;20,6;2,0\n"
    lay = layout(bom + text.encode(encoding))
    assert lay.names == ["Zeit", "Temperatur", "Dehnung"]
    assert lay.units == ["s", "°C", "µm/m"]
    assert codecs.lookup(lay.encoding).name.startswith(codecs.lookup(encoding).name[:6])


def test_binary_and_empty_refused() -> None:
    with pytest.raises(LayoutError, match="binary"):
        layout(b"\x00\x01\x02junk\x03")
    with pytest.raises(LayoutError, match="no data"):
        layout("# only a comment\n\n")
    with pytest.raises(LayoutError, match="no line of numbers"):
        layout("a,b\nc,d\n")


@pytest.mark.parametrize(
    ("label", "expected"),
    [
        ("voltage_V", ("voltage", "V")),
        ("strain_raw", ("strain_raw", "")),
        ("T_degC", ("T", "degC")),
        ("Voltage [mV]", ("Voltage", "mV")),
        ("disp / um", ("disp", "um")),
        ('"time (s)"', ("time", "s")),
        ("command_voltage", ("command_voltage", "")),
    ],
)
def test_split_label(label: str, expected: tuple[str, str]) -> None:
    assert split_label(label) == expected


@pytest.mark.parametrize(
    ("unit", "kind", "value", "expected"),
    [
        ("mV", "voltage", 1500.0, 1.5),
        ("kV", "voltage", 0.1, 100.0),
        ("ms", "time", 250.0, 0.25),
        ("K", "temperature", 300.0, 26.85),
        ("degF", "temperature", 212.0, 100.0),
        ("C", "temperature", 21.5, 21.5),
        ("%", "strain", 0.1, 1000.0),
        ("ppm", "strain", 7.0, 7.0),
        ("mm/m", "strain", 1.0, 1000.0),
        ("µε", "strain", 3.0, 3.0),
    ],
)
def test_units_convert_to_run_units(unit: str, kind: str, value: float, expected: float) -> None:
    u = parse_unit(unit)
    assert u.kind == kind
    out, stored, _ = convert(np.array([value]), u, kind)
    assert stored in ("V", "s", "degC", "ue")
    assert out[0] == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("unit", ["raw", "counts", "a.u.", "V/V", "rad", "m**99999999"])
def test_unknown_or_foreign_units_kept_as_text(unit: str) -> None:
    out, stored, note = convert(np.array([2.0]), parse_unit(unit), "voltage")
    assert (out[0], stored, note) == (2.0, unit, "")


def test_names() -> None:
    assert entry_name(Path("my-run 1.csv"), "", 1, set()) == "my_run_1"
    assert entry_name(Path("run.csv"), "", 1, set()) == "run_2"
    assert entry_name(Path("3.csv"), "", 1, set()) == "entry_3"
    assert entry_name(Path("d.mat"), "cap 1", 2, {"d_cap_1"}) == "d_cap_1_2"
    assert short_channel_name("Model Root/amp/Out1") == "amp"
    assert short_channel_name('"Model Root"/mr/scale\\gm_ia') == "gm_ia"


def test_every_named_column_kept_temperature_in_degc_without_options(tmp_path: Path) -> None:
    t = np.arange(50) / 100.0
    rows = [
        f"{x:.2f},{2 * x:.3f},{3 * x:.3f},{300 + x:.3f},{0.5 * x:.3f},{x:.3f},2024-01-0{1 + i % 5}"
        for i, x in enumerate(t)
    ]
    f = tmp_path / "heated.csv"
    f.write_text("time_s,voltage_V,strain_ue,T_K,current_mA,gain,stamp\n" + "\n".join(rows))
    out = tmp_path / "h.h5"
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(out)])
    assert res.exit_code == 0, res.output
    (e,) = list(read_run(out))
    assert e.units["temperature"] == "degC" and e.units["current"] == "mA"
    assert e.units["gain"] == ""
    np.testing.assert_allclose(e["temperature"], 300 + t - 273.15, atol=1e-9)
    np.testing.assert_allclose(e["current"], 0.5 * t, atol=1e-9)
    assert "stamp" not in e.channels
    assert any("stamp" in s and "text" in s for s in e.step["skipped"])
    (rec,) = records_from_run(out)
    np.testing.assert_allclose(rec.aux["temperature"], 300 + t - 273.15, atol=1e-9)


def test_scale_sign_and_stack_length_are_applied_and_recorded(tmp_path: Path) -> None:
    f = tmp_path / "d.csv"
    f.write_text("t [ms],u [mV],disp [um]\n0,1000,9\n5,2000,18\n10,3000,27\n")
    out = tmp_path / "d.h5"
    args = ["import", str(f), "--out", str(out), "--time", "t", "--voltage", "u", "--strain"]
    args += ["disp", "--stack-length-mm", "18", "--strain-scale", "-1", "--voltage-scale", "10"]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    (e,) = list(read_run(out))
    assert e.rate_hz == pytest.approx(200.0)
    np.testing.assert_allclose(e["command_voltage"], [10.0, 20.0, 30.0])  # mV -> V, x10
    np.testing.assert_allclose(e["strain"], [-500.0, -1000.0, -1500.0])  # 9 um / 18 mm = 500 ue
    ch = e.step["channels"]
    assert ch["strain"]["scale"] == -1.0 and ch["strain"]["unit_in_file"] == "um"
    assert ch["command_voltage"]["conversion"] == "mV -> V" and ch["command_voltage"]["scale"] == 10


def test_the_import_says_what_it_assumed_of_the_units(tmp_path: Path) -> None:
    """A column stating no unit is taken in the run file's unit, and the import says so for
    that column (a time in ms would otherwise pass for seconds unnoticed); a column stating its
    unit gets no such line; ``--stack-length-mm`` given for a strain that is no displacement is
    said to be unused. The entry's metadata holds the same notes."""
    t = np.arange(400) / 1000.0
    v = 50 * (1 - np.cos(2 * np.pi * 5 * t))
    bare = tmp_path / "bare.csv"
    np.savetxt(bare, np.column_stack([t * 1000, v, 9 * v]), delimiter=",")  # time in ms
    labelled = tmp_path / "labelled.csv"
    with labelled.open("w") as f:
        f.write("time [ms],voltage [V],strain [ue]\n")
        np.savetxt(f, np.column_stack([t * 1000, v, 9 * v]), delimiter=",")
    runner = CliRunner()
    res = runner.invoke(app, ["import", str(bare), "--out", str(tmp_path / "a.h5"),
                              "--time", "1", "--voltage", "2", "--strain", "3",
                              "--strain-units", "ue", "--stack-length-mm", "18"])  # fmt: skip
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert "  time: no unit given: taken as s" in lines
    assert "  command_voltage: no unit given: taken as V" in lines
    assert any("--stack-length-mm not used" in line for line in lines)
    (rec,) = records_from_run(tmp_path / "a.h5")
    assert rec.rate_hz == pytest.approx(1.0)  # what the notes warn of: ms read as s
    res = runner.invoke(app, ["import", str(labelled), "--out", str(tmp_path / "b.h5")])
    assert res.exit_code == 0, res.output
    assert "taken as" not in res.output and "not used" not in res.output
    (rec,) = records_from_run(tmp_path / "b.h5")
    assert rec.rate_hz == pytest.approx(1000.0)


def test_a_column_in_a_time_unit_is_the_time(tmp_path: Path) -> None:
    """Named in another language (``Zeit``), the only column in a time unit is the time, as
    the only one in volts is the voltage: its rate is read from it, and a wrong ``--rate-hz``
    is refused against it. With two columns in seconds neither is chosen (give ``--time``)."""
    t = np.arange(200) / 10_000.0
    v = 50 * (1 - np.cos(2 * np.pi * 100 * t))
    one = tmp_path / "zeit.csv"
    with one.open("w") as f:
        f.write("Zeit;Spannung;Weg\ns;V;um\n")
        for a, b in zip(t, v, strict=True):
            f.write(f"{a:.6f};{b:.5f};{0.16 * b:.5f}\n".replace(".", ","))
    runner = CliRunner()
    res = runner.invoke(app, ["import", str(one), "--out", str(tmp_path / "a.h5"),
                              "--stack-length-mm", "18"])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "time=column 1 (Zeit)" in res.output
    (rec,) = records_from_run(tmp_path / "a.h5")
    assert rec.rate_hz == pytest.approx(10_000.0)
    res = runner.invoke(app, ["import", str(one), "--out", str(tmp_path / "b.h5"),
                              "--stack-length-mm", "18", "--rate-hz", "1000"])  # fmt: skip
    assert res.exit_code == 2 and "disagrees with the time column" in res.output
    two = tmp_path / "two.csv"
    with two.open("w") as f:
        f.write("Zeit;Verzug;Spannung;Weg\ns;s;V;um\n")
        for a, b in zip(t, v, strict=True):
            f.write(f"{a:.6f};0,001;{b:.5f};{0.16 * b:.5f}\n".replace(".", ","))
    res = runner.invoke(app, ["import", str(two), "--out", str(tmp_path / "c.h5"),
                              "--stack-length-mm", "18"])  # fmt: skip
    assert res.exit_code == 2 and "time" in res.output, res.output
