"""The shared Bouc-Wen closed form (labrig.model.bouc_wen) against independent integration."""

from __future__ import annotations

import numpy as np
import pytest

from labrig.model.bouc_wen import bouc_wen_exact, bouc_wen_step, bouc_wen_stream, max_slope


@pytest.mark.parametrize(
    ("A", "beta", "gamma"),
    [
        (1.5, 0.04, 0.013),
        (1.5, 0.04, -0.02),
        (-1.0, 0.04, 0.02),  # h moves against the input: saturates at A / (beta - gamma)
        (-1.0, 0.04, -0.03),
    ],
)
def test_bouc_wen_closed_form_matches_fine_integration(A, beta, gamma):
    v = np.concatenate(
        [np.linspace(0, 100, 201), np.linspace(100, 20, 161), np.linspace(20, 60, 81)]
    )
    # reference: explicit Euler on a 1000x finer grid
    vf = np.interp(np.linspace(0, v.size - 1, (v.size - 1) * 1000 + 1), np.arange(v.size), v)
    # (on Python floats: the same double arithmetic as on numpy scalars, several times faster)
    vl, x = vf.tolist(), 0.0
    hl = [0.0] * vf.size
    for k in range(1, vf.size):
        dv = vl[k] - vl[k - 1]
        x += A * dv - beta * abs(dv) * x - gamma * dv * abs(x)
        hl[k] = x
    hf = np.array(hl)
    ref = hf[::1000]
    tol = 2e-3 * np.max(np.abs(ref))
    h, _ = bouc_wen_stream(v, 0.0, 0.0, A, beta, gamma)
    assert np.max(np.abs(h - ref)) < tol
    exact = bouc_wen_exact(np.concatenate(([0.0], v)), A, beta, gamma)[1:]
    assert np.max(np.abs(exact - ref)) < tol
    if A < 0:  # against the input: falls on the way up
        assert ref[200] < -0.5 * abs(A) / (beta - gamma)
    # the steepest slope seen stays below max_slope
    dv = np.diff(vf)
    moving = dv != 0
    dh = np.diff(hf)[moving] / dv[moving]
    assert np.max(dh) <= max_slope(A, beta, gamma) + 1e-6


def test_three_forms_agree_and_a_unipolar_excursion_leaves_a_remanence():
    # vanishing unipolar sine, then rest at 0 V: forms must agree sample by sample
    t = np.arange(6000) / 1000.0
    env = np.clip(1.0 - t / 5.0, 0.0, None)
    v = 50.0 * env * (1.0 - np.cos(2 * np.pi * t))
    A, beta, gam = 1.5, 0.04, 0.013
    h_exact = bouc_wen_exact(np.concatenate(([0.0], v)), A, beta, gam)[1:]
    h_stream = np.concatenate(
        [bouc_wen_stream(v[:2500], 0.0, 0.0, A, beta, gam)[0],
         bouc_wen_stream(v[2500:], h_exact[2499], v[2499], A, beta, gam)[0]]
    )  # fmt: skip
    h_step, h = np.empty(v.size), 0.0
    for k in range(v.size):
        h = bouc_wen_step(h, v[k] - (v[k - 1] if k else 0.0), A, beta, gam)
        h_step[k] = h
    scale = A / (beta + gam)
    assert np.max(np.abs(h_exact - h_stream)) < 1e-9 * scale
    assert np.max(np.abs(h_exact - h_step)) < 1e-9 * scale
    # back at 0 V the state is not zero (the loop did not close) and stays put during the rest
    assert abs(h_exact[-1]) > 0.05 * A and np.ptp(h_exact[-900:]) == 0.0
