"""The one output check (labrig.core.outputs.check_outputs), through every command that the
issue caught replacing one of its own inputs with ``--overwrite``, and through the Python API.

Each case: exit code 2, one ``error:`` line naming the output and the option, no traceback, and
the input intact byte for byte. Before the check was one function, each of these exited 0 and
replaced the input (``sim fleet --out FILE`` exited 1 with a traceback; ``export --out A --csv B``
silently wrote to B).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

import labrig
from labrig.core.errors import InputFileError
from labrig.core.outputs import OutputExistsError, ReadFolder, check_outputs
from labrig.model import PAPER_TABLE1

from helpers import TINY, invoke, start_writer, stop_writer


def refused(res, *words: str) -> str:
    assert res.exit_code == 2, res.output
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.stderr.startswith("error: ") and "Traceback" not in res.output, res.output
    for w in words:
        assert w in res.stderr, (w, res.stderr)
    return res.stderr


def digest(*paths: Path) -> list[str]:
    return [hashlib.sha256(p.read_bytes()).hexdigest() for p in paths]


@pytest.fixture
def two_runs(tiny_run: Path, tmp_path: Path) -> tuple[Path, Path]:
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    a.write_bytes(tiny_run.read_bytes())
    b.write_bytes(tiny_run.read_bytes())
    return a, b


def test_run_never_writes_over_its_protocol(tmp_path: Path):
    proto = tmp_path / "P.yaml"
    proto.write_text(TINY)
    before = digest(proto)
    refused(invoke("run", proto, "--out", proto, "--overwrite"), str(proto), "is an input")
    assert digest(proto) == before


def test_run_never_writes_over_its_rig_file(tmp_path: Path):
    from labrig.rig.rigspec import DEFAULT_RIG_YAML

    proto, rig = tmp_path / "P.yaml", tmp_path / "R.yaml"
    proto.write_text(TINY)
    rig.write_text(DEFAULT_RIG_YAML)
    before = digest(rig)
    res = invoke("run", proto, "--rig", rig, "--out", rig, "--overwrite")
    refused(res, str(rig), "--out", "is an input")
    assert digest(rig) == before


def test_run_never_writes_over_the_live_views_parameters(tmp_path: Path):
    proto, params = tmp_path / "P.yaml", tmp_path / "P.json"
    proto.write_text(TINY)
    params.write_text(json.dumps({"params": PAPER_TABLE1.model_dump()}))  # a valid one
    before = digest(params)
    res = invoke("run", proto, "--live", "--params", params, "--out", params, "--overwrite")
    refused(res, str(params), "is an input")
    assert "live view:" not in res.output  # refused before the live view started
    assert digest(params) == before


def test_info_of_several_files_never_writes_over_one_of_them(two_runs):
    a, b = two_runs
    before = digest(a, b)
    refused(invoke("info", a, b, "--out", b, "--overwrite"), str(b), "is an input")
    assert digest(a, b) == before


def test_runs_never_writes_over_a_run_file_of_the_folder_it_lists(two_runs, tmp_path: Path):
    a, _ = two_runs
    before = digest(a)
    res = invoke("runs", tmp_path, "--out", a, "--overwrite")
    refused(res, str(a), f"is inside {tmp_path}")
    assert digest(a) == before
    # a new run file there would be listed next time: refused as well
    refused(invoke("runs", tmp_path, "--out", tmp_path / "sub" / "new.h5"), "is inside")
    # but a JSON listing beside the runs is fine
    res = invoke("runs", tmp_path, "--out", tmp_path / "listing.json")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "listing.json").read_text().startswith("{")


def test_fit_never_replaces_a_run_file_being_written(two_runs, tmp_path: Path):
    other, _ = two_runs
    target = tmp_path / "X.h5"
    writer = start_writer(target)
    try:
        res = invoke("fit", other, "--no-heldout", "--out", target, "--overwrite")
        refused(res, str(target), "being written now", f"process {writer.pid}")
    finally:
        stop_writer(writer)
    run = labrig.open(target)  # the run's file, whole, not a JSON file
    assert run.status == "complete" and run.protocol == "being written"


def test_sim_fleet_into_a_file_is_bad_input_not_a_traceback(tmp_path: Path):
    f = tmp_path / "notes.txt"
    f.write_text("notes\n")
    refused(invoke("sim", "fleet", "2", "--out", f), str(f), "is a file; give a folder")
    assert f.read_text() == "notes\n"


def test_export_refuses_out_and_csv_together(two_runs, tmp_path: Path):
    a, _ = two_runs
    res = invoke("export", a, "--out", tmp_path / "A", "--csv", tmp_path / "B")
    refused(res, "--out and --csv")
    assert not (tmp_path / "A").exists() and not (tmp_path / "B").exists()
    res = invoke("export", a, "--csv", tmp_path / "B")  # the older name alone still works
    assert res.exit_code == 0, res.output
    assert len(list((tmp_path / "B").glob("*.csv"))) == 3


# -- the Python API --------------------------------------------------------------------------


def test_the_api_uses_the_same_check(two_runs, tmp_path: Path):
    a, b = two_runs
    proto = tmp_path / "P.yaml"
    proto.write_text(TINY)
    before = digest(a, b, proto)
    with pytest.raises(InputFileError, match="is an input"):
        labrig.run(proto, out=proto, overwrite=True, progress=False)
    run = labrig.open(a)
    with pytest.raises(InputFileError, match="is an input"):
        run.report(out=a, overwrite=True, heldout=False)
    with pytest.raises(FileExistsError):  # an existing file without overwrite, as Python says
        run.report(out=b, heldout=False)
    with pytest.raises(IsADirectoryError):
        run.report(out=tmp_path, heldout=False)
    assert digest(a, b, proto) == before


# -- the check itself, at its edges -----------------------------------------------------------


def test_read_folder_edges(tmp_path: Path):
    folder = ReadFolder(tmp_path / "runs", (".h5", ".hdf5"))
    assert folder.reads(tmp_path / "runs" / "a.h5")
    assert folder.reads(tmp_path / "runs" / "deep" / "b.HDF5")
    assert not folder.reads(tmp_path / "runs" / "listing.json")  # not a kind it reads
    assert not folder.reads(tmp_path / "runs-old" / "a.h5")  # a sibling with the same prefix
    assert not folder.reads(tmp_path / "a.h5")


def test_a_link_to_an_input_is_the_input(tmp_path: Path):
    src = tmp_path / "in.json"
    src.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(src)
    with pytest.raises(InputFileError, match="is an input"):
        check_outputs([link], inputs=[src], overwrite=True)
    with pytest.raises(InputFileError, match="is an input"):  # the same path spelled otherwise
        check_outputs([tmp_path / "x" / ".." / "in.json"], inputs=[src], overwrite=True)


def test_the_writer_probe_is_asked_only_about_existing_files(tmp_path: Path):
    asked: list[Path] = []

    def probe(p: Path) -> str | None:
        asked.append(p)
        return "process 1" if p.name == "busy.h5" else None

    busy, idle, new = tmp_path / "busy.h5", tmp_path / "idle.h5", tmp_path / "new.h5"
    busy.write_bytes(b"x")
    idle.write_bytes(b"x")
    check_outputs([idle, new], overwrite=True, being_written=probe)
    with pytest.raises(InputFileError, match="being written now"):
        check_outputs([busy], overwrite=True, being_written=probe)
    assert asked == [idle, busy]
    with pytest.raises(OutputExistsError):
        check_outputs([idle], being_written=probe)


def test_export_of_a_run_being_written_says_so(tmp_path: Path):
    """The CSV files of a run still being written end where the file did when read: exit 0
    (what is there is exported) with a note naming the writer; none for a finished run."""
    target = tmp_path / "X.h5"
    writer = start_writer(target)
    try:
        res = invoke("export", target, "--out", tmp_path / "csv")
        assert res.exit_code == 0, res.output
        assert "is being written" in res.stderr and f"process {writer.pid}" in res.stderr
    finally:
        stop_writer(writer)
    res = invoke("export", target, "--out", tmp_path / "csv2")
    assert res.exit_code == 0 and "being written" not in res.stderr, res.output
