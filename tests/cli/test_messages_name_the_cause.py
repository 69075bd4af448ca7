"""Refusals say what is actually wrong: the option a user typed, why a file is not a labrig run
file, and that a path exists but is not a file nor a folder (exit 2, one line, no traceback)."""

from __future__ import annotations

import os
import socket
from pathlib import Path

import h5py
import pytest

from helpers import invoke


def refused(res, *words: str) -> None:
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    flat = " ".join(res.stderr.split())
    for w in words:
        assert w in flat, (w, res.stderr)


def test_watch_on_a_port_in_use_names_its_own_option(tiny_run: Path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        res = invoke("watch", tiny_run, "--port", port)
    refused(res, f"127.0.0.1:{port}", "--port", "cannot serve there")
    assert "--live-port" not in res.stderr


@pytest.mark.parametrize(
    ("creator", "said"),
    [(None, "no creator attribute"), ("another program", "its creator is 'another program'")],
)
def test_a_file_of_another_creator_is_said_to_be_so(tmp_path: Path, creator, said: str):
    path = tmp_path / "theirs.h5"
    with h5py.File(path, "w") as f:
        f.create_group("run")
        if creator is not None:
            f.attrs["creator"] = creator
    refused(invoke("info", path), "not a labrig run file", said)


def test_a_file_of_labrig_without_its_run_group_is_said_to_be_so(tmp_path: Path):
    path = tmp_path / "cut.h5"
    with h5py.File(path, "w") as f:
        f.attrs["creator"] = "labrig"
    refused(invoke("info", path), "not a labrig run file (no /run group)")


def test_a_pipe_given_to_runs_is_not_called_missing(tmp_path: Path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    refused(invoke("runs", fifo), f"{fifo}", "not a file nor a folder")
    refused(invoke("runs", tmp_path / "absent"), "not found")
