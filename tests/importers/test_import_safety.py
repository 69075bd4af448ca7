"""``labrig import`` never destroys or silently corrupts data (issue 16): an existing run file
survives every bad input byte for byte, core channels cannot be replaced by auxiliary ones,
absurd rates are refused with the valid range, and no MATLAB file can hang the command."""

from __future__ import annotations

import hashlib
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from scipy.io import savemat

from labrig.importers.isolated import ReaderError, call_isolated
from labrig.importers.limits import MAX_STRUCT_DEPTH
from labrig.store import read_run

from helpers import copied, slack
from helpers import invoke as run_cli

DATA = Path(__file__).resolve().parents[1] / "data" / "import"


def invoke(*args: object):
    return run_cli(*args, columns=None)


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def csv(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def precious_original(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run file imported once per module (the tests get copies of it)."""
    out = tmp_path_factory.mktemp("original") / "precious.h5"
    res = invoke("import", DATA / "header.csv", "--out", out)
    assert res.exit_code == 0, res.output
    out.chmod(0o444)
    return out


@pytest.fixture
def precious(tmp_path: Path, precious_original: Path) -> Path:
    """An existing run file of the test's own, byte for byte the module's imported one."""
    (out,) = copied(tmp_path, precious_original)
    return out


@pytest.mark.parametrize(
    ("inputs", "options", "needle", "code"),
    [
        (["nan_time.csv"], [], "nan_time.csv:3", 2),
        (["good.csv", "nan_time.csv"], [], "time is needed", 2),
        (["good.csv"], ["--aux", "1bad=1"], "not a channel name", 64),  # an option's value
        (["good.csv"], ["--rate-hz", "nan"], "--rate-hz", 64),
        (["good.csv"], ["--aux", "strain=2"], "core channel", 64),
        (["good.csv", "missing.csv"], [], "file not found", 2),
    ],
)
def test_bad_input_leaves_existing_run_file_untouched(
    tmp_path: Path, precious: Path, inputs: list[str], options: list[str], needle: str, code: int
) -> None:
    csv(tmp_path / "good.csv", "time_s,voltage_V,strain_ue\n0,1,2\n0.1,2,3\n0.2,3,4\n")
    csv(tmp_path / "nan_time.csv", "time_s,voltage_V,strain_ue\n0,1,2\nnan,2,3\n0.2,3,4\n")
    before = digest(precious)
    files = [tmp_path / f for f in inputs]
    res = invoke("import", *files, "--out", precious, "--overwrite", *options)
    assert res.exit_code == code, res.output
    assert needle in res.output and "Traceback" not in res.output
    assert digest(precious) == before
    assert sorted(p.name for p in tmp_path.iterdir() if "partial" in p.name) == []


def test_failed_write_leaves_existing_file_and_no_partial(
    tmp_path: Path, precious: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import labrig.importers.writer as writer

    def failing_write(path: Path, entries: list, description: dict) -> None:
        path.write_bytes(b"half a run file")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(writer, "write_entries", failing_write)
    before = digest(precious)
    res = invoke("import", DATA / "bom.csv", "--out", precious, "--overwrite")
    assert res.exit_code != 0
    assert digest(precious) == before
    assert [p.name for p in tmp_path.iterdir()] == ["precious.h5"]


def test_overwrite_replaces_whole_file_and_input_named_run(tmp_path: Path, precious: Path):
    res = invoke("import", DATA / "bom.csv", "--out", precious)
    assert res.exit_code == 2 and "--overwrite" in res.output
    run_csv = tmp_path / "run.csv"
    run_csv.write_bytes((DATA / "header.csv").read_bytes())
    res = invoke("import", run_csv, "--out", precious, "--overwrite")
    assert res.exit_code == 0, res.output
    run = read_run(precious)
    assert [e.name for e in run] == ["run_2"]  # the file's own /run group keeps its name
    assert run.status == "complete"
    assert h5py.File(precious).attrs["file_name"] == "precious.h5"
    res = invoke("import", precious, "--out", precious, "--overwrite")
    assert res.exit_code == 2 and "is an input" in res.output


def test_aux_never_replaces_core_channels(tmp_path: Path) -> None:
    f = csv(tmp_path / "a.csv", "time_s,time_ms,voltage_V,strain_ue,strain_raw\n"
            "0,0,1,2,5\n0.1,100,2,3,6\n0.2,200,3,4,7\n")  # fmt: skip
    out = tmp_path / "a.h5"
    res = invoke("import", f, "--out", out, "--aux", "strain_raw")
    assert res.exit_code == 0, res.output
    (e,) = list(read_run(out))
    np.testing.assert_array_equal(e["strain"], [2, 3, 4])
    np.testing.assert_array_equal(e["strain_raw"], [5, 6, 7])
    np.testing.assert_array_equal(e.time, [0, 0.1, 0.2])
    np.testing.assert_allclose(e["time_aux"], [0, 0.1, 0.2])  # ms -> s, under its own name
    assert e.units["strain"] == "ue" and e.units["time_aux"] == "s"
    # 64: the option alone is wrong; 2: it is wrong for this file
    cases = [("strain=1", "core channel", 64), ("time_ms", "--aux time_aux=time_ms", 2),
             ("voltage_V", "already the time, voltage or strain", 2)]  # fmt: skip
    for spec, needle, code in cases:
        res = invoke("import", f, "--out", tmp_path / "b.h5", "--aux", spec)
        assert res.exit_code == code and needle in res.output, res.output
        assert not (tmp_path / "b.h5").exists()


@pytest.mark.parametrize("rate", ["1e-320", "0", "-200", "nan", "inf", "-inf", "1e300"])
def test_absurd_rates_refused_with_range(tmp_path: Path, rate: str) -> None:
    res = invoke("import", DATA / "headerless_index.csv", "--out", tmp_path / "r.h5",
                 "--voltage", "3", "--strain", "4", "--rate-hz", rate)  # fmt: skip
    assert res.exit_code == 64, res.output  # a bad option value: a usage error
    assert "expected a sample rate from 0.001 to 1e+08 Hz" in res.output


def test_time_column_with_absurd_rate_refused(tmp_path: Path) -> None:
    f = csv(tmp_path / "fast.csv", "time_s,voltage_V,strain_ue\n0,1,2\n1e-300,2,3\n2e-300,3,4\n")
    res = invoke("import", f, "--out", tmp_path / "r.h5")
    assert res.exit_code == 2 and "expected 0.001 to 1e+08 Hz" in res.output


def _nested(depth: int) -> dict:
    node: dict = {"x": np.arange(3.0)}
    for _ in range(depth):
        node = {"inner": node}
    return node


def test_deeply_nested_mat_refused(tmp_path: Path) -> None:
    f = tmp_path / "deep.mat"
    savemat(f, {"s": _nested(MAX_STRUCT_DEPTH + 5)})
    res = invoke("import", f, "--out", tmp_path / "r.h5", "--rate-hz", "10")
    assert res.exit_code == 2, res.output
    assert f"nested more than {MAX_STRUCT_DEPTH} deep" in res.output and "deep.mat" in res.output


@pytest.mark.parametrize("cut", [600, 2000, 3000])
def test_truncated_or_zeroed_v73_is_exit_2_quickly(tmp_path: Path, cut: int) -> None:
    raw = (DATA / "plain_v73.mat").read_bytes()
    truncated = tmp_path / "cut.mat"
    truncated.write_bytes(raw[:cut])
    zeroed = tmp_path / "zeroed.mat"
    zeroed.write_bytes(raw[:cut] + b"\x00" * 512 + raw[cut + 512 :])
    for f in (truncated, zeroed):
        t0 = time.monotonic()
        res = invoke("import", f, "--out", tmp_path / "r.h5", "--time", "t")
        assert time.monotonic() - t0 < slack(10.0)
        assert res.exit_code == 2, res.output
        assert f.name in res.output and "Traceback" not in res.output


def _sleep(seconds: float) -> str:
    time.sleep(seconds)
    return "done"


def _crash() -> None:
    import os
    import signal

    os.kill(os.getpid(), signal.SIGSEGV)


def test_isolated_reader_times_out_and_reports_crashes() -> None:
    assert call_isolated(_sleep, 0.0, timeout_s=5) == "done"
    t0 = time.monotonic()
    with pytest.raises(ReaderError, match=r"longer than 0\.3 s"):
        call_isolated(_sleep, 30.0, timeout_s=0.3)
    assert time.monotonic() - t0 < slack(5.0)
    with pytest.raises(ReaderError, match="crashed"):
        call_isolated(_crash, timeout_s=5)
    with pytest.raises(ReaderError, match="boom"):
        call_isolated(_raise, timeout_s=5)


def _raise() -> None:
    raise ValueError("boom")


def test_list_writes_nothing(tmp_path: Path) -> None:
    res = invoke("import", DATA / "header.csv", "--list")
    assert res.exit_code == 0 and "temperature" in res.output
    res = invoke("import", DATA / "header.csv")
    assert res.exit_code == 64 and "--out" in res.output  # a missing option: a usage error


def test_a_file_that_appears_at_out_during_the_import_is_kept(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Another process creates ``--out`` while the import writes: without ``--overwrite`` its
    file survives and the import is refused (exit 2); with it, the import replaces it."""
    import labrig.importers.writer as writer

    out = tmp_path / "race.h5"
    real = writer.write_entries

    def write_then_race(path: Path, *args: object) -> None:
        real(path, *args)
        out.write_bytes(b"precious")  # appears after the output check, before the rename

    monkeypatch.setattr(writer, "write_entries", write_then_race)
    res = invoke("import", DATA / "header.csv", "--out", out)
    assert res.exit_code == 2, res.output
    assert "appeared while the command ran; kept" in res.output and "Traceback" not in res.output
    assert out.read_bytes() == b"precious"
    assert [p.name for p in tmp_path.iterdir()] == ["race.h5"]  # no partial folder left
    out.unlink()
    res = invoke("import", DATA / "header.csv", "--out", out, "--overwrite")
    assert res.exit_code == 0, res.output
    assert [e.name for e in read_run(out)] == ["header"]


def test_a_full_disk_during_the_import_names_what_is_left(
    tmp_path: Path, precious: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The partial file is removed, so the message names the target and what became of it,
    never the partial file."""
    import labrig.importers.writer as writer
    from labrig.core.errors import StorageError

    def full(path: Path, *args: object) -> None:
        path.write_bytes(b"half")
        raise StorageError(str(path), "write", "disk full: 1 kB free; the file keeps every block")

    monkeypatch.setattr(writer, "write_entries", full)
    before = digest(precious)
    res = invoke("import", DATA / "bom.csv", "--out", precious, "--overwrite")
    assert res.exit_code == 3, res.output
    text = " ".join(res.output.split())
    assert f"{precious} kept as it was" in text and ".partial" not in text
    assert digest(precious) == before
    res = invoke("import", DATA / "bom.csv", "--out", tmp_path / "new.h5")
    assert res.exit_code == 3 and "new.h5 not written" in " ".join(res.output.split())
    assert not (tmp_path / "new.h5").exists()
