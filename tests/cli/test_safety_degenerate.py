"""Degenerate data is refused before any fit, not reported as a result (labrig.commands.prepare).

Run files written with the store's writer (three entries of a 2 Hz, 0-100 V sine at 1 kHz, the
strain 9 ue/V plus 1 ue of noise) with one defect each: 2-sample entries, all-zero voltage,
constant strain, one NaN strain sample, an absurd sample rate, a rest that is not a number, and
(edited in the file) a sample rate of 0, NaN or -5. ``fit``, ``report`` and ``diagnose`` end with
exit 2 naming the entry and what would be valid, before fitting (the fit is never called); the
same file without the defect fits. The minimums are checked at their boundaries.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest

from labrig.analysis.records import Record
from labrig.commands.prepare import (
    MAX_ABS_STRAIN_UE,
    MAX_ABS_VOLTAGE_V,
    MAX_REST_S,
    MIN_SAMPLES,
    MIN_VOLTAGE_SPAN_V,
    RATE_RANGE_HZ,
    check_records,
)
from labrig.core.errors import InputFileError
from labrig.store import RunWriter
from labrig.store.writer import seal_all

from helpers import invoke

N = 2000
RATE = 1000.0


def sine(n: int) -> np.ndarray:
    return 50.0 * (1 - np.cos(2 * np.pi * 2.0 * np.arange(n) / RATE))


def write(
    path: Path,
    n: int = N,
    rate: float = RATE,
    volt: Callable[[int], np.ndarray] | None = None,
    strain: Callable[[int], np.ndarray] | None = None,
    step: dict | None = None,
) -> Path:
    with RunWriter(path, "name: t\n", "", {}, 1, protocol_name="t") as w:
        for k in range(3):
            v = sine(n) if volt is None else volt(n)
            s = 9 * v + np.random.default_rng(k).normal(0, 1, n) if strain is None else strain(n)
            meta = {"kind": "sine", "frequency_hz": 2.0, "rest_after_s": 0.5, **(step or {})}
            e = w.begin_entry(f"e{k}", meta, rate, ["command_voltage", "strain"])
            e.append({"time": np.arange(n) / RATE, "command_voltage": v, "strain": s})
            e.finish("complete")
    return path


def one_nan(n: int) -> np.ndarray:
    s = 9 * sine(n) + np.random.default_rng(0).normal(0, 1, n)
    s[5] = np.nan
    return s


def rate_in_file(value: float) -> Callable[[Path], Path]:
    def make(path: Path) -> Path:
        write(path)
        with h5py.File(path, "r+") as f:
            del f["e1/sample_rate"]
            f["e1/sample_rate"] = value
            seal_all(f)
        return path

    return make


CASES: dict[str, tuple[Callable[[Path], Path], list[str]]] = {
    "two_samples": (lambda p: write(p, n=2), ["[e0/data]", f"at least {MIN_SAMPLES}"]),
    "zero_voltage": (
        lambda p: write(p, volt=np.zeros),
        ["[command_voltage]", "spans 0 V", f"at least {MIN_VOLTAGE_SPAN_V:g} V"],
    ),
    "constant_strain": (
        lambda p: write(p, strain=lambda n: np.full(n, 3.0)),
        ["[e0/data/strain]", "constant"],
    ),
    "one_nan_strain": (
        lambda p: write(p, strain=one_nan),
        ["[e0/data/strain]", "1 non-finite sample", "first at sample 5"],
    ),
    "absurd_rate": (lambda p: write(p, rate=1e-320), ["[e0/sample_rate]", "outside"]),
    "rest_not_a_number": (
        lambda p: write(p, step={"rest_after_s": "forever"}),
        ["[e0/step_definition]", "rest_after_s", f"0 to {MAX_REST_S:g}"],
    ),
    "rest_huge": (lambda p: write(p, step={"rest_after_s": 1e300}), ["rest_after_s"]),
    "rate_zero": (rate_in_file(0.0), ["[e1/sample_rate]", "positive sample rate"]),
    "rate_nan": (rate_in_file(float("nan")), ["[e1/sample_rate]", "found nan"]),
    "rate_negative": (rate_in_file(-5.0), ["[e1/sample_rate]", "found -5"]),
}


@pytest.fixture
def no_fitting(monkeypatch) -> list:
    """The fits and the diagnosis record a call instead of running."""
    import labrig.analysis.diagnose as diagnose
    import labrig.commands.fit as fit_run
    import labrig.commands.report as build

    called: list = []

    def record(name: str):
        def f(*args, **kwargs):
            called.append(name)
            raise AssertionError(f"{name} ran on degenerate data")

        return f

    monkeypatch.setattr(fit_run, "fit_model", record("fit_model"))
    monkeypatch.setattr(fit_run, "fit_baseline", record("fit_baseline"))
    monkeypatch.setattr(build, "fit_dynamic", record("fit_dynamic"))
    monkeypatch.setattr(diagnose, "diagnose", record("diagnose"))
    return called


@pytest.fixture(scope="module")
def degenerate_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Each case's file, made once for the three commands (on first use) and copied."""
    return {"": tmp_path_factory.mktemp("degenerate")}


def degenerate_file(made: dict[str, Path], case: str, where: Path) -> Path:
    if case not in made:
        folder = made[""] / case
        folder.mkdir()
        made[case] = CASES[case][0](folder / f"{case}.h5")
    return Path(shutil.copyfile(made[case], where / f"{case}.h5"))


@pytest.mark.parametrize("command", ["fit", "report", "diagnose"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_degenerate_data_is_refused_before_any_fit(
    tmp_path: Path, degenerate_files: dict[str, Path], no_fitting: list, case: str, command: str
):
    words = CASES[case][1]
    path = degenerate_file(degenerate_files, case, tmp_path)
    extra = {"report": ["--out", tmp_path / "r.html"], "fit": ["--no-heldout"]}.get(command, [])
    res = invoke(command, path, *extra)
    assert res.exit_code == 2, res.output
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.stderr.startswith(f"error: {path}:"), res.stderr
    for w in words:
        assert w in res.stderr, (w, res.stderr)
    assert "Traceback" not in res.output and "+- 0 (0 %)" not in res.output
    assert "inf times" not in res.output
    assert no_fitting == [] and not (tmp_path / "r.html").exists()


def test_the_same_file_without_a_defect_fits(tmp_path: Path):
    path = write(tmp_path / "good.h5")
    res = invoke("fit", path, "--no-heldout", "--json")
    assert res.exit_code == 0, res.output
    assert "alpha0_ue_per_V" in res.stdout


def record(n: int = 100, span: float = 100.0, rate: float = RATE, **meta) -> Record:
    v = span / 2 * (1 - np.cos(2 * np.pi * np.arange(n) / n))
    s = 9 * v + np.random.default_rng(1).normal(0, 1, n)
    return Record.from_arrays("e", rate, v, s, **{"rest_after_s": 0.0, **meta})


@pytest.mark.parametrize(
    ("ok", "bad"),
    [
        (record(n=MIN_SAMPLES), record(n=MIN_SAMPLES - 1)),
        (record(span=MIN_VOLTAGE_SPAN_V * 1.01), record(span=MIN_VOLTAGE_SPAN_V * 0.99)),
        (record(rate=RATE_RANGE_HZ[0]), record(rate=RATE_RANGE_HZ[0] * 0.99)),
        (record(rate=RATE_RANGE_HZ[1]), record(rate=RATE_RANGE_HZ[1] * 1.01)),
        (record(rest_after_s=MAX_REST_S), record(rest_after_s=MAX_REST_S * 1.01)),
        (record(rest_after_s=0), record(rest_after_s=-0.001)),
    ],
)
def test_the_minimums_at_their_boundaries(ok: Record, bad: Record):
    path = Path("run.h5")
    check_records(path, [ok], ["e"], alone=True)
    with pytest.raises(InputFileError):
        check_records(path, [bad], ["e"], alone=True)


def with_sample(channel: str, value: float) -> Record:
    """:func:`record` with one sample of ``channel`` set to ``value``."""
    r = record()
    getattr(r, channel)[40] = value
    return r


@pytest.mark.parametrize(
    ("channel", "bound", "field"),
    [
        ("voltage_V", MAX_ABS_VOLTAGE_V, "command_voltage"),
        ("strain_ue", MAX_ABS_STRAIN_UE, "strain"),
    ],
)
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_sample_beyond_the_magnitude_bound_is_refused_naming_it(channel, bound, field, sign):
    """An imported 1e300 made the fit divide by zero (a traceback) or print inf %; the bound
    just inside (accepted) and just outside (refused, naming the entry, the channel and the
    sample), and far outside."""
    path = Path("run.h5")
    check_records(path, [with_sample(channel, sign * bound)], ["e"], alone=True)
    for value in (sign * bound * (1 + 1e-9), sign * 1e300):
        with pytest.raises(InputFileError) as e:
            check_records(path, [with_sample(channel, value)], ["e"], alone=True)
        said = str(e.value)
        assert f"[e/data/{field}]" in said and "at sample 40" in said and "beyond" in said


def test_a_constant_voltage_entry_is_fine_in_a_chain_but_not_alone():
    hold = Record.from_arrays("hold", RATE, np.full(100, 50.0), 450 + np.arange(100) * 0.01)
    moving = record()
    moving.name = "sine"
    check_records(Path("r.h5"), [moving, hold], ["sine", "hold"], alone=False)
    with pytest.raises(InputFileError, match=r"\[hold/data/command_voltage\] the voltage spans 0"):
        check_records(Path("r.h5"), [moving, hold], ["sine", "hold"], alone=True)
    # history (not scored) needs finite voltage and time only
    hold.strain_ue[3] = np.nan
    check_records(Path("r.h5"), [moving, hold], ["sine"], alone=False)
    hold.voltage_V[3] = np.inf
    with pytest.raises(InputFileError, match="hold/data/command_voltage"):
        check_records(Path("r.h5"), [moving, hold], ["sine"], alone=False)
