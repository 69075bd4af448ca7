"""A run file deleted or replaced at its path by another program while the run writes it: the
run stops (exit 3, a storage fault), ramps to 0 V and says so; it never reports "run complete"
for samples that are not in the file at the path it prints. Another program's file put there is
left as it was; with ``--overwrite`` the old run file is kept."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from labrig.cli import app
from labrig.runner import execute as runner
from labrig.store import read_run

from helpers import TINY, arm

#: TINY's entries: 2 cycles at 2 Hz, 500 samples a second: 500 samples each
PER_ENTRY = 500


@pytest.fixture(scope="module")
def a_complete_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A complete run of the same protocol (written once; tests copy it)."""
    folder = tmp_path_factory.mktemp("complete")
    res = run(folder, folder / "run.h5")
    assert res.exit_code == 0, res.output
    return folder / "run.h5"


def run(tmp_path: Path, out: Path, *extra: str):
    proto = tmp_path / "tiny.yaml"
    proto.write_text(TINY)
    return CliRunner().invoke(app, ["run", str(proto), "--out", str(out), "--seed", "1", *extra])


def stopped_for_the_file(res, rigs: list) -> None:
    assert res.exit_code == 3, res.output
    assert "Traceback" not in res.output and "run complete" not in res.output
    assert "deleted, moved or replaced at its path" in " ".join(res.output.split())
    assert rigs[0].sim.bench.amp.v_out == 0.0


def test_a_run_file_deleted_during_an_entry_stops_the_run(tmp_path: Path, monkeypatch):
    out = tmp_path / "run.h5"
    rigs = arm(monkeypatch, PER_ENTRY + 100, out.unlink)  # in the second entry
    res = run(tmp_path, out)
    stopped_for_the_file(res, rigs)
    assert not out.exists()


def test_a_run_file_replaced_by_another_programs_file_is_left_alone(tmp_path: Path, monkeypatch):
    out = tmp_path / "run.h5"
    theirs = b"another program's file"

    def replace() -> None:
        other = tmp_path / "theirs.tmp"
        other.write_bytes(theirs)
        other.replace(out)

    rigs = arm(monkeypatch, 100, replace)  # in the first entry
    res = run(tmp_path, out)
    stopped_for_the_file(res, rigs)
    assert out.read_bytes() == theirs


def test_a_run_file_deleted_after_its_last_block_is_not_a_complete_run(tmp_path: Path, monkeypatch):
    """Deleted while the output ramps down (after every block was checked): the run's end
    still finds it gone."""
    out = tmp_path / "run.h5"
    real_open = runner.open_rig
    rigs: list = []

    def open_and_arm(path=None, seed=None):
        rig = real_open(path, seed)
        rigs.append(rig)
        real_ramp = rig.ramp_to_zero

        def ramp():
            out.unlink(missing_ok=True)  # (the rig's close ramps again)
            return real_ramp()

        rig.ramp_to_zero = ramp
        return rig

    monkeypatch.setattr(runner, "open_rig", open_and_arm)
    res = run(tmp_path, out)
    stopped_for_the_file(res, rigs)


def test_a_run_file_truncated_during_the_run_stops_it(tmp_path: Path, monkeypatch):
    """The same file (same inode), cut short by another program (``truncate -s 0``)."""
    out = tmp_path / "run.h5"
    rigs = arm(monkeypatch, PER_ENTRY + 100, lambda: os.truncate(out, 0))
    res = run(tmp_path, out)
    assert res.exit_code == 3, res.output
    assert "truncated or written over" in " ".join(res.output.split())
    assert "run complete" not in res.output and rigs[0].sim.bench.amp.v_out == 0.0


def test_another_file_copied_over_the_run_file_stops_it(
    tmp_path: Path, monkeypatch, a_complete_run: Path
):
    """``cp other.h5 run.h5`` during the run writes over the same inode: said as such, not as
    HDF5's errors."""
    out = tmp_path / "run.h5"

    def copy_over() -> None:
        shutil.copyfile(a_complete_run, out)  # (opens the same file, O_TRUNC)

    arm(monkeypatch, PER_ENTRY + 100, copy_over)
    res = run(tmp_path, out)
    assert res.exit_code == 3, res.output
    flat = " ".join(res.output.split())
    assert "truncated or written over" in flat and "HDF5" not in flat


@pytest.mark.parametrize("damage", ["delete", "truncate"])
def test_with_overwrite_the_old_file_stays_when_the_new_one_is_damaged(
    tmp_path: Path, monkeypatch, damage: str, a_complete_run: Path
):
    """``--overwrite`` writes the new file beside the old one (a hidden partial folder): that
    file deleted or truncated, the run stops and the old run file is untouched (not replaced
    by the damaged new one)."""
    out = Path(shutil.copyfile(a_complete_run, tmp_path / "run.h5"))
    before = out.read_bytes()

    def damage_the_new_one() -> None:
        (staged,) = tmp_path.glob(".run.h5.*.partial/run.h5")
        staged.unlink() if damage == "delete" else os.truncate(staged, 0)

    rigs = arm(monkeypatch, PER_ENTRY + 100, damage_the_new_one)
    res = run(tmp_path, out, "--overwrite")
    assert res.exit_code == 3, res.output
    assert "run complete" not in res.output and rigs[0].sim.bench.amp.v_out == 0.0
    assert f"{out} is kept as it was" in " ".join(res.output.split())
    assert out.read_bytes() == before
    assert read_run(out).status == "complete"
    assert not list(tmp_path.glob(".run.h5.*.partial"))


def test_touching_copying_or_reading_the_file_does_not_stop_the_run(tmp_path: Path, monkeypatch):
    """What a person does to a file being written without taking it away changes nothing."""
    out = tmp_path / "run.h5"

    def look() -> None:
        out.touch()
        shutil.copyfile(out, tmp_path / "copy.h5")
        os.chmod(out, 0o444)

    arm(monkeypatch, PER_ENTRY + 100, look)
    res = run(tmp_path, out)
    assert res.exit_code == 0, res.output
    assert "run complete" in res.output and read_run(out).status == "complete"


def test_a_folder_renamed_during_the_run_keeps_no_reserve_file(tmp_path: Path, monkeypatch):
    """The run's folder renamed away (and back after): the run stops, and the reserve file
    (room kept for the final records) is deleted where the folder went."""
    folder = tmp_path / "runs"
    folder.mkdir()
    out = folder / "run.h5"
    away = tmp_path / "elsewhere"
    rigs = arm(monkeypatch, PER_ENTRY + 100, lambda: folder.rename(away))
    res = run(tmp_path, out)
    stopped_for_the_file(res, rigs)
    away.rename(folder)
    assert sorted(p.name for p in folder.iterdir()) == ["run.h5"]
