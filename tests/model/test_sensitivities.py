"""``Relaxor.filter_sensitivities``: ``(y, dy/d ln tau, dy/d lam)`` of the fast realisation.

Reference: central differences of ``filter(method="fast")`` (node positions do not move with
``tau`` or ``lam``, so the differences see the same bank structure), on the orders the fit uses
(``lam_t`` ~ 0.1-0.5, ``lam_d`` ~ 0.6-1.8, including the pole-corrected range near 1 and the
pole pair above it), both holds, a relaxor at rest at a non-zero voltage.
"""

from __future__ import annotations

import numpy as np
import pytest

from labrig.model import Relaxor

RATE = 1e3
REST = 20.0


def _drive(n: int = 20_000) -> np.ndarray:
    t = np.arange(n) / RATE
    return 50 * (1 - np.cos(2 * np.pi * 3 * t)) + 10 * np.sin(2 * np.pi * 17 * t) + REST


def _fd(tau: float, lam: float, v: np.ndarray, hold: str) -> tuple[np.ndarray, np.ndarray]:
    """4th-order central differences in ln tau and lam (steps 1e-3): truncation ~1e-12."""

    def f(t: float, lm: float) -> np.ndarray:
        return REST + Relaxor(t, lm).filter(v - REST, RATE, method="fast", hold=hold)

    h = 1e-3
    d_tau = (8 * (f(tau * np.exp(h), lam) - f(tau * np.exp(-h), lam))
             - (f(tau * np.exp(2 * h), lam) - f(tau * np.exp(-2 * h), lam))) / (12 * h)  # fmt: skip
    d_lam = (8 * (f(tau, lam + h) - f(tau, lam - h))
             - (f(tau, lam + 2 * h) - f(tau, lam - 2 * h))) / (12 * h)  # fmt: skip
    return d_tau, d_lam


CASES = [
    (15.5e-5, 0.15), (1.0, 0.1), (1e-3, 0.5),  # G_t-like
    (2e-3, 1.35), (1e-3, 0.6), (5e-3, 1.8), (1e-3, 0.9), (1e-3, 1.1), (1e-4, 1.2),  # G_d-like
]  # fmt: skip


@pytest.mark.parametrize("hold", ["zoh", "linear"])
@pytest.mark.parametrize(("tau", "lam"), CASES)
def test_matches_central_differences(tau: float, lam: float, hold: str) -> None:
    v = _drive()
    r = Relaxor(tau, lam)
    y, d_tau, d_lam = r.filter_sensitivities(v, RATE, hold, rest_V=REST)
    np.testing.assert_allclose(y, REST + r.filter(v - REST, RATE, "fast", hold), rtol=0, atol=1e-11)
    fd_tau, fd_lam = _fd(tau, lam, v, hold)
    for got, want in ((d_tau, fd_tau), (d_lam, fd_lam)):
        scale = np.max(np.abs(want))
        assert scale > 1e-3  # the parameter matters on this drive
        assert np.max(np.abs(got - want)) <= 1e-6 * scale


def test_rest_voltage_and_empty_record() -> None:
    r = Relaxor(2e-3, 1.35)
    v = _drive(3000)
    y, dt1, dl1 = r.filter_sensitivities(v, RATE, "linear", rest_V=REST)
    y2, dt2, dl2 = r.filter_sensitivities(v - REST, RATE, "linear")
    np.testing.assert_allclose(y - REST, y2, atol=1e-12)
    np.testing.assert_allclose(dt1, dt2, atol=1e-12)
    np.testing.assert_allclose(dl1, dl2, atol=1e-12)
    # a constant drive at the rest voltage moves nothing
    y, dt_, dl = r.filter_sensitivities(np.full(100, REST), RATE, "zoh", rest_V=REST)
    assert np.all(y == REST) and not np.any(dt_) and not np.any(dl)
    assert all(x.size == 0 for x in r.filter_sensitivities(np.zeros(0), RATE))
    with pytest.raises(ValueError):
        r.filter_sensitivities(np.ones((2, 2)), RATE)
