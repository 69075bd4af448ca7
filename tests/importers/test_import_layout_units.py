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
        # quantity/unit without spaces (DIN 1313), a colon or a dash: split only when what
        # follows is a unit and the whole is not a ratio of like units (a strain unit)
        ("t/ms", ("t", "ms")),
        ("U/mV", ("U", "mV")),
        ("S/µm", ("S", "µm")),
        ("voltage: mV", ("voltage", "mV")),
        ("voltage - mV", ("voltage", "mV")),
        ("voltage <mV>", ("voltage", "mV")),
        ("Dehnung/µm/m", ("Dehnung", "µm/m")),
        ("mm/m", ("mm/m", "")),
        ("um/m", ("um/m", "")),
        ("force/disp", ("force/disp", "")),
        ("x-y", ("x-y", "")),
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


def _write(path: Path, header: str, scale_v: float = 1.0, scale_t: float = 1.0) -> Path:
    t = np.arange(400) / 1000.0
    v = 50 + 50 * np.sin(2 * np.pi * 5 * t)
    rows = "".join(
        f"{a * scale_t:.6f};{b * scale_v:.6f};{10 * b:.6f}\n" for a, b in zip(t, v, strict=True)
    )
    path.write_text(header + "\n" + rows.replace(".", ","))
    return path


def test_din_style_headers_give_the_units(tmp_path: Path) -> None:
    """``t/ms;U/mV;S/ue`` with decimal commas: the time in ms and the voltage in mV are
    converted (read as s and V before: a rate of 1 Hz and 100 000 V)."""
    f = _write(tmp_path / "din.csv", "t/ms;U/mV;S/ue", scale_v=1e3, scale_t=1e3)
    out = tmp_path / "din.h5"
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(out), "--time", "1",
                                   "--voltage", "2", "--strain", "3"])  # fmt: skip
    assert res.exit_code == 0, res.output
    (e,) = list(read_run(out))
    assert e.rate_hz == pytest.approx(1000.0, rel=1e-9)
    assert float(np.max(e["command_voltage"])) == pytest.approx(100.0, abs=1e-3)
    assert e.units["strain"] == "ue"


@pytest.mark.parametrize("unit", ["mv", "mA", "counts", "um"])
def test_a_voltage_column_not_in_volts_is_refused_unless_scaled(tmp_path: Path, unit: str):
    """The model's input is volts: a voltage column in an unknown unit (``mv``, ``counts``) or
    another quantity (``mA``, ``um``) is refused, naming the column; ``--voltage-scale``
    turns raw numbers into volts (a unit of another quantity stays refused)."""
    f = _write(tmp_path / "v.csv", f"time [s];voltage [{unit}];strain [ue]", scale_v=1e3)
    out = tmp_path / "v.h5"
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert "column 2" in res.output and unit in res.output and "Traceback" not in res.output
    assert not out.exists()
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(out), "--voltage-scale", "1e-3"])
    if unit in ("mA", "um"):  # pint knows them, and they are no voltage: never a voltage
        assert res.exit_code == 2, res.output
        return
    assert res.exit_code == 0, res.output
    (e,) = list(read_run(out))
    assert e.units["command_voltage"] == "V"
    assert float(np.max(e["command_voltage"])) == pytest.approx(100.0, abs=1e-3)


@pytest.mark.parametrize("column", ["time", "temperature"])
def test_a_time_or_temperature_column_is_not_taken_as_the_strain(tmp_path: Path, column: str):
    f = tmp_path / "a.csv"
    f.write_text("time [s],voltage [V],strain [ue],temperature [degC]\n"
                 + "".join(f"{i / 1000},{i % 50},{i % 7},25\n" for i in range(200)))  # fmt: skip
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(tmp_path / "x.h5"),
                                   "--strain", column, "--rate-hz", "1000"])  # fmt: skip
    assert res.exit_code == 2 and "not a strain unit" in res.output, res.output
    ok = CliRunner().invoke(app, ["import", str(f), "--out", str(tmp_path / "x.h5"),
                                  "--strain", column, "--strain-units", "raw",
                                  "--rate-hz", "1000"])  # fmt: skip
    assert ok.exit_code == 0, ok.output  # said to keep the numbers: kept, labelled raw


def test_records_in_two_strain_units_are_not_fitted_or_validated_together(tmp_path: Path):
    """One run file holding an entry in ue and one in raw numbers, or a training file in ue and
    a test file in raw: refused (exit 2) naming both, never one NRMSE over mixed scales."""
    t = np.arange(2000) / 1000.0
    v = 50 + 50 * np.sin(2 * np.pi * 2 * t)
    for name, unit, k in (("a", "ue", 10.0), ("b", "raw", 0.01)):
        (tmp_path / f"{name}.csv").write_text(
            f"time [s],voltage [V],strain [{unit}]\n"
            + "".join(
                f"{x:.4f},{y:.4f},{k * y + 0.1 * np.sin(x):.6f}\n"
                for x, y in zip(t, v, strict=True)
            )
        )
    run = CliRunner()
    both = tmp_path / "both.h5"
    res = run.invoke(app, ["import", str(tmp_path / "a.csv"), str(tmp_path / "b.csv"),
                           "--out", str(both)])  # fmt: skip
    assert res.exit_code == 0, res.output
    res = run.invoke(app, ["fit", str(both), "--no-heldout"])
    assert res.exit_code == 2, res.output
    text = " ".join(res.output.split())
    assert "b/strain" in text and "'raw'" in text and "'ue'" in text
    for name in ("a", "b"):
        res = run.invoke(app, ["import", str(tmp_path / f"{name}.csv"), "--out",
                               str(tmp_path / f"{name}.h5")])  # fmt: skip
        assert res.exit_code == 0, res.output
    res = run.invoke(app, ["validate", str(tmp_path / "a.h5"), "--on", str(tmp_path / "b.h5"),
                           "--json"])  # fmt: skip
    assert res.exit_code == 2 and "one strain unit" in " ".join(res.output.split()), res.output


@pytest.mark.parametrize(
    ("first", "origin"),
    [
        (2**53 - 20_000 * 9_999, 0),  # the last stamp is 2**53 itself: exact as float64 already
        (2**53 - 20_000 * 9_999 + 1, 2**53 - 20_000 * 9_999 + 1),  # the last is 2**53 + 1
        (1_732_900_000_000_000_000, 1_732_900_000_000_000_000),  # ns since 1970 (int64)
        (2**63 + 12_345, 2**63 + 12_345),  # past int64: read as uint64
    ],
)
def test_integer_time_stamps_past_2_53_keep_their_steps_exact(
    tmp_path: Path, first: int, origin: int
) -> None:
    """Time in integer nanoseconds: 10 000 stamps 20 000 ns apart are a uniform 50 kHz record.
    As float64 the stamps past 2**53 lose their low bits (steps of 19 968 and 20 480 ns: refused
    as not uniform before); counted from the first stamp in integers, every step is exact."""
    f = tmp_path / "ns.csv"
    f.write_text("time [ns],voltage [V],strain [ue],counter\n" + "".join(
        f"{first + 20_000 * i},{50 + 40 * np.sin(i / 50):.4f},{np.sin(i / 50):.5f},{first + i}\n"
        for i in range(10_000)
    ))  # fmt: skip
    out = tmp_path / "ns.h5"
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(out)])
    assert res.exit_code == 0, res.output
    (e,) = list(read_run(out))
    assert e.rate_hz == pytest.approx(50_000.0, rel=1e-12)
    # ns -> s rounds each step to float64 (1e-16 relative); the float64 stamps were 2 % off
    np.testing.assert_allclose(np.diff(e.time), 2e-5, rtol=1e-9)
    assert ("counted from its first value" in res.output) == bool(origin)
    counter = e["counter"]
    np.testing.assert_array_equal(np.diff(counter), np.ones(9_999))  # exact steps of 1
    assert counter[0] == (0 if first + 9_999 > 2**53 else first)  # past 2**53: from the first


def test_integer_time_stamps_past_2_53_in_a_mat_file(tmp_path: Path) -> None:
    from scipy.io import savemat

    t = np.uint64(1_732_900_000_000_000_000) + np.arange(5_000, dtype=np.uint64) * np.uint64(
        1_000_000
    )  # 1 kHz in ns
    v = 50 + 40 * np.sin(np.arange(5_000) / 40)
    savemat(tmp_path / "ns.mat", {"time_ns": t, "voltage_V": v, "strain_ue": 10 * v})
    out = tmp_path / "ns.h5"
    res = CliRunner().invoke(app, ["import", str(tmp_path / "ns.mat"), "--out", str(out)])
    assert res.exit_code == 0, res.output
    (e,) = list(read_run(out))
    assert e.rate_hz == pytest.approx(1000.0, rel=1e-12)  # 999.596 Hz from float64 stamps
    np.testing.assert_allclose(np.diff(e.time), 1e-3, rtol=1e-9)


@pytest.mark.parametrize(
    "options",
    [["--strain-scale", "1e308"], ["--strain", "disp", "--stack-length-mm", "1e-310"],
     ["--voltage-scale", "1e307"]],
)  # fmt: skip
def test_a_conversion_that_overflows_is_refused_at_the_import(tmp_path: Path, options: list[str]):
    f = tmp_path / "a.csv"
    f.write_text("time [s],voltage [V],strain [ue],disp [um]\n"
                 + "".join(f"{i / 1000},{20 + i % 50},{5 + i % 7},{3 + i % 7}\n"
                           for i in range(200)))  # fmt: skip
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(tmp_path / "x.h5"), *options])
    assert res.exit_code == 2, res.output
    assert "after the unit conversion and scale" in " ".join(res.output.split())
    assert "Warning" not in res.output and not (tmp_path / "x.h5").exists()
    ok = CliRunner().invoke(app, ["import", str(f), "--out", str(tmp_path / "y.h5"),
                                  *[o.replace("1e308", "1e3").replace("1e-310", "18")
                                    .replace("1e307", "10") for o in options]])  # fmt: skip
    assert ok.exit_code == 0, ok.output


def test_a_complex_variable_of_a_v5_mat_file_is_left_out_not_cut_to_its_real_part(
    tmp_path: Path,
) -> None:
    from scipy.io import savemat

    t = np.arange(2000) / 1000
    v = 50 + 40 * np.sin(2 * np.pi * 5 * t)
    savemat(tmp_path / "c.mat", {"time_s": t, "voltage_V": v + 1j * np.cos(t),
                                 "strain_ue": 10 * v, "s": {"z": v + 1j, "w": v}})  # fmt: skip
    res = CliRunner().invoke(app, ["import", str(tmp_path / "c.mat"), "--list"])
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    assert "left out: variable voltage_V: complex values" in text
    assert "variable s.z: complex values" in text and "variable s.w" in text
    assert "ComplexWarning" not in res.output
    out = tmp_path / "c.h5"
    res = CliRunner().invoke(app, ["import", str(tmp_path / "c.mat"), "--out", str(out)])
    assert res.exit_code == 2 and "which column is the voltage" in res.output, res.output


def test_names_keep_base_letters_and_the_import_says_what_it_left_out(tmp_path: Path):
    from labrig.importers.labels import safe_name

    assert safe_name("ümlaut") == "umlaut" and safe_name("Temperatur °C") == "Temperatur_C"
    assert split_label("dehnung_µm") == ("dehnung", "µm")
    f = tmp_path / "gap.csv"
    f.write_text("time [s],voltage [V],strain [ue],temperature [degC]\n0,1,2,25\n0.001,2,3,\n"
                 "0.002,3,4,25\n")  # fmt: skip
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(tmp_path / "g.h5")])
    assert res.exit_code == 0, res.output
    assert "left out: column 4 (temperature)" in res.output


def test_a_mat_file_without_signals_says_so(tmp_path: Path):
    from scipy.io import savemat

    savemat(tmp_path / "e.mat", {})
    res = CliRunner().invoke(
        app, ["import", str(tmp_path / "e.mat"), "--out", str(tmp_path / "e.h5")]
    )
    assert res.exit_code == 2 and "holds no numeric signal" in res.output, res.output
    assert "from 1 to 0" not in res.output


def test_the_column_named_temperature_is_the_temperature(tmp_path: Path):
    """Two columns in degC: the one named ``temperature`` is the channel the analysis reads,
    whatever its place; the other keeps its own name."""
    f = tmp_path / "t.csv"
    rows = "".join(f"{i / 1000},{1 + i},{2 + i},{20 + i},25\n" for i in range(5))
    f.write_text("time [s],voltage [V],strain [ue],temp 1 [degC],temperature [degC]\n" + rows)
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(tmp_path / "t.h5")])
    assert res.exit_code == 0, res.output
    (e,) = list(read_run(tmp_path / "t.h5"))
    np.testing.assert_array_equal(e["temperature"], [25.0] * 5)
    np.testing.assert_array_equal(e["temp_1"], [20.0, 21.0, 22.0, 23.0, 24.0])


def test_two_columns_of_one_name_and_unit_are_not_guessed(tmp_path: Path):
    """``voltage [V]`` twice: refused naming both (the first was taken silently); a number
    picks one; ``time_s`` beside ``time_ms`` (one quantity in two units) still takes the first."""
    f = tmp_path / "v.csv"
    f.write_text("time [s],voltage [V],strain [ue],voltage [V]\n"
                 + "".join(f"{i / 1000},{1 + i},{2 + i},5\n" for i in range(5)))  # fmt: skip
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(tmp_path / "v.h5")])
    assert res.exit_code == 2, res.output
    assert "column 2 (voltage), column 4 (voltage)" in " ".join(res.output.split())
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(tmp_path / "v.h5"),
                                   "--voltage", "4"])  # fmt: skip
    assert res.exit_code == 0, res.output
    (e,) = list(read_run(tmp_path / "v.h5"))
    np.testing.assert_array_equal(e["command_voltage"], [5.0] * 5)


@pytest.mark.parametrize("unit", ["v", "Vdc", "V DC", "volt", "Volts"])
def test_spellings_of_volts_are_volts(tmp_path: Path, unit: str):
    f = _write(tmp_path / "v.csv", f"time [s];voltage [{unit}];strain [ue]")
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(tmp_path / "v.h5")])
    assert res.exit_code == 0, res.output
    (e,) = list(read_run(tmp_path / "v.h5"))
    assert e.units["command_voltage"] == "V"
    assert float(np.max(e["command_voltage"])) == pytest.approx(100.0, abs=1e-3)


def test_voltage_scale_1_takes_raw_numbers_as_volts_and_ue_spelled_with_mu(tmp_path: Path):
    f = _write(tmp_path / "c.csv", "time [s];voltage [counts];strain [µe]")
    res = CliRunner().invoke(app, ["import", str(f), "--out", str(tmp_path / "c.h5"),
                                   "--voltage-scale", "1"])  # fmt: skip
    assert res.exit_code == 0, res.output
    (e,) = list(read_run(tmp_path / "c.h5"))
    assert e.units["command_voltage"] == "V" and e.units["strain"] == "ue"
    assert float(np.max(e["command_voltage"])) == pytest.approx(100.0, abs=1e-3)


def test_a_run_file_an_earlier_import_wrote_in_v_is_still_fitted(tmp_path: Path):
    """Files written before the voltage's unit was checked may say ``v`` or ``Vdc``: volts;
    ``mV`` is a voltage but not in volts: refused (the model's input is volts)."""
    from labrig.commands.prepare import unit_issues

    f = _write(tmp_path / "a.csv", "time [s];voltage [V];strain [ue]")
    out = tmp_path / "a.h5"
    assert CliRunner().invoke(app, ["import", str(f), "--out", str(out)]).exit_code == 0
    (r,) = records_from_run(out)
    assert r.meta["units"]["command_voltage"] == "V"
    for unit, ok in (("Vdc", True), ("v", True), ("", True), ("mV", False), ("raw", False)):
        r.meta["units"]["command_voltage"] = unit
        issues = unit_issues([(out, r)])
        assert (issues == []) == ok, (unit, issues)


def test_a_complex_voltage_variable_is_named_when_the_voltage_is_missing(tmp_path: Path):
    from scipy.io import savemat

    t = np.arange(500) / 1000
    savemat(tmp_path / "c.mat", {"time_s": t, "voltage_V": (5 * t) + 0j * t + 1j * (t > 2),
                                 "strain_ue": 40 * t})  # fmt: skip
    res = CliRunner().invoke(app, ["import", str(tmp_path / "c.mat"), "--out",
                                   str(tmp_path / "c.h5")])  # fmt: skip
    assert res.exit_code == 2, res.output
    assert "left out: variable voltage_V: complex values" in " ".join(res.output.split())
