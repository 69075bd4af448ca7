"""The runner in-process: Ctrl-C, device faults, rests and bad --out paths on the simulated rig.

``labrig.runner.execute.open_rig`` is wrapped (not replaced) so each test keeps the rig the runner
opened: its simulators (``rig.sim``) stay inspectable after the run closed them, which is how
these tests see the amplifier's real output voltage (the virtual bench's ``amp.v_out``), and
how faults are injected mid-run through the simulators' own hooks (the drivers under test are
the real ones, talking over their transports).
"""

from __future__ import annotations

import itertools
import os
import signal
import threading
import time
from pathlib import Path

import h5py
import pytest
import yaml

from labrig.core.errors import InputFileError
from labrig.runner import execute as runner
from labrig.runner.rigfile import DEFAULT_RIG_YAML
from labrig.store import read_run

pytestmark = pytest.mark.timeout(60)

RATE = 1000.0


def write_protocol(tmp_path: Path, steps: list[dict], rest_s: float = 0.0) -> Path:
    p = tmp_path / "protocol.yaml"
    p.write_text(
        yaml.safe_dump({"name": "runner test", "rate_hz": RATE, "rest_s": rest_s, "steps": steps})
    )
    return p


@pytest.fixture
def fast_rig(tmp_path: Path) -> Path:
    """The default simulated rig with short device timeouts (a lost link fails fast)."""
    data = yaml.safe_load(DEFAULT_RIG_YAML)
    data["amplifier"]["timeout_s"] = 0.2
    data["conditioner"]["timeout_s"] = 0.2
    p = tmp_path / "rig.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


@pytest.fixture
def rigs(monkeypatch) -> list:
    """Every rig the runner opens (the real open_rig, wrapped)."""
    opened = []
    real = runner.open_rig

    def spy(path=None, seed=None):
        rig = real(path, seed)
        opened.append(rig)
        return rig

    monkeypatch.setattr(runner, "open_rig", spy)
    return opened


def fire_after(rig, n_samples: int, action) -> dict:
    """Call ``action(rig)`` once, after ``n_samples`` samples have been played (steps and rests;
    the bench's own settling does not count)."""
    bench = rig.sim.bench
    real_step = bench.step
    state = {"played": 0, "fired_at": None}

    def step(ao):
        out = real_step(ao)
        if bench.playing and state["fired_at"] is None:
            state["played"] += len(ao)
            if state["played"] >= n_samples:
                state["fired_at"] = state["played"]
                action(rig)
        return out

    bench.step = step
    return state


def run(plan_path: Path, rig_path: Path | None, out: Path, **kw) -> runner.RunOutcome:
    plan, rig = runner.preflight(plan_path, rig_path)
    return runner.execute(plan, rig, out, seed=kw.pop("seed", 3), **kw)


def final_voltage(path: Path) -> float:
    with h5py.File(path, "r") as f:
        ds = f["run/final_amplifier_voltage_V"]
        assert ds.attrs["units"] == "V"
        return float(ds[()])


def assert_at_zero(rig) -> None:
    """The actuator is at 0 V and held there (amplifier ONLINE at 0 V, or the DAQ at 0 V)."""
    amp = rig.sim.bench.amp
    assert amp.v_out == 0.0
    assert (amp.online and amp.sva_V == 0.0) or rig.sim.bench.ao_level == 0.0


SINE_100V_1HZ = {"kind": "sine", "amplitude_V": 100, "frequency_hz": 1, "cycles": 3}
HOLD_0V = {"kind": "hold", "voltage_V": 0, "duration_s": 0.5}


# -- Ctrl-C -------------------------------------------------------------------------------------


def test_ctrl_c_mid_step_ramps_to_zero_within_the_current_limit(tmp_path, rigs):
    proto = write_protocol(tmp_path, [SINE_100V_1HZ, HOLD_0V])
    out = tmp_path / "run.h5"

    def progress(k, n, name, frac, left):
        if k == 0 and frac >= 0.15:  # t = 0.45 s: about 98 V on the stack
            raise KeyboardInterrupt

    o = run(proto, None, out, progress=progress)
    assert (o.status, o.exit_code) == ("aborted", 130)
    assert "interrupted" in o.reason
    assert o.entries == []

    rig = rigs[0]
    assert_at_zero(rig)
    # the output came down at half the peak current: the amplifier never had to limit it (an
    # abrupt step to 0 V from ~98 V would have hit the current limit and latched the overflow)
    assert not rig.sim.bench.amp.overflow_latch

    f = read_run(out)
    assert f.status == "aborted" and "Ctrl-C" in f.reason
    assert list(f.entries) == ["sine_100V_1Hz"]
    e = f["sine_100V_1Hz"]
    assert e.status == "aborted" and "Ctrl-C" in e.reason
    assert e.data["amplifier_voltage"][-1] > 90.0  # it was interrupted while energised
    assert e.n_samples == 500  # 0.5 s: the blocks written before the interrupt, all of them
    assert final_voltage(out) == 0.0


def test_ctrl_c_during_a_rest(tmp_path, rigs):
    proto = write_protocol(tmp_path, [{**HOLD_0V, "voltage_V": 20}, HOLD_0V], rest_s=2.0)
    out = tmp_path / "run.h5"

    def progress(k, n, name, frac, left):
        if name.startswith("the rest after") and frac >= 0.5:
            raise KeyboardInterrupt

    o = run(proto, None, out, progress=progress)
    assert (o.status, o.exit_code) == ("aborted", 130)
    f = read_run(out)
    assert f.status == "aborted"
    assert [(e.name, e.status) for e in f] == [("hold_20V_0p5s", "complete")]
    assert_at_zero(rigs[0])
    assert final_voltage(out) == 0.0


# -- device faults ------------------------------------------------------------------------------

FAULTS = [
    # id, injection, words in the run's reason (device, what)
    ("overload", lambda r: r.sim.bench.inject("overload"), ["amplifier", "overflow"]),
    (
        "over_temperature",
        lambda r: r.sim.bench.inject("over_temperature"),
        ["amplifier", "over-temperature"],
    ),
    ("link_drop", lambda r: r.sim.gcs.inject("drop"), ["amplifier (PI E-503", "link lost"]),
    (
        "excitation_fault",
        lambda r: r.sim.bench.inject("excitation_fault"),
        ["conditioner", "excitation"],
    ),
    (
        "modbus_timeout",
        lambda r: r.sim.modbus_tcp.inject("timeout", count=2),
        ["conditioner", "no valid answer"],
    ),
]


@pytest.mark.parametrize(("inject", "words"), [f[1:] for f in FAULTS], ids=[f[0] for f in FAULTS])
def test_device_fault_mid_step_fails_the_run_at_0V(
    tmp_path, fast_rig, rigs, monkeypatch, inject, words
):
    proto = write_protocol(tmp_path, [SINE_100V_1HZ, HOLD_0V])
    out = tmp_path / "run.h5"
    fault_at = 1250  # samples: 1.25 s into the 3 s sine
    spy = runner.open_rig

    def open_and_arm(path=None, seed=None):
        rig = spy(path, seed)
        fire_after(rig, fault_at, inject)
        return rig

    monkeypatch.setattr(runner, "open_rig", open_and_arm)
    o = run(proto, fast_rig, out)
    rig = rigs[0]
    assert (o.status, o.exit_code) == ("failed", 3), o.reason
    for w in words:
        assert w in o.reason
    assert "during sine_100V_1Hz" in o.reason  # what was happening

    f = read_run(out)
    assert f.status == "failed" and f.reason == o.reason
    assert list(f.entries) == ["sine_100V_1Hz"]  # the run stopped at the fault
    e = f["sine_100V_1Hz"]
    assert e.status == "failed" and words[0] in e.reason
    # seen within one health-check interval (plus a block) of the fault, not at the step's end
    limit = fault_at + (runner.STATUS_CHECK_S + runner.BLOCK_S) * RATE
    assert fault_at <= e.n_samples <= limit < 3 * RATE
    assert_at_zero(rig)
    assert final_voltage(out) == 0.0


def test_fault_during_a_rest_is_seen_there(tmp_path, fast_rig, rigs, monkeypatch):
    proto = write_protocol(tmp_path, [{**HOLD_0V, "voltage_V": 20}, HOLD_0V], rest_s=3.0)
    out = tmp_path / "run.h5"
    spy = runner.open_rig

    def open_and_arm(path=None, seed=None):
        rig = spy(path, seed)
        fire_after(rig, 1500, lambda r: r.sim.bench.inject("over_temperature"))  # 1 s into it
        return rig

    monkeypatch.setattr(runner, "open_rig", open_and_arm)
    o = run(proto, fast_rig, out)
    assert (o.status, o.exit_code) == ("failed", 3)
    assert "over-temperature" in o.reason and "rest after hold_20V_0p5s" in o.reason
    f = read_run(out)
    assert f.status == "failed"
    assert [(e.name, e.status) for e in f] == [("hold_20V_0p5s", "complete")]
    assert_at_zero(rigs[0])


def test_faulty_amplifier_at_start_refuses_before_any_file_or_voltage(tmp_path, rigs, monkeypatch):
    proto = write_protocol(tmp_path, [SINE_100V_1HZ])
    out = tmp_path / "run.h5"
    spy = runner.open_rig

    def open_hot(path=None, seed=None):
        rig = spy(path, seed)
        rig.sim.bench.inject("over_temperature")
        return rig

    monkeypatch.setattr(runner, "open_rig", open_hot)
    with pytest.raises(runner.DeviceError, match="over-temperature") as ei:
        run(proto, None, out)
    assert ei.value.exit_code == 3
    assert not out.exists()
    assert rigs[0].sim.bench.amp.v_out == 0.0
    assert rigs[0]._closed


# -- rests and progress ------------------------------------------------------------------------


def test_rests_are_played_at_0V_and_reported(tmp_path, rigs):
    """A rest lasts its time on the rig (it is played through the DAQ, not skipped): the
    simulated bench's clock covers the entries and the rests, and progress counts down."""
    steps = [{**HOLD_0V, "voltage_V": 80}, HOLD_0V, {**HOLD_0V, "voltage_V": 40}]
    proto = write_protocol(tmp_path, steps, rest_s=2.0)
    out = tmp_path / "run.h5"
    seen = []
    o = run(proto, None, out, progress=lambda k, n, name, frac, left: seen.append((name, left)))
    assert o.status == "complete" and o.exit_code == 0
    bench = rigs[0].sim.bench
    f = read_run(out)
    recorded = sum(e.n_samples for e in f) / RATE
    assert bench.time_s >= recorded + 2 * 2.0  # two rests of 2 s (the last entry has none)
    assert any(name.startswith("the rest after") for name, _ in seen)
    lefts = [left for _, left in seen]
    assert all(b <= a + 1e-9 for a, b in itertools.pairwise(lefts))
    assert lefts[-1] == pytest.approx(0.0, abs=1e-6)
    assert final_voltage(out) == 0.0
    assert_at_zero(rigs[0])


# -- where the run file goes --------------------------------------------------------------------


def test_unwritable_out_is_an_input_error_and_no_voltage(tmp_path, rigs):
    proto = write_protocol(tmp_path, [HOLD_0V])
    target = tmp_path / "a_directory"
    target.mkdir()
    with pytest.raises(InputFileError) as ei:
        run(proto, None, target, overwrite=True)
    assert ei.value.exit_code == 2
    assert "--out" in str(ei.value) and str(target) in str(ei.value)
    assert rigs == []  # refused before the rig was opened (the output check comes first)


# -- signals ------------------------------------------------------------------------------------


def test_interrupt_once_raises_once_then_ignores_repeats_until_the_end():
    before = (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM))
    with runner.interrupt_once():
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5)  # the handler raises here
        # the cleanup that follows is not interrupted again, by SIGINT or SIGTERM
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGINT):
            os.kill(os.getpid(), sig)
        time.sleep(0.05)
        with runner.interrupt_once():  # nested (execute() inside the CLI's): the outer rules
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before


def test_interrupt_once_outside_the_main_thread_does_nothing():
    seen = []

    def body():
        before = signal.getsignal(signal.SIGINT)
        with runner.interrupt_once():
            seen.append(signal.getsignal(signal.SIGINT) is before)

    t = threading.Thread(target=body)
    t.start()
    t.join(5)
    assert seen == [True]


def test_a_default_name_taken_meanwhile_moves_the_run_to_the_next_free_name(tmp_path: Path):
    """``labrig run`` without ``--out`` chooses ``runs/NAME-STAMP.h5``; another run started in
    the same second may create that file first: this run then takes the next free name (never
    a refusal, never a write into the other run's file), while a name the user gave is
    refused as before."""
    p = write_protocol(tmp_path, [{"kind": "hold", "voltage_V": 1.0, "duration_s": 0.05}])
    plan, rig = runner.preflight(p, None)
    chosen = runner.default_out_path(plan, tmp_path / "runs")
    chosen.parent.mkdir()
    chosen.write_bytes(b"the other run's file")  # it appeared after the name was chosen
    outcome = runner.execute(plan, rig, chosen, seed=1, default_name=True)
    assert outcome.exit_code == 0, outcome.reason
    assert outcome.path != chosen and outcome.path.parent == chosen.parent
    # the same second's next name, or a later second's (the clock may have moved on)
    assert outcome.path.name.startswith("runner_test-") and outcome.path.suffix == ".h5"
    assert chosen.read_bytes() == b"the other run's file"
    assert read_run(outcome.path).status == "complete"
    with pytest.raises(InputFileError, match="exists"):
        runner.execute(plan, rig, chosen, seed=1)  # given by the user: refused


def test_the_writer_never_truncates_a_file_created_after_its_check(tmp_path, monkeypatch):
    """Two writers racing for one path: the second's create fails (O_EXCL), the first's file
    keeps its bytes."""
    from labrig.store import RunWriter

    target = tmp_path / "r.h5"
    real_exists = Path.exists

    def racing_exists(self: Path, *a, **k) -> bool:
        if self == target and not real_exists(self):
            target.write_bytes(b"the other writer's file")  # created right after the check
            return False
        return real_exists(self, *a, **k)

    monkeypatch.setattr(Path, "exists", racing_exists)
    with pytest.raises(FileExistsError):
        RunWriter(target, "name: x\n", "", {}, 1)
    assert target.read_bytes() == b"the other writer's file"
