"""The fleet page's axes: a log axis only where the values span a decade (on a narrower range
matplotlib labels every minor tick of a log axis, and in a quarter-width panel they overlap)."""

from __future__ import annotations

import numpy as np
import pytest

from labrig.fleet.fleet_report import spans_a_decade


@pytest.mark.parametrize(
    ("values", "log"),
    [
        ([1.0, 10.0], True),  # exactly a decade
        ([1.0, 9.999], False),  # just under
        ([2e-4, 3e-2], True),
        ([1.6e-3, 2.8e-3], False),  # the case that printed overlapping labels
        ([5.0, 5.0], False),  # one value (a fleet of one)
        ([0.0, 100.0], False),  # not all positive
        ([-1.0, 100.0], False),
        ([], False),
    ],
)
def test_log_axis_only_over_a_decade(values, log):
    assert spans_a_decade(np.array(values, dtype=float)) is log
