"""``labrig run --resume`` on a damaged run file: refused before the rig is opened.

A resume appends to the file it continues; one whose stored samples fail their Fletcher-32
checksum was once accepted, the rig energised, 11 entries appended, and afterwards ``info``,
``export`` and ``fit`` refused the file: the whole campaign lost. Now every sample and seal is
verified first (labrig.store.resume.verify_samples): exit 2 naming the damage, the rig never
opened, the file byte for byte as it was.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import h5py
import pytest
import yaml

from labrig.core.errors import InputFileError
from labrig.runner import execute as runner
from labrig.store import read_run

from helpers import copied, invoke

pytestmark = pytest.mark.timeout(120)

STEPS = [
    {"kind": "sine", "amplitude_V": 50, "frequency_hz": 5, "cycles": 2},
    {"kind": "sine", "amplitude_V": 80, "frequency_hz": 5, "cycles": 2},
]


def digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def aborted_once(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A run stopped (Ctrl-C) in its second entry: resumable (recorded once, read-only)."""
    folder = tmp_path_factory.mktemp("aborted")
    proto = folder / "campaign.yaml"
    proto.write_text(yaml.safe_dump({"name": "verify", "rate_hz": 1000, "steps": STEPS}))

    def progress(k, n, name, f, left):
        if k == 1 and f >= 0.5:
            raise KeyboardInterrupt

    plan, rig = runner.preflight(proto, None)
    out = folder / "run.h5"
    o = runner.execute(plan, rig, out, seed=3, progress=progress)
    assert o.status == "aborted"
    return proto, out


@pytest.fixture
def aborted(aborted_once: tuple[Path, Path], tmp_path: Path) -> tuple[Path, Path]:
    """A copy of :func:`aborted_once`'s protocol and run file in ``tmp_path``, the test's own."""
    proto, out = copied(tmp_path, *aborted_once)
    return proto, out


def damage(path: Path) -> None:
    """16 bytes flipped among the first entry's first strain samples (a bad sector). (Bytes of
    a chunk past the dataset's end, the unused part of its last chunk, are not samples: HDF5's
    checksum does not report them, and nothing reads them.)"""
    with h5py.File(path, "r") as f:
        info = f["sine_50V_5Hz/data/strain"].id.get_chunk_info(0)
    with open(path, "r+b") as fh:
        fh.seek(info.byte_offset + 64)
        raw = bytearray(fh.read(16))
        fh.seek(info.byte_offset + 64)
        fh.write(bytes(b ^ 0xFF for b in raw))


def test_a_damaged_file_is_refused_before_the_rig_is_opened(aborted):
    proto, out = aborted
    damage(out)
    before = digest(out)
    opened = []

    def opener(*args):
        opened.append(args)
        raise AssertionError("the rig was opened for a damaged file")

    plan, rig = runner.preflight(proto, None)
    with pytest.raises(InputFileError) as e:
        runner.execute(plan, rig, None, seed=4, resume=out, opener=opener)
    assert "cannot be resumed, the file is damaged" in str(e.value)
    assert "checksum mismatch" in str(e.value) and "sine_50V_5Hz" in str(e.value)
    assert opened == [] and digest(out) == before


def test_the_command_says_so_and_opens_nothing(aborted, monkeypatch):
    proto, out = aborted
    damage(out)
    before = digest(out)
    opened = []

    def opener(*args, **kwargs):
        opened.append(args)
        raise AssertionError("the rig was opened for a damaged file")

    monkeypatch.setattr(runner, "open_rig", opener)  # the existing test seam
    res = invoke("run", proto, "--resume", out)
    assert res.exit_code == 2, res.output
    assert res.stderr.startswith("error: ") and "Traceback" not in res.output
    assert "--resume" in res.stderr and "checksum mismatch" in res.stderr
    assert opened == [] and digest(out) == before
    assert not list(out.parent.glob(".run.h5.*.partial"))


def test_a_sound_file_is_still_resumed(aborted):
    proto, out = aborted
    plan, rig = runner.preflight(proto, None)
    o = runner.execute(plan, rig, None, seed=4, resume=out)
    assert (o.status, o.entries) == ("complete", ["sine_80V_5Hz"])


def test_the_command_resumes_a_sound_file(aborted):
    """``labrig run --resume FILE`` on a sound file finishes it in place. The command hands the
    runner the checked resume (a ``ResumePlan``), which the runner once took for the output
    path: a TypeError traceback after the check (found by the type check, tests/test_types.py)."""
    proto, out = aborted
    res = invoke("run", proto, "--resume", out)
    assert res.exit_code == 0, res.output
    assert "Traceback" not in res.output
    after = read_run(out)
    assert after.status == "complete"
    assert [e.name for e in after if e.status == "complete"][-1] == "sine_80V_5Hz"
