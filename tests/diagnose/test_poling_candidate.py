"""``negative_field_asymmetry`` is a default candidate of diagnose where the drive goes against
the poling (below -0.2 x the largest |V|), left out where it is identically null."""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.diagnose.procedure import (
    AGAINST_POLING_SHARE,
    candidate_names,
    drives_against_poling,
)
from labrig.analysis.records import Record
from labrig.model.effects import EFFECT_NAMES, library


def _rec(lo: float, hi: float) -> Record:
    t = np.arange(1000) / 1000.0
    v = lo + (hi - lo) * 0.5 * (1 - np.cos(2 * np.pi * 2 * t))
    return Record("r", 1000.0, t, v, v * 10.0)


@pytest.mark.parametrize(
    ("lo", "hi", "against"),
    [
        (0.0, 100.0, False),  # unipolar
        (-19.0, 100.0, False),  # just above -0.2 x 100 V
        (-21.0, 100.0, True),  # just below
        (-100.0, 73.0, True),  # biased, as the four-waveform captures
        (-150.0, 150.0, True),  # bipolar
    ],
)
def test_drives_against_poling_threshold(lo: float, hi: float, against: bool) -> None:
    assert AGAINST_POLING_SHARE == 0.2
    assert drives_against_poling([_rec(0.0, 50.0), _rec(lo, hi)]) is against


def test_default_candidate_only_against_the_poling() -> None:
    assert "negative_field_asymmetry" in EFFECT_NAMES
    lib = library()
    msgs: list[str] = []
    uni = candidate_names([_rec(0.0, 100.0)], lib, None, False, False, (), msgs)
    bi = candidate_names([_rec(-100.0, 73.0)], lib, None, False, False, (), msgs)
    assert "negative_field_asymmetry" not in uni and "negative_field_asymmetry" in bi
    assert set(bi) - set(uni) == {"negative_field_asymmetry"}
    assert not any("negative_field_asymmetry" in m for m in msgs)
    asked = candidate_names(
        [_rec(0.0, 100.0)], lib, None, False, False, ("negative_field_asymmetry",), msgs
    )
    assert "negative_field_asymmetry" in asked
    assert any("tried as asked" in m for m in msgs)
