"""``labrig runs``: the catalogue lists run files with their metadata, filters them with
``--where``, keeps its index in step with the folder, and lists damaged files as unreadable.

The run files are written here with the store's writer; metadata groups are added in the
layout docs/catalogue.md asks of run files (``/run/metadata``, NXsample ``sample`` and NXuser
``user`` in each entry) and sealed as the writer seals. Expected selections come from the
table of what each file holds, never from the catalogue's own code.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from labrig.catalogue import list_runs
from labrig.catalogue.index import INDEX_NAME
from labrig.catalogue.read import read_metadata_here
from labrig.cli import app
from labrig.store import RunWriter
from labrig.store.format import SEAL_ATTR, seal_of
from labrig.store.writer import seal_all

STEP_KEYS = {"sine": ("amplitude_V", "frequency_hz"), "hold": ("voltage_V",)}


def write_run(
    path: Path,
    protocol: str,
    steps: Sequence[tuple[str, float, float | None]],
    *,
    start: str | None = None,
    run_metadata: Mapping[str, Any] | None = None,
    sample: Mapping[str, Any] | None = None,
    user: Mapping[str, Any] | None = None,
    samples: int = 20,
) -> Path:
    """A small run file: one entry per ``(kind, volts, hz)`` (``hz`` None for a hold), each
    ``samples`` long at 100 Hz, then the metadata groups (module docstring), sealed."""
    with RunWriter(
        path, f"name: {protocol}\n", "", {"name": "test"}, 1, protocol_name=protocol
    ) as w:
        for kind, volts, hz in steps:
            step: dict[str, Any] = {"kind": kind}
            if kind == "hold":
                step["voltage_V"] = volts
                name = f"hold_{volts:g}V"
            else:
                step.update(amplitude_V=volts, frequency_hz=hz)
                name = f"{kind}_{volts:g}V_{hz:g}Hz"
            e = w.begin_entry(name, step, 100.0, ["command_voltage", "strain"])
            v = np.linspace(0.0, volts, samples)
            e.append({"command_voltage": v, "strain": 10.0 * v})
            e.finish()
    with h5py.File(path, "a") as f:
        if start is not None:
            f["run/start_time"][()] = start
        if run_metadata:
            g = f["run"].create_group("metadata")
            g.attrs["NX_class"] = "NXcollection"
            for k, v in run_metadata.items():
                g[k] = v
        for name, obj in f.items():
            if name == "run":
                continue
            for group, nx_class, values in (
                ("sample", "NXsample", sample),
                ("user", "NXuser", user),
            ):
                if values:
                    g = obj.create_group(group)
                    g.attrs["NX_class"] = nx_class
                    for k, v in values.items():
                        g[k] = v
        seal_all(f)
    return path


#: what each file of the filter test holds; the expected selections below are read off this
FILES: dict[str, dict[str, Any]] = {
    "a.h5": dict(
        protocol="paper sine sweep",
        steps=[("sine", 100, 10), ("sine", 100, 40)],
        start="2026-03-05T10:00:00.000+01:00",
        sample={"name": "P-888 #3", "serial_number": "SN-3"},
        user={"name": "alice"},
    ),
    "b.h5": dict(
        protocol="sweep",
        steps=[("sine", 100, 5)],
        start="2026-02-20T09:00:00.000+01:00",
        sample={"name": "P-888 #4"},
        user={"name": "bob"},
    ),
    "c.h5": dict(
        protocol="creep hold",
        steps=[("hold", 80, None)],
        start="2026-04-01T08:00:00.000+02:00",
        sample={"name": "P-888 #3"},
        run_metadata={"operator": "carol", "temperature_C": 23.5},
    ),
    "d.h5": dict(
        protocol="paper sine sweep",
        steps=[("sine", 50, 20), ("sine", 100, 40)],
        start="2026-03-31T23:30:00.000+02:00",
    ),
}

SELECTIONS: list[tuple[list[str], set[str]]] = [
    (["sample=P-888#3"], {"a.h5", "c.h5"}),
    (["sample=p-888 #3"], {"a.h5", "c.h5"}),
    (["sample!=P-888#3"], {"b.h5", "d.h5"}),
    (["sample~888"], {"a.h5", "b.h5", "c.h5"}),
    (["serial_number=SN-3"], {"a.h5"}),
    (["protocol~sweep"], {"a.h5", "b.h5", "d.h5"}),
    (["protocol=sweep"], {"b.h5"}),
    (["since=2026-03-01"], {"a.h5", "c.h5", "d.h5"}),
    (["until=2026-03-31"], {"a.h5", "b.h5", "d.h5"}),
    (["since=2026-03", "until=2026-03"], {"a.h5", "d.h5"}),
    (["date<2026-03-01"], {"b.h5"}),
    (["date~2026-03"], {"a.h5", "d.h5"}),
    # the file's path, as listed and as an absolute path
    (["file~b.h"], {"b.h5"}),
    (["file!~b.h"], {"a.h5", "c.h5", "d.h5"}),
    (["file~h5", "protocol=sweep"], {"b.h5"}),
    # with an offset, as instants: d began 21:30 UTC on March 31st
    (["since=2026-03-31T21:00+00:00"], {"c.h5", "d.h5"}),
    (["since=2026-03-31T22:00+00:00"], {"c.h5"}),
    (["amplitude_V=100"], {"a.h5", "b.h5", "d.h5"}),
    (["amplitude=50"], {"d.h5"}),
    # one same entry must hold both: d has 50 V at 20 Hz and 100 V at 40 Hz only
    (["amplitude_V=100", "frequency_hz<=20"], {"a.h5", "b.h5"}),
    (["frequency_hz>30"], {"a.h5", "d.h5"}),
    (["kind=hold"], {"c.h5"}),
    (["voltage_V>=80"], {"c.h5"}),
    (["entries=2"], {"a.h5", "d.h5"}),
    (["operator=alice"], {"a.h5"}),
    (["operator=carol"], {"c.h5"}),
    (["temperature_C<30"], {"c.h5"}),
    (["status=complete"], {"a.h5", "b.h5", "c.h5", "d.h5"}),
    (
        [
            "sample=P-888#3",
            "protocol~sweep",
            "since=2026-03-01",
            "amplitude_V=100",
            "frequency_hz<=20",
        ],
        {"a.h5"},
    ),
]


def cli(*args: str) -> Any:
    return CliRunner().invoke(app, ["runs", *args])


def listed(result: Any) -> set[str]:
    assert result.exit_code == 0, result.output
    return {Path(r["path"]).name for r in json.loads(result.stdout)["runs"]}


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("runs")
    for name, spec in FILES.items():
        write_run(d / name, **spec)
    return d


@pytest.mark.parametrize(
    ("where", "expected"),
    SELECTIONS,
    ids=lambda x: repr(sorted(x)) if isinstance(x, set) else str(x),
)
def test_where_selects_the_right_files(folder: Path, where: list[str], expected: set[str]):
    args = [str(folder), "--json"]
    for w in where:
        args += ["--where", w]
    assert listed(cli(*args)) == expected


def test_where_file_equals_the_path_as_listed_or_absolute(folder: Path):
    absolute = str((folder / "c.h5").absolute())
    assert listed(cli(str(folder), "--json", "--where", f"file={absolute}")) == {"c.h5"}
    listed_as = str(folder / "d.h5")
    assert listed(cli(str(folder), "--json", "--where", f"file={listed_as}")) == {"d.h5"}
    dotted = f"{folder}/./sub/../b.h5"  # another spelling of the same path
    assert listed(cli(str(folder), "--json", "--where", f"file={dotted}")) == {"b.h5"}
    assert listed(cli(str(folder), "--json", "--where", f"file!={dotted}")) == {
        "a.h5", "c.h5", "d.h5"}  # fmt: skip


def test_listing_shows_status_protocol_date_metadata_and_entries(folder: Path):
    result = cli(str(folder))
    assert result.exit_code == 0, result.output
    lines = {line.split()[0].rsplit("/", 1)[-1]: line for line in result.stdout.splitlines()[1:]}
    assert set(lines) == set(FILES)
    a = lines["a.h5"]
    for text in ("complete", "2026-03-05 10:00", "paper sine sweep", "2 sine", "100 V"):
        assert text in a
    assert "10, 40 Hz" in a and "sample=P-888 #3" in a and "operator=alice" in a
    assert "operator=carol" in lines["c.h5"] and "1 hold" in lines["c.h5"]
    assert "4 runs" in result.stderr


def test_json_has_the_metadata_and_the_entries(folder: Path):
    runs = {Path(r["path"]).name: r for r in json.loads(cli(str(folder), "--json").stdout)["runs"]}
    a = runs["a.h5"]
    assert a["metadata"]["sample/name"] == "P-888 #3"
    assert a["metadata"]["user/name"] == "alice"
    assert a["metadata"]["instrument/name"] == "test"
    assert a["summary"]["amplitudes_V"] == [100.0] and a["summary"]["frequencies_hz"] == [10, 40]
    assert [e["samples"] for e in a["entries"]] == [20, 20]
    assert runs["c.h5"]["metadata"]["metadata/temperature_C"] == 23.5


def test_metadata_is_read_generically(tmp_path: Path):
    """Any group under an entry or /run is indexed; entries that differ give a list; the
    'null' of unset values and long texts are left out."""
    p = write_run(
        tmp_path / "m.h5",
        "p",
        [("sine", 10, 1), ("sine", 20, 1)],
        run_metadata={"operator": "dora", "unset": "null", "note": "x" * 500},
    )
    with h5py.File(p, "a") as f:
        for i, name in enumerate(("sine_10V_1Hz", "sine_20V_1Hz")):
            g = f[name].create_group("sample")
            g.attrs["NX_class"] = "NXsample"
            g["name"] = f"stack {i}"
            g["model"] = "P-888.51"
            assert f[name]["definition"][()] == b"NXlabrig"  # written by the store
        seal_all(f)
    meta, _ = read_metadata_here(p)
    assert meta["metadata/operator"] == "dora"
    assert meta["sample/name"] == ["stack 0", "stack 1"]
    assert meta["sample/model"] == "P-888.51" and meta["definition"] == "NXlabrig"
    assert "metadata/unset" not in meta and "metadata/note" not in meta


def test_index_notices_changed_added_and_removed_files(tmp_path: Path):
    d = tmp_path / "runs"
    d.mkdir()
    for name in ("x.h5", "y.h5", "z.h5"):
        write_run(d / name, "first", [("sine", 10, 1)])
    first = list_runs([d])
    assert first.read == 3 and len(first.runs) == 3 and (d / INDEX_NAME).is_file()
    again = list_runs([d])
    assert again.read == 0 and len(again.runs) == 3

    before = os.stat(d / "y.h5")
    (d / "y.h5").unlink()
    write_run(d / "y.h5", "second", [("sine", 10, 1)])
    os.utime(d / "y.h5", ns=(before.st_atime_ns, before.st_mtime_ns + 1_000_000_000))
    write_run(d / "new.h5", "third", [("sine", 10, 1)])
    (d / "z.h5").unlink()
    after = list_runs([d])
    assert after.read == 2  # y changed, new added; x from the index
    protocols = {r.path.name: r.record["protocol"] for r in after.runs}
    assert protocols == {"x.h5": "first", "y.h5": "second", "new.h5": "third"}
    assert {r.path.name for r in list_runs([d], ["protocol=first"]).runs} == {"x.h5"}


def test_index_rebuilds_when_damaged(tmp_path: Path):
    write_run(tmp_path / "x.h5", "first", [("sine", 10, 1)])
    (tmp_path / INDEX_NAME).write_bytes(b"this is not SQLite" * 100)
    listing = list_runs([tmp_path])
    assert [r.path.name for r in listing.runs] == ["x.h5"]
    assert any("rebuilt" in n for n in listing.notes)


def test_damaged_files_are_listed_as_unreadable(tmp_path: Path):
    good = write_run(tmp_path / "good.h5", "fine", [("sine", 10, 1)])
    (tmp_path / "garbage.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + os.urandom(4000))
    data = good.read_bytes()
    (tmp_path / "truncated.h5").write_bytes(data[: len(data) // 3])
    result = cli(str(tmp_path), "--json")
    assert result.exit_code == 0, result.output
    runs = {Path(r["path"]).name: r for r in json.loads(result.stdout)["runs"]}
    assert runs["good.h5"]["status"] == "complete"
    for bad in ("garbage.h5", "truncated.h5"):
        assert runs[bad]["status"] == "unreadable" and runs[bad]["error"], bad
        assert bad in result.stderr
    assert "2 files unreadable" in result.stderr
    text = cli(str(tmp_path))
    assert text.exit_code == 0 and "unreadable" in text.stdout
    assert list_runs([tmp_path]).read == 0  # remembered as unreadable, not read again


def test_the_listing_shows_a_file_its_data_read_checks(tmp_path: Path):
    """Seals are checked when the data is read, not when a folder is listed: a run file whose
    text another program changed is listed from its summary, and ``labrig info`` refuses it."""
    good = write_run(tmp_path / "good.h5", "fine", [("sine", 10, 1)])
    with h5py.File(good, "a") as f:  # a change the file's seals do not cover
        f["run/protocol_name"][()] = "changed behind labrig's back"
    result = cli(str(tmp_path), "--json")
    assert result.exit_code == 0, result.output
    (run,) = json.loads(result.stdout)["runs"]
    assert run["status"] == "complete" and run["protocol"] == "fine"
    info = CliRunner().invoke(app, ["info", str(good)])
    assert info.exit_code == 2, info.output
    assert "[run/protocol_name]" in info.stderr and "checksum" in info.stderr


@pytest.mark.parametrize(
    "bad",
    [
        "sample",
        "=P-888",
        "amplitude_V=abc",
        "frequency_hz<=",
        "since>2026-03-01",
        "date=yesterday",
        "protocol<sweep",
        "until=2026-13",
    ],
)
def test_bad_where_exits_2_saying_what_is_valid(folder: Path, bad: str):
    result = cli(str(folder), "--where", bad)
    assert result.exit_code == 2, result.output
    assert repr(bad) in result.stderr and "valid:" in result.stderr
    assert "Traceback" not in result.output


def test_missing_path_exits_2(tmp_path: Path):
    result = cli(str(tmp_path / "nowhere"))
    assert result.exit_code == 2 and "not found" in result.stderr


def test_files_and_folders_together_are_listed_once(folder: Path):
    result = cli(str(folder), str(folder / "a.h5"), "--json")
    names = [Path(r["path"]).name for r in json.loads(result.stdout)["runs"]]
    assert sorted(names) == sorted(FILES)


def test_without_a_path_lists_runs_here(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.chdir(tmp_path)
    result = cli()
    assert result.exit_code == 2 and "runs/" in result.stderr
    write_run(tmp_path / "runs" / "x.h5", "here", [("sine", 10, 1)])
    assert listed(cli("--json")) == {"x.h5"}


def test_listing_shows_each_fact_once():
    """``--operator ana --sample X`` is stored in /run/metadata and as NXuser/NXsample names:
    the listing shows ``operator=ana sample=X`` once each, and an NXuser alone as the operator."""
    from labrig.cli.runs import metadata_text

    both = {
        "metadata/operator": "ana",
        "metadata/sample": "X",
        "user/name": "ana",
        "sample/name": "X",
    }
    assert metadata_text({"metadata": both}) == "operator=ana sample=X"
    assert metadata_text({"metadata": {"user/name": "bob"}}) == "operator=bob"
    different = {"metadata/operator": "ana", "user/name": "bob"}
    assert metadata_text({"metadata": different}) == "operator=ana operator=bob"


# -- status as printed, exact integers, bad keys and operators ------------------------------


def write_unfinished(path: Path, protocol: str = "crashed") -> Path:
    """A run file whose writer closed it without finishing the run (status ``running``:
    the listing prints ``incomplete``)."""
    w = RunWriter(path, f"name: {protocol}\n", "", {"name": "test"}, 1, protocol_name=protocol)
    e = w.begin_entry("sine_10V_1Hz", {"kind": "sine", "amplitude_V": 10.0}, 100.0, ["strain"])
    e.append({"strain": np.zeros(20)})
    w.close()
    return path


@pytest.fixture(scope="module")
def mixed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """done.h5 complete; crashed.h5 incomplete; two complete runs with 63-bit seeds that one
    float cannot tell apart (2**63 - 25 and 2**63 - 26 both round to 2**63)."""
    d = tmp_path_factory.mktemp("mixed")
    write_run(d / "done.h5", "done", [("sine", 10, 1)])
    write_unfinished(d / "crashed.h5")
    for name, seed in (("big25.h5", 2**63 - 25), ("big26.h5", 2**63 - 26)):
        with RunWriter(d / name, "name: big\n", "", {}, seed, protocol_name="big") as w:
            e = w.begin_entry("hold_1V", {"kind": "hold", "voltage_V": 1.0}, 100.0, ["strain"])
            e.append({"strain": np.zeros(5)})
    return d


@pytest.mark.parametrize(
    ("where", "expected"),
    [
        (["status=incomplete"], {"crashed.h5"}),
        (["status=running"], {"crashed.h5"}),  # as the file stores it and --json prints it
        (["status!=incomplete"], {"done.h5", "big25.h5", "big26.h5"}),
        (["status=complete"], {"done.h5", "big25.h5", "big26.h5"}),
        (["seed=9223372036854775783"], {"big25.h5"}),
        (["seed=9223372036854775782"], {"big26.h5"}),
        (["seed>=9223372036854775783"], {"big25.h5"}),
        (["seed<9223372036854775783", "protocol=big"], {"big26.h5"}),
        # a decimal between the two seeds, as written (as a float it is 2**63, above both)
        (["seed>=9223372036854775782.5"], {"big25.h5"}),
        (["seed<9223372036854775782.5", "protocol=big"], {"big26.h5"}),
        # the last dates Python represents: a span that ends past year 9999 is not an error
        (["since=9999"], set()),
        (["since=9999-12"], set()),
        (["date>=9999"], set()),
        (["until=9999-12-31", "protocol=big"], {"big25.h5", "big26.h5"}),
        (["until=9999", "protocol=big"], {"big25.h5", "big26.h5"}),
    ],
    ids=lambda x: repr(sorted(x)) if isinstance(x, set) else str(x),
)
def test_status_as_printed_and_seeds_exactly(mixed: Path, where: list[str], expected: set[str]):
    args = [str(mixed), "--json"]
    for w in where:
        args += ["--where", w]
    assert listed(cli(*args)) == expected


def test_the_listing_prints_incomplete_and_every_digit_of_a_seed(mixed: Path):
    result = cli(str(mixed))
    line = next(x for x in result.stdout.splitlines() if "crashed.h5" in x)
    assert line.split()[1] == "incomplete"
    runs = {Path(r["path"]).name: r for r in json.loads(cli(str(mixed), "--json").stdout)["runs"]}
    assert runs["big25.h5"]["seed"] == 2**63 - 25 and runs["big26.h5"]["seed"] == 2**63 - 26
    assert '"seed": 9223372036854775783' in cli(str(mixed), "--json").stdout


@pytest.mark.parametrize(
    ("bad", "says"),
    [
        ("freq<20", ["'freq'", "frequency_hz", "valid keys:", "amplitude_V"]),
        ("temperature_K<30", ["'temperature_K'", "temperature_C", "valid keys:"]),
        ("status==complete", ["'==' is not an operator", "!=", ">="]),
        ("date=>2026-03-01", ["'=>' is not an operator"]),
        ("amplitude_V<>50", ["'<>' is not an operator"]),
        ("status=finished", ["'finished' is not a status", "incomplete", "unreadable"]),
        ("seed=1.5", ["seed is a whole number", "'1.5'"]),
        ("entries=two", ["entries is a whole number"]),
        ("cycles=3", ["no run listed has the key 'cycles'"]),  # a step key, but none has it
    ],
)
def test_unknown_keys_operators_and_values_exit_2(folder: Path, bad: str, says: list[str]):
    result = cli(str(folder), "--where", bad)
    assert result.exit_code == 2, result.output
    assert repr(bad) in result.stderr and "Traceback" not in result.output
    for text in says:
        assert text in result.stderr, (text, result.stderr)


@pytest.mark.parametrize(
    "good",
    [
        "frequency_hz<20",  # just inside each bad case above
        "temperature_C<30",
        "status=complete",
        "status!=complete",
        "date>=2026-03-01",
        "amplitude_V<50",
        "seed=1",
        "entries=2",
        "serial_number=SN-3",  # a metadata key one file has
        "instrument/name=test",  # a key of the index's second part
        "voltage_V>=80",  # a step key one run has
    ],
)
def test_valid_expressions_next_to_the_bad_ones_are_accepted(folder: Path, good: str):
    result = cli(str(folder), "--where", good, "--json")
    assert result.exit_code == 0, result.output


# -- the index's stamp, the summary -----------------------------------------------------------


def test_a_file_replaced_by_one_of_the_same_size_and_mtime_is_read_again(tmp_path: Path):
    """Same size, modification time put back (``cp -p``, ``touch -d``, ``os.utime``): the
    inode and its change time still tell the files apart."""
    d = tmp_path / "runs"
    d.mkdir()
    write_run(d / "x.h5", "first", [("sine", 10, 1)])
    other = write_run(tmp_path / "other.h5", "secnd", [("sine", 10, 1)])
    before = os.stat(d / "x.h5")
    assert other.stat().st_size == before.st_size  # the case at hand: only the content differs
    assert [r.record["protocol"] for r in list_runs([d]).runs] == ["first"]
    os.replace(other, d / "x.h5")
    os.utime(d / "x.h5", ns=(before.st_atime_ns, before.st_mtime_ns))
    after = list_runs([d])
    assert after.read == 1 and [r.record["protocol"] for r in after.runs] == ["secnd"]
    # rewritten in place (same inode), same size, time put back
    data = (d / "x.h5").read_bytes()
    write_run(tmp_path / "third.h5", "third", [("sine", 10, 1)])
    st = os.stat(d / "x.h5")
    (d / "x.h5").write_bytes((tmp_path / "third.h5").read_bytes())
    os.utime(d / "x.h5", ns=(st.st_atime_ns, st.st_mtime_ns))
    assert os.stat(d / "x.h5").st_ino == st.st_ino and len(data) == st.st_size
    again = list_runs([d])
    assert again.read == 1 and [r.record["protocol"] for r in again.runs] == ["third"]


def records_of(folder: Path, reindex: bool = False) -> dict[str, dict[str, Any]]:
    listing = list_runs([folder], detail=True, reindex=reindex)
    return {r.path.name: r.record for r in listing.runs}


def drop_summary(path: Path) -> None:
    """The file as an older labrig, a crash or another program leaves it: no summary."""
    with h5py.File(path, "a") as f:
        del f["run/summary"]
        seal_all(f)


def test_a_summary_and_a_full_read_give_the_same_record(folder: Path, mixed: Path, tmp_path):
    """The listing reads the summary the writer left; files without one (older, interrupted,
    or a summary another program broke) are read in full: the records are the same."""
    for source in (folder, mixed):
        copy = tmp_path / source.name
        shutil.copytree(source, copy, ignore=shutil.ignore_patterns(".*"))
        from_summary = records_of(copy)
        for p in copy.glob("*.h5"):
            with h5py.File(p, "r") as f:
                has_summary = "summary" in f["run"]
            assert has_summary, p.name  # the writer closed every one, finished or not
            drop_summary(p)
        from_files = records_of(copy)
        assert set(from_files) == set(from_summary)
        for name, record in from_summary.items():
            assert record == from_files[name], name


def test_the_listing_reads_the_summary_and_reindex_reads_the_file(tmp_path: Path):
    p = write_run(tmp_path / "x.h5", "the file's", [("sine", 10, 1)])
    with h5py.File(p, "a") as f:  # a summary that says another name, sealed as labrig seals
        ds = f["run/summary"]
        summary = json.loads(ds[()])
        summary["protocol"] = "the summary's"
        ds[()] = json.dumps(summary)
        ds.attrs[SEAL_ATTR] = seal_of(ds)
    assert records_of(tmp_path)["x.h5"]["protocol"] == "the summary's"
    assert records_of(tmp_path, reindex=True)["x.h5"]["protocol"] == "the file's"


def test_a_summary_that_does_not_match_its_seal_is_not_used(tmp_path: Path):
    p = write_run(tmp_path / "x.h5", "the file's", [("sine", 10, 1)])
    with h5py.File(p, "a") as f:
        summary = json.loads(f["run/summary"][()])
        summary["protocol"] = "changed by another program"
        f["run/summary"][()] = json.dumps(summary)
    assert records_of(tmp_path)["x.h5"]["protocol"] == "the file's"


def test_the_python_listing_keeps_big_whole_numbers(tmp_path: Path):
    """``labrig.runs``: an id above 2**53 in one run (absent from the other) keeps its digits."""
    import labrig

    write_run(tmp_path / "a.h5", "a", [("sine", 10, 1)], run_metadata={"batch_id": 2**62 + 3})
    write_run(tmp_path / "b.h5", "b", [("sine", 10, 1)])
    frame = labrig.runs(tmp_path)
    ids = dict(zip(frame["protocol"], frame["metadata/batch_id"], strict=True))
    assert ids["a"] == 2**62 + 3 and type(ids["a"]) is int
    assert ids["b"] is None or ids["b"] != ids["b"]  # absent: None or NaN


@pytest.mark.parametrize("target_kind", ["database", "text"])
def test_an_index_that_is_a_symbolic_link_is_not_followed(tmp_path: Path, target_kind: str):
    """``DIR/.labrig-index.sqlite`` linking elsewhere: the listing keeps its index in memory
    and says so; the file linked to keeps its tables and rows, the link stays a link."""
    import sqlite3

    d = tmp_path / "runs"
    d.mkdir()
    write_run(d / "x.h5", "first", [("sine", 10, 1)])
    other = tmp_path / "other.sqlite"
    if target_kind == "database":
        db = sqlite3.connect(other)
        db.execute("CREATE TABLE files (path TEXT, precious TEXT)")
        db.execute("INSERT INTO files VALUES ('a', 'kept')")
        db.commit()
        db.close()
    else:
        other.write_text("not a database, and not labrig's")
    before = other.read_bytes()
    (d / INDEX_NAME).symlink_to(other)
    listing = list_runs([d])
    assert [r.path.name for r in listing.runs] == ["x.h5"]
    assert any("not followed" in n for n in listing.notes), listing.notes
    assert (d / INDEX_NAME).is_symlink() and other.read_bytes() == before
