"""An adversarial tester's second round on the analysis commands.

1. A strain that does not follow the voltage (a constant 12.50 ue with three 0.01 ue flickers
   under an 80 V drive; 12.5 ue of noise that ignores it) got an NRMSE "near the noise floor"
   from ``fit`` and ``report`` and "consistent with noise" from ``diagnose``. One check of
   :func:`labrig.commands.prepare.check_records` now refuses it for every command (exit 2,
   naming the file, the entry, the figure and the threshold): the share of the strain's
   variance a linear response to the voltage explains must be at least
   :data:`~labrig.commands.prepare.MIN_RESPONSE_SHARE`. Checked just inside and just outside
   with records whose share is known by construction, and on the real records of
   ``tests/data/real``.
2. Messages that did not name the field: a parameter file that is a JSON list (an empty field
   name), ``--leave-one-out`` with a copy of one file among the files (``[--on]``, an option
   not used), an integer of 300 digits in a parameter file (no field).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from labrig.analysis.records import Record
from labrig.core.errors import InputFileError
from labrig.model import PAPER_TABLE1

from helpers import DATA, SMART_CSV, invoke

RATE = 1000.0
REAL = DATA / "real" / "yan9a-micromanipulator"


def _csv(path: Path, v: np.ndarray, s: np.ndarray) -> Path:
    t = np.arange(v.size) / RATE
    rows = "\n".join(
        f"{a!r},{b!r},{c!r}" for a, b, c in zip(t.tolist(), v.tolist(), s.tolist(), strict=True)
    )
    path.write_text("time_s,voltage_V,strain_ue\n" + rows + "\n")
    return path


def _imported(csv: Path) -> Path:
    out = csv.with_suffix(".h5")
    res = invoke("import", csv, "--out", out)
    assert res.exit_code == 0, res.output
    return out


def _drive(n: int) -> np.ndarray:
    """80 V unipolar sine at 5 Hz (the tester's drive)."""
    return 40 * (1 - np.cos(2 * np.pi * 5 * np.arange(n) / RATE))


def _follows(n: int, seed: int) -> np.ndarray:
    """A strain that follows :func:`_drive`: 8.9 ue/V through a 5 ms lag, 2 ue of noise."""
    v = _drive(n)
    y = np.zeros(n)
    a = np.exp(-1 / (RATE * 0.005))
    for i in range(1, n):
        y[i] = a * y[i - 1] + (1 - a) * v[i]
    return 8.9 * y + np.random.default_rng(seed).normal(0, 2, n)


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The tester's two records that ignore the drive, two that follow it, a copy of one."""
    tmp = tmp_path_factory.mktemp("trials2")
    flicker = np.full(4001, 12.5)
    flicker[[500, 1700, 3100]] = 12.51
    noise = 12.5 + np.random.default_rng(5).normal(0, 0.01, 1001)
    out = {
        "flicker": _imported(_csv(tmp / "flicker.csv", _drive(4001), flicker)),
        "noiseflat": _imported(_csv(tmp / "noiseflat.csv", _drive(1001), noise)),
        "good1": _imported(_csv(tmp / "good1.csv", _drive(1001), _follows(1001, 1))),
        "good2": _imported(_csv(tmp / "good2.csv", _drive(1201), _follows(1201, 2))),
    }
    out["good1_copy"] = Path(shutil.copyfile(out["good1"], tmp / "good1_copy.h5"))
    return out


# -- 1. a strain that does not follow the voltage -------------------------------------------


@pytest.mark.parametrize("name", ["flicker", "noiseflat"])
@pytest.mark.parametrize("command", ["fit", "report", "diagnose", "validate"])
def test_a_strain_that_ignores_the_drive_is_refused_by_every_command(
    files: dict[str, Path], tmp_path: Path, name: str, command: str
) -> None:
    path = files[name]
    args = {
        "fit": ["fit", path, "--no-heldout"],
        "report": ["report", path, "--out", tmp_path / "r.html"],
        "diagnose": ["diagnose", path, "--json"],
        "validate": ["validate", files["good1"], files["good2"], "--on", path, "--json"],
    }[command]
    res = invoke(*args)
    assert res.exit_code == 2, res.output
    said = " ".join(res.stderr.split())
    assert said.startswith(f"error: {path}: [{name}/data/strain] the strain does not follow "), said
    assert "% of the strain's variance; at least 25 % is needed" in said
    assert "the voltage spans 80 V" in said and "--strain N" in said
    assert "Traceback" not in res.output and "NRMSE" not in res.output
    assert not (tmp_path / "r.html").exists()


def _record(share: float) -> Record:
    """A 10 Hz, 80 V drive over 4 s at 10 kHz whose strain is ``sqrt(share)`` of a unit
    response in phase with it plus ``sqrt(1 - share)`` of a unit vibration at 433.25 Hz that
    ignores it: over whole cycles the two are orthogonal, so the share of the strain's
    variance that follows the drive is ``share`` by construction."""
    k = np.arange(40_000)
    v = 40 * (1 - np.cos(2 * np.pi * 40 * k / k.size))
    follows = -np.cos(2 * np.pi * 40 * k / k.size)
    other = np.sin(2 * np.pi * 1733 * k / k.size)
    s = 10 + np.sqrt(share) * follows + np.sqrt(1 - share) * other
    return Record.from_arrays("e", 10_000.0, v, s, rest_after_s=0.0)


def test_the_threshold_just_inside_and_just_outside() -> None:
    from labrig.commands.prepare import MIN_RESPONSE_SHARE, check_records, response_share

    assert MIN_RESPONSE_SHARE == 0.25
    path = Path("run.h5")
    inside, outside = _record(0.255), _record(0.245)
    assert response_share(inside.voltage_V, inside.strain_ue) == pytest.approx(0.255, abs=1e-3)
    assert response_share(outside.voltage_V, outside.strain_ue) == pytest.approx(0.245, abs=1e-3)
    check_records(path, [inside], ["e"], alone=True)
    with pytest.raises(InputFileError) as e:
        check_records(path, [outside], ["e"], alone=True)
    (issue,) = e.value.issues
    assert issue.field == "e/data/strain"
    assert "explains 24.5 % of the strain's variance; at least 25 % is needed" in issue.message


def test_a_response_that_lags_its_drive_counts_in_full() -> None:
    """A strain in quadrature with its drive is uncorrelated with it at the same instant
    (R^2 0); it follows the drive all the same, a quarter period late."""
    from labrig.commands.prepare import check_records, response_share

    k = np.arange(4000)
    v = 40 * (1 - np.cos(2 * np.pi * 10 * k / k.size))
    s = 300 * np.sin(2 * np.pi * 10 * k / k.size)
    assert abs(np.corrcoef(v, s)[0, 1]) < 1e-9
    assert response_share(v, s) > 0.999
    check_records(Path("run.h5"), [Record.from_arrays("e", RATE, v, s)], ["e"], alone=True)


def test_real_records_pass_with_a_wide_margin(tmp_path: Path) -> None:
    """The micromanipulator files imported as their README says, the SmartHysteresis record as
    its PROVENANCE says (and cut in four for ``diagnose``): each entry 0.99 or more."""
    from labrig.analysis.split import split_entries
    from labrig.commands.prepare import prepare, prepare_diagnosis, response_share

    real, smart = tmp_path / "real.h5", tmp_path / "smart.h5"
    res = invoke(
        "import", REAL / "Model_Vi_Do.dat", REAL / "Test_Vi_Do_Di.dat", "--out", real,
        "--voltage", 1, "--strain", 5, "--rate-hz", 200, "--strain-units", "raw",
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    res = invoke(
        "import", SMART_CSV, "--time", 2, "--voltage", 4, "--strain", 3, "--strain-units",
        "raw", "--out", smart,
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    records = prepare(real).records + prepare(smart).records
    parts = split_entries(prepare(smart).records, 4)
    assert len(prepare_diagnosis(smart, say=lambda _: None).records) == 4
    for r in records + parts:
        assert response_share(r.voltage_V, r.strain_ue) >= 0.99, r.name


# -- 2. messages that name the field --------------------------------------------------------


def test_a_parameter_file_that_is_a_list_says_what_is_expected(
    files: dict[str, Path], tmp_path: Path
) -> None:
    from labrig.analysis.params_file import read_fit_output, start_params

    path = tmp_path / "p.json"
    path.write_text("[1, 2]")
    for read in (read_fit_output, lambda p: start_params(p, print)):
        with pytest.raises(InputFileError) as e:
            read(path)
        (issue,) = e.value.issues
        assert issue.file == str(path)
        assert issue.message.startswith("the file holds a list ([1, 2]), not an object; ")
        assert "expected the output of labrig fit --json" in issue.message
    res = invoke("diagnose", files["good1"], "--params", path)
    assert res.exit_code == 2, res.output
    assert res.stderr.startswith(f"error: {path}: the file holds a list ([1, 2]), not an object")
    assert ": :" not in res.stderr and "Input should be" not in res.stderr


def test_a_params_section_that_is_not_an_object_is_named(tmp_path: Path) -> None:
    from labrig.analysis.params_file import read_fit_output

    path = tmp_path / "p.json"
    path.write_text('{"params": [1], "method": "global"}')
    with pytest.raises(InputFileError) as e:
        read_fit_output(path)
    (issue,) = e.value.issues
    assert issue.field == "params"
    assert issue.message.startswith("a list ([1]), not an object; expected the model's parameters")


def test_leave_one_out_with_a_copy_names_both_files_and_the_option(
    files: dict[str, Path],
) -> None:
    """Before any fit, whichever fold would meet the pair first (it was the second fold's
    ``[--on]`` after the first fold's fits, with the copy last)."""
    good1, copy, good2 = files["good1"], files["good1_copy"], files["good2"]
    for order in ((good1, copy, good2), (good2, good1, copy)):
        res = invoke("validate", "--leave-one-out", *order, "--json")
        assert res.exit_code == 2, res.output
        said = " ".join(res.stderr.split())
        assert said.startswith(
            f"error: {copy}: [--leave-one-out] its record 'good1' holds the same samples as the "
            f"record 'good1' of {good1}: "
        ), said
        assert "--on" not in said and "fit" not in said and "Traceback" not in res.output


def test_an_integer_of_300_digits_is_named_by_its_field(
    files: dict[str, Path], tmp_path: Path
) -> None:
    from labrig.core.jsonsafe import JSONLimitError, loads_bounded

    path = tmp_path / "p.json"
    params = json.dumps(PAPER_TABLE1.model_dump()).replace('"vc_V": 65.0', '"vc_V": ' + "9" * 300)
    assert "9" * 300 in params
    path.write_text('{"params": ' + params + "}")
    for command in ("report", "diagnose"):
        extra = ["--out", tmp_path / "r.html"] if command == "report" else []
        res = invoke(command, files["good1"], "--params", path, *extra)
        assert res.exit_code == 2, res.output
        said = " ".join(res.stderr.split())
        assert said.startswith(
            f"error: {path}: [params.vc_V] an integer with 300 digits (at most 100 are read)"
        ), said
        assert "9" * 50 not in said
    with pytest.raises(JSONLimitError) as e:
        loads_bounded('{"effects": [{"params": {"tau_s": 1, "k": -' + "1" * 101 + "}}]}")
    assert e.value.where == "effects[0].params.k" and "101 digits" in str(e.value)


def test_lone_spikes_do_not_read_as_a_strain_that_ignores_its_drive() -> None:
    """A spike within the magnitude bound (1e6 ue in a 900 ue record) dominated the strain's
    variance, and the record read as a strain that does not follow its voltage. Up to 1 % of
    the samples (``OUTLIER_SHARE``) far from the median are left out of that judgement: 10
    spikes in 1 000 samples pass; 11 are part of the record and it is refused."""
    from labrig.commands.prepare import OUTLIER_SHARE, check_records

    n = 1000
    assert int(OUTLIER_SHARE * n) == 10
    v = 50.0 * (1 - np.cos(2 * np.pi * np.arange(n) / 200))
    rng = np.random.default_rng(4)
    for spikes, ok in ((10, True), (11, False)):
        s = 9.0 * v + rng.normal(0.0, 1.0, n)
        s[rng.choice(n, spikes, replace=False)] = 1e6
        rec = Record.from_arrays("e", 1000.0, v, s, rest_after_s=0.0)
        if ok:
            check_records(Path("run.h5"), [rec], ["e"], alone=True)
        else:
            with pytest.raises(InputFileError, match="does not follow the voltage"):
                check_records(Path("run.h5"), [rec], ["e"], alone=True)
