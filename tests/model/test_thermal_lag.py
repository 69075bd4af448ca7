"""``thermal_drift``'s thermal state without a temperature channel: the first-order lag of the
entries' loss power in closed form (:func:`labrig.model.effects.thermal_drift.lag_of_steps`)
against ``scipy.signal.lfilter`` of the same recursion, the independent reference."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from labrig.model.effects.thermal_drift import lag_of_steps


@pytest.mark.parametrize("tau_samples", [3.0, 300.0, 3e5])
def test_lag_of_piecewise_constant_power_equals_lfilter(tau_samples: float) -> None:
    """Runs of random lengths (1 to 5000 samples) and levels (zeros between, as during rests):
    equal to lfilter to 1e-12 of the input's scale, for a fast, a medium and a very slow lag."""
    rng = np.random.default_rng(7)
    lengths = rng.integers(1, 5000, 40)
    levels = np.where(rng.random(40) < 0.3, 0.0, rng.random(40))
    x = np.repeat(levels, lengths)
    a = float(np.exp(-1.0 / tau_samples))
    ref = signal.lfilter([0.0, 1.0 - a], [1.0, -a], x)
    np.testing.assert_allclose(lag_of_steps(x, a), ref, rtol=0, atol=1e-12)


def test_lag_of_any_input_equals_lfilter() -> None:
    """Every sample its own run (white noise): still the recursion, exactly; and the empty
    input."""
    x = np.random.default_rng(3).normal(size=2000)
    a = 0.97
    ref = signal.lfilter([0.0, 1.0 - a], [1.0, -a], x)
    np.testing.assert_allclose(lag_of_steps(x, a), ref, rtol=0, atol=1e-12)
    assert lag_of_steps(np.array([]), a).size == 0
