"""Who ran what on which actuator: a protocol's ``metadata:`` and ``--meta``, ``--operator``,
``--sample`` on ``labrig run`` and ``labrig import``, written as NeXus (NXuser, NXsample,
``definition``, ``program_name``, ``/run/metadata``); units pint reads; unset values absent;
old files (units ``ue``) and new ones read alike."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

import labrig
from labrig.cli import app
from labrig.core.metadata import MetadataError, from_options, parse_assignment
from labrig.store import RunWriter, read_run
from labrig.store.format import SEAL_ATTR
from labrig.store.writer import seal_all

pytestmark = pytest.mark.timeout(120)

PROTOCOL = {
    "name": "metadata test",
    "rate_hz": 1000,
    "metadata": {"project": "creep study", "sample": "P-888 #1", "temperature_degC": 23.5},
    "steps": [
        {"kind": "sine", "amplitude_V": 50, "frequency_hz": 5, "cycles": 2},
        {"kind": "sine", "amplitude_V": 100, "frequency_hz": 5, "cycles": 2},
    ],
}
ENTRIES = ["sine_50V_5Hz", "sine_100V_5Hz"]


@pytest.fixture(scope="module")
def run_file(tmp_path_factory) -> Path:
    """``labrig run`` with a protocol's metadata and the options over it."""
    d = tmp_path_factory.mktemp("meta")
    proto = d / "p.yaml"
    proto.write_text(yaml.safe_dump(PROTOCOL, sort_keys=False))
    out = d / "run.h5"
    args = ["run", str(proto), "--out", str(out), "--seed", "2", "--operator", "alice"]
    args += ["--sample", "P-888 #3", "--meta", "actuator_model=P-888.51"]
    args += ["--meta", "actuator_serial=00123", "--meta", "repeat_no=4"]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    return out


def test_run_file_holds_nexus_user_sample_definition_and_program(run_file: Path):
    with h5py.File(run_file) as f:
        meta = f["run/metadata"]
        assert meta.attrs["NX_class"] == "NXcollection"
        got = {k: meta[k][()] for k in meta}
        assert got == {
            "project": b"creep study",
            "sample": b"P-888 #3",  # --sample wins over the protocol's
            "temperature_degC": 23.5,
            "operator": b"alice",
            "actuator_model": b"P-888.51",
            "actuator_serial": b"00123",  # an identifier stays text, zeros and all
            "repeat_no": 4,
        }
        assert meta["temperature_degC"].attrs["units"] == "degC"
        assert "program_name" in f["run"]  # kept for older readers
        for name in ENTRIES:
            e = f[name]
            assert e["definition"][()] == b"NXlabrig"
            assert e["program_name"][()] == b"labrig"
            assert e["program_name"].attrs["version"] == labrig.__version__
            assert e["user"].attrs["NX_class"] == "NXuser"
            assert e["user/name"][()] == b"alice"
            assert e["sample"].attrs["NX_class"] == "NXsample"
            assert {k: e["sample"][k][()] for k in e["sample"]} == {
                "name": b"P-888 #3",
                "model": b"P-888.51",
                "serial_number": b"00123",
            }
    run = read_run(run_file)
    assert run["sine_50V_5Hz"].sample["serial_number"] == "00123"
    assert run.metadata["operator"] == "alice"


def test_every_new_object_is_sealed_and_the_file_reads(run_file: Path):
    with h5py.File(run_file) as f:
        unsealed = []
        f.visititems(lambda n, o: unsealed.append(n) if SEAL_ATTR not in o.attrs else None)
        assert unsealed == []


def test_every_unit_is_one_pint_reads_and_nothing_unset_is_stored(run_file: Path):
    import pint  # here: it imports dask, about half a second for every test process

    ureg = pint.UnitRegistry()
    units, nulls = {}, []

    def visit(name, obj):
        if "units" in obj.attrs:
            units[name] = obj.attrs["units"]
        if isinstance(obj, h5py.Dataset) and obj.shape == () and obj[()] in (b"null", "null"):
            nulls.append(name)

    with h5py.File(run_file) as f:
        f.visititems(visit)
        strain = f["sine_50V_5Hz/data/strain"]
        assert strain.attrs["units"] == "um/m"
        assert "microstrain" in strain.attrs["long_name"]
    assert nulls == []  # unset values are absent, not the text "null"
    for name, u in units.items():
        q = ureg.Quantity(1.0, u)  # raises on a unit pint cannot read
        if name.endswith("/strain"):
            assert q.to("dimensionless").magnitude == pytest.approx(1e-6)
    assert any(u == "mV/(um/m)" for u in units.values())  # sensitivity in the instrument


def test_the_catalogue_filters_on_the_metadata(run_file: Path):
    where = ["operator=alice", "sample=P-888#3", "serial_number=00123"]
    args = ["runs", str(run_file.parent), "--json"]
    for w in where:
        args += ["--where", w]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert [Path(x["path"]).name for x in doc["runs"]] == ["run.h5"]
    r = CliRunner().invoke(app, ["runs", str(run_file.parent), "--where", "operator=bob", "--json"])
    assert json.loads(r.stdout)["runs"] == []


def test_old_files_with_ue_units_read_like_new_ones(run_file: Path, tmp_path: Path):
    """A copy of the file as older labrig wrote it (strain in ``ue``, long name ``strain``)
    reads to the same units, long names, CSV header and DataFrame columns."""
    old = tmp_path / "old.h5"
    old.write_bytes(run_file.read_bytes())
    with h5py.File(old, "a") as f:
        for name in ENTRIES:
            f[name]["data/strain"].attrs["units"] = "ue"
            f[name]["data/strain"].attrs["long_name"] = "strain"
        seal_all(f)
    new_run, old_run = read_run(run_file), read_run(old)
    for name in ENTRIES:
        assert new_run[name].units == old_run[name].units
        assert new_run[name].units["strain"] == "ue"
        assert new_run[name].long_names == old_run[name].long_names
    a, b = labrig.open(run_file).to_pandas(), labrig.open(old).to_pandas()
    assert list(a.columns) == list(b.columns) and "strain_ue" in a.columns
    np.testing.assert_array_equal(a["strain_ue"].to_numpy(), b["strain_ue"].to_numpy())
    csv_new, csv_old = tmp_path / "new_csv", tmp_path / "old_csv"
    labrig.store.export_csv(run_file, csv_new)
    labrig.store.export_csv(old, csv_old)
    head = (csv_new / "sine_50V_5Hz.csv").read_text().splitlines()[0]
    assert head == (csv_old / "sine_50V_5Hz.csv").read_text().splitlines()[0]
    assert "strain_ue" in head


def test_import_records_the_metadata(tmp_path: Path):
    t = np.arange(0, 2, 0.005)
    v = 50 * (1 - np.cos(2 * np.pi * t))
    src = tmp_path / "bench.csv"
    np.savetxt(src, np.c_[t, v, 9 * v], delimiter=",", header="time,voltage,strain_ue", comments="")
    out = tmp_path / "imported.h5"
    args = ["import", str(src), "--out", str(out), "--operator", "carol"]
    args += ["--sample", "P-888 #7", "--meta", "actuator_serial=SN-7"]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    run = read_run(out)
    assert run.metadata == {"actuator_serial": "SN-7", "operator": "carol", "sample": "P-888 #7"}
    assert run["bench"].user == {"name": "carol"}
    assert run["bench"].sample == {"name": "P-888 #7", "serial_number": "SN-7"}


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--meta", "novalue"], "expected KEY=VALUE"),
        (["--meta", "9lives=1"], "use a letter"),
        (["--meta", "x=" + "y" * 300], "at most 200 characters"),
    ],
)
def test_bad_metadata_options_are_usage_errors_before_anything(tmp_path: Path, args, words):
    proto = tmp_path / "p.yaml"
    proto.write_text(yaml.safe_dump(PROTOCOL, sort_keys=False))
    out = tmp_path / "never.h5"
    r = CliRunner().invoke(app, ["run", str(proto), "--out", str(out), *args])
    said = " ".join(r.output.replace("│", " ").split())  # the message as one line
    assert r.exit_code not in (0, 1) and words in said
    assert not out.exists()


def test_bad_protocol_metadata_is_refused_at_its_line(tmp_path: Path):
    doc = {**PROTOCOL, "metadata": {"operator": "dora", "nested": {"a": 1}}}
    proto = tmp_path / "p.yaml"
    proto.write_text(yaml.safe_dump(doc, sort_keys=False))
    r = CliRunner().invoke(app, ["check", str(proto)])
    assert r.exit_code == 2 and "metadata.nested" in r.output


@pytest.mark.parametrize(
    ("value", "words"),
    [(10**23, "64 bits"), ("a\u200bb", "printable"), ("x" * 201, "200 characters")],
)
def test_protocol_metadata_run_could_not_store_is_refused_by_check_and_run(
    tmp_path: Path, value, words
):
    """What the run file cannot store is refused by ``check`` (exit 2, the file's line), and
    ``run`` refuses it the same way before anything is energised."""
    doc = {**PROTOCOL, "metadata": {"note": value}}
    proto = tmp_path / "p.yaml"
    proto.write_text(yaml.safe_dump(doc, sort_keys=False, allow_unicode=True))
    out = tmp_path / "r.h5"
    for args in (["check", str(proto)], ["run", str(proto), "--out", str(out)]):
        r = CliRunner().invoke(app, args)
        assert r.exit_code == 2 and words in r.output, (args, r.output)
    assert not out.exists()


def test_command_line_values_are_typed():
    assert parse_assignment("temperature_degC=23.5") == ("temperature_degC", 23.5)
    assert parse_assignment("n=-4") == ("n", -4)
    assert parse_assignment("ok=true") == ("ok", True)
    assert parse_assignment("actuator_serial=123") == ("actuator_serial", "123")
    assert parse_assignment("note=a=b") == ("note", "a=b")
    with pytest.raises(MetadataError):
        parse_assignment("x=1e999")  # reads as a number, and is not finite
    m = from_options(["operator=zed", "a=1"], operator="alice")
    assert m.operator == "alice" and m.values["a"] == 1


def test_a_run_without_metadata_has_no_user_or_sample(tmp_path: Path):
    p = tmp_path / "r.h5"
    with RunWriter(p, "", "", {"amp": {"i_peak_A": None, "gain_V_per_V": 10.0}}, seed=1) as w:
        w.begin_entry("a", {}, 100.0, ["strain"]).finish()
    with h5py.File(p) as f:
        assert "user" not in f["a"] and "sample" not in f["a"] and "metadata" not in f["run"]
        assert f["a/definition"][()] == b"NXlabrig"
        assert "i_peak_A" not in f["run/instrument/amp"]  # unset: absent
        assert f["run/instrument/amp/gain_V_per_V"].attrs["units"] == "V/V"


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("n=9223372036854775807", 2**63 - 1),  # the largest 64-bit whole number: kept exactly
        ("n=-9223372036854775808", -(2**63)),
        ("n=9007199254740993", 2**53 + 1),  # past 2**53: no float on the way
        # past 64 bits, or with a leading zero: an identifier (a barcode, a lot), kept as text
        ("n=9223372036854775808", "9223372036854775808"),  # 2**63: just outside
        ("n=12345678901234567890123", "12345678901234567890123"),  # never 1.2e+22
        ("n=007", "007"),
        ("n=01234567890123456789012", "01234567890123456789012"),
        ("n=0", 0),
    ],
)
def test_whole_numbers_of_meta_are_exact_or_text(text: str, expected: int | str) -> None:
    key, value = parse_assignment(text)
    assert key == "n" and type(value) is type(expected) and value == expected


def test_a_digit_string_past_the_text_limit_is_refused() -> None:
    with pytest.raises(MetadataError, match="at most"):
        parse_assignment("n=" + "9" * 5000)  # beyond Python's digit limit for int() too
