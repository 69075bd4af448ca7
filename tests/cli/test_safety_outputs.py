"""No command destroys a file without ``--overwrite``, none destroys the old file before the new
one is complete, and no output may be an input (labrig.core.outputs).

fit --out, report --out, diagnose --out DIR, export --csv DIR and run --overwrite: an input as
the output is refused whatever the flags (the input unchanged, byte for byte); an existing output
is refused without --overwrite (exit 2 naming it and --overwrite) and replaced with it; an
unwritable place is found before the computation (the computation is never called); the old
run file of ``run --overwrite`` stays whole while the new run is recorded, and after a SIGKILL.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from labrig.core.errors import InputFileError
from labrig.core.outputs import check_outputs, stage, staged_outputs

from helpers import TINY, invoke

SLOW = """\
name: slow
rate_hz: 200
steps:
  - kind: sine
    amplitude_V: 40
    frequency_hz: 1
    cycles: 6
"""
EXE = Path(sys.executable).parent / "labrig"


def refused(res, *words: str) -> str:
    assert res.exit_code == 2, res.output
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.stderr.startswith("error: ") and "Traceback" not in res.output, res.output
    for w in words:
        assert w in res.stderr, (w, res.stderr)
    return res.stderr


def partials(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if ".partial" in p.name]


@pytest.fixture
def run_copy(tiny_run: Path, tmp_path: Path) -> Path:
    p = tmp_path / "run.h5"
    p.write_bytes(tiny_run.read_bytes())
    return p


@pytest.mark.parametrize(
    "args",
    [
        ["fit", "{run}", "--no-heldout", "--out", "{run}"],
        ["fit", "{run}", "--no-heldout", "--out", "{run}", "--overwrite"],
        ["report", "{run}", "--no-heldout", "--out", "{run}"],
        ["report", "{run}", "--no-heldout", "--out", "{run}", "--overwrite"],
        ["report", "{run}", "--params", "{params}", "--out", "{params}", "--overwrite"],
        ["diagnose", "{run}", "--params", "{params}", "--out", "{dir}", "--overwrite"],
        ["export", "{run}", "--csv", "{run}"],
    ],
)
def test_an_input_is_never_an_output(run_copy: Path, tmp_path: Path, args: list[str]):
    params = tmp_path / "diagnosis.json"
    params.write_text('{"params": {}}\n')
    subs = {"run": run_copy, "params": params, "dir": tmp_path}
    before = run_copy.read_bytes(), params.read_bytes()
    res = invoke(*[a.format(**subs) for a in args])
    refused(res)
    assert ("is an input of this command" in res.stderr) or ("not a directory" in res.stderr)
    assert (run_copy.read_bytes(), params.read_bytes()) == before
    assert partials(tmp_path) == []


def test_fit_and_report_refuse_an_existing_out_and_replace_it_with_overwrite(
    run_copy: Path, tmp_path: Path
):
    for command, name in (("fit", "p.json"), ("report", "r.html")):
        out = tmp_path / name
        out.write_text("precious\n")
        res = invoke(command, run_copy, "--no-heldout", "--out", out)
        refused(res, str(out), "--overwrite")
        assert out.read_text() == "precious\n"
        res = invoke(command, run_copy, "--no-heldout", "--out", out, "--overwrite")
        assert res.exit_code == 0, res.output
        assert out.read_text() != "precious\n"
    assert json.loads((tmp_path / "p.json").read_text())["method"] == "global"
    assert partials(tmp_path) == []


@pytest.mark.parametrize(
    ("command", "target", "extra"),
    [
        ("fit", "labrig.commands.fit.fit_run_file", ["--out", "{blocker}/p.json"]),
        ("report", "labrig.commands.report.build_run_report", ["--out", "{blocker}/r.html"]),
        ("diagnose", "labrig.commands.prepare.prepare_diagnosis", ["--out", "{blocker}/d"]),
        ("fit", "labrig.commands.fit.fit_run_file", ["--out", "{tmp}"]),
    ],
)
def test_an_unwritable_out_is_found_before_the_computation(
    run_copy: Path, tmp_path: Path, monkeypatch, command: str, target: str, extra: list[str]
):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    module, name = target.rsplit(".", 1)
    called = []
    monkeypatch.setattr(sys.modules[module], name, lambda *a, **k: called.append(1))
    res = invoke(command, run_copy, *[e.format(blocker=blocker, tmp=tmp_path) for e in extra])
    refused(res, "--out")
    said = ("cannot write there", "is a directory", "a_file: [--out] is a file; give a folder")
    assert any(s in res.stderr for s in said), res.stderr
    assert called == [], "the computation ran before --out was checked"
    assert blocker.read_text() == "x" and partials(tmp_path) == []


def test_diagnose_refuses_existing_outputs_before_the_computation(
    run_copy: Path, tmp_path: Path, monkeypatch
):
    import labrig.commands.prepare as prepare

    called = []
    monkeypatch.setattr(prepare, "prepare_diagnosis", lambda *a, **k: called.append(1))
    out = tmp_path / "d"
    out.mkdir()
    (out / "diagnosis.html").write_text("precious")
    res = invoke("diagnose", run_copy, "--out", out)
    refused(res, str(out / "diagnosis.html"), "--overwrite")
    assert called == [] and (out / "diagnosis.html").read_text() == "precious"


def test_export_refuses_existing_csvs_keeps_other_files_and_replaces_with_overwrite(
    run_copy: Path, tmp_path: Path
):
    out = tmp_path / "csv"
    res = invoke("export", run_copy, "--csv", out)
    assert res.exit_code == 0, res.output
    written = sorted(out.iterdir())
    assert [p.name for p in written] == [
        "sine_100V_2Hz.csv",
        "sine_60V_2Hz.csv",
        "sine_80V_2Hz.csv",
    ]
    (out / "sine_60V_2Hz.csv").write_text("another run's export\n")
    (out / "other_run_entry.csv").write_text("keep me\n")
    res = invoke("export", run_copy, "--csv", out)
    text = refused(res, "--overwrite", "sine_60V_2Hz.csv", "sine_80V_2Hz.csv")
    assert "other_run_entry" not in text
    assert (out / "sine_60V_2Hz.csv").read_text() == "another run's export\n"
    res = invoke("export", run_copy, "--csv", out, "--overwrite")
    assert res.exit_code == 0, res.output
    assert (out / "sine_60V_2Hz.csv").read_text().startswith("time_s,")
    assert (out / "other_run_entry.csv").read_text() == "keep me\n"
    assert partials(tmp_path) == []


def test_export_into_a_file_is_refused(run_copy: Path, tmp_path: Path):
    f = tmp_path / "notes.txt"
    f.write_text("notes")
    refused(invoke("export", run_copy, "--csv", f), "not a directory")
    assert f.read_text() == "notes"


# -- labrig run --overwrite ------------------------------------------------------------------


@pytest.mark.skipif(not EXE.exists(), reason="needs the labrig entry point")
def test_run_overwrite_keeps_the_old_file_until_the_new_one_is_complete(
    tiny_run: Path, tmp_path: Path
):
    proto = tmp_path / "slow.yaml"
    proto.write_text(SLOW)
    out = tmp_path / "run.h5"
    old = tiny_run.read_bytes()
    out.write_bytes(old)
    args = [str(EXE), "run", str(proto), "--out", str(out), "--overwrite", "--realtime"]
    # killed while recording: the old file whole, the new one beside it
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 30
        while not list(tmp_path.glob(".run.h5.*.partial/run.h5")):
            assert time.monotonic() < deadline, "the new run file never appeared beside"
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.05)
        time.sleep(1.0)
        assert out.read_bytes() == old
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert out.read_bytes() == old
    assert len(list(tmp_path.glob(".run.h5.*.partial/run.h5"))) == 1  # what was recorded
    # to the end: replaced, nothing left beside (in-process: the same command, not paced to
    # the clock; the process and its SIGKILL were the part above)
    for p in tmp_path.glob(".run.h5.*.partial"):
        for q in p.iterdir():
            q.unlink()
        p.rmdir()
    res = invoke("run", proto, "--out", out, "--overwrite")
    assert res.exit_code == 0, res.output
    assert out.read_bytes() != old and partials(tmp_path) == []
    info = invoke("info", out)
    assert info.exit_code == 0 and "protocol: slow" in info.stdout


def test_run_without_overwrite_refuses_an_existing_file(tiny_run: Path, tmp_path: Path):
    proto = tmp_path / "small.yaml"
    proto.write_text(TINY)
    out = tmp_path / "run.h5"
    out.write_bytes(b"precious")
    refused(invoke("run", proto, "--out", out), "--overwrite")
    assert out.read_bytes() == b"precious"


# -- the helper ------------------------------------------------------------------------------


def test_staging_never_clobbers_a_file_that_appeared_meanwhile(tmp_path: Path):
    target = tmp_path / "new" / "deeper" / "out.json"
    with (
        pytest.raises(InputFileError, match="appeared while the command ran"),
        staged_outputs([target]) as st,
    ):
        st.write_text(target, "mine")
        target.write_text("someone else's")
    assert target.read_text() == "someone else's"
    assert partials(tmp_path) == []


def test_a_failed_command_leaves_nothing_behind(tmp_path: Path):
    target = tmp_path / "new" / "deeper" / "out.json"
    with pytest.raises(RuntimeError), staged_outputs([target]) as st:
        st.write_text(target, "half")
        raise RuntimeError("the computation failed")
    assert not (tmp_path / "new").exists()  # the folders made for it are gone too


def test_check_outputs_lists_existing_files_and_refuses_inputs(tmp_path: Path):
    files = [tmp_path / f"e{k}.csv" for k in range(8)]
    for f in files:
        f.write_text("x")
    with pytest.raises(InputFileError) as e:
        check_outputs(files, option="--csv")
    assert "and 3 more" in str(e.value) and "--overwrite" in str(e.value)
    check_outputs(files, overwrite=True)
    link = tmp_path / "link.csv"
    link.hardlink_to(files[0])
    with pytest.raises(InputFileError, match="is an input"):
        check_outputs([link], inputs=[files[0]], overwrite=True)
    st = stage([tmp_path / "x.json"])
    assert st.path(tmp_path / "x.json").parent.name.startswith(".x.json.")
    st.discard()
    assert partials(tmp_path) == []
