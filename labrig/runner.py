"""Execute a protocol on a rig: preflight, acquisition, logging, and a safe exit on every path.

The runner is the only place that sequences hardware. For each concrete step of the plan it
plays the command waveform through the DAQ (actuator volts / amplifier gain), converts the
acquired channels to physical units, and appends every block to the run file, which is flushed
after each block (so a crash loses at most the block in flight). On Ctrl-C, a device fault or
any error the output is ramped to 0 V within the amplifier's current limit, the amplifier is
disabled, the entry and the run are marked ``aborted`` / ``failed`` with the reason, and the
file is closed.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

from labrig import __version__
from labrig.errors import DeviceError, LabrigError
from labrig.instruments import Rig
from labrig.limits import RigLimits
from labrig.protocol.check import load_plan
from labrig.protocol.plan import Plan, PlannedStep
from labrig.protocol.preflight import preflight as check_plan
from labrig.rigfile import load_rig, open_rig
from labrig.store import Channel, RunWriter

#: acquisition block length (s): the most a crash can lose
BLOCK_S = 0.1
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
    entry = writer.begin_entry(
        step.name, step.definition, step.rate_hz, chans, title=getattr(step, "title", None)
    )
    command = step.samples()
    ao = rig.volts_to_ao(command)
    block = max(1, round(BLOCK_S * step.rate_hz))
    dt = 1.0 / step.rate_hz
    try:
        for blk in rig.daq.play(ao, block):
            n = len(blk)
            sl = slice(blk.start, blk.start + n)
            data = {
                "time": np.arange(blk.start, blk.start + n) * dt,
                "command_voltage": command[sl],
                "gauge_raw": blk.channels["gauge"],
            }
            for c in ai:
                values, _ = rig.convert(c, blk.channels[c])
                data[_CHANNEL_MAP[c][0]] = values
            entry.append(data)
            if progress:
                frac = (blk.start + n) / max(1, step.n_samples)
                progress(k, n_steps, step.name, frac, left - frac * step.duration_s)
        st = rig.amplifier.status()
        if not st.ok:
            raise DeviceError("amplifier", f"step {step.name}", "; ".join(st.problems()))
    except KeyboardInterrupt:
        entry.finish("aborted", "interrupted (Ctrl-C)")
        raise
    except BaseException as e:
        entry.finish("failed", str(e) or type(e).__name__)
        raise
    entry.finish("complete")


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
    device faults or Ctrl-C: those are recorded in the file and in the outcome)."""
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
        with RunWriter(
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
        ) as writer:
            try:
                rig.amplifier.enable()
                left = plan.total_duration_s
                for k, step in enumerate(plan.steps):
                    _run_step(rig, writer, step, ai, chans, progress, k, len(plan.steps), left)
                    outcome.entries.append(step.name)
                    left -= step.duration_s
                    if step.rest_after_s > 0:
                        rig.daq.write_static(0.0)
                        if realtime:
                            time.sleep(step.rest_after_s)
                        left -= step.rest_after_s
                writer.finish("complete")
                outcome.status = "complete"
            except KeyboardInterrupt:
                ramp_to_zero(rig, _last_output(rig))
                writer.finish("aborted", "interrupted (Ctrl-C)")
                outcome.status, outcome.reason, outcome.exit_code = "aborted", "interrupted", 130
            except LabrigError as e:
                ramp_to_zero(rig, _last_output(rig))
                writer.finish("failed", str(e))
                outcome.status, outcome.reason, outcome.exit_code = "failed", str(e), e.exit_code
            except Exception as e:
                ramp_to_zero(rig, _last_output(rig))
                writer.finish("failed", f"{type(e).__name__}: {e}")
                outcome.status, outcome.reason = "failed", f"{type(e).__name__}: {e}"
                outcome.exit_code = 1
    finally:
        rig.close()
    return outcome


def _last_output(rig: Rig) -> float:
    try:
        return float(rig.amplifier.read_voltage())
    except Exception:
        return 0.0
