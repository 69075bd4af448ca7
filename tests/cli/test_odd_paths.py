"""Paths that are not plain files, as outputs and inputs: each is exit 2 with one ``error:`` line
naming it and no traceback, and nothing it points to is replaced.

- an output that is a symbolic link, a pipe (a device is the same case: not a regular file),
  or a name that is not UTF-8: refused even with ``--overwrite``; a regular file beside them is
  still replaced with ``--overwrite`` (just inside the rule);
- a symbolic link given to ``run --resume`` (the resumed file would replace the link);
- a loop of symbolic links as an input or an output folder;
- a standard output that cannot be written (``/dev/full``);
- a folder holding a run file whose name is not UTF-8: listed without it, with a note.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from helpers import invoke

EXE = Path(sys.executable).parent / "labrig"


def _refused(res, *said: str) -> None:
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    for s in said:
        assert s in res.output, res.output


def test_a_symbolic_link_as_output_is_refused_and_its_file_kept(tiny_run, tmp_path):
    target = tmp_path / "params.json"
    target.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    res = invoke("fit", tiny_run, "--out", link, "--overwrite")
    _refused(res, "symbolic link", "params.json")
    assert link.is_symlink() and target.read_text() == "{}"


def test_a_batch_folder_may_be_a_link_to_a_folder_not_a_loop(tiny_run, tmp_path, monkeypatch):
    # the fleet page (its figures, most of this batch's CPU) is not read here; its own tests:
    # tests/fleet/test_fleet.py, tests/api/test_day_one.py
    import labrig.fleet.fleet_report as fleet_report

    monkeypatch.setattr(fleet_report, "write_fleet_report", lambda path, *args: path)
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    res = invoke("batch", "fit", tiny_run, "--out", tmp_path / "a", "--serial")
    _refused(res, "symbolic link")
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")  # just beside: a link to a folder
    res = invoke("batch", "fit", tiny_run, "--out", tmp_path / "link", "--serial")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "link").is_symlink() and (tmp_path / "real" / "fleet.parquet").is_file()


def test_a_symbolic_link_is_not_resumed(tiny_run, tmp_path):
    from helpers import TINY

    proto = tmp_path / "p.yaml"
    proto.write_text(TINY)
    link = tmp_path / "link.h5"
    link.symlink_to(tiny_run)
    before = tiny_run.read_bytes()
    res = invoke("run", proto, "--resume", link)
    _refused(res, "symbolic link", "--resume")
    assert link.is_symlink() and tiny_run.read_bytes() == before


def test_a_pipe_as_output_is_refused_a_regular_file_is_replaced(tiny_run, tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    res = invoke("fit", tiny_run, "--out", fifo, "--overwrite")
    _refused(res, "not a regular file")
    assert fifo.is_fifo()
    plain = tmp_path / "plain.json"
    plain.write_text("{}")
    res = invoke("fit", tiny_run, "--out", plain, "--overwrite")
    assert res.exit_code == 0, res.output
    assert plain.read_text() != "{}"


def test_an_output_name_that_is_not_utf8_is_refused_before_any_work(tiny_run, tmp_path):
    name = os.fsdecode(bytes(tmp_path) + b"/\xff.json")
    res = invoke("fit", tiny_run, "--out", name)
    _refused(res, "not valid UTF-8")
    assert list(tmp_path.iterdir()) == []


def test_a_loop_of_symbolic_links_is_an_input_error(tmp_path):
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    for args in (("validate", tmp_path / "a", "--on", tmp_path / "b"), ("import", tmp_path / "a")):
        res = invoke(*args, "--out", tmp_path / "x.h5") if args[0] == "import" else invoke(*args)
        _refused(res, "loop of symbolic links")


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_a_full_standard_output_is_one_error_line(tiny_run):
    with open("/dev/full", "w") as full:
        res = subprocess.run(
            [str(EXE), "info", str(tiny_run)], stdout=full, stderr=subprocess.PIPE, text=True,
            timeout=120,
        )  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr and "Exception ignored" not in res.stderr
    assert "standard output cannot be written" in res.stderr


def test_a_run_file_named_in_other_bytes_is_left_out_of_the_listing_with_a_note(tiny_run, tmp_path):
    shutil.copy(tiny_run, tmp_path / "ok.h5")
    shutil.copy(tiny_run, os.fsdecode(bytes(tmp_path) + b"/\xff.h5"))
    res = invoke("runs", tmp_path)
    assert res.exit_code == 0, res.output
    assert "ok.h5" in res.output and "not UTF-8" in res.output and "\\xff.h5" in res.output
