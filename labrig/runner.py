"""Execute a protocol on a rig: preflight, acquisition, logging, and a safe exit on every path.

The runner is the only place that sequences hardware. For each concrete step of the plan it
plays the command waveform through the DAQ (actuator volts / amplifier gain), converts the
acquired channels to physical units, and appends every block to the run file, which is flushed
after each block (so a crash loses at most the block in flight). On Ctrl-C, a device fault or
any error the output is ramped to 0 V within the amplifier's current limit, the amplifier is
disabled, the entry and the run are marked ``aborted`` / ``failed`` with the reason, and the
file is closed. Device health (amplifier and conditioner status) is checked every
``STATUS_CHECK_S`` of protocol time and at the end of each step; rests between entries are
played as 0 V through the DAQ (not recorded). On every exit path the amplifier's read-back
voltage after zeroing is stored as ``/run/final_amplifier_voltage_V``.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

from labrig import __version__
from labrig.errors import DeviceError, InputFileError, InputIssue, LabrigError
from labrig.instruments import Rig
from labrig.limits import RigLimits
from labrig.protocol.check import load_plan
from labrig.protocol.plan import Plan, PlannedStep
from labrig.protocol.preflight import preflight as check_plan
from labrig.rigfile import load_rig, open_rig
from labrig.store import Channel, RunWriter

#: acquisition block length (s): the most a crash can lose
BLOCK_S = 0.1
#: device health (amplifier and conditioner status) is checked at least this often during a
#: step or a rest, in protocol time (s), and at the end of every step
STATUS_CHECK_S = 1.0
#: ramp-down current as a fraction of the amplifier's peak current
RAMP_CURRENT_FRACTION = 0.5

# DAQ channel -> (run-file dataset, units, long name)
_CHANNEL_MAP: dict[str, tuple[str, str, str]] = {
    "gauge": ("strain", "ue", "strain"),
    "amp_monitor": ("amplifier_voltage", "V", "amplifier output voltage (monitor)"),
    "temperature": ("temperature", "degC", "actuator temperature"),
}


@dataclass
class RunOutcome:
    """What happened: the file, the run status and the exit code the CLI should return."""

    path: Path
    status: str
    reason: str = ""
    exit_code: int = 0
    entries: list[str] = field(default_factory=list)
    seed: int | None = None


ProgressFn = Callable[[int, int, str, float, float], None]
"""``progress(step_index, n_steps, entry_name, fraction_of_step, seconds_left_total)``."""


def default_out_path(plan: Plan, runs_dir: Path = Path("runs")) -> Path:
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in plan.name) or "run"
    path = runs_dir / f"{safe}-{stamp}.h5"
    k = 2
    while path.exists():
        path = runs_dir / f"{safe}-{stamp}-{k}.h5"
        k += 1
    return path


def preflight(protocol: Path, rig_path: Path | None) -> tuple[Plan, Path | None]:
    """Validate the protocol against the rig's limits without opening any device.

    The rig is ``rig_path``, else the protocol's ``rig`` key, else the built-in simulated rig.
    Raises :class:`~labrig.errors.InputFileError` (exit 2) on any problem.
    """
    plan = load_plan(protocol)
    rig = rig_path if rig_path is not None else plan.rig_path
    limits: RigLimits = load_rig(rig).limits
    check_plan(plan, limits)
    return plan, rig


def ramp_to_zero(rig: Rig, from_volts: float) -> None:
    """Bring the actuator from ``from_volts`` to 0 V at a current within the amplifier's limit.

    A ramp at ``RAMP_CURRENT_FRACTION`` of the peak current (``dV/dt = I / C_eff``) written
    with ``write_static`` steps; then the DAQ stops at 0 V. Never raises.
    """
    try:
        lim = rig.limits
        slew = RAMP_CURRENT_FRACTION * lim.i_peak_A / lim.effective_capacitance_F  # V/s
        n = max(2, int(np.ceil(abs(from_volts) / (slew * 1e-3))))
        for v in np.linspace(from_volts, 0.0, min(n, 200)):
            rig.daq.write_static(float(rig.volts_to_ao(v)))
    except Exception:
        pass
    rig.safe_zero()


def _channels(rig: Rig) -> tuple[list[str], list[Channel]]:
    names = [c for c in rig.daq.ai_channel_names() if c in _CHANNEL_MAP]
    if "gauge" not in names:
        raise DeviceError("daq", "configure", "the DAQ has no 'gauge' input channel")
    chans = [
        Channel("command_voltage", "V", "commanded actuator voltage"),
        Channel("gauge_raw", "V", "strain-gauge conditioner output"),
    ]
    chans += [Channel(*_CHANNEL_MAP[c]) for c in names]
    return names, chans


def _run_step(rig, writer, step: PlannedStep, ai: list[str], chans, progress, k, n_steps, left):
    # the rest that follows matters to analysis: the actuator's long memory spans it
    meta = {**step.definition, "rest_after_s": step.rest_after_s}
    # channels the plan adds to this entry (strain-command steps: command_strain, ue)
    aux = getattr(step, "aux", None) or {}
    chans = [*chans, *(Channel(k, u, ln) for k, (u, ln, _) in aux.items())]
    entry = writer.begin_entry(
        step.name, meta, step.rate_hz, chans, title=getattr(step, "title", None)
    )
    command = step.samples()
    ao = rig.volts_to_ao(command)
    block = max(1, round(BLOCK_S * step.rate_hz))
    check_every = max(1, round(STATUS_CHECK_S * step.rate_hz / block))
    dt = 1.0 / step.rate_hz
    gen = None
    try:
        gen = rig.daq.play(ao, block)
        for j, blk in enumerate(gen, start=1):
            n = len(blk)
            sl = slice(blk.start, blk.start + n)
            data = {
                "time": np.arange(blk.start, blk.start + n) * dt,
                "command_voltage": command[sl],
                "gauge_raw": blk.channels["gauge"],
            }
            data.update({k: vals[sl] for k, (_, _, vals) in aux.items()})
            for c in ai:
                values, _ = rig.convert(c, blk.channels[c])
                data[_CHANNEL_MAP[c][0]] = values
            entry.append(data)
            if progress:
                frac = (blk.start + n) / max(1, step.n_samples)
                progress(k, n_steps, step.name, frac, left - frac * step.duration_s)
            if j % check_every == 0:
                _check_health(rig, step.name)
        _close_playback(gen)
        _check_health(rig, step.name)
    except KeyboardInterrupt:
        _close_playback(gen)
        entry.finish("aborted", "interrupted (Ctrl-C)")
        raise
    except BaseException as e:
        _close_playback(gen)
        entry.finish("failed", str(e) or type(e).__name__)
        raise
    entry.finish("complete")


def _check_health(rig: Rig, where: str) -> None:
    """Raise :class:`DeviceError` naming the device and the step if a device reports a fault
    (:meth:`Rig.check`: amplifier overflow / over-temperature / error, conditioner faults)."""
    try:
        rig.check()
    except DeviceError as e:
        raise DeviceError(e.device, f"{e.operation} during {where}", e.detail) from e


def _close_playback(gen) -> None:
    """End a DAQ playback iterator: a generator left suspended keeps the device "playing"
    (the simulated DAQ then ignores ``write_static``, so a ramp to 0 V would not happen)."""
    close = getattr(gen, "close", None)
    if close is not None:
        with contextlib.suppress(Exception):
            close()


def _rest(rig: Rig, step: PlannedStep, progress, k: int, n_steps: int, left: float) -> None:
    """Hold 0 V for the step's ``rest_after_s`` (not recorded).

    The rest is played through the DAQ as zeros, like a step: it takes real time on a real rig
    (with or without ``--realtime``), is paced with ``--realtime`` on a simulated one, and
    advances a simulated rig's physics (the strain relaxes as on the bench); Ctrl-C and device
    faults are seen during a rest as during a step.
    """
    n = round(step.rest_after_s * step.rate_hz)
    if n <= 0:
        return
    rig.daq.write_static(0.0)
    block = max(1, round(BLOCK_S * step.rate_hz))
    check_every = max(1, round(STATUS_CHECK_S * step.rate_hz / block))
    where = f"the rest after {step.name}"
    gen = rig.daq.play(np.zeros(n), block)
    try:
        for j, blk in enumerate(gen, start=1):
            if progress:
                frac = (blk.start + len(blk)) / n
                progress(k, n_steps, where, frac, left - frac * step.rest_after_s)
            if j % check_every == 0:
                _check_health(rig, where)
    finally:
        _close_playback(gen)


def execute(
    plan: Plan,
    rig_path: Path | None,
    out: Path | None = None,
    seed: int | None = None,
    realtime: bool = False,
    progress: ProgressFn | None = None,
    overwrite: bool = False,
) -> RunOutcome:
    """Run a preflighted plan on the rig and log it; returns the outcome (never raises for
    device faults or Ctrl-C: those are recorded in the file and in the outcome).

    Called from the main thread, Ctrl-C (SIGINT) and SIGTERM stop the run once: repeats are
    ignored until the output is at 0 V and the file is closed (see :func:`interrupt_once`).
    """
    with interrupt_once():
        return _execute(plan, rig_path, out, seed, realtime, progress, overwrite)


@contextlib.contextmanager
def interrupt_once():
    """SIGINT and SIGTERM raise :class:`KeyboardInterrupt` the first time only; later ones are
    ignored until the block ends (a second, impatient Ctrl-C must not interrupt the ramp to
    0 V or the closing of the run file). The previous handlers come back afterwards. Does
    nothing outside the main thread (Python delivers signals there only)."""
    if threading.current_thread() is not threading.main_thread() or getattr(
        signal.getsignal(signal.SIGINT), "labrig_interrupt_once", False
    ):  # not the main thread, or inside an outer interrupt_once (the CLI's)
        yield
        return
    seen: list[int] = []

    def handler(signum, frame):
        # decide before recording: a repeat can run this handler again at any bytecode of this
        # one, and the first call must still raise
        first = not seen
        seen.append(signum)
        if first:
            raise KeyboardInterrupt

    handler.labrig_interrupt_once = True
    old = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    for sig in old:
        signal.signal(sig, handler)
    try:
        yield
    finally:
        for sig, h in old.items():
            if h is not None:
                signal.signal(sig, h)


def _execute(plan, rig_path, out, seed, realtime, progress, overwrite) -> RunOutcome:
    out = out or default_out_path(plan)
    rig = open_rig(rig_path, seed)
    outcome = RunOutcome(path=out, status="running", seed=rig.seed)
    try:
        if realtime and hasattr(rig.daq, "realtime"):
            rig.daq.realtime = True
        rig.check()
        ai, chans = _channels(rig)
        rig.daq.configure(plan.rate_hz, ["gauge", *[c for c in ai if c != "gauge"]])
        rig.conditioner.zero()
        try:
            writer = RunWriter(
                out,
                plan.text,
                rig.rig_text,
                rig.describe(),
                rig.seed,
                __version__,
                protocol_name=plan.name,
                protocol_file=str(plan.path),
                rig_file=str(rig_path or ""),
                planned_entries=[s.name for s in plan.steps],
                overwrite=overwrite,
            )
        except FileExistsError:
            raise
        except OSError as e:  # unwritable --out (a directory, no permission, no such place)
            why = e.strerror or str(e)
            raise InputFileError(
                [InputIssue(str(out), None, "--out", f"cannot create the run file: {why}")]
            ) from None
        with writer:
            try:
                rig.amplifier.enable()
                left = plan.total_duration_s
                for k, step in enumerate(plan.steps):
                    _run_step(rig, writer, step, ai, chans, progress, k, len(plan.steps), left)
                    outcome.entries.append(step.name)
                    left -= step.duration_s
                    if step.rest_after_s > 0:
                        _rest(rig, step, progress, k, len(plan.steps), left)
                        left -= step.rest_after_s
                rig.safe_zero()
                status, reason, code = "complete", "", 0
            except KeyboardInterrupt:
                ramp_to_zero(rig, _last_output(rig))
                status, reason, code = "aborted", "interrupted (Ctrl-C)", 130
            except LabrigError as e:
                ramp_to_zero(rig, _last_output(rig))
                status, reason, code = "failed", str(e), e.exit_code
            except Exception as e:
                ramp_to_zero(rig, _last_output(rig))
                status, reason, code = "failed", f"{type(e).__name__}: {e}", 1
            _record_final_voltage(writer, rig)
            writer.finish(status, reason or None)
            outcome.status, outcome.reason, outcome.exit_code = status, reason, code
    finally:
        rig.close()
    return outcome


def _record_final_voltage(writer: RunWriter, rig: Rig) -> None:
    """Store the amplifier's read-back output voltage, taken after the output was brought to
    0 V at the end of the run (every exit path), as ``/run/final_amplifier_voltage_V`` (NaN and
    an ``error`` attribute if it could not be read). Never raises."""
    try:
        try:
            volts, err = float(rig.amplifier.read_voltage()), ""
        except Exception as e:
            volts, err = float("nan"), str(e) or type(e).__name__
        group = writer._g  # the /run group: RunWriter has no public API for run-level values
        ds = group.create_dataset("final_amplifier_voltage_V", data=volts)
        ds.attrs["units"] = "V"
        ds.attrs["long_name"] = "amplifier output voltage read back after the output was zeroed"
        if err:
            ds.attrs["error"] = err
        writer.flush()
    except Exception:
        pass


def _last_output(rig: Rig) -> float:
    try:
        return float(rig.amplifier.read_voltage())
    except Exception:
        return 0.0
