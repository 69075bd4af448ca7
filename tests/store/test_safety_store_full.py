"""The run-file writer when the disk is (nearly) full, in-process: a block that does not fit is
refused before anything is written, a block the disk refuses is cut back out, and the reserve
file gives its room back for the final records. (tests/store/test_safety_disk_full.py does it on a
real full filesystem.)"""

from __future__ import annotations

import errno
from pathlib import Path

import numpy as np
import pytest

from labrig.core.errors import StorageError
from labrig.store import RunWriter, read_run
from labrig.store import writer as store_writer

CHANNELS = ["command_voltage", "strain"]
BLOCK = 300


def block(k: int) -> dict[str, np.ndarray]:
    x = np.arange(k * BLOCK, (k + 1) * BLOCK, dtype=float)
    return {"command_voltage": x, "strain": -x}


def writer(path: Path, **kw) -> RunWriter:
    return RunWriter(path, "name: p", "", {}, 1, protocol_name="p", **kw)


def test_a_block_that_does_not_fit_is_refused_before_writing(tmp_path, monkeypatch):
    path = tmp_path / "run.h5"
    with writer(path) as w:
        e = w.begin_entry("e0", {}, 1000.0, CHANNELS)
        for k in range(3):
            e.append(block(k))
        monkeypatch.setattr(store_writer, "free_bytes", lambda p: 20_000)
        with pytest.raises(StorageError) as ei:
            e.append(block(3))  # crosses into a new chunk: 3 x 8 kB plus the margin
        assert e.n_samples == 3 * BLOCK
        msg = str(ei.value)
        assert str(path) in msg and "disk full" in msg and "20 kB free" in msg
        assert ei.value.exit_code == 3
        w.finish("failed", msg)
    run = read_run(path)
    assert run.status == "failed" and run["e0"].n_samples == 3 * BLOCK
    np.testing.assert_array_equal(run["e0"]["strain"], -np.arange(3 * BLOCK, dtype=float))


def test_a_block_the_disk_refuses_is_cut_back_out(tmp_path, monkeypatch):
    """HDF5 wrote the block but could not flush it (ENOSPC): every channel goes back to the
    blocks before it, so the file never holds a half-written block."""
    path = tmp_path / "run.h5"
    with writer(path) as w:
        e = w.begin_entry("e0", {}, 1000.0, CHANNELS)
        e.append(block(0))
        e.append(block(1))
        real_flush = w.flush

        def full():
            raise OSError(errno.ENOSPC, "No space left on device")

        monkeypatch.setattr(w, "flush", full)
        with pytest.raises(StorageError, match="disk full"):
            e.append(block(2))
        monkeypatch.setattr(w, "flush", real_flush)
        assert e.n_samples == 2 * BLOCK
        w.finish("failed", "disk full")
    run = read_run(path)
    entry = run["e0"]
    assert entry.n_samples == 2 * BLOCK and not entry.trimmed
    for name in ("time", *CHANNELS):
        assert len(entry[name]) == 2 * BLOCK, name
    np.testing.assert_array_equal(entry["command_voltage"], np.arange(2 * BLOCK, dtype=float))


def test_the_reserve_is_held_during_the_run_and_given_back_for_the_end(tmp_path):
    path = tmp_path / "run.h5"
    reserve = tmp_path / ".run.h5.reserve"
    with writer(path, reserve_bytes=1 << 20) as w:
        assert reserve.stat().st_size == 1 << 20
        assert reserve.stat().st_blocks * 512 >= 1 << 20  # allocated, not a sparse promise
        w.begin_entry("e0", {}, 1000.0, CHANNELS).append(block(0))
        assert reserve.exists()
        w.set_run_value("exit_code", 0)  # a final record: the reserve goes first
        assert not reserve.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.h5"]


def test_the_reserve_goes_with_the_writer_even_without_a_finish(tmp_path):
    path = tmp_path / "run.h5"
    w = writer(path, reserve_bytes=4096)
    w.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.h5"]
