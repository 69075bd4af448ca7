"""A full disk during a run, for real: a small tmpfs in a private mount namespace.

Each case runs a child process under ``unshare --user --map-root-user --mount`` (or, where user
namespaces are not allowed but we are root, ``unshare --mount``) that mounts a tmpfs of a few
MB, runs labrig there, fills the disk from outside labrig, and copies the run file out for the
checks here. The mount is private to the child and disappears with it.

- disk filled by another program during ``labrig run``: exit 3, a message naming the run file
  and the full disk, no traceback, the output ramped to 0 V, and the file (status ``failed``,
  every block before the full disk intact) readable by ``labrig info``;
- the same when HDF5 itself meets the full disk (labrig's free-space check bypassed, as when
  another program takes the space between the check and the write): no segfault, same file;
- a disk too small for the run from the start: exit 2 before anything is energised.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest

from labrig.runner.execute import preflight
from labrig.store import read_run

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[2]
SWEEP = ROOT / "experiments" / "sweep.yaml"
LABRIG = Path(sys.executable).parent / "labrig"


@pytest.fixture(scope="module")
def namespace() -> list[str]:
    """The unshare prefix that can mount a tmpfs here, or skip saying why not."""
    if shutil.which("unshare") is None:
        pytest.skip("no unshare(1) on this machine: cannot make a small filesystem")
    probe = Path("/tmp") / f"labrig-ns-probe-{os.getpid()}"
    probe.mkdir(exist_ok=True)
    tried = []
    try:
        for prefix in (["unshare", "--user", "--map-root-user", "--mount"], ["unshare", "--mount"]):
            cmd = [*prefix, "sh", "-c", f"mount -t tmpfs -o size=1m tmpfs {probe}"]
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=20)
            if res.returncode == 0:
                return prefix
            tried.append(f"{' '.join(prefix)}: {res.stderr.strip()}")
    finally:
        probe.rmdir()
    pytest.skip("cannot mount a tmpfs in a private mount namespace: " + "; ".join(tried))


# Runs inside the namespace: mount, run labrig, fill the disk from outside it, report.
FILL_DURING_RUN = textwrap.dedent(
    """
    import json, os, shutil, subprocess, sys, time
    mnt, out_dir, labrig, proto, size = sys.argv[1:6]
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", mnt], check=True)
    run = os.path.join(mnt, "run.h5")
    p = subprocess.Popen([labrig, "run", proto, "--realtime", "--out", run],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    while not os.path.exists(run) and p.poll() is None and time.monotonic() - t0 < 30:
        time.sleep(0.02)
    time.sleep(2.4)  # into the first entry (a 50 V, 1 Hz sine), near its peak
    fd = os.open(os.path.join(mnt, "filler"), os.O_WRONLY | os.O_CREAT)
    try:
        while True:
            os.write(fd, b"\\xa5" * 65536)
    except OSError as e:
        fill_errno = e.errno
    os.close(fd)
    out, err = p.communicate(timeout=60)
    info = subprocess.run([labrig, "info", run], capture_output=True, text=True, timeout=60)
    if os.path.exists(run):
        shutil.copy(run, os.path.join(out_dir, "run.h5"))
    print(json.dumps({"code": p.returncode, "stdout": out, "stderr": err,
                      "fill_errno": fill_errno, "info_code": info.returncode,
                      "info": info.stdout + info.stderr, "left": sorted(os.listdir(mnt))}))
    """
)

# Runs inside the namespace: the runner in-process with the free-space check bypassed, so the
# full disk is met by HDF5's own write; then `labrig info` (in this process too: labrig is loaded
# here already) and the process's own clean exit.
HDF5_MEETS_IT = textwrap.dedent(
    """
    import json, os, shutil, subprocess, sys, threading, time
    from pathlib import Path
    mnt, out_dir, labrig_exe, proto, size = sys.argv[1:6]
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", mnt], check=True)
    import labrig.store.writer
    labrig.store.writer.free_bytes = lambda path: 1 << 40  # the check sees room; HDF5 won't
    from labrig.runner.execute import execute, preflight
    plan, rig = preflight(Path(proto), None)
    run = Path(mnt) / "run.h5"

    def fill():
        while not run.exists():
            time.sleep(0.01)
        time.sleep(1.4)
        fd = os.open(os.path.join(mnt, "filler"), os.O_WRONLY | os.O_CREAT)
        try:
            while True:
                os.write(fd, b"\\xa5" * 65536)
        except OSError:
            pass
        os.close(fd)

    threading.Thread(target=fill, daemon=True).start()
    o = execute(plan, rig, run, seed=4, realtime=True)
    from typer.testing import CliRunner
    from labrig.cli import app
    info = CliRunner().invoke(app, ["info", str(run)])
    shutil.copy(run, os.path.join(out_dir, "run.h5"))
    print(json.dumps({"status": o.status, "code": o.exit_code, "reason": o.reason,
                      "info_code": info.exit_code, "info": info.output,
                      "left": sorted(os.listdir(mnt))}))
    """
)


def in_namespace(prefix: list[str], script: str, tmp_path: Path, size: str) -> dict:
    mnt, out = tmp_path / "mnt", tmp_path / "out"
    mnt.mkdir()
    out.mkdir()
    args = [str(mnt), str(out), str(LABRIG), str(SWEEP), size]
    res = subprocess.run(
        [*prefix, sys.executable, "-c", script, *args],
        capture_output=True,
        text=True,
        timeout=100,
        cwd=tmp_path,
        env={**os.environ, "COLUMNS": "250"},  # rich wraps messages at the terminal width
    )
    # the child itself must end normally: 139 here was the segfault of a disk-full run
    assert res.returncode == 0, (res.returncode, res.stderr[-3000:])
    report = json.loads(res.stdout.strip().splitlines()[-1])
    report["child_stderr"] = res.stderr
    report["file"] = out / "run.h5"
    return report


def check_file(path: Path, reason_words: list[str], min_start_V: float) -> None:
    """Failed, exit 3, ramped from the voltage it was at to 0 V, every block intact."""
    f = read_run(path)
    assert f.status == "failed" and f.exit_code == 3
    for w in reason_words:
        assert w in f.reason
    (entry,) = list(f)
    assert entry.status == "failed"
    plan, _ = preflight(SWEEP, None)
    n = entry.n_samples
    assert n >= 1000
    np.testing.assert_array_equal(entry["command_voltage"], plan.step(entry.name).samples(0, n))
    np.testing.assert_allclose(entry["time"], np.arange(n) / 1000.0, rtol=0, atol=1e-12)
    with h5py.File(path, "r") as h:
        assert float(h["run/final_amplifier_voltage_V"][()]) == 0.0
        ramp = h["run/ramp_to_zero"]
        assert ramp.attrs["path"] == "daq"
        # it was energised; the ramp starts where the sine was when the disk filled (any
        # phase: 0 V at a zero crossing)
        assert np.max(np.abs(entry["command_voltage"])) > min_start_V
        assert abs(float(ramp.attrs["start_voltage_V"])) <= np.max(np.abs(entry["command_voltage"]))
        assert ramp["voltage"][-1] == 0.0


def test_disk_filled_during_a_run(namespace, tmp_path):
    r = in_namespace(namespace, FILL_DURING_RUN, tmp_path, "6m")
    assert r["fill_errno"] == 28  # the filler really met a full disk (ENOSPC)
    assert r["code"] == 3, r["stderr"]
    err = " ".join(r["stderr"].split())  # rich wraps lines
    assert "Traceback" not in r["stderr"]
    assert "run failed" in err and "disk full" in err
    assert f"run file {tmp_path / 'mnt' / 'run.h5'}" in err  # the message names the file
    assert r["info_code"] == 0, r["info"]
    assert "failed" in r["info"] and "disk full" in " ".join(r["info"].split())
    assert r["left"] == ["filler", "run.h5"]  # the reserve file was given back
    check_file(r["file"], ["disk full", "run.h5"], min_start_V=10.0)


def test_disk_full_met_by_hdf5_itself(namespace, tmp_path):
    r = in_namespace(namespace, HDF5_MEETS_IT, tmp_path, "6m")
    assert (r["status"], r["code"]) == ("failed", 3), r["reason"]
    assert "disk full" in r["reason"]
    assert "Traceback" not in r["child_stderr"]
    assert r["info_code"] == 0, r["info"]
    # HDF5 meets the full disk when a block needs a new chunk (every 1024 samples, near the
    # 1 Hz sine's 0 V): a lower voltage, but a ramp all the same
    check_file(r["file"], ["disk full"], min_start_V=0.5)


def test_a_disk_too_small_for_the_run_is_refused_before_it_starts(namespace, tmp_path):
    script = textwrap.dedent(
        """
        import json, os, subprocess, sys
        mnt, out_dir, labrig, proto, size = sys.argv[1:6]
        subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", mnt], check=True)
        res = subprocess.run([labrig, "run", proto, "--out", os.path.join(mnt, "run.h5")],
                             capture_output=True, text=True, timeout=60)
        print(json.dumps({"code": res.returncode, "stderr": res.stderr,
                          "left": sorted(os.listdir(mnt))}))
        """
    )
    r = in_namespace(namespace, script, tmp_path, "2m")
    err = " ".join(r["stderr"].split())
    assert r["code"] == 2, err
    assert "not enough disk space" in err and "--out" in err and "run.h5" in err
    assert "Traceback" not in err
    assert r["left"] == []  # no run file, no reserve


def test_a_raw_hdf5_disk_full_anywhere_in_the_run_is_exit_3(tmp_path, monkeypatch):
    """HDF5's own error (a ``RuntimeError`` carrying ``errno = 28``) raised where the writer
    does not wrap it (here: creating the second entry, as when the disk fills between two
    entries) is still a full disk: exit 3 naming it, the output ramped to 0 V, the file
    readable. Without the classification the run ended with exit 1 ("internal error")."""
    from labrig.runner.execute import execute
    from labrig.store.writer import RunWriter

    proto = tmp_path / "p.yaml"
    proto.write_text(
        "name: two sines\nrate_hz: 500\nrest_s: 0.05\nsteps:\n"
        "  - {kind: sine, amplitude_V: 20, frequency_hz: 5, cycles: 2}\n"
        "  - {kind: sine, amplitude_V: 20, frequency_hz: 5, cycles: 2}\n"
    )
    real_begin = RunWriter.begin_entry
    calls = []

    def begin_entry(self, *a, **kw):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError(
                "Unable to flush file (file write failed: errno = 28, error message = "
                "'No space left on device')"
            )
        return real_begin(self, *a, **kw)

    monkeypatch.setattr(RunWriter, "begin_entry", begin_entry)
    plan, rig = preflight(proto, None)
    out = tmp_path / "run.h5"
    o = execute(plan, rig, out, seed=1)
    assert (o.status, o.exit_code) == ("failed", 3), o.reason
    assert "disk full" in o.reason and str(out) in o.reason
    f = read_run(out)
    assert f.status == "failed" and [e.status for e in f] == ["complete"]
    with h5py.File(out, "r") as h:
        assert float(h["run/final_amplifier_voltage_V"][()]) == 0.0


def test_an_error_that_is_not_a_full_disk_stays_exit_1(tmp_path, monkeypatch):
    """The other side of the rule: an unexpected error without errno 28 is not called a full
    disk."""
    from labrig.runner.execute import execute
    from labrig.store.writer import RunWriter

    proto = tmp_path / "p.yaml"
    proto.write_text(
        "name: one sine\nrate_hz: 500\nsteps:\n"
        "  - {kind: sine, amplitude_V: 20, frequency_hz: 5, cycles: 2}\n"
    )

    def begin_entry(self, *a, **kw):
        raise RuntimeError("Unable to flush file (file write failed: errno = 5, I/O error)")

    monkeypatch.setattr(RunWriter, "begin_entry", begin_entry)
    plan, rig = preflight(proto, None)
    o = execute(plan, rig, tmp_path / "run.h5", seed=1)
    assert (o.status, o.exit_code) == ("failed", 1), o.reason
    assert "disk full" not in o.reason
