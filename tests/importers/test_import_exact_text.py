"""``labrig import`` of text as it is written: time stamps since 1970 with sub-second digits
counted from their first value exactly (float64 keeps 1.7e9 s only to 2.4e-7 s, so a 10 kHz
record read as 10 010 Hz, or was refused as unevenly sampled), and quoted fields with decimal
commas read like unquoted ones. Every expected value is built from integers: the n-th sample
of a 10 kHz record is n / 10 000 s."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from labrig.store import read_run

from helpers import invoke

N = 2_000  # samples of each record
STEP_US = 100  # 10 kHz
UNIX_S = 1_764_480_000  # 2025-11-30 05:20 UTC, in s since 1970


def _signals(k: int) -> tuple[str, str]:
    """The voltage (V) and strain (ue) of sample ``k`` as text: whole hundredths."""
    return f"{50 + (k * 37) % 4000 / 100:.2f}", f"{(k * 53) % 9000 / 100:.2f}"


def _decimal(units: int, digits: int, sign: str = "") -> str:
    """``units * 10**-digits`` as fixed-point text, e.g. ``1764480000.000100``."""
    whole, frac = divmod(units, 10**digits)
    return f"{sign}{whole}.{frac:0{digits}d}"


def _exponent(units: int, exponent: int) -> str:
    """The digits of ``units`` with the point after the first, times 10**``exponent``, e.g.
    ``1.764480000000100e+09`` (1764480000.000100)."""
    digits = str(units)
    return f"{digits[0]}.{digits[1:]}e+{exponent:02d}"


def _us_in_s(k: int) -> str:
    return _decimal(UNIX_S * 10**6 + STEP_US * k, 6)


# (header unit of the time, the time text of sample k, the text of its first value as noted)
STAMPS: dict[str, tuple[str, Callable[[int], str], str]] = {
    "s with us digits": ("s", _us_in_s, "1764480000.000000"),
    "s with ns digits": (
        "s",
        lambda k: _decimal(UNIX_S * 10**9 + STEP_US * 1_000 * k, 9),
        "1764480000.000000000",
    ),
    "ms with us digits": (
        "ms",
        lambda k: _decimal(UNIX_S * 10**6 + STEP_US * k, 3),
        "1764480000000.000",
    ),
    "ms with ns digits": (
        "ms",
        lambda k: _decimal(UNIX_S * 10**9 + STEP_US * 1_000 * k, 6),
        "1764480000000.000000",
    ),
    # before 1970: -1764480000.000000, -1764479999.999900, ... (increasing)
    "negative": (
        "s",
        lambda k: _decimal(UNIX_S * 10**6 - STEP_US * k, 6, "-"),
        "-1764480000.000000",
    ),
    "exponent": ("s", lambda k: _exponent(UNIX_S * 10**6 + STEP_US * k, 9), "1764480000.000000"),
    "trailing zeros dropped": (
        "s",
        lambda k: _us_in_s(k).rstrip("0").rstrip("."),
        "1764480000",
    ),
}


def _write_csv(path: Path, unit: str, stamp: Callable[[int], str]) -> Path:
    lines = [f"time [{unit}],voltage [V],strain [ue]"]
    lines += [",".join((stamp(k), *_signals(k))) for k in range(N)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _imported(tmp_path: Path, source: Path):
    out = tmp_path / f"{source.stem}.h5"
    res = invoke("import", source, "--out", out)
    assert res.exit_code == 0, res.output
    (entry,) = list(read_run(out))
    return entry, " ".join(res.output.split())


def _assert_10_khz(entry) -> None:
    """Every time n / 10 000 s and the rate 10 000 Hz, each to 1e-12."""
    n = np.arange(N)
    assert entry.time[0] == 0.0
    np.testing.assert_allclose(entry.time[1:], n[1:] / 10_000, rtol=1e-12, atol=0)
    assert entry.rate_hz == pytest.approx(10_000.0, rel=1e-12)


@pytest.mark.parametrize("spelling", list(STAMPS))
def test_unix_time_stamps_with_sub_second_digits_keep_their_steps(
    tmp_path: Path, spelling: str
) -> None:
    unit, stamp, first = STAMPS[spelling]
    assert stamp(1) != stamp(0)  # the spelling holds the step
    entry, output = _imported(tmp_path, _write_csv(tmp_path / "unix.csv", unit, stamp))
    _assert_10_khz(entry)
    assert f"time: counted from its first value {first}" in output
    # the other columns read as they always were: the nearest float64 to their text
    texts = [_signals(k) for k in range(N)]
    np.testing.assert_array_equal(entry["command_voltage"], [float(v) for v, _ in texts])
    np.testing.assert_array_equal(entry["strain"], [float(s) for _, s in texts])


def test_quoted_decimal_comma_stamps_with_blank_and_comment_lines(tmp_path: Path) -> None:
    """A European spreadsheet's semicolon file: every field quoted, a space after each
    separator, decimal commas; blank and comment lines inside the data are skipped by both
    readings of the time column alike."""
    rows = [
        "; ".join(f'"{x.replace(".", ",")}"' for x in (_us_in_s(k), *_signals(k))) for k in range(N)
    ]
    rows[700:700] = ["", "# paused", ""]
    path = tmp_path / "messung.csv"
    path.write_text('"Zeit [s]"; "Spannung [V]"; "Dehnung [ue]"\n' + "\n".join(rows) + "\n")
    entry, output = _imported(tmp_path, path)
    _assert_10_khz(entry)
    assert "counted from its first value 1764480000.000000" in output
    np.testing.assert_array_equal(
        entry["command_voltage"], [float(_signals(k)[0]) for k in range(N)]
    )


def test_decimal_stamps_counted_exactly_only_past_2_20_steps_from_zero(tmp_path: Path) -> None:
    """The bound: a record starting 2**20 - 1 steps of 0.1 ms from zero (104.8575 s) is read as
    float64, as before; one starting 2**20 + 1 steps out (104.8577 s) is counted exactly."""
    for start, exact in ((2**20 - 1, False), (2**20 + 1, True)):
        texts = [_decimal(start + k, 4) for k in range(N)]
        path = _write_csv(tmp_path / f"start_{start}.csv", "s", lambda k, t=texts: t[k])
        entry, output = _imported(tmp_path, path)
        assert ("counted from its first value" in output) == exact, output
        if exact:
            _assert_10_khz(entry)
        else:  # the float64 of each stamp minus that of the first, as the import always read it
            as_read = np.array([float(t) for t in texts])
            np.testing.assert_array_equal(entry.time, as_read - as_read[0])


SPELLINGS = {
    "unquoted": "{t};{u};{s}",
    "quoted": '"{t}";"{u}";"{s}"',
    "quoted, a space after each separator": '"{t}"; "{u}"; "{s}"',
    "quoted, spaces around each separator": '"{t}" ; "{u}" ; "{s}"',
}


def _european(path: Path, spelling: str, bad_row: int | None = None) -> Path:
    """``t;U;S`` with decimal commas: t = k ms, U = k / 10 V, S = k / 4 ue."""
    header = SPELLINGS[spelling].format(t="t [s]", u="U [V]", s="S [ue]")
    rows = []
    for k in range(200):
        t, u, s = _decimal(k, 3), _decimal(k, 1), _decimal(25 * k, 2)
        if k == bad_row:
            u = "1.5x"
        rows.append(SPELLINGS[spelling].format(t=t, u=u, s=s).replace(".", ","))
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def test_quoted_decimal_comma_fields_read_like_unquoted_ones(tmp_path: Path) -> None:
    k = np.arange(200)
    read = {}
    for i, spelling in enumerate(SPELLINGS):
        entry, _ = _imported(tmp_path, _european(tmp_path / f"e{i}.csv", spelling))
        np.testing.assert_allclose(entry.time, k / 1000, rtol=1e-15, atol=1e-18)
        np.testing.assert_allclose(entry["command_voltage"], k / 10, rtol=1e-15)
        np.testing.assert_allclose(entry["strain"], k / 4, rtol=1e-15)
        assert entry.rate_hz == pytest.approx(1000.0, rel=1e-12)
        read[spelling] = (entry.time, entry["command_voltage"], entry["strain"])
    for spelling, channels in read.items():  # the same float64, bit for bit
        for got, unquoted in zip(channels, read["unquoted"], strict=True):
            np.testing.assert_array_equal(got, unquoted, err_msg=spelling)


def test_a_quoted_field_that_is_no_number_names_file_line_and_column(tmp_path: Path) -> None:
    for i, spelling in enumerate(SPELLINGS):
        path = _european(tmp_path / f"bad{i}.csv", spelling, bad_row=30)  # on line 32
        out = tmp_path / f"bad{i}.h5"
        res = invoke("import", path, "--out", out)
        text = " ".join(res.output.split())
        assert res.exit_code == 2, (spelling, text)
        assert "Traceback" not in text
        assert (
            f"bad{i}.csv:32: [column 2 (U)] '1,5x' is not a number "
            "(expected a number with a decimal comma)"
        ) in text, (spelling, text)
        assert not out.exists()
