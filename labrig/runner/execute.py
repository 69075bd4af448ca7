"""Execute a protocol on a rig: preflight, acquisition, logging, and a safe exit on every path.

The runner is the only place that sequences hardware. For each concrete step of the plan it
plays the command waveform through the DAQ (actuator volts / amplifier gain), converts the
acquired channels to physical units, and appends every block to the run file, which is flushed
after each block (so a crash loses at most the block in flight). Device health (amplifier and
conditioner status) is checked every ``STATUS_CHECK_S`` of protocol time and at the end of each
step; rests between entries are played as 0 V through the DAQ (not recorded).

Every way a run ends - complete, a stop signal (SIGINT, SIGTERM, SIGHUP, SIGQUIT), a device
fault, a full disk, any other error - ends the same way: the output is ramped to 0 V within
the current limit, paced by the wall clock (:mod:`labrig.rig.ramp`), the amplifier is disabled, and
the file records the cause (``status``, ``status_reason``, ``exit_code``), the ramp
(``/run/ramp_to_zero``) and the amplifier's read-back voltage after it
(``/run/final_amplifier_voltage_V``). Exit codes: 0 complete, 128 + signal number for a signal
(SIGINT 130, SIGTERM 143, SIGHUP 129, SIGQUIT 131), 3 for a device fault or a full disk, 2
for bad input found before the output is energised, 1 for anything unexpected.

Stop signals are deferred while the rig is energised (:class:`labrig.core.interrupts.SignalGuard`)
and acted on after the block in flight, so no exception lands in the middle of a write; a
second signal never interrupts the ramp or the closing of the file.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

from labrig.core.errors import DeviceError, InputFileError, InputIssue, LabrigError, StorageError
from labrig.core.interrupts import SignalGuard, exit_code_for, interrupt_once, reason_for, signum_of
from labrig.core.metadata import RunMetadata, combine
from labrig.core.outputs import Staged, check_outputs, never_an_output, stage
from labrig.core.seeds import check_seed
from labrig.core.version import __version__
from labrig.model.accel import kernels
from labrig.protocol.check import load_plan
from labrig.protocol.plan import Plan, PlannedStep
from labrig.protocol.preflight import preflight as check_plan
from labrig.rig.instruments import Rig
from labrig.rig.limits import RigLimits
from labrig.rig.ramp import RAMP_CURRENT_FRACTION, RampRecord
from labrig.runner.examples import resolve_existing
from labrig.runner.record import record_end
from labrig.runner.rigfile import load_rig, open_rig
from labrig.store import Channel, RunWriter, estimate_run_bytes, free_bytes
from labrig.store.reader import being_written
from labrig.store.resume import ResumePlan, check_resume, check_same_rig, record_resume
from labrig.store.space import DISK_FULL, RESERVE_BYTES, is_disk_full

#: acquisition block length (s): the most a crash can lose
BLOCK_S = 0.1
#: the cost rule of :func:`repays_kernels`: numba's start (CPU s per process) against what the
#: simulated bench's numpy code costs over the compiled code per block and per sample (CPU s;
#: measured in benchmarks/RESULTS.md, "Seventeenth round")
NUMBA_START_S = 1.2
NUMPY_BLOCK_S = 0.7e-3
NUMPY_SAMPLE_S = 0.2e-6
#: device health (amplifier and conditioner status) is checked at least this often during a
#: step or a rest, in protocol time (s), and at the end of every step
STATUS_CHECK_S = 1.0

__all__ = [
    "BLOCK_S",
    "NUMBA_START_S",
    "NUMPY_BLOCK_S",
    "NUMPY_SAMPLE_S",
    "RAMP_CURRENT_FRACTION",
    "STATUS_CHECK_S",
    "DeviceError",
    "RunOutcome",
    "check_resume_of",
    "check_run_output",
    "default_out_path",
    "execute",
    "interrupt_once",
    "numpy_excess_s",
    "open_rig",
    "preflight",
    "ramp_to_zero",
    "repays_kernels",
    "run_inputs",
]

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


def preflight(protocol: Path | str, rig_path: Path | str | None) -> tuple[Plan, Path | None]:
    """Validate the protocol against the rig's limits without opening any device.

    ``protocol`` is a file or the name of a shipped example (``paper``;
    :mod:`labrig.runner.examples`), as is ``rig_path`` (``hybrid``). The rig is ``rig_path``,
    else the protocol's ``rig`` key, else the built-in simulated rig. Raises
    :class:`~labrig.core.errors.InputFileError` (exit 2) on any problem.
    """
    plan = load_plan(resolve_existing(protocol, "protocol"))
    given_rig = None if rig_path is None else resolve_existing(rig_path, "rig")
    rig = given_rig if given_rig is not None else plan.rig_path
    limits: RigLimits = load_rig(rig).limits
    check_plan(plan, limits)
    return plan, rig


def run_inputs(plan: Plan, rig_path: Path | None) -> list[Path]:
    """The files a run reads: the protocol, the rig file and the CSV files of its steps."""
    files = [Path(plan.path)] + ([Path(rig_path)] if rig_path is not None else [])
    base = Path(plan.path).parent
    for step in plan.steps:
        name = step.definition.get("file")
        if isinstance(name, str) and name:
            files.append(Path(name) if Path(name).is_absolute() else base / name)
    return files


def check_resume_of(plan: Plan, path: Path) -> ResumePlan:
    """Whether the run file ``path`` can be resumed with ``plan`` and what remains
    (:func:`labrig.store.resume.check_resume`: the same protocol, not complete, not being
    written, every sample and seal sound; not a symbolic link, which the resumed file, written
    beside it and renamed into place, would replace); :class:`InputFileError` (exit 2)
    otherwise."""
    why = never_an_output(Path(path))
    if why:
        raise InputFileError([InputIssue(str(path), None, "--resume", why)])
    return check_resume(path, plan.text, [s.name for s in plan.steps], plan.file)


def check_run_output(
    plan: Plan,
    rig_path: Path | None,
    out: Path,
    overwrite: bool,
    inputs: Sequence[Path | None] = (),
) -> None:
    """The one output check (:func:`labrig.core.outputs.check_outputs`) for the run file
    ``out``: not the protocol, the rig file, a CSV file the protocol reads or another of
    ``inputs`` (the live view's parameters); not a run file being written; not a folder; not
    an existing file without ``overwrite``. :class:`InputFileError` (exit 2)."""
    check_outputs(
        [out],
        inputs=[*run_inputs(plan, rig_path), *inputs],
        overwrite=overwrite,
        being_written=being_written,
    )


def ramp_to_zero(rig: Rig) -> RampRecord:
    """Ramp the actuator to 0 V within the current limit, paced by the wall clock, and hold it
    there (:meth:`labrig.rig.instruments.Rig.ramp_to_zero`). Never raises."""
    return rig.ramp_to_zero()


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


def _run_step(
    rig: Rig,
    writer: RunWriter,
    step: PlannedStep,
    ai: list[str],
    chans: list[Channel],
    progress: ProgressFn | None,
    k: int,
    n_steps: int,
    left: float,
    guard: SignalGuard,
) -> None:
    """Play one step, log every block, check health; a pending stop signal is raised after
    the block in flight. On any exception the playback ends (the output holds its value for
    the ramp) and the exception propagates: the run's end finishes the entry."""
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
            entry.append(data)  # logged first: the file shows what was clipped
            clipped = rig.clipped_input(blk.channels)
            if clipped is not None:
                _check_health(rig, step.name)  # a device's own fault is the cause to name
                raise DeviceError("daq", f"acquisition during {step.name}", clipped)
            if progress:
                frac = (blk.start + n) / max(1, step.n_samples)
                progress(k, n_steps, step.name, frac, left - frac * step.duration_s)
            if j % check_every == 0:
                _check_health(rig, step.name)
            guard.check()
        _close_playback(gen)
        _check_health(rig, step.name)
    except BaseException:
        _close_playback(gen)
        raise
    entry.finish("complete")


def _check_health(rig: Rig, where: str) -> None:
    """Raise :class:`DeviceError` naming the device and the step if a device reports a fault
    (amplifier overflow / over-temperature / error, conditioner faults). The output is left
    where it is: the run's end ramps it."""
    try:
        amp = rig.amplifier.status()
        cond = rig.conditioner.status() if amp.ok else None
    except DeviceError as e:
        raise DeviceError(e.device, f"{e.operation} during {where}", e.detail) from e
    if not amp.ok:
        raise DeviceError("amplifier", f"status check during {where}", "; ".join(amp.problems()))
    if cond is not None and not cond.ok:
        problems = "; ".join(cond.problems())
        raise DeviceError("conditioner", f"status check during {where}", problems)


def _close_playback(gen) -> None:
    """End a DAQ playback iterator: a generator left suspended keeps the device "playing"
    (the simulated DAQ then ignores ``write_static``, so a ramp to 0 V would not happen)."""
    close = getattr(gen, "close", None)
    if close is not None:
        with contextlib.suppress(Exception):
            close()


def _rest(
    rig: Rig,
    step: PlannedStep,
    writer: RunWriter,
    progress: ProgressFn | None,
    k: int,
    n_steps: int,
    left: float,
    guard: SignalGuard,
) -> None:
    """Hold 0 V for the step's ``rest_after_s`` (not recorded).

    The rest is played through the DAQ as zeros, like a step: it takes real time on a real rig
    (with or without ``--realtime``), is paced with ``--realtime`` on a simulated one, and
    advances a simulated rig's physics (the strain relaxes as on the bench); stop signals and
    device faults are seen during a rest as during a step.
    """
    n = round(step.rest_after_s * step.rate_hz)
    if n <= 0:
        return
    block = max(1, round(BLOCK_S * step.rate_hz))
    check_every = max(1, round(STATUS_CHECK_S * step.rate_hz / block))
    where = f"the rest after {step.name}"
    gen = rig.daq.play(np.zeros(n), block)
    try:
        for j, blk in enumerate(gen, start=1):
            writer.heartbeat()  # the file is still being written (labrig.store.writing)
            if progress:
                frac = (blk.start + len(blk)) / n
                progress(k, n_steps, where, frac, left - frac * step.rest_after_s)
            if j % check_every == 0:
                _check_health(rig, where)
            guard.check()
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
    *,
    metadata: RunMetadata | None = None,
    resume: Path | ResumePlan | None = None,
    on_file: Callable[[Path], None] | None = None,
    inputs: Sequence[Path | None] = (),
    opener: Callable[[Path | None, int | None], Rig] | None = None,
    default_name: bool = False,
) -> RunOutcome:
    """Run a preflighted plan on the rig and log it; returns the outcome (never raises for
    device faults, a full disk or stop signals once the run file exists: those are recorded
    in the file and in the outcome).

    ``metadata``: the options' metadata (``--meta``, ``--operator``, ``--sample``), put over
    the protocol's ``metadata:`` (:mod:`labrig.core.metadata`). ``resume``: continue that run file
    with the planned entries it does not hold complete (:mod:`labrig.store.resume`; ``out`` is
    then ignored). ``on_file(path)`` is called once the run file exists, with the path being
    written (a copy beside the target with ``overwrite`` or ``resume``). ``inputs``: other
    files the command reads, never the run file (:func:`check_run_output`). ``opener``:
    opens the rig (default :func:`~labrig.runner.rigfile.open_rig`, after loading numba's
    kernels for a simulated run that repays them, :func:`repays_kernels`; tests pass one that
    records, and nothing is preloaded for it). ``default_name``: ``out`` is
    :func:`default_out_path`'s choice (as it is when ``out`` is None), so a file that appears
    there meanwhile (another run started in the same second) moves this run to the next free
    name instead of refusing it.

    Called from the main thread, SIGINT, SIGTERM, SIGHUP and SIGQUIT stop the run once:
    repeats are ignored until the output is at 0 V and the file is closed (see
    :func:`labrig.core.interrupts.interrupt_once`). Before the run file exists, a stop signal
    propagates as :class:`labrig.core.interrupts.Interrupted`, and bad input as
    :class:`~labrig.core.errors.InputFileError` (nothing energised).
    """
    check_seed(seed)
    job = _Job(plan, rig_path, realtime, progress, overwrite, on_file)
    if resume is not None:
        job.resume = resume if isinstance(resume, ResumePlan) else check_resume_of(plan, resume)
        job.metadata = (metadata or RunMetadata()).over(RunMetadata(job.resume.metadata))
        job.options = metadata or RunMetadata()
        out = job.resume.path  # the file resumed (a ResumePlan names it)
    else:
        job.metadata = combine(getattr(plan.protocol, "metadata", None), metadata)
        job.default_name = default_name or out is None
        out = _free_name(job, out or default_out_path(plan))
        check_run_output(plan, rig_path, out, overwrite, inputs)
    with interrupt_once() as guard:
        if opener is None and _long_simulation(job):
            kernels()  # before the bench is made (None without numba: it runs its numpy code)
        # a stop signal here: open_rig closes what it opened (looked up now: a test seam)
        rig = (opener or open_rig)(rig_path, seed)
        try:
            with guard.defer():
                return _run_on(rig, job, out, guard)
        finally:
            with guard.defer():
                rig.close()


def numpy_excess_s(steps: Sequence[PlannedStep]) -> float:
    """What the simulated bench's numpy code would cost over the compiled code to play
    ``steps`` and their rests (CPU s): :data:`NUMPY_BLOCK_S` per block of :data:`BLOCK_S` plus
    :data:`NUMPY_SAMPLE_S` per sample."""
    out = 0.0
    for st in steps:
        seconds = st.duration_s + st.rest_after_s
        out += seconds / BLOCK_S * NUMPY_BLOCK_S + seconds * st.rate_hz * NUMPY_SAMPLE_S
    return out


def repays_kernels(steps: Sequence[PlannedStep]) -> bool:
    """Whether playing ``steps`` on a simulated rig repays numba's start: the numpy code's
    excess (:func:`numpy_excess_s`) above :data:`NUMBA_START_S`. Such a run loads the compiled
    kernels before its rig opens, so the bench runs the model on them
    (:func:`labrig.model.accel.stream_engine`)."""
    return numpy_excess_s(steps) > NUMBA_START_S


def _long_simulation(job: _Job) -> bool:
    """The job repays numba's start (:func:`repays_kernels`) on a simulated rig."""
    return repays_kernels(job.steps) and load_rig(job.rig_path).simulated


@dataclass
class _Job:
    """What :func:`execute` was asked to do."""

    plan: Plan
    rig_path: Path | None
    realtime: bool
    progress: ProgressFn | None
    overwrite: bool
    on_file: Callable[[Path], None] | None
    metadata: RunMetadata = field(default_factory=RunMetadata)
    resume: ResumePlan | None = None
    #: the options given to a resume (recorded with it)
    options: RunMetadata = field(default_factory=RunMetadata)
    #: the run file's name was chosen here, not given: another free name will do
    default_name: bool = False

    @property
    def steps(self) -> list[PlannedStep]:
        """The steps to play: all, or a resume's remaining ones."""
        if self.resume is None:
            return list(self.plan.steps)
        return [self.plan.step(n) for n in self.resume.to_run]


@dataclass
class _Setup:
    ai: list[str]
    chans: list[Channel]


def _prepare(rig: Rig, plan: Plan, realtime: bool) -> _Setup:
    """Devices ready, nothing energised: health, channels, DAQ rate, conditioner balance."""
    if realtime and hasattr(rig.daq, "realtime"):
        rig.daq.realtime = True
    rig.check()
    ai, chans = _channels(rig)
    rig.daq.configure(plan.rate_hz, ["gauge", *[c for c in ai if c != "gauge"]])
    rig.conditioner.zero()
    return _Setup(ai, chans)


def _check_disk(job: _Job, rig: Rig, out: Path, chans: list[Channel]) -> None:
    """Refuse (exit 2, before anything is energised) a run whose file cannot fit on the disk
    that holds ``out``: the estimated size plus the reserve (plus the copy a resume writes)
    against the free space."""
    entries = [
        (s.n_samples, s.rate_hz, 1 + len(chans) + len(getattr(s, "aux", None) or {}))
        for s in job.steps
    ]
    need = estimate_run_bytes(entries, len(job.plan.text) + len(rig.rig_text)) + RESERVE_BYTES
    if job.resume is not None:
        need += job.resume.size_bytes
    free = free_bytes(out)  # with --overwrite the old file stays until the new one is complete
    if free < need:
        samples = sum(e[0] for e in entries)
        raise InputFileError(
            [
                InputIssue(
                    str(out),
                    None,
                    "--out",
                    f"not enough disk space: {free / 1e6:.2f} MB free where the run file goes, "
                    f"the run needs about {need / 1e6:.2f} MB ({len(entries)} entries, "
                    f"{samples} samples); free some space or choose another --out",
                )
            ]
        )


def instrument_description(rig: Rig) -> dict:
    """The rig's description with every device's identity (``*IDN?``, the conditioner's
    identity registers, the DAQ's name), asked of a device whose description lacks it."""
    desc = rig.describe()
    for role in ("daq", "amplifier", "conditioner"):
        dev = desc.get(role)
        if isinstance(dev, dict) and not dev.get("identity"):
            try:
                dev["identity"] = str(getattr(rig, role).identify())
            except Exception as e:  # describing must never stop a run
                dev["identity_error"] = str(e) or type(e).__name__
    return desc


def _cannot_create(out: Path, e: OSError, option: str = "--out") -> InputFileError:
    why = e.strerror or str(e)
    return InputFileError(
        [InputIssue(str(out), None, option, f"cannot create the run file: {why}")]
    )


def _open_writer(
    job: _Job, rig: Rig, out: Path, chans: list[Channel], staged: Staged | None
) -> RunWriter:
    """The run file, once its place exists and has room for it (InputFileError otherwise);
    written at ``staged``'s place for ``out`` when it replaces an existing file."""
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise _cannot_create(out, e) from None
    _check_disk(job, rig, out, chans)
    plan = job.plan
    try:
        return RunWriter(
            staged.path(out) if staged is not None else out,
            plan.text,
            rig.rig_text,
            instrument_description(rig),
            rig.seed,
            __version__,
            protocol_name=plan.name,
            protocol_file=str(plan.path),
            rig_file=str(job.rig_path or ""),
            planned_entries=[s.name for s in plan.steps],
            overwrite=job.overwrite,
            reserve_bytes=RESERVE_BYTES,
            metadata=job.metadata,
        )
    except FileExistsError:
        raise
    except OSError as e:  # unwritable --out (a directory, no permission, no such place)
        raise _cannot_create(out, e) from None


def _reopen_writer(
    job: _Job, rig: Rig, out: Path, chans: list[Channel], staged: Staged
) -> RunWriter:
    """A resume's writer: ``out`` copied beside itself, the copy reopened and the resume
    recorded in it (:mod:`labrig.store.resume`)."""
    assert job.resume is not None
    _check_disk(job, rig, out, chans)
    copy = staged.path(out)
    try:
        shutil.copyfile(out, copy)
        writer = RunWriter.reopen(copy, job.metadata, reserve_bytes=RESERVE_BYTES)
    except OSError as e:
        raise _cannot_create(out, e, "--resume") from None
    try:
        desc = instrument_description(rig)
        record_resume(
            writer.root, job.resume, rig.seed, __version__, os.getpid(), desc, job.options
        )
        writer.seal_and_flush()
    except BaseException:
        writer.close()
        raise
    return writer


def _free_name(job: _Job, out: Path) -> Path:
    """``out``, or when its name was chosen here and another run has taken it meanwhile (two
    runs started in one second), the next free name."""
    if job.default_name and out.exists():
        return default_out_path(job.plan, out.parent)
    return out


def _run_on(rig: Rig, job: _Job, out: Path, guard: SignalGuard) -> RunOutcome:
    """The run proper, with stop signals deferred (checked between blocks)."""
    setup = _prepare(rig, job.plan, job.realtime)
    guard.check()  # a stop signal during the setup: nothing written, nothing energised
    if job.resume is not None:
        check_same_rig(job.resume, rig.rig_text, str(job.rig_path or ""))
        staged: Staged | None = stage([out], overwrite=True, option="--resume")
    else:
        out = _free_name(job, out)
        # a file that appeared since check_run_output: refused unless --overwrite
        check_run_output(job.plan, job.rig_path, out, job.overwrite)
        # --overwrite: the new file is written beside the old one and replaces it once closed
        replace = job.overwrite and out.exists()
        staged = stage([out], overwrite=True, being_written=being_written) if replace else None
    try:
        if job.resume is not None and staged is not None:
            writer = _reopen_writer(job, rig, out, setup.chans, staged)
        else:
            writer = _open_writer(job, rig, out, setup.chans, staged)
        if job.on_file is not None:
            job.on_file(writer.path)
        outcome = _record(rig, job, writer, setup, out, guard)
    except BaseException:
        if staged is not None:
            staged.discard()
        raise
    if staged is not None and writer.lost:  # the new file is not what was written: not put
        staged.discard()  # in place of the old one
        outcome.reason += f"; {out} is kept as it was"
    elif staged is not None:
        _replace(staged, outcome)
    return outcome


def _replace(staged: Staged, outcome: RunOutcome) -> None:
    """Put the new run file in place of the old one, whatever the outcome (it records what
    the rig did); if that fails, keep it where it is and say so (exit 3 if it was 0)."""
    try:
        staged.commit()
    except InputFileError as e:
        kept = staged.path(outcome.path)
        outcome.reason += f"; {e}; the new run file is {kept}"
        outcome.path = kept
        outcome.exit_code = outcome.exit_code or 3
        return
    staged.discard()


def _record(
    rig: Rig, job: _Job, writer: RunWriter, setup: _Setup, out: Path, guard: SignalGuard
) -> RunOutcome:
    """Energise, play every step into ``writer``, and end the same way on every path
    (module docstring)."""
    outcome = RunOutcome(path=out, status="running", seed=rig.seed)
    steps = job.steps
    with writer:
        try:
            guard.check()
            rig.amplifier.enable()
            left = sum(s.duration_s + s.rest_after_s for s in steps)
            n = len(steps)
            for k, step in enumerate(steps):
                guard.check()
                _run_step(rig, writer, step, setup.ai, setup.chans, job.progress, k, n, left, guard)
                outcome.entries.append(step.name)
                left -= step.duration_s
                if step.rest_after_s > 0:
                    _rest(rig, step, writer, job.progress, k, n, left, guard)
                    left -= step.rest_after_s
            status, reason, code = "complete", "", 0
        except KeyboardInterrupt as e:
            sig = signum_of(e)
            status, reason, code = "aborted", reason_for(sig), exit_code_for(sig)
        except LabrigError as e:
            status, reason, code = "failed", str(e), e.exit_code
        except Exception as e:
            status, reason, code = "failed", f"{type(e).__name__}: {e}", 1
            if is_disk_full(e):  # HDF5 met the full disk outside a wrapped write
                full = StorageError(str(out), "writing the run file", DISK_FULL)
                status, reason, code = "failed", f"{full} ({reason})", full.exit_code
        ramp = rig.ramp_to_zero()
        reason = _late_signals(guard, status, reason)
        problems = record_end(writer, rig, ramp, status, reason, code)
    if writer.close_error:
        problems.append(writer.close_error)
    lost = writer.lost or writer.problem()  # (after its last block's check: the ramp, the close)
    if status == "complete" and lost:
        gone = StorageError(str(out), "closing the run file", lost)
        status, reason, code = "failed", str(gone), gone.exit_code
    outcome.status, outcome.reason, outcome.exit_code = status, reason, code
    if problems:
        outcome.reason += "; the run file could not record its end: " + "; ".join(problems)
    return outcome


def _late_signals(guard: SignalGuard, status: str, reason: str) -> str:
    """Name stop signals that arrived while the run was already ending for another cause."""
    if status == "aborted" or not guard.received:
        return reason
    late = ", ".join(dict.fromkeys(reason_for(s).split(" (")[0] for s in guard.received))
    note = f"stop signal(s) during the shutdown ({late}) waited for the output to reach 0 V"
    return f"{reason}; {note}" if reason else note
