"""negative_field_asymmetry's sentence says which way d33 moves at -V_ref: a fit with a < 0
(a gain, not a loss) must not read "-37 % lower"."""

from __future__ import annotations

import pytest

from labrig.model.effects import library


@pytest.mark.parametrize(("a", "way"), [(0.3, "lower"), (-0.5, "higher"), (1e-9, "lower")])
def test_the_sentence_names_the_direction(a, way):
    text = library()["negative_field_asymmetry"].describe({"a": a}, {"a": 0.01})
    assert f"% {way} at -" in text, text
    assert float(text.split("d33 ")[1].split("%")[0]) >= 0, text
