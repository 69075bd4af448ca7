"""The noise floor's two rules (labrig.analysis.noise_floor): the period-to-period rule for a
periodic residual holding at least ``MIN_PERIODS`` periods, the second-difference rule for any
other; each checked against its formula written out here, at the threshold and one sample
short of it, and on a residual that settles after its start, which inflated the period rule on
short entries (the parts of one imported record)."""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.noise_floor import MIN_PERIODS, residual_noise

P = 100  # samples per period


def residual(n: int, sigma: float = 1.0, settle: float = 0.0, seed: int = 0) -> np.ndarray:
    """White noise, an error locked to the drive (it repeats every period) and a slow settling
    ``settle * (1 + k / P)^-0.5`` after the start."""
    k = np.arange(n)
    rng = np.random.default_rng(seed)
    locked = 5.0 * np.sin(2 * np.pi * k / P) + 2.0 * np.cos(6 * np.pi * k / P)
    return locked + settle * (1 + k / P) ** -0.5 + sigma * rng.standard_normal(n)


def period_rule(r: np.ndarray) -> float:
    x = r[r.size - r.size // 2 :]
    d = x[P:] - x[:-P]
    return float(np.sqrt(np.mean(d**2) / 2))


def second_difference_rule(r: np.ndarray) -> float:
    d = r[2:] - 2 * r[1:-1] + r[:-2]
    return float(np.sqrt(np.mean(d**2) / 6))


def test_the_threshold_is_four_periods() -> None:
    assert MIN_PERIODS == 4


@pytest.mark.parametrize(
    ("n", "rule"),
    [
        (4 * P, period_rule),
        (4 * P - 1, second_difference_rule),
        (9 * P + 37, period_rule),
        (2 * P, second_difference_rule),
    ],
)
def test_each_rule_where_it_applies(n: int, rule) -> None:
    r = residual(n)
    assert residual_noise(r, P) == pytest.approx(rule(r), rel=1e-12)


def test_a_short_entry_that_settles_after_its_start_gets_its_noise() -> None:
    """Three periods that settle by 30x the noise: the period rule over the last two periods
    reads the settling as noise (here over 2x sigma); the floor is the noise within 15 %."""
    r = residual(3 * P, sigma=1.0, settle=30.0, seed=4)
    x = r[-2 * P :]  # the period rule over the last two periods, as it was applied before
    assert np.sqrt(np.mean((x[P:] - x[:-P]) ** 2) / 2) > 2.0
    assert residual_noise(r, P) == pytest.approx(1.0, rel=0.15)


def test_a_long_entry_keeps_the_period_rule_that_cancels_a_locked_error() -> None:
    """Twenty periods: the locked error cancels period to period, the noise is found within
    5 % (the second-difference rule also sees the locked error's curvature)."""
    r = residual(20 * P, sigma=0.2, seed=5)
    assert residual_noise(r, P) == pytest.approx(0.2, rel=0.05)
