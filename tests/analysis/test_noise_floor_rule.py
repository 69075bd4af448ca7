"""The noise floor's two rules (labrig.analysis.noise_floor): the period-to-period rule for a
periodic residual holding at least ``MIN_PERIODS`` periods, the second-difference rule for any
other; each checked against its formula written out here, at the threshold and one sample
short of it, and on a residual that settles after its start, which inflated the period rule on
short entries (the parts of one imported record)."""

from __future__ import annotations

import numpy as np
import pytest

from labrig.analysis.noise_floor import HEAVY_TAIL_RATIO, MIN_PERIODS, residual_noise, resolution_of

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


# -- the second-difference rule on heavy-tailed residuals -----------------------------------------


def robust_rule(r: np.ndarray) -> float:
    """The second difference's normal-consistent MAD over sqrt 6 (scipy's, not the code's)."""
    from scipy.stats import median_abs_deviation

    d = r[2:] - 2 * r[1:-1] + r[:-2]
    return float(median_abs_deviation(d, scale="normal") / np.sqrt(6))


def step_errors(n: int, amplitude: float, every: int = 40, seed: int = 0) -> np.ndarray:
    """White noise of RMS 1 plus a model error at every ``every``-th sample: a decaying
    transient of ``amplitude`` over 4 samples (a step the model follows late)."""
    rng = np.random.default_rng(seed)
    r = rng.standard_normal(n)
    kernel = amplitude * np.array([1.0, 0.6, 0.3, 0.1])
    for k in range(every // 2, n - 4, every):
        r[k : k + 4] += kernel * (1 if (k // every) % 2 else -1)
    return r


def test_errors_at_steps_do_not_inflate_the_floor() -> None:
    """Transients at every 40th sample touch 15 % of the second differences: the RMS rule reads
    3x the noise, the robust spread 1.12x (the contaminated share widens it a little)."""
    r = step_errors(20_000, amplitude=25.0)
    assert second_difference_rule(r) > 2.5  # the RMS rule: model error read as noise
    assert residual_noise(r, None) == pytest.approx(1.0, rel=0.15)
    assert residual_noise(r, None) == pytest.approx(robust_rule(r), rel=1e-9)


def test_the_heavy_tail_ratio_just_inside_and_outside() -> None:
    assert HEAVY_TAIL_RATIO == 1.5

    def ratio(a: float) -> float:
        r = step_errors(20_000, a, seed=3)
        return second_difference_rule(r) / robust_rule(r)

    lo, hi = 0.0, 25.0  # the transient's amplitude where the ratio crosses 1.5
    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if ratio(mid) < 1.5 else (lo, mid)
    below, above = step_errors(20_000, lo * 0.999, seed=3), step_errors(20_000, hi * 1.001, seed=3)
    assert second_difference_rule(below) / robust_rule(below) < 1.5
    assert residual_noise(below, None) == pytest.approx(second_difference_rule(below), rel=1e-12)
    assert second_difference_rule(above) / robust_rule(above) > 1.5
    assert residual_noise(above, None) == pytest.approx(robust_rule(above), rel=1e-9)


def test_gaussian_noise_keeps_the_rms_rule() -> None:
    for seed in range(5):
        r = np.random.default_rng(seed).normal(0, 0.3, 2_000)
        assert residual_noise(r, None) == pytest.approx(second_difference_rule(r), rel=1e-12)


def test_a_quantised_sensor_keeps_its_quantisation_noise() -> None:
    """A slow signal read by a sensor of resolution q and a perfect model: the residual is the
    quantisation error (RMS about q / sqrt 12), its second difference mostly 0: the robust
    spread alone would call the floor 0; it is kept at q / sqrt 12."""
    q = 0.5
    t = np.linspace(0, 1, 20_000)
    true = 40 * np.sin(2 * np.pi * 1.3 * t) + 15 * t
    measured = np.round(true / q) * q
    res = measured - true
    assert resolution_of(measured) == pytest.approx(q, rel=1e-12)
    assert robust_rule(res) < 0.2 * q / np.sqrt(12)  # what the spread alone would say
    assert residual_noise(res, None, resolution_of(measured)) == pytest.approx(
        q / np.sqrt(12), rel=1e-12
    )
    assert residual_noise(res, None, q) == pytest.approx(float(np.std(res)), rel=0.15)


def test_resolution_of_constant_and_short_signals() -> None:
    assert resolution_of(np.full(10, 3.0)) == 0.0 and resolution_of(np.array([1.0])) == 0.0
    assert resolution_of(np.array([0.0, 0.25, 0.25, 1.0])) == 0.25
