"""Physics of the virtual bench, checked through the real drivers and the DAQ path."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from labrig.drivers.sim.bench import BenchConfig, VirtualBench
from labrig.drivers.sim.effects import ButterLowpass, Creep, LogCreep, SelfHeating, Thermal
from labrig.drivers.sim.hybrid import EQ11_DEN, EQ11_NUM, HybridParams, HybridPlant

from labrig.model import PAPER_TABLE1, DynamicHysteresisModel
from labrig.runner.rigfile import open_rig

from helpers import rig_path

pytestmark = pytest.mark.timeout(60)

IDEAL_BENCH = {
    "amplifier": {"current_limit": False, "monitor_noise_V": 0.0},
    "gauge": {"noise_ue": 0.0, "bridge_offset_ue": 0.0},
    "daq": {"ai_bits": None, "ao_bits": None},
}


def unipolar(amp_V: float, f_hz: float, rate_hz: float, seconds: float) -> np.ndarray:
    t = np.arange(round(seconds * rate_hz)) / rate_hz
    return amp_V / 2 * (1 - np.cos(2 * np.pi * f_hz * t))


def acquire(rig, v_actuator: np.ndarray, rate_hz: float, block: int = 997) -> dict:
    rig.daq.configure(rate_hz, rig.daq.ai_channel_names())
    rig.amplifier.enable()
    blocks = list(rig.daq.play(rig.volts_to_ao(v_actuator), block))
    starts = [b.start for b in blocks]
    assert starts == list(range(0, v_actuator.size, block))
    return {k: np.concatenate([b.channels[k] for b in blocks]) for k in blocks[0].channels}


def test_paper_truth_reproduces_the_model_through_the_daq_path(tmp_path):
    rate = 1000.0
    v = unipolar(100.0, 5.0, rate, 2.0) + 4.0 * np.sin(2 * np.pi * 13 * np.arange(2000) / rate)
    v = np.clip(v, -20, 100)
    with open_rig(rig_path(tmp_path, bench=IDEAL_BENCH), seed=1) as rig:
        ch = acquire(rig, v, rate)
        strain = rig.gauge_to_strain(ch["gauge"])
        monitor = rig.monitor_to_volts(ch["amp_monitor"])
    ref = DynamicHysteresisModel(PAPER_TABLE1).predict(v, rate, method="fast")
    assert np.max(np.abs(monitor - v)) < 1e-10
    assert np.max(np.abs(strain - ref)) < 1e-9 * np.max(np.abs(ref))
    assert 800 < np.ptp(ref) < 1400  # a real loop, not a trivial record


def test_hybrid_truth_loop_size_and_width():
    rate = 1000.0
    v = unipolar(100.0, 1.0, rate, 4.0)
    y = HybridPlant(HybridParams(), rate).process(v)
    n = int(rate)
    vc, yc = v[-n:], y[-n:]
    span = np.ptp(yc)
    grid = np.linspace(5, 95, 91)
    up = np.interp(grid, vc[: n // 2], yc[: n // 2])
    down = np.interp(grid, vc[n // 2 :][::-1], yc[n // 2 :][::-1])
    width = np.max(down - up) / span
    assert 1000 < span < 1300
    assert 0.10 < width < 0.15
    assert np.all(down - up > -1e-9)  # ascending branch below the descending one


def test_hybrid_eq11_discretisation_matches_the_continuous_response():
    from scipy import signal

    rate = 1000.0
    t = np.arange(4000) / rate
    u = np.sin(2 * np.pi * 40 * t)
    plant = HybridPlant(HybridParams(), rate)
    y = signal.lfilter(plant._b, plant._a, u)
    _, yc, _ = signal.lsim((EQ11_NUM, EQ11_DEN), u, t)
    assert np.max(np.abs(y - yc)) < 2e-3
    h = np.polyval(EQ11_NUM, 2j * np.pi * 40) / np.polyval(EQ11_DEN, 2j * np.pi * 40)
    assert abs(h) == pytest.approx(0.919, abs=2e-3)  # spec model.md section 5


def test_fast_large_sine_is_slew_limited_as_the_current_limit_predicts(tmp_path):
    rate = 20_000.0
    f = 80.0
    bench = {"amplifier": {"monitor_noise_V": 0.0}, "gauge": {"noise_ue": 0.0}}
    with open_rig(rig_path(tmp_path, bench=bench), seed=2) as rig:
        rig.amplifier.status()  # clear the overflow latch
        v = unipolar(100.0, f, rate, 1.0)
        mon = rig.monitor_to_volts(acquire(rig, v, rate, block=2000)["amp_monitor"])
        st = rig.amplifier.status()
        lim = rig.limits
        c_eff = lim.effective_capacitance_F
    assert st.overflow
    slope = np.diff(mon) * rate
    s_peak, s_avg = lim.i_peak_A / c_eff, lim.i_avg_A / c_eff  # 17.6 V/ms, 11.8 V/ms
    cmd_max = 100.0 / 2 * 2 * np.pi * f  # 25.1 V/ms: beyond the peak current
    assert cmd_max > s_peak
    first = slope[: int(0.006 * rate)]  # the first half period: peak current
    assert np.max(np.abs(first)) == pytest.approx(s_peak, rel=0.01)
    late = slope[int(0.5 * rate) :]  # after the average-current fold-back
    assert np.max(np.abs(late)) == pytest.approx(s_avg, rel=0.01)
    mean_i = np.mean(np.abs(late)) * c_eff
    assert mean_i <= lim.i_avg_A * 1.01
    pp = np.ptp(mon[int(0.5 * rate) :])
    triangle = s_avg / (2 * f)  # peak-to-peak of a triangle at the average-current slope
    assert 0.9 * triangle < pp <= 1.01 * triangle
    assert pp < 80.0  # visibly short of the commanded 100 V


def test_40_hz_full_swing_is_not_limited(tmp_path):
    rate = 20_000.0
    bench = {"amplifier": {"monitor_noise_V": 0.0}, "daq": {"ai_bits": None, "ao_bits": None}}
    with open_rig(rig_path(tmp_path, bench=bench), seed=2) as rig:
        rig.amplifier.status()
        v = unipolar(100.0, 40.0, rate, 0.5)
        mon = rig.monitor_to_volts(acquire(rig, v, rate, block=5000)["amp_monitor"])
        assert not rig.amplifier.status().overflow
    assert np.max(np.abs(mon - v)) < 1e-9


def test_gauge_noise_and_quantisation_have_the_configured_size(tmp_path):
    rate = 10_000.0
    n = 40_000
    with open_rig(rig_path(tmp_path, bench={"gauge": {"noise_ue": 2.0}}), seed=3) as rig:
        s = rig.gauge_to_strain(acquire(rig, np.zeros(n), rate, block=4096)["gauge"])
    lsb_ue = 20.0 / 2**16 / 1.085e-3
    expected = math.sqrt(2.0**2 + lsb_ue**2 / 12)
    assert np.std(s) == pytest.approx(expected, rel=0.03)
    codes = s * 1.085e-3 / (20.0 / 2**16)
    assert np.max(np.abs(codes - np.round(codes))) < 1e-6  # 16-bit codes
    assert abs(np.mean(s)) < 0.6  # zeroed on open: 40 ue offset gone (residual noise/10 rms)


@pytest.mark.parametrize("bits", [12, 16])
def test_quantisation_error_is_half_an_lsb(tmp_path, bits):
    rate = 1000.0
    v = np.linspace(0, 100, 5000)
    out = {}
    for b in (bits, None):
        bench = {
            "gauge": {"noise_ue": 0.0},
            "amplifier": {"monitor_noise_V": 0.0},
            "daq": {"ai_bits": b, "ao_bits": None},
        }
        with open_rig(rig_path(tmp_path, bench=bench), seed=4) as rig:
            out[b] = acquire(rig, v, rate)["gauge"]
    lsb = 20.0 / 2**bits
    err = out[bits] - out[None]
    assert np.max(np.abs(err)) <= lsb / 2 * (1 + 1e-9)
    assert np.std(err) == pytest.approx(lsb / math.sqrt(12), rel=0.1)


def test_daq_clips_at_its_range(tmp_path):
    bench = {"gauge": {"noise_ue": 0.0}, "daq": {"ai_bits": None}}
    with open_rig(rig_path(tmp_path, bench=bench, conditioner={"gain": 20}), seed=5) as rig:
        g = acquire(rig, np.full(200, 100.0), 1000.0)["gauge"]
    assert g.max() == pytest.approx(10.0)  # ~900 ue x 21.7 mV/ue would be ~19.5 V


def test_conditioner_filter_setting_and_hidden_lowpass():
    rate = 20_000.0
    t = np.arange(20_000) / rate
    for fc in (100.0, 1000.0):
        lp = ButterLowpass(fc, 2, rate)
        u = np.sin(2 * np.pi * fc * t)
        y = lp.process(u)[-4000:]
        ref = np.exp(-1j * 2 * np.pi * fc * t[-4000:])
        z = np.mean(y * ref) / np.mean(u[-4000:] * ref)
        assert abs(z) == pytest.approx(1 / math.sqrt(2), rel=0.01)  # -3 dB
        assert np.degrees(np.angle(z)) == pytest.approx(-90.0, abs=1.5)


def test_filter_above_nyquist_is_stable_and_unit_gain_at_dc():
    lp = ButterLowpass(1000.0, 2, 1000.0)  # cutoff at the sample rate
    y = lp.process(np.ones(500))
    assert y[-1] == pytest.approx(1.0, abs=1e-9)


def test_self_heating_power_matches_the_sine_formula():
    cfg = SelfHeating(name="self_heating", heat_capacity_J_per_K=1.0)
    rate, f, c_eff = 5000.0, 40.0, 6e-6 * 1.7
    th = Thermal(cfg, rate)
    v = unipolar(100.0, f, rate, 4.0)
    i = c_eff * np.gradient(v) * rate
    T = th.process(v, i)
    p_sine = math.pi * f * c_eff * cfg.tan_delta * 100.0**2 / 4  # 0.16 W
    tau = cfg.thermal_resistance_K_per_W * cfg.heat_capacity_J_per_K
    dT = p_sine * cfg.thermal_resistance_K_per_W * (1 - math.exp(-(4.0 - 1.0) / tau))
    # the reference level of v settles within ~1 s; compare the rise over the last 3 s
    got = T[-1] - T[int(rate)]
    assert got == pytest.approx(dT * math.exp(-1.0 / tau), rel=0.1)


def test_self_heating_raises_temperature_channel_and_gain(tmp_path):
    eff = [{"name": "self_heating", "heat_capacity_J_per_K": 0.2}]
    v = unipolar(100.0, 40.0, 2000.0, 5.0)
    bench = {"gauge": {"noise_ue": 0.0}, "daq": {"ai_bits": None}}
    with open_rig(rig_path(tmp_path, bench={**bench, "effects": eff}), seed=6) as rig:
        assert "temperature" in rig.daq.ai_channel_names()
        ch = acquire(rig, v, 2000.0)
        T = rig.temperature_to_degC(ch["temperature"])
        hot = rig.gauge_to_strain(ch["gauge"])
    with open_rig(rig_path(tmp_path, bench=bench), seed=6) as rig:
        assert "temperature" not in rig.daq.ai_channel_names()
        cold = rig.gauge_to_strain(acquire(rig, v, 2000.0)["gauge"])
    assert T[:100].mean() == pytest.approx(23.0, abs=0.1)
    assert T[-100:].mean() > 25.0
    ratio = np.ptp(hot[-2000:]) / np.ptp(cold[-2000:])
    assert ratio - 1 == pytest.approx(0.002 * (T[-2000:].mean() - 23.0), rel=0.15)


def test_log_creep_per_decade():
    cfg = LogCreep(name="log_creep", per_decade=0.02)
    rate = 100.0
    y = Creep(cfg, rate).process(np.ones(int(1000 * rate)))
    t = (np.arange(y.size) + 1) / rate
    at = {d: np.interp(10.0**d, t, y) for d in (0, 1, 2, 3)}
    for d in (0, 1, 2):
        assert at[d + 1] - at[d] == pytest.approx(0.02, rel=0.12)


def test_mains_pickup_and_offset_drift(tmp_path):
    eff = [
        {"name": "mains_pickup", "amplitude_mV": 3.0},
        {"name": "offset_drift", "rate_ue_per_s": 0.5, "random_walk_ue_per_sqrt_s": 0.0},
    ]
    rate = 1000.0
    bench = {"effects": eff, "gauge": {"noise_ue": 0.0}, "daq": {"ai_bits": None}}
    with open_rig(rig_path(tmp_path, bench=bench), seed=7) as rig:
        g = acquire(rig, np.zeros(10_000), rate)["gauge"]
        strain = rig.gauge_to_strain(g)
    t = np.arange(g.size) / rate
    slope = np.polyfit(t, strain, 1)[0]
    assert slope == pytest.approx(0.5, rel=0.02)
    detr = g - np.polyval(np.polyfit(t, g, 1), t)
    spec = np.abs(np.fft.rfft(detr)) * 2 / g.size
    freqs = np.fft.rfftfreq(g.size, 1 / rate)
    assert spec[np.argmin(np.abs(freqs - 50))] == pytest.approx(3e-3, rel=0.05)
    assert spec[np.argmin(np.abs(freqs - 150))] == pytest.approx(0.9e-3, rel=0.05)


def test_weaker_amplifier_effect_limits_a_20_hz_sine(tmp_path):
    eff = [{"name": "amplifier_current_limit", "i_peak_A": 0.05, "i_avg_A": 0.04}]
    rate = 10_000.0
    bench = {"effects": eff, "amplifier": {"monitor_noise_V": 0.0}, "daq": {"ai_bits": None}}
    with open_rig(rig_path(tmp_path, bench=bench), seed=8) as rig:
        mon = rig.monitor_to_volts(acquire(rig, unipolar(100, 20, rate, 0.5), rate)["amp_monitor"])
    slope = np.abs(np.diff(mon)) * rate
    c_eff = 6e-6 * 1.7
    assert np.max(slope) <= 0.05 / c_eff * 1.001
    assert np.max(slope[-2000:]) == pytest.approx(0.04 / c_eff, rel=0.01)


def test_rate_change_rebuilds_the_chain_at_rest():
    b = VirtualBench(BenchConfig.ideal(), seed=0)
    b.step(np.full(100, 5.0))
    b.set_rate(2000.0)
    assert b.rate_hz == 2000.0
    out = b.step(np.zeros(10))
    assert np.all(np.isfinite(out["gauge"]))


def test_the_average_current_below_the_peak_rating_is_its_first_order_recursion(monkeypatch):
    """Below the peak rating the amplifier's average current is computed block by block by the
    model's modal bank (the fast path: a spy sees one bank run per block); a plain loop of
    ``i_avg = (1 - k) i_avg + k |C fs dv|`` (k from the averaging time) over the same blocks is
    the reference for every sample of it and for the state carried (1e-12 relative)."""
    import labrig.model.modal as modal

    runs: list[np.ndarray] = []
    real = modal.run_bank

    def spy(*args, **kwargs):
        y, state = real(*args, **kwargs)
        runs.append(y.copy())
        return y, state

    monkeypatch.setattr(modal, "run_bank", spy)
    bench = VirtualBench(BenchConfig(), rate_hz=10_000.0)
    amp = bench.config.amplifier
    fs, C = bench.rate_hz, bench.c_eff_F
    k = 1.0 - math.exp(-1.0 / (fs * amp.avg_tau_s))
    i_peak, _ = bench.current_ratings_A
    f = 0.6 * i_peak / (C * 2 * np.pi * 50.0)  # a 50 V sine at 60 % of the peak current
    cmd = unipolar(100.0, f, fs, 0.3)
    ref, v_prev = 0.0, 0.0
    for block in np.array_split(cmd, [1000, 1999]):
        runs.clear()
        out, limited, _ = bench._slew(block)
        assert not limited and out is block  # the fast path returns the command itself
        want = []
        for v in block:
            ref = (1 - k) * ref + k * abs(C * fs * (v - v_prev))
            v_prev = v
            want.append(ref)
        bench.amp.v_out = float(block[-1])  # as the bench's step leaves it
        assert len(runs) == 1
        np.testing.assert_allclose(runs[0], want, rtol=1e-12, atol=0)
        assert bench.amp.i_avg == pytest.approx(ref, rel=1e-12)
    assert ref > 0.1 * i_peak  # the average moved: the comparison is not of zeros


def test_which_benches_load_scipy_signal():
    """``BenchConfig.filters``: scipy.signal (a second of import CPU) only for a bench with an
    effect, a truth other than the paper's, or the conditioner's low-pass on (1 Hz is on)."""
    assert not BenchConfig().filters()
    assert not BenchConfig().filters(0)
    assert BenchConfig().filters(1)
    assert BenchConfig(gauge={"filter_hz": 1}).filters()
    assert BenchConfig(truth={"preset": "hybrid"}).filters()
    assert BenchConfig(effects=[{"name": "mains_pickup"}]).filters()


def test_simulators_load_what_a_reply_needs_before_answering():
    """Before any server answers, the simulators have loaded what a reply may need. In a
    process without numba's kernels the bench runs the model's numpy code and never imports
    numba (its start costs more than a short run, seconds on a new machine); in a process that
    has loaded them (a fleet simulation) the compiled bank of the amplifier's average current is
    loaded at start (a first block must not compile it past a driver's 1 s timeout: no kernel
    signature is added by the block). scipy.signal is loaded only when the bench filters (a
    paper-truth bench without a filter runs without it; a rig setting the conditioner's
    low-pass has it at start)."""
    code = (
        "import sys, numpy as np\n"
        "from labrig.drivers.sim.bench import BenchConfig\n"
        "from labrig.drivers.sim.serve import Simulators\n"
        "def served(hz):\n"
        "    sims = Simulators(BenchConfig(), conditioner_filter_hz=hz).start()\n"
        "    before = signatures()\n"
        "    try:\n"
        "        sims.bench.step(np.linspace(0.0, 5.0, 3000))\n"
        "    finally:\n"
        "        sims.stop()\n"
        "    return sims.bench.engine, before, signatures(), 'scipy.signal' in sys.modules\n"
        "def signatures():\n"
        "    mod = sys.modules.get('labrig.model.compiled')\n"
        "    return -1 if mod is None else len(mod.bank_run.signatures)\n"
        "print(*served(0.0), 'numba' in sys.modules)\n"
        "from labrig.model.accel import kernels\n"
        "assert kernels() is not None\n"
        "for hz in (0.0, 1.0):\n"
        "    print(*served(hz))\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    alone, first, second = (line.split() for line in res.stdout.splitlines())
    assert alone == ["numpy", "-1", "-1", "False", "False"]
    assert first[0] == "compiled" and first[1] == first[2] != "0" and first[3] == "False"
    assert second[0] == "compiled" and second[1] == second[2] and second[3] == "True"


@pytest.fixture
def kernels_as_they_were():
    """The process's compiled kernels loaded again after the test if they were before (the
    tests below forget them to make numpy benches), so later benches of this worker run the
    code they would have run without these tests."""
    from labrig.model import accel

    was = accel.loaded()
    yield
    accel.reset()
    if was:
        accel.kernels()


@pytest.mark.parametrize("truth", ["paper", "hybrid"])
def test_the_bench_gives_the_same_record_on_either_engine(truth, kernels_as_they_were):
    """The bench runs its model on the numpy code unless numba's kernels are already loaded in
    the process (labrig.model.accel.stream_engine); the two records agree. With ideal
    converters the strain differs by under 1e-10 of full scale (rounding, and the compiled
    stream keeping fewer relaxor modes, within 1e-12 of the input's scale); with the default
    16-bit converters the recorded codes are equal. Blocks of 100 samples, as the DAQ plays
    them."""
    from labrig.model import accel

    rate = 10_000.0
    v = unipolar(100.0, 10.0, rate, 1.0) / 10.0  # AO volts (gain 10)
    v[5000:] = np.minimum(v[5000:], 2.0)  # a partial return: minor loops in the operator

    def record(config: BenchConfig, engine: str) -> dict:
        accel.reset()
        if engine == "compiled":
            assert accel.kernels() is not None
        bench = VirtualBench(config, seed=3, rate_hz=rate)
        assert bench.engine == engine
        parts = [bench.step(v[i : i + 100]) for i in range(0, v.size, 100)]
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    try:
        ideal = BenchConfig.ideal(truth)
        a, b = record(ideal, "numpy"), record(ideal, "compiled")
        scale = float(np.max(np.abs(a["gauge"])))
        assert scale > 0.1
        np.testing.assert_allclose(a["gauge"], b["gauge"], rtol=0, atol=1e-10 * scale)
        plain = BenchConfig(truth={"preset": truth})
        a, b = record(plain, "numpy"), record(plain, "compiled")
        for name in a:
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    finally:
        accel.reset()


def test_the_engine_is_kept_when_the_rate_changes(kernels_as_they_were):
    """A bench made without numba's kernels keeps the numpy code when its chain is rebuilt at
    another rate after the kernels were loaded (a first compiled block could otherwise wait on
    their loading while holding the bench, past a driver's answer timeout): the record is that
    of a numpy bench made at the new rate, sample for sample."""
    from labrig.model import accel

    v = unipolar(100.0, 10.0, 2000.0, 0.5) / 10.0
    try:
        accel.reset()
        bench = VirtualBench(BenchConfig.ideal(), seed=3, rate_hz=1000.0)
        assert accel.kernels() is not None
        bench.set_rate(2000.0)
        assert bench.engine == "numpy"
        got = np.concatenate([bench.step(v[i : i + 100])["gauge"] for i in range(0, v.size, 100)])
        accel.reset()
        ref = VirtualBench(BenchConfig.ideal(), seed=3, rate_hz=2000.0)
        want = np.concatenate([ref.step(v[i : i + 100])["gauge"] for i in range(0, v.size, 100)])
        np.testing.assert_array_equal(got, want)
    finally:
        accel.reset()
