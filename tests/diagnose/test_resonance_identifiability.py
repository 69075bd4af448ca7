"""What sampled records can tell of a mechanical resonance (``mechanical_resonance``).

References are independent of the code under test: the ringing's frequency is read off the FFT
of the sampled section's impulse response; the base relaxor's peak is found on a dense
frequency grid, its equivalent damping by root-finding on a second-order section's own peak
(also found on a grid). Planted records are simulated with the library's form on the paper's
model (``helpers.planted_records``, 0.5 ue of noise). Each test runs in well under 5 s.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize

from labrig.analysis.extended import ExtendedProblem, effect_context
from labrig.analysis.records import Record
from labrig.model import PAPER_TABLE1
from labrig.model.effects import library
from labrig.model.effects.mechanical_resonance import (
    RESOLVED_NYQUIST_SHARE,
    MechanicalResonance,
    aliased_hz,
    relaxor_resonance,
    resonance_filter,
)
from labrig.model.sections import run_section

from helpers import planted_records

RATE = 10_000.0
TRUTH = PAPER_TABLE1.model_dump()


def _ringing_hz(f_r: float, zeta: float, rate: float) -> float:
    """Where the ringing of the sampled section's impulse response (its samples from the
    fifth on, a damped sinusoid) peaks in its spectrum (Hz), to 0.1 Hz."""
    section = resonance_filter(1.0 / (2 * np.pi * f_r), zeta, rate)
    n = round(10 * rate)  # 10 s: 0.1 Hz bins
    x = np.zeros(n + 1)
    x[1] = 1.0  # at rest at 0 before the unit sample
    y = run_section(section, x)[1:]
    spec = np.abs(np.fft.rfft(y[4:], n))
    return float(np.fft.rfftfreq(n, 1.0 / rate)[1 + np.argmax(spec[1:])])


@pytest.mark.parametrize(
    ("f_r", "want"),
    [(1200.0, 1200.0), (7351.0, 2649.0), (12_500.0, 2500.0)],
)
def test_the_samples_ring_at_the_alias(f_r, want):
    """A lightly damped section (zeta 0.005, the bound) sampled at 10 kHz rings at f_r when
    below the Nyquist frequency, at |f_r - k 10 kHz| above it (the 7.35 kHz the four-waveform
    refit reached is a 2.65 kHz ringing): within 0.2 % (a damped sinusoid's spectral peak)."""
    got = _ringing_hz(f_r, 0.005, RATE)
    assert got == pytest.approx(want, rel=2e-3)
    assert aliased_hz(f_r, RATE) == pytest.approx(want, abs=1e-9)


def _numeric_peak(lam: float, tau: float) -> tuple[float, float]:
    f = np.logspace(0, 5, 400_001)
    g = np.abs(1.0 / (1.0 + (2j * np.pi * f * tau) ** lam))
    k = int(np.argmax(g))
    return float(f[k]), float(g[k])


def _second_order_peak(zeta: float) -> float:
    w = np.linspace(0.01, 2.0, 200_001)
    return float(np.max(np.abs(1.0 / (1.0 - w**2 + 2j * zeta * w))))


@pytest.mark.parametrize("lam", [1.2, 1.5, 1.886])
def test_the_relaxor_resonance_is_the_gain_peak(lam):
    """``relaxor_resonance``: the peak of ``|1/(1 + (j w tau)^lam)|`` on a dense grid (0.003 %
    steps) within 0.01 %, and the damping whose second-order peak has the same height within
    0.5 % (lam 1.886, tau 0.13 ms: the stand-in's base G_d, 1.21 kHz, zeta 0.09)."""
    tau = 1.3e-4
    f_num, peak = _numeric_peak(lam, tau)
    got = relaxor_resonance(lam, tau)
    assert got is not None
    f, zeta = got
    assert f == pytest.approx(f_num, rel=1e-4)
    z_ref = optimize.brentq(lambda z: _second_order_peak(z) - peak, 1e-3, 0.7)
    assert zeta == pytest.approx(z_ref, rel=5e-3)


def test_a_relaxor_of_order_up_to_one_is_no_resonance():
    """Order 1 (a first-order low-pass) has no gain peak: ``None``; just above 1 it has one."""
    assert relaxor_resonance(1.0, 1e-4) is None
    assert relaxor_resonance(0.8, 1e-4) is None
    assert relaxor_resonance(1.01, 1e-4) is not None


def _applied(rates: list[float]) -> MechanicalResonance:
    """The effect as diagnose configures it for records at ``rates`` (the library's context
    from the records: their lowest rate)."""
    recs = [
        Record(f"r{k}", rate, np.arange(64) / rate, np.linspace(0.0, 50.0, 64), np.zeros(64))
        for k, rate in enumerate(rates)
    ]
    return library(**effect_context(recs, mains_hz=50.0))["mechanical_resonance"]


def _p(f_hz: float) -> dict[str, float]:
    return {"tau_r_s": 1.0 / (2 * np.pi * f_hz), "zeta": 0.05, "internal": 0.5}


def test_a_fit_beyond_what_the_samples_resolve_is_refused():
    """Refused just above RESOLVED_NYQUIST_SHARE of the Nyquist frequency (4.5 kHz at 10 kHz),
    kept just below; the reason names the alias; the records' lowest rate sets the limit."""
    eff = _applied([RATE])
    top = RESOLVED_NYQUIST_SHARE * RATE / 2
    assert eff.refusals(_p(0.99 * top), {}) == []
    (why,) = eff.refusals(_p(7351.0), {})
    assert "2649 Hz" in why and "Nyquist" in why
    (near,) = eff.refusals(_p(1.01 * top), {})  # below Nyquist: no alias to name
    assert "alias" not in near and "too few samples" in near
    assert "alias" in eff.describe(_p(7351.0), {})
    assert "alias" not in eff.describe(_p(1200.0), {})
    slow = _applied([RATE, 2000.0])
    assert slow.refusals(_p(1200.0), {}) != []  # above 900 Hz at 2 kHz
    assert MechanicalResonance().refusals(_p(7351.0), {}) == []  # no rate known: no limit
    assert library()["mechanical_resonance"].refusals(_p(7351.0), {}) == []


def _edges() -> list[tuple[str, np.ndarray]]:
    """Two PRBS (10-90 V, 2 ms bits) and a 50 Hz triangle at 10 kHz."""
    rng = np.random.default_rng(0)
    out = []
    for i in range(2):
        n = round(0.2 * RATE)
        bits = rng.integers(0, 2, n // 20)
        out.append((f"prbs_{i}", np.repeat(bits, 20)[:n] * 80.0 + 10.0))
    t = np.arange(round(0.1 * RATE)) / RATE
    out.append(("triangle_50Hz", 50 * (1 + (2 / np.pi) * np.arcsin(np.sin(2 * np.pi * 50 * t)))))
    return out


def _fit_from_best_probe(recs):
    """Base + resonance fitted (from a base 3 % off in gain) from the ranking's probe of
    lowest cost, as diagnose's refit starts; and the base alone."""
    eff = library()["mechanical_resonance"]
    start = {**TRUTH, "alpha0_ue_per_V": 1.03 * TRUTH["alpha0_ue_per_V"]}
    prob = ExtendedProblem(recs, [eff], chain=True, offset=True)
    probes = eff.probes([s.context for s in prob.sequences])
    costs = []
    for p in probes:
        r = prob.residual(prob.z_of(start, {eff.name: p}), start)
        costs.append(float(r @ r))
    best = probes[int(np.argmin(costs))]
    fo = prob.fit(start, {eff.name: best}, sd=False, max_nfev=60)
    alone = ExtendedProblem(recs, [], chain=True, offset=True).fit(start, sd=False)
    return eff, fo, alone


def test_a_planted_stack_resonance_is_recovered():
    """The stand-in's resonance (1.2 kHz, zeta 0.05, all of the damping the stack's own)
    planted on the paper's model under PRBS edges: f_r within 0.5 %, zeta within 5 %, not
    refused, and the fit at least 4 times better in-sample than the base alone."""
    planted = {"tau_r_s": 1.0 / (2 * np.pi * 1200.0), "zeta": 0.05, "internal": 1.0}
    recs = planted_records(
        _edges(), RATE, "mechanical_resonance", planted, np.random.default_rng(3), offset=True
    )
    eff, fo, alone = _fit_from_best_probe(recs)
    got = fo.effects["mechanical_resonance"]
    assert 1.0 / (2 * np.pi * got["tau_r_s"]) == pytest.approx(1200.0, rel=5e-3)
    assert got["zeta"] == pytest.approx(0.05, rel=0.05)
    assert eff.refusals(got, {}) == []
    assert fo.nrmse_pct <= 0.25 * alone.nrmse_pct


def test_no_resonance_gains_too_little_to_be_cross_validated():
    """No resonance planted (the paper's model and noise only): base + resonance gains under
    half the minimum gain in-sample (7.5 % of NRMSE), the diagnosis's bar for a
    cross-validation: the candidate is refused there."""
    null = {"tau_r_s": 0.0, "zeta": 0.1, "internal": 0.0}
    recs = planted_records(
        _edges(), RATE, "mechanical_resonance", null, np.random.default_rng(4), offset=True
    )
    _eff, fo, alone = _fit_from_best_probe(recs)
    assert 1.0 - fo.nrmse_pct / alone.nrmse_pct < 0.075


def test_the_description_says_when_the_base_rings_by_itself():
    """Shown a base whose G_d is the stand-in's (order 1.886, 0.13 ms: 1.21 kHz, damping
    0.09), the description says a resonance there and G_d can stand in for each other; shown the
    three-capture fold's (order 1.13) it says nothing. The threshold (a peak of a section at
    damping 0.3) just inside and outside: the order whose |G_d| peak (dense grid) is that
    high, +-0.01."""
    eff = MechanicalResonance()
    eff.note_base({"lam_d": 1.886, "tau_d_s": 1.3e-4})
    text = eff.describe(_p(1239.0), {})
    assert "G_d a 1214 Hz resonance" in text and "stand in for each other" in text
    eff.note_base({"lam_d": 1.13, "tau_d_s": 1.4e-4})
    assert "G_d" not in eff.describe(_p(1239.0), {})
    z03 = _second_order_peak(0.3)
    lam_edge = optimize.brentq(lambda lam: _numeric_peak(lam, 1e-4)[1] - z03, 1.05, 1.9)
    for lam, says in ((lam_edge + 0.01, True), (lam_edge - 0.01, False)):
        eff.note_base({"lam_d": lam, "tau_d_s": 1e-4})
        assert ("stand in for each other" in eff.describe(_p(1239.0), {})) is says, lam
