"""Property-based tests of the CSV and MATLAB importers (hypothesis): any bytes, any table, any
damaged file ends in success or a clear error (InputFileError, exit 2), never another exception
or a hang; numbers written by a lab's software come back exactly. Bounded: a few seconds."""

from __future__ import annotations

import io
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.io import savemat

from labrig.core.errors import InputFileError
from labrig.importers import ImportOptions, check_options, read_entries

from helpers import children_cpu_s

DATA = Path(__file__).resolve().parents[1] / "data" / "import"
FAST = settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def read(path: Path, **options) -> list | None:
    """The entries, or None when refused with InputFileError (anything else fails the test).
    Bounded: 10 s of CPU, this process's and the isolated reader's (a reader spinning in
    compiled code), and 60 s of wall clock (one waiting; half the reader's own limit): CPU,
    not the wall clock, for the tight bound, so that a loaded machine does not fail a sound
    reading."""
    t0, c0 = time.monotonic(), time.process_time() + children_cpu_s()
    try:
        return read_entries([path], check_options(ImportOptions(**options)))
    except InputFileError as e:
        assert str(e)  # a message for the user
        return None
    finally:
        assert time.process_time() + children_cpu_s() - c0 < 10
        assert time.monotonic() - t0 < 60


TOKENS = st.sampled_from(
    ["0", "1.5", "-2e3", "nan", "inf", "", ",", ";", "\t", " ", "\n", "\r\n", '"', "#", "x",
     "time_s", "voltage_V", "[um]", "1,5", "\ufeff", "°C", "\x00", "1e999", "--", "%"]
)  # fmt: skip


@FAST
@given(data=st.binary(max_size=600))
def test_arbitrary_bytes_as_csv(tmp_path: Path, data: bytes) -> None:
    f = tmp_path / "fuzz.csv"
    f.write_bytes(data)
    read(f, voltage="1", strain="2", rate_hz=10.0)


@FAST
@given(
    parts=st.lists(TOKENS, max_size=120), encoding=st.sampled_from(["utf-8", "utf-16", "cp1252"])
)
def test_arbitrary_text_tables(tmp_path: Path, parts: list[str], encoding: str) -> None:
    f = tmp_path / "fuzz.csv"
    f.write_bytes("".join(parts).encode(encoding, errors="replace"))
    read(f, voltage="1", strain="2", rate_hz=10.0)
    read(f)  # every role found by name, or a clear error


FINITE = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e300, max_value=1e300)


NUMBER_TABLES = {
    "values": st.lists(st.lists(FINITE, min_size=3, max_size=3), min_size=2, max_size=30),
    "style": st.sampled_from(
        [(",", "."), (";", "."), (";", ","), ("\t", "."), ("\t", ","), (" ", ".")]
    ),
    "header": st.booleans(),
    "index": st.booleans(),
}


def _numbers_round_trip(tmp_path: Path, values, style, header: bool, index: bool) -> None:
    sep, decimal = style
    table = np.asarray(values)
    lead = sep if index and sep != " " else ""
    lines = ["c1" + sep + "c2" + sep + "c3"] if header and not index else []
    for row in table:
        cells = [repr(float(x)).replace(".", decimal) for x in row]
        lines.append(lead + sep.join(cells))
    f = tmp_path / "table.csv"
    f.write_text("\n".join(lines) + "\n")
    k = 1 if lead else 0
    columns = {"voltage": str(k + 2), "strain": str(k + 3), "strain_units": "ue"}
    (entry,) = read(f, rate_hz=100.0, **columns) or [None]
    assert entry is not None
    np.testing.assert_array_equal(entry.voltage_V, table[:, 1])
    np.testing.assert_array_equal(entry.strain, table[:, 2])


@settings(FAST, max_examples=15)
@given(**NUMBER_TABLES)
def test_numbers_round_trip(tmp_path: Path, values, style, header: bool, index: bool) -> None:
    _numbers_round_trip(tmp_path, values, style, header, index)


@pytest.mark.slow
@settings(FAST, max_examples=200)
@given(**NUMBER_TABLES)
def test_numbers_round_trip_200(tmp_path: Path, values, style, header: bool, index: bool):
    """The round trip on 200 tables.

    Fast equivalent in the default tier: tests/importers/test_import_fuzz.py::test_numbers_round_trip
    """  # noqa: E501
    _numbers_round_trip(tmp_path, values, style, header, index)


#: the MATLAB cases read each input through the isolated reader (a forked process per read):
#: 10 inputs each in the default tier, and the same properties on 200 in the slow tier
MAT = settings(FAST, max_examples=10)
MAT_LONG = settings(FAST, max_examples=200)


def mat_cases(case, **strategies):
    """``case`` on :data:`MAT` inputs, and its slow-tier twin on :data:`MAT_LONG`."""
    return MAT(given(**strategies)(case)), pytest.mark.slow(MAT_LONG(given(**strategies)(case)))


def _bytes_as_mat(tmp_path: Path, data: bytes) -> None:
    f = tmp_path / "fuzz.mat"
    f.write_bytes(b"MATLAB 5.0 MAT-file".ljust(116) + b"\x00" * 8 + b"\x00\x01IM" + data)
    read(f, voltage="1", strain="2", rate_hz=10.0)


test_arbitrary_bytes_as_mat, test_arbitrary_bytes_as_mat_200 = mat_cases(
    _bytes_as_mat, data=st.binary(max_size=400)
)


def _damaged_mat(tmp_path: Path, source: str, flips) -> None:
    raw = bytearray((DATA / source).read_bytes())
    for where, mask in flips:
        raw[where % len(raw)] ^= mask
    f = tmp_path / source
    f.write_bytes(bytes(raw))
    read(f, rate_hz=200.0, voltage="1", strain="2", stack_length_mm=18.0)


test_damaged_mat_files, test_damaged_mat_files_200 = mat_cases(
    _damaged_mat,
    source=st.sampled_from(["plain_v5.mat", "plain_v73.mat", "controldesk.mat", "rows_v5.mat"]),
    flips=st.lists(st.tuples(st.integers(0, 10**6), st.integers(1, 255)), min_size=1, max_size=8),
)

SHAPES = st.sampled_from([(1, 20), (20, 1), (20,), (3, 20), (20, 3), (4, 4), (2, 3, 4), (0, 0)])


def _mat_variables(tmp_path: Path, variables: dict, seed: int) -> None:
    rng = np.random.default_rng(seed)
    arrays = {name: rng.normal(size=shape) for name, shape in variables.items()}
    buffer = io.BytesIO()
    savemat(buffer, arrays)
    f = tmp_path / "vars.mat"
    f.write_bytes(buffer.getvalue())
    entries = read(f, voltage="1", strain="2", rate_hz=50.0)
    if entries:
        (entry,) = entries
        assert entry.voltage_V.size == entry.strain.size >= 2
        signals = [a.ravel() if min(a.shape, default=0) <= 1 else a for a in arrays.values()]
        assert any(np.array_equal(entry.voltage_V, s) for s in _all_signals(signals))


test_arbitrary_mat_variables, test_arbitrary_mat_variables_200 = mat_cases(
    _mat_variables,
    variables=st.dictionaries(
        st.from_regex(r"[a-z][a-z0-9_]{0,8}", fullmatch=True), SHAPES, min_size=1, max_size=5
    ),
    seed=st.integers(0, 2**32 - 1),
)


def _all_signals(arrays: list[np.ndarray]) -> list[np.ndarray]:
    out = []
    for a in arrays:
        if a.ndim == 1:
            out.append(a)
        elif a.ndim == 2:
            out += list(a if a.shape[0] < a.shape[1] else a.T)
    return out


@pytest.mark.parametrize("name", ["header.csv", "plain_v5.mat"])
def test_fuzz_harness_sees_a_real_file(name: str) -> None:
    # the harness itself: a good file gives entries (so "None" above means refused, not broken)
    entries = read(DATA / name)
    assert entries and entries[0].voltage_V.size == 64
