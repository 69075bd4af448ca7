"""Input paths that are not files to read whole: a device (``/dev/zero`` read until memory ran
out: 24 GB), a pipe, a file over its limit, a name longer than the file system allows. Each is
exit 2 with one line naming the path, at once, no traceback."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from labrig.core.outputs import MAX_OUTPUT_NAME_BYTES
from labrig.core.textfile import read_bytes_bounded

from helpers import ROOT, invoke

SWEEP = ROOT / "experiments" / "sweep.yaml"
ZERO = Path("/dev/zero")
needs_dev_zero = pytest.mark.skipif(not ZERO.exists(), reason="no /dev/zero here")


def _refused(res, path: object) -> None:
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    assert str(path) in res.stderr, res.stderr


@needs_dev_zero
@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    "args",
    [
        ("check", ZERO),
        ("check", SWEEP, "--rig", ZERO),
        ("sim", "fleet", "1", "--out", "{tmp}/fleet", "--protocol", ZERO),
    ],
)
def test_a_device_as_a_yaml_input_is_refused_at_once(tmp_path, args):
    res = invoke(*(str(a).format(tmp=tmp_path) for a in args))
    _refused(res, ZERO)
    assert "not a regular file" in res.stderr


@needs_dev_zero
@pytest.mark.timeout(60)
def test_a_device_as_a_parameter_file_is_refused_at_once(tiny_run):
    res = invoke("report", tiny_run, "--params", ZERO)
    _refused(res, ZERO)


@pytest.mark.timeout(60)
@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_a_named_pipe_nobody_writes_is_refused_not_waited_on(tmp_path):
    fifo = tmp_path / "protocol.yaml"
    os.mkfifo(fifo)
    res = invoke("check", fifo)
    _refused(res, fifo)


def test_the_size_limit_just_inside_and_outside(tmp_path):
    f = tmp_path / "x.json"
    f.write_bytes(b"1" * 1000)
    assert read_bytes_bounded(f, 1000) == b"1" * 1000
    with pytest.raises(ValueError, match="larger than"):
        read_bytes_bounded(f, 999)


def test_a_protocol_over_the_yaml_limit_is_refused(tmp_path):
    from labrig.core.yamlio import MAX_BYTES

    big = tmp_path / "big.yaml"
    big.write_text("# " + "x" * MAX_BYTES + "\n")
    res = invoke("check", big)
    _refused(res, big)
    assert "too large" in res.stderr


@pytest.mark.parametrize("command", ["check-out", "check-in", "info"])
def test_a_name_over_255_bytes_is_a_bad_input_and_255_is_a_name(tmp_path, command):
    long = tmp_path / ("a" * 251 + ".json")  # 256 bytes
    args = {
        "check-out": ("check", SWEEP, "--out", long),
        "check-in": ("check", long),
        "info": ("info", long),
    }[command]
    res = invoke(*args)
    _refused(res, long)
    assert "too long (256 bytes" in res.stderr


def test_an_outputs_name_is_at_most_237_bytes(tmp_path):
    """An output is written into ``.NAME.XXXXXXXX.partial`` beside it first, 18 bytes more
    than its name: 237 bytes is the longest name that fits in 255."""
    assert MAX_OUTPUT_NAME_BYTES == 237
    ok, over = tmp_path / ("a" * 232 + ".json"), tmp_path / ("b" * 233 + ".json")
    res = invoke("check", SWEEP, "--out", ok)
    assert res.exit_code == 0, res.output
    assert ok.is_file()
    res = invoke("check", SWEEP, "--out", over)
    _refused(res, over)
    assert "name too long (238 bytes" in res.stderr and not over.exists()
