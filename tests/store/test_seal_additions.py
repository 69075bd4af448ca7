"""Seals cover what labrig wrote and tolerate what other tools add.

A NeXus file is meant to be annotated: another tool (h5py, nexusformat) may add an attribute,
a group or a dataset. Those are *additions*: ``labrig info`` lists them and every command reads
the file. A change to what labrig wrote (an attribute's value, an attribute or member removed,
a value's bytes, samples rewritten through HDF5, which recomputes their Fletcher32) is refused,
exit 2, naming the object. Files sealed before this (``@labrig_crc32`` over everything) are
still checked, and an addition to them is recognised as one.
"""

from __future__ import annotations

import shutil
import zlib
from pathlib import Path

import h5py
import numpy as np
import pytest

from labrig.catalogue.read import file_record_here
from labrig.core.errors import InputFileError
from labrig.store import read_run
from labrig.store.format import LEGACY_SEAL_ATTR, SEAL_ATTR

from helpers import invoke

PROTOCOL = """\
name: one sine
rate_hz: 200
steps:
  - kind: sine
    amplitude_V: 80
    frequency_hz: 2
    cycles: 2
"""
E = "sine_80V_2Hz"


@pytest.fixture(scope="module")
def original(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("sealed")
    (d / "p.yaml").write_text(PROTOCOL)
    result = invoke("run", d / "p.yaml", "--seed", 3, "--out", d / "run.h5")
    assert result.exit_code == 0, result.output
    return d / "run.h5"


@pytest.fixture
def run(original: Path, tmp_path: Path) -> Path:
    return Path(shutil.copy(original, tmp_path / "run.h5"))


def refused(path: Path, where: str, *commands: str) -> None:
    """Each command exits 2 naming the object, without a traceback."""
    for cmd in commands or ("info",):
        args = ["--out", path.parent / "csv"] if cmd == "export" else []
        result = invoke(cmd, path, *args)
        assert result.exit_code == 2, (cmd, result.output)
        named = f"[{where}]" if where else f"{path}: does not match"  # the root: the file
        assert named in result.stderr and "checksum" in result.stderr, result.stderr
        assert "Traceback" not in result.output


# -- additions ---------------------------------------------------------------------------------


def add_with_h5py(f: h5py.File) -> list[str]:
    f.attrs["annotated_by"] = "another tool"
    f["run"].attrs["comment"] = "looked at on Monday"
    f[f"{E}/data/strain"].attrs["reviewed"] = np.int64(1)
    notes = f[E].create_group("review")
    notes.attrs["NX_class"] = "NXnote"
    notes["description"] = "the loop looks fine"
    f[f"{E}/data"].create_dataset("strain_filtered", data=np.zeros(7))
    return [
        "@annotated_by",
        "run/@comment",
        f"{E}/data/strain/@reviewed",
        f"{E}/review",
        f"{E}/data/strain_filtered",
    ]


def test_additions_with_h5py_are_listed_and_the_file_reads(run: Path):
    before = read_run(run)
    with h5py.File(run, "a") as f:
        added = add_with_h5py(f)
    after = read_run(run)
    assert sorted(after.additions) == sorted(added)
    np.testing.assert_array_equal(after[E]["strain"], before[E]["strain"])
    info = invoke("info", run)
    assert info.exit_code == 0, info.output
    assert "added by another program" in info.stdout and f"{E}/review" in info.stdout
    assert invoke("export", run, "--out", run.parent / "csv").exit_code == 0


def test_names_added_by_another_program_are_printed_escaped(run: Path):
    """A name with a newline cannot forge a line of ``labrig info``; an escape sequence does not
    reach the terminal; rich markup in a name is printed as written, not applied."""
    with h5py.File(run, "a") as f:
        f[E].create_group("a\nstatus: forged")
        f[E].create_group("\x1b[2Jwiped")
        f[E].attrs["[/red]"] = 1
    info = invoke("info", run)
    assert info.exit_code == 0, info.output
    assert "\x1b" not in info.stdout and "\nstatus: forged" not in info.stdout
    assert f"{E}/a\\nstatus: forged" in info.stdout
    assert f"{E}/\\x1b[2Jwiped" in info.stdout and f"{E}/@[/red]" in info.stdout


def test_an_annotated_file_fits(run: Path):
    with h5py.File(run, "a") as f:
        add_with_h5py(f)
    result = invoke("fit", run, "--no-heldout", "--json")
    assert result.exit_code == 0, result.output


def test_additions_with_nexusformat_are_listed_and_the_file_reads(run: Path):
    nexus = pytest.importorskip("nexusformat.nexus")
    root = nexus.nxload(str(run), "rw")
    root[E]["notes"] = nexus.NXnote(description="checked by hand")
    root[E]["data/strain"].attrs["comment"] = "fine"
    root.close()
    assert sorted(read_run(run).additions) == [f"{E}/data/strain/@comment", f"{E}/notes"]
    assert invoke("info", run).exit_code == 0


# -- changes to what labrig wrote --------------------------------------------------------------


@pytest.mark.parametrize(
    ("where", "edit"),
    [
        (f"{E}/data/strain", lambda f: f[f"{E}/data/strain"].attrs.__setitem__("units", "um")),
        (f"{E}/data/strain", lambda f: f[f"{E}/data/strain"].attrs.__delitem__("long_name")),
        ("", lambda f: f.attrs.__setitem__("creator_version", "9.9")),
        ("run/seed", lambda f: f["run/seed"].__setitem__((), 2)),
        (f"{E}/data", lambda f: f[f"{E}/data"].__delitem__("gauge_raw")),
        (f"{E}", lambda f: f[E].move("sample_rate", "rate")),
    ],
    ids=["changed", "attribute removed", "root attribute", "value", "removed", "renamed"],
)
def test_a_change_to_what_labrig_wrote_exits_2(run: Path, where: str, edit):
    with h5py.File(run, "a") as f:
        edit(f)
    refused(run, where, "info", "export")


def test_a_seal_removed_where_labrig_seals_everything_exits_2(run: Path):
    with h5py.File(run, "a") as f:
        del f[f"{E}/sample_rate"].attrs[SEAL_ATTR]
    result = invoke("info", run)
    assert result.exit_code == 2 and f"[{E}/sample_rate] has no seal" in result.stderr


def test_a_value_overwritten_in_the_file_exits_2(run: Path):
    """The bytes of a value (not chunked: no Fletcher32) overwritten on disk."""
    with h5py.File(run, "r") as f:
        offset = f["run/seed"].id.get_offset()
    with open(run, "r+b") as fh:
        fh.seek(offset)
        fh.write((99).to_bytes(8, "little"))
    with h5py.File(run, "r") as f:
        assert f["run/seed"][()] == 99  # the change is there to read
    refused(run, "run/seed")


def test_samples_rewritten_through_hdf5_exit_2(run: Path):
    """h5py writes new samples with a new Fletcher32: only the seal's CRC of the samples tells."""
    with h5py.File(run, "a") as f:
        ds = f[f"{E}/data/strain"]
        ds[10] = ds[10] + 1.0
    refused(run, f"{E}/data/strain", "info", "export", "fit")
    read_run(run, load_data=False)  # the metadata is still there to see


def test_samples_cut_short_through_hdf5_exit_2_even_reading_metadata(run: Path):
    with h5py.File(run, "a") as f:
        f[f"{E}/data/strain"].resize((100,))
    with pytest.raises(InputFileError, match=rf"\[{E}/data/strain\] holds 100 samples"):
        read_run(run, load_data=False)


# -- files sealed before: @labrig_crc32 over everything ------------------------------------------


def _legacy_canonical(value: object) -> bytes:
    """The value bytes of the seals labrig wrote before (an independent copy of that format)."""
    if isinstance(value, str):
        return b"s" + value.encode("utf-8", "surrogatepass")
    if isinstance(value, bytes):
        return b"b" + value
    if isinstance(value, np.ndarray) and value.dtype.kind == "O":
        return b"o" + b"\x1f".join(_legacy_canonical(v) for v in value.ravel())
    if isinstance(value, np.ndarray | np.generic):
        a = np.asarray(value)
        return a.dtype.str.encode() + repr(a.shape).encode() + a.tobytes()
    return b"r" + repr(value).encode()


def legacy_seal(obj: h5py.Group | h5py.Dataset) -> None:
    if SEAL_ATTR in obj.attrs:
        del obj.attrs[SEAL_ATTR]
    crc = 0
    for name in sorted(obj.attrs):
        if name != LEGACY_SEAL_ATTR:
            piece = b"@" + name.encode() + b"=" + _legacy_canonical(obj.attrs[name])
            crc = zlib.crc32(piece, crc)
    if isinstance(obj, h5py.Group):
        crc = zlib.crc32(b"/" + "\x1f".join(sorted(obj)).encode(), crc)
    elif obj.chunks is None:
        crc = zlib.crc32(b"=" + _legacy_canonical(obj[()]), crc)
    obj.attrs[LEGACY_SEAL_ATTR] = np.uint32(crc)


@pytest.fixture
def legacy(run: Path) -> Path:
    """The run file as labrig sealed files before (and without a summary, as then)."""
    with h5py.File(run, "a") as f:
        del f["run/summary"]
        objects = [f]
        f.visititems(lambda _name, obj: objects.append(obj))
        for obj in objects:
            legacy_seal(obj)
    assert read_run(run).additions == []
    return run


def test_an_older_file_with_additions_reads(legacy: Path):
    with h5py.File(legacy, "a") as f:
        f["run"].attrs["comment"] = "looked at on Monday"
        f[E].create_group("review")
        f[E]["checked"] = True
        f[f"{E}/data/strain"].attrs["reviewed"] = 1
    assert sorted(read_run(legacy).additions) == sorted(
        ["run/@comment", f"{E}/review", f"{E}/checked", f"{E}/data/strain/@reviewed"]
    )
    assert invoke("info", legacy).exit_code == 0


def test_an_older_file_changed_exits_2(legacy: Path):
    with h5py.File(legacy, "a") as f:
        f[f"{E}/data/strain"].attrs["units"] = "um"
        f[f"{E}/data/strain"].attrs["reviewed"] = 1  # an addition does not hide the change
    refused(legacy, f"{E}/data/strain")


def test_an_older_file_with_an_added_channel_like_dataset_lists_and_reads(legacy: Path):
    """An added dataset in an entry's data is not a channel, for the listing too (which reads
    an older file in full, and so finds its additions by its seals)."""
    with h5py.File(legacy, "a") as f:
        f[f"{E}/data"].create_dataset("strain_filtered", data=np.zeros(7))
    record = file_record_here(legacy)
    assert record["readable"] and record["entries"][0]["samples"] == 201, record
    assert read_run(legacy).additions == [f"{E}/data/strain_filtered"]
