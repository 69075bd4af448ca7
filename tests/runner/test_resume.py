"""``labrig run PROTOCOL --resume FILE``: an aborted run finished into its own file, the resume
recorded, the protocol checked, and a failed resume leaving the file as it was."""

from __future__ import annotations

import hashlib
import os
import select
import signal
import time
from pathlib import Path

import h5py
import pytest
import yaml

from labrig.core.errors import InputFileError
from labrig.core.metadata import from_options
from labrig.runner import execute as runner
from labrig.store import read_run, run_info

from helpers import copied, fork_saying, reaped

pytestmark = pytest.mark.timeout(120)

STEPS = [
    {"kind": "sine", "amplitude_V": 50, "frequency_hz": 5, "cycles": 3},
    {"kind": "sine", "amplitude_V": 80, "frequency_hz": 5, "cycles": 3},
    {"kind": "sine", "amplitude_V": 100, "frequency_hz": 5, "cycles": 3},
]
NAMES = ["sine_50V_5Hz", "sine_80V_5Hz", "sine_100V_5Hz"]


def protocol(tmp_path: Path, **extra) -> Path:
    p = tmp_path / "campaign.yaml"
    doc = {"name": "resume test", "rate_hz": 1000, "rest_s": 0.2, "steps": STEPS, **extra}
    p.write_text(yaml.safe_dump(doc, sort_keys=False))
    return p


def run(proto: Path, out: Path | None, **kw) -> runner.RunOutcome:
    plan, rig = runner.preflight(proto, None)
    return runner.execute(plan, rig, out, seed=kw.pop("seed", 3), **kw)


def interrupt_in(entry: int, frac: float = 0.5):
    """A progress callback that presses Ctrl-C halfway through entry ``entry``."""

    def progress(k, n, name, f, left):
        if k == entry and f >= frac:
            raise KeyboardInterrupt

    return progress


def digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def aborted_once(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A run aborted halfway through its second entry, by alice (recorded once, read-only)."""
    folder = tmp_path_factory.mktemp("aborted")
    proto = protocol(folder)
    out = folder / "run.h5"
    o = run(proto, out, progress=interrupt_in(1), metadata=from_options(operator="alice"))
    assert (o.status, o.exit_code) == ("aborted", 130)
    return proto, out


@pytest.fixture
def aborted(aborted_once: tuple[Path, Path], tmp_path: Path) -> tuple[Path, Path]:
    """A copy of :func:`aborted_once`'s protocol and run file in ``tmp_path``, the test's own."""
    proto, out = copied(tmp_path, *aborted_once)
    return proto, out


def test_resume_finishes_the_campaign_and_records_it(aborted, tmp_path):
    proto, out = aborted
    before = read_run(out)
    first = before[NAMES[0]]
    assert [e.status for e in before] == ["complete", "aborted"]

    o = run(proto, None, resume=out, seed=11, metadata=from_options(operator="bob"))
    assert (o.status, o.exit_code, o.path) == ("complete", 0, out)
    assert o.entries == NAMES[1:]

    after = read_run(out)
    assert after.status == "complete" and not after.incomplete
    complete = [e.name for e in after if e.complete]
    assert complete == NAMES  # every planned entry, complete, in plan order
    # the aborted attempt kept its samples under another name, before the resumed entries
    order = [e.name for e in after]
    assert order == [NAMES[0], f"{NAMES[1]}_partial1", NAMES[1], NAMES[2]]
    partial = after[f"{NAMES[1]}_partial1"]
    assert partial.status == "aborted" and partial.n_samples == before[NAMES[1]].n_samples
    # the entry that was complete is untouched
    assert after[NAMES[0]].start_time == first.start_time
    assert (after[NAMES[0]]["strain"] == first["strain"]).all()
    # the resume is recorded: when, which entries, the new seed, how the run had ended
    (r,) = after.resumes
    assert r["number"] == 1 and r["entries"] == NAMES[1:] and r["seed"] == 11
    assert r["superseded"] == {NAMES[1]: f"{NAMES[1]}_partial1"}
    assert r["previous_status"] == "aborted" and "Ctrl-C" in r["previous_reason"]
    assert r["previous_exit_code"] == 130
    assert after.seed == 3  # the run's own seed stays the first part's
    # who ran which entry: alice the first, bob the resumed ones
    assert after[NAMES[0]].user == {"name": "alice"}
    assert after[NAMES[1]].user == {"name": "bob"} and after[NAMES[2]].user == {"name": "bob"}
    assert after.metadata == {"operator": "alice"}
    with h5py.File(out) as f:
        assert "previous_ramp_to_zero" in f["run/resumes/resume_1"]
        assert f["run/final_amplifier_voltage_V"][()] == 0.0
    # labrig info says so
    from rich.console import Console

    console = Console(width=160, record=True)
    console.print(run_info(out))
    text = console.export_text()
    assert "resumed" in text and NAMES[1] in text


def test_a_second_resume_after_another_interrupt(aborted):
    proto, out = aborted
    o = run(proto, None, resume=out, progress=interrupt_in(1))  # Ctrl-C again, in the 3rd entry
    assert (o.status, o.exit_code) == ("aborted", 130)
    mid = read_run(out)
    assert [e.name for e in mid if e.complete] == NAMES[:2] and len(mid.resumes) == 1
    o = run(proto, None, resume=out)
    assert o.status == "complete"
    final = read_run(out)
    assert [e.name for e in final if e.complete] == NAMES
    assert [r["number"] for r in final.resumes] == [1, 2]
    assert final.resumes[1]["entries"] == [NAMES[2]]


def test_another_protocol_or_a_complete_file_is_refused_before_anything(aborted, tmp_path):
    proto, out = aborted
    before = digest(out)
    other = tmp_path / "other" / "campaign.yaml"
    other.parent.mkdir()
    other.write_text(proto.read_text().replace("rest_s: 0.2", "rest_s: 0.3"))
    with pytest.raises(InputFileError, match=r"another protocol.*line \d+: 'rest_s: 0.3' given"):
        run(other, None, resume=out)
    assert digest(out) == before
    run(proto, None, resume=out)
    with pytest.raises(InputFileError, match="every planned entry is complete"):
        run(proto, None, resume=out)


def test_a_failed_resume_leaves_the_aborted_file_as_it_was(aborted, tmp_path):
    """A resume killed (SIGKILL) in the middle of its entries: the aborted file is byte for
    byte what it was, and still reads as aborted; a later resume finishes it. (The resume runs
    in a fork of this process, labrig already loaded: the kill ends a process all the same.)"""
    proto, out = aborted
    before = digest(out)

    def resume(said: int) -> None:
        def progress(k, n, name, f, left):
            if f > 0.3:
                os.write(said, b"playing\n")

        plan, rig = runner.preflight(proto, None)
        runner.execute(plan, rig, None, seed=5, realtime=True, progress=progress, resume=out)

    pid, read_fd = fork_saying(resume)
    try:
        with os.fdopen(read_fd) as said:
            assert select.select([said], [], [], 60)[0], "the resume never played"
            assert said.readline().strip() == "playing"  # recording into its copy
            partial = list(tmp_path.glob(".run.h5.*.partial/run.h5"))
            assert len(partial) == 1
            os.kill(pid, signal.SIGKILL)
    finally:
        status = reaped(pid)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL
    assert digest(out) == before
    assert read_run(out).status == "aborted"
    for d in tmp_path.glob(".run.h5.*.partial"):  # what a person deletes by hand
        for f in d.iterdir():
            f.unlink()
        d.rmdir()
    time.sleep(0.05)
    assert run(proto, None, resume=out).status == "complete"
