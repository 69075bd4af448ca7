"""The ramp to 0 V, measured: the amplifier's voltage against the wall clock stays within the
current limit on every exit path.

The rig is the simulated one with a *fast link*: the DAQ's static writes advance the bench by
the wall-clock time that passed (``realtime``), and the simulated amplifier has no current
limit of its own (``current_limit: false``), so it follows every write at once. Nothing but
the ramp's own pacing can then keep the slope down: a ramp written back to back, or a step to
0 V, shows up as a slope far beyond the limit. The bench's output voltage is sampled after
every static change it makes (DAQ writes and the amplifier's digital setpoint alike), with
``time.monotonic()``.

The limit, from the rig file's numbers: ``0.5 i_peak / C_eff`` with ``i_peak`` 0.18 A and
``C_eff`` = 6 uF x 1.7 (8824 V/s, 80 V in 9.1 ms); the "slow" rig has 60 uF (882 V/s, 80 V in
91 ms). Tolerances: every sample lies above the line from the ramp's first write at the limit,
less 1 ms of the limit's slope (the timing of one write); a straight-line fit through the
samples between 90 % and 10 % of the start has a slope within 10 % of the limit or below it.
"""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from labrig.core.errors import DeviceError
from labrig.rig.ramp import RAMP_STEP_S
from labrig.runner import execute as runner
from labrig.runner.rigfile import DEFAULT_RIG_YAML, open_rig

pytestmark = pytest.mark.timeout(60)

I_PEAK_A = 0.18
LARGE_SIGNAL_FACTOR = 1.7
#: the promise: half the peak current into the stack's large-signal capacitance
CURRENT_FRACTION = 0.5
TIMING_SLACK_S = 1e-3
FIT_TOLERANCE = 0.10


def limit_V_per_s(capacitance_F: float) -> float:
    return CURRENT_FRACTION * I_PEAK_A / (capacitance_F * LARGE_SIGNAL_FACTOR)


def fast_link_rig(tmp_path: Path, capacitance_F: float = 6e-6, **amp) -> Path:
    data = yaml.safe_load(DEFAULT_RIG_YAML)
    data["daq"]["realtime"] = True
    data["bench"]["amplifier"]["current_limit"] = False
    data["limits"]["capacitance_F"] = capacitance_F
    data["amplifier"].update(timeout_s=0.2, **amp)
    data["conditioner"]["timeout_s"] = 0.2
    p = tmp_path / "fast-link.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


class Trace:
    """The bench's output voltage after every static change (no playback running), with the
    wall-clock time; from any thread (the GCS server settles the bench in its own)."""

    def __init__(self, rig):
        self.bench = rig.sim.bench
        self.points: list[tuple[float, float]] = []
        self.last_played = float("nan")
        self._lock = threading.Lock()
        real = self.bench.step

        def step(ao):
            out = real(ao)
            with self._lock:
                if self.bench.playing:
                    self.last_played = self.bench.amp.v_out
                else:
                    self.points.append((time.monotonic(), self.bench.amp.v_out))
            return out

        self.bench.step = step

    def since(self, t: float) -> np.ndarray:
        with self._lock:
            return np.array([p for p in self.points if p[0] >= t]).reshape(-1, 2)


def check_descent(points: np.ndarray, v0: float, rate: float) -> dict:
    """Check a descent from ``v0`` to 0 V against ``rate`` (see the module docstring); returns
    the measured duration and fitted slope (V/s)."""
    assert len(points), "no voltage was seen after the ramp began"
    t, v = points[:, 0], points[:, 1]
    assert abs(v[-1]) < 1e-9, f"the output did not reach 0 V: {v[-1]} V"
    t0 = t[0]  # the first change seen: the ramp's first write (or a step, if there is a bug)
    floor = abs(v0) - rate * (t - t0 + TIMING_SLACK_S)
    worst = int(np.argmax(floor - np.abs(v)))
    assert np.all(np.abs(v) >= floor - 1e-9), (
        f"{abs(v[worst]):.2f} V at {1e3 * (t[worst] - t0):.3f} ms: the output fell faster than "
        f"{rate:.0f} V/s allows from {v0:.1f} V"
    )
    mid = (np.abs(v) <= 0.9 * abs(v0)) & (np.abs(v) >= 0.1 * abs(v0))
    slope = float(-np.polyfit(t[mid], np.abs(v[mid]), 1)[0]) if mid.sum() >= 3 else float("nan")
    if mid.sum() >= 3:
        assert slope <= rate * (1 + FIT_TOLERANCE), (slope, rate)
    done = t[np.argmax(np.abs(v) < 1e-9)]
    return {"duration_s": float(done - t0), "slope_V_per_s": slope}


def energise(rig, volts: float) -> None:
    rig.amplifier.enable()
    rig.daq.write_static(volts / rig.amplifier.gain)
    assert rig.sim.bench.amp.v_out == pytest.approx(volts, abs=0.01)


@pytest.mark.parametrize("capacitance_F", [6e-6, 60e-6], ids=["default-6uF", "slow-60uF"])
def test_ramp_through_the_daq_stays_within_the_current_limit(tmp_path, capacitance_F):
    rate = limit_V_per_s(capacitance_F)
    with open_rig(fast_link_rig(tmp_path, capacitance_F), seed=1) as rig:
        energise(rig, 80.0)
        trace = Trace(rig)
        t_call = time.monotonic()
        rec = rig.ramp_to_zero()
        m = check_descent(trace.since(t_call), 80.0, rate)
    assert rec.path == "daq" and rec.start_source == "amplifier read-back"
    assert rec.rate_V_per_s == pytest.approx(rate, rel=1e-12)
    # not needlessly slow either: no more writes than the plan's steps of RAMP_STEP_S at the
    # rate (a ramp in smaller steps, or one restarting its line, writes more). How long those
    # writes take on the wall clock depends on the machine's load: benchmarks, not this test.
    planned = math.ceil(80.0 / (rate * RAMP_STEP_S))
    assert len(rec.volts) <= planned + 2, (len(rec.volts), planned, m)  # + the first and last


def test_ramp_through_the_amplifier_setpoint_when_the_daq_fails(tmp_path, monkeypatch):
    """The DAQ refuses to write: the amplifier takes the output over from its digital setpoint
    at the present voltage and ramps that, paced the same way."""
    rate = limit_V_per_s(60e-6)
    with open_rig(fast_link_rig(tmp_path, 60e-6), seed=1) as rig:
        energise(rig, 80.0)

        def broken(volts):
            raise DeviceError("daq (simulated)", "write_static", "the AO task died")

        monkeypatch.setattr(rig.daq, "write_static", broken)
        trace = Trace(rig)
        t_call = time.monotonic()
        rec = rig.ramp_to_zero()
        check_descent(trace.since(t_call), 80.0, rate)
        assert rec.path == "amplifier setpoint", rec
        assert any("AO task died" in e for e in rec.errors)
        assert rig.sim.bench.amp.online and rig.sim.bench.amp.sva_V == 0.0


HOLD_80V = {"kind": "hold", "voltage_V": 80, "duration_s": 1.5}


def write_protocol(tmp_path: Path) -> Path:
    p = tmp_path / "hold.yaml"
    p.write_text(yaml.safe_dump({"name": "ramp test", "rate_hz": 1000, "steps": [HOLD_80V]}))
    return p


def arm(monkeypatch, when_s: float, action) -> dict:
    """Open the runner's rig as usual, then ``action(rig)`` once ``when_s`` of the step has
    played; the rig and a trace of its bench are kept in the returned dict."""
    real = runner.open_rig
    box: dict = {}

    def open_and_arm(path=None, seed=None):
        rig = real(path, seed)
        bench, step = rig.sim.bench, rig.sim.bench.step
        played = {"n": 0}

        def fire(ao):
            out = step(ao)
            if bench.playing and "fired" not in box:
                played["n"] += len(ao)
                if played["n"] >= when_s * 1000:
                    box["fired"] = time.monotonic()
                    action(rig)
            return out

        bench.step = fire
        box["rig"], box["trace"] = rig, Trace(rig)
        return rig

    monkeypatch.setattr(runner, "open_rig", open_and_arm)
    return box


FAULTS = [
    ("conditioner excitation", lambda r: r.sim.bench.inject("excitation_fault"), "excitation"),
    ("amplifier overload", lambda r: r.sim.bench.inject("overload"), "overflow"),
    ("amplifier link lost", lambda r: r.sim.gcs.inject("drop", count=3), "link lost"),
    ("conditioner timeout", lambda r: r.sim.modbus_tcp.inject("timeout", 2), "no valid answer"),
]


@pytest.mark.parametrize(("inject", "words"), [f[1:] for f in FAULTS], ids=[f[0] for f in FAULTS])
def test_a_device_fault_ramps_rather_than_zeroing_at_once(tmp_path, monkeypatch, inject, words):
    box = arm(monkeypatch, 0.5, inject)
    plan, rig_path = runner.preflight(write_protocol(tmp_path), fast_link_rig(tmp_path, 60e-6))
    o = runner.execute(plan, rig_path, tmp_path / "run.h5", seed=2, realtime=True)
    assert (o.status, o.exit_code) == ("failed", 3), o.reason
    assert words in o.reason
    assert box["trace"].last_played == pytest.approx(80.0, abs=0.01)  # energised at the fault
    check_descent(box["trace"].since(box["fired"]), 80.0, limit_V_per_s(60e-6))


def test_an_unexpected_error_ramps_too(tmp_path, monkeypatch):
    box = arm(monkeypatch, 10.0, lambda r: None)  # never fires: a trace only

    def progress(k, n, name, frac, left):
        if frac >= 0.4:
            box["fired"] = time.monotonic()
            raise RuntimeError("a bug in a progress callback")

    plan, rig_path = runner.preflight(write_protocol(tmp_path), fast_link_rig(tmp_path, 60e-6))
    o = runner.execute(
        plan, rig_path, tmp_path / "run.h5", seed=2, realtime=True, progress=progress
    )
    assert (o.status, o.exit_code) == ("failed", 1) and "RuntimeError" in o.reason
    check_descent(box["trace"].since(box["fired"]), 80.0, limit_V_per_s(60e-6))
