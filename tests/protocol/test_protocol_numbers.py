"""Numbers in limit messages: a value over a limit reads as over it, huge values stay short,
recommendations are on the safe side (issue 16)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from labrig.core.errors import InputFileError
from labrig.core.numbers import amps, at_least, at_most, beyond, exact, fixed, fixed_down
from labrig.protocol.check import check_protocol

finite = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e300, max_value=1e300)


def issues_of(tmp_path: Path, steps: str, head: str = "") -> list:
    p = tmp_path / "p.yaml"
    p.write_text("name: t\nrate_hz: 1000\n" + head + "steps:\n" + steps)
    with pytest.raises(InputFileError) as e:
        check_protocol(p)
    return e.value.issues


@given(finite, finite)
def test_beyond_stays_on_its_side_of_the_limit(x, limit):
    s = beyond(x, limit)
    assert len(s) <= 24
    if x != limit:
        assert (float(s) > limit) == (x > limit) and float(s) != limit


@given(finite)
def test_recommendations_round_towards_the_safe_side(x):
    hi, lo = at_most(x), at_least(x)
    assert float(hi) <= x <= float(lo)
    assert len(hi) <= 24 and len(lo) <= 24
    assert float(exact(x)) == x


def test_short_forms():
    assert beyond(100.000001, 100.0) == "100.000001"
    assert beyond(-20.0000001, -20.0) == "-20.0000001"
    assert beyond(1e300, 100.0) == "1e+300"
    assert at_most(60.0) == "60" and at_most(17647.06) == "17600"
    assert at_least(0.0030612345) == "0.00307" and at_least(0.003061) == "0.003061"
    assert fixed(1e300, 1) == "1e+300" and fixed(56.17, 1) == "56.2"
    # rounded down, never past the value; a value a hair (1e-9 relative) below a round one is it
    assert fixed_down(56.17, 1) == "56.1" and fixed_down(56.1, 1) == "56.1"
    assert fixed_down(199.99999999997, 1) == "200.0" and fixed_down(199.9999, 1) == "199.9"
    assert fixed_down(-0.05, 1) == "-0.1" and fixed_down(1e300, 1) == "1e+300"
    assert amps(0.26, 0.18) == "0.26 A"
    assert amps(0.18000018, 0.18) == "0.1800002 A"  # tolerance is 1e-6 relative
    assert amps(1e300, 0.18) == "1e+300 A"


@pytest.mark.parametrize(
    ("voltage", "shown"), [("100.000001", "100.000001"), ("-20.0000001", "-20.0000001")]
)
def test_a_hold_just_over_the_limit_prints_over_it(tmp_path, voltage, shown):
    (issue,) = issues_of(tmp_path, f"  - {{kind: hold, voltage_V: {voltage}, duration_s: 1}}\n")
    assert f"reaches {shown} V; the rig allows -20 to 100 V" in issue.message


def test_huge_values_print_short(tmp_path):
    """Found while expanding (a total of 1e300 s) and in the preflight (1e300 V in a hold and
    a CSV file, 1e295 A): every message short, the numbers in exponent notation."""
    issues = issues_of(tmp_path, "  - {kind: ramp, to_V: 50, duration_s: 1, rest_s: 1.0e+300}\n"
                                 "  - {kind: hold, voltage_V: 50, duration_s: 1}\n")  # fmt: skip
    (tmp_path / "x.csv").write_text("0\n1e300\n0\n")
    issues += issues_of(
        tmp_path,
        "  - {kind: hold, voltage_V: 1.0e+300, duration_s: 1}\n  - {kind: csv, path: x.csv}\n",
        head="edge_slew_V_per_s: 1.0e+300\n",
    )
    assert len(issues) >= 5
    assert all(len(i.message) < 300 for i in issues), [i.message for i in issues]
    text = "\n".join(i.message for i in issues)
    assert "e+296 h" in text and "reaches 1e+300 V" in text and "e+295 A" in text
