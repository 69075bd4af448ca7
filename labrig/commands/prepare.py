"""A run file's records as an analysis command fits and scores them: :func:`prepare` for ``fit``
and ``report``, :func:`training_setup` for several files fitted together (``validate``),
:func:`prepare_diagnosis` for ``diagnose``.

How a run file's entries are treated (:func:`prepare`):

- **Rig runs** (entries recorded by ``labrig run``: a DAQ-driven, zero-order-hold voltage, one
  sample rate): the actuator's memory spans the entries and the 0 V rests between them, so the
  entries are simulated back to back as the run (``chain``), each followed by the rest recorded
  in its step definition; entries that are not scored (not chosen with ``--entries``, or not
  complete) still drive the simulation as history. The run starts at rest: no warm-up, no
  offset (the conditioner is zeroed at rest).
- **Imported data** (``labrig import``: a measured voltage, linear hold, unrelated files): every
  entry on its own, from rest at 0 V; one constant strain offset per entry is fitted (the
  sensor's zero is arbitrary); when a record does not start at rest (its first voltage is not
  near 0 V) the first two drive periods are a warm-up, simulated but not scored
  (:func:`auto_warmup`).

``--warmup-s`` and ``--offset/--no-offset`` override the automatic choices; every choice is
stated in :attr:`Setup.notes` (the commands print them and the report shows them).

Data that cannot be fitted is refused before any fit (:func:`check_records`, exit code 2,
naming the entry and what would be valid): a sample rate outside :data:`RATE_RANGE_HZ`;
a non-finite time, voltage or scored strain sample, or one beyond :data:`MAX_ABS_VOLTAGE_V` or
:data:`MAX_ABS_STRAIN_UE`; a scored entry of fewer than
:data:`MIN_SAMPLES` samples; a voltage that spans less than :data:`MIN_VOLTAGE_SPAN_V` over the
scored entries (and over each entry simulated on its own); a scored strain that does not
change, or that does not follow the voltage (:func:`response_share` below
:data:`MIN_RESPONSE_SHARE`); a step definition whose ``rest_after_s`` is not a number from 0 to
:data:`MAX_REST_S`.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from labrig.analysis import load
from labrig.analysis.metrics import drive_frequency_hz
from labrig.analysis.records import Record, unit_of, warmup_samples
from labrig.analysis.split import split_entries
from labrig.core.errors import InputFileError, InputIssue, LabrigError, option_error
from labrig.model import ModelParams
from labrig.store import RunFile, read_run

#: fewest entries ``diagnose`` scores (leave-one-entry-out needs some left in)
MIN_DIAGNOSE_ENTRIES = 3
#: fewest samples in an entry that is scored
MIN_SAMPLES = 20
#: the least voltage span (V) over the scored entries, and over each entry simulated on its own
MIN_VOLTAGE_SPAN_V = 1.0
#: sample rates fitted (Hz): those ``labrig import`` accepts
RATE_RANGE_HZ = (1e-3, 1e8)
#: the longest rest after an entry (``rest_after_s``, s) simulated
MAX_REST_S = 3600.0
#: the largest |voltage| (V) and |strain| (ue) a sample may have: far beyond any piezo actuator
#: (kilovolts, a few thousand ue), a bound that keeps sums of squares finite; a larger sample is
#: a units mistake or a damaged value (an imported 1e300 made the fit divide by zero)
MAX_ABS_VOLTAGE_V = 1e5
MAX_ABS_STRAIN_UE = 1e7
#: a run file of a single entry is cut into this many parts for ``diagnose``
DIAGNOSE_SPLIT = 4
#: the least share of a scored strain's variance that a linear response to the voltage must
#: explain (:func:`response_share`, adjusted R^2). Measured (docs/analysis.md, "A strain that
#: does not follow the voltage"): every legitimate record 0.878 or more (the simulated
#: experiments 0.978, the real records 0.9975), strains that ignore the drive 0.04 or less
MIN_RESPONSE_SHARE = 0.25
#: the longest stretch of samples :func:`response_share` reads at a time (bounds its memory)
RESPONSE_CHUNK = 1 << 16


class AnalysisError(LabrigError):
    """The data cannot be fitted as asked (exit code 2)."""

    exit_code = 2


@dataclass
class Setup:
    """The records of a run file and how to fit them (module docstring)."""

    path: Path
    run: RunFile
    records: list[Record]  # simulated, in run order (with chain: history included)
    scored: list[str]  # fitted and scored
    chain: bool
    warmup_s: float
    offset: bool
    imported: bool
    notes: list[str] = field(default_factory=list)

    @property
    def scored_records(self) -> list[Record]:
        keep = set(self.scored)
        return [r for r in self.records if r.name in keep]


def _issue(path: Path, message: str, fld: str = "") -> InputFileError:
    return InputFileError([InputIssue(str(path), None, fld, message)])


def parse_entries(text: str | None) -> list[str] | None:
    """``--entries a,b``: the names, or ``None`` for every complete entry."""
    if text is None:
        return None
    names = [n.strip() for n in text.split(",") if n.strip()]
    return names or None


def auto_warmup(records: Sequence[Record]) -> tuple[float, str | None]:
    """Two drive periods (s, at the lowest drive frequency; at most a quarter of the shortest
    record) when a record does not start at rest, else 0; and why, for the notes."""
    late = []
    for r in records:
        span = float(np.ptp(r.voltage_V)) or 1.0
        if abs(float(r.voltage_V[0])) > 0.01 * span:
            late.append(r)
    if not late:
        return 0.0, None
    fs = [f for f in (drive_frequency_hz(r) for r in records) if f]
    w = 2.0 / min(fs) if fs else 1.0
    shortest = min(r.duration_s for r in records)
    w = min(w, 0.25 * shortest)
    w = float(f"{w:.3g}")
    first = late[0]
    if len(records) == 1:
        some = f"{first.name} does not start at rest (it starts"
    else:
        some = f"{len(late)} of {len(records)} records do not start at rest (e.g. {first.name}"
        some += " starts"
    why = (
        f"{some} at {first.voltage_V[0]:.3g} V): the first {w:g} s of every record are "
        "simulated but not scored (warm-up; --warmup-s to change)"
    )
    return w, why


def prepare(
    path: Path,
    entries: list[str] | None = None,
    warmup_s: float | None = None,
    offset: bool | None = None,
    run: RunFile | None = None,
) -> Setup:
    """Read the run file and decide chain, warm-up and offset (module docstring). ``run``:
    the file as already read (one snapshot for several steps of a command), else read now."""
    run = read_run(path) if run is None else run
    names = list(run.entries)
    if not names:
        raise _issue(path, "the run file has no entries")
    _check_entries(path, names, entries)
    complete = [n for n in names if run[n].complete]
    all_recs = load.records_of(run, path, names)  # incomplete ones too (history of a chain)
    by_name = {r.name: r for r in all_recs}
    if entries:
        unusable = [n for n in entries if n not in by_name]
        if unusable:
            raise _issue(
                path,
                f"entry {unusable[0]!r} has no voltage and strain (to fit or to score)",
                "--entries",
            )
        scored = [n for n in names if n in set(entries)]
    else:
        scored = [n for n in names if n in by_name and n in set(complete)]
    if not scored:
        raise _issue(path, "no complete entry with voltage and strain (to fit or to score)")
    notes: list[str] = []
    skipped = [n for n in names if n not in complete and n not in scored]
    if skipped:
        notes.append(
            f"not complete, not scored (name them with --entries to score them anyway): "
            f"{', '.join(skipped)}"
        )
    imported = all(
        r.hold == "linear" or r.meta.get("kind") == "import" for r in all_recs if r.name in scored
    )
    chain = (
        not imported
        and all(r.hold == "zoh" for r in all_recs)
        and len({r.rate_hz for r in all_recs}) == 1
    )
    if not imported and not chain:
        notes.append("entries differ in sample rate or hold: each is simulated on its own")
    if chain:
        records = all_recs
        history = [r.name for r in records if r.name not in set(scored)]
        if history:
            notes.append(f"not scored, simulated as history of the run: {', '.join(history)}")
    else:
        records = [by_name[n] for n in scored]
    check_records(path, records, scored, alone=not chain)
    warmup = _warmup(path, records, chain, warmup_s, notes)
    offset = _offset(imported, offset, notes)
    _check_scored_samples(path, [r for r in records if r.name in set(scored)], warmup)
    return Setup(path, run, records, scored, chain, warmup, offset, imported, notes)


def training_setup(
    paths: Sequence[Path],
    warmup_s: float | None = None,
    offset: bool | None = None,
) -> Setup:
    """The training records of ``paths`` as one :class:`~labrig.commands.prepare.Setup`: one
        file as ``labrig fit`` prepares it; several files (each entry simulated on its own) put
        together, an entry renamed ``STEM:ENTRY`` where names repeat (``PATH:ENTRY`` where stems
    do too), with one warm-up
        (:func:`~labrig.commands.prepare.auto_warmup` over them all, unless given) and an offset per
        entry when any file gets one."""
    setups = [prepare(Path(p), None, warmup_s, offset) for p in paths]
    if len(setups) == 1:
        return setups[0]
    chained = next((s for s in setups if s.chain), None)
    if chained is not None:
        raise _issue(
            chained.path,
            "a recorded run is simulated as one chain of its entries and cannot be fitted "
            "together with other files: give it as the only training file (--leave-one-out "
            "takes imported records, one per file; `labrig diagnose RUN` leaves one entry of a "
            "recorded run out at a time)",
            "TRAIN",
        )
    counts: dict[str, int] = {}
    for s in setups:
        for r in s.scored_records:
            counts[r.name] = counts.get(r.name, 0) + 1
    stems = [s.path.stem for s in setups]
    records: list[Record] = []
    notes: list[str] = []
    for s in setups:
        prefix = s.path.stem if stems.count(s.path.stem) == 1 else str(s.path)
        for r in s.scored_records:
            name = r.name if counts[r.name] == 1 else f"{prefix}:{r.name}"
            records.append(dataclasses.replace(r, name=name))
        notes += [f"{s.path.name}: {n}" for n in s.notes if "warm-up" not in n]
    if warmup_s is None:
        warm, why = auto_warmup(records)
        if why:
            notes.append(why)
    else:
        warm = float(warmup_s)
    first = setups[0]
    return Setup(
        first.path,
        first.run,
        records,
        [r.name for r in records],
        False,
        warm,
        any(s.offset for s in setups),
        all(s.imported for s in setups),
        notes,
    )


def check_records(
    path: Path, records: Sequence[Record], scored: Sequence[str], alone: bool
) -> None:
    """Refuse data that cannot be fitted (module docstring), every problem at once, each
    naming the entry: ``records`` are simulated, ``scored`` of them fitted; ``alone``: each
    record is simulated on its own (from rest), so each must move its voltage."""
    keep = set(scored)
    issues = unit_issues([(path, r) for r in records if r.name in keep])
    for r in records:
        issues += _record_issues(path, r, r.name in keep, alone)
    fitted = [r for r in records if r.name in keep]
    if fitted and not issues:
        span = max(float(np.max(r.voltage_V)) for r in fitted) - min(
            float(np.min(r.voltage_V)) for r in fitted
        )
        if span < MIN_VOLTAGE_SPAN_V:
            issues.append(
                InputIssue(
                    str(path),
                    None,
                    "command_voltage",
                    f"the voltage spans {span:.3g} V over the entries to fit; at least "
                    f"{MIN_VOLTAGE_SPAN_V:g} V is needed (nothing drives the actuator)",
                )
            )
    if issues:
        raise InputFileError(issues)


def _in_volts(unit: str) -> bool:
    """``""`` (the run file's unit), ``V``, or another spelling of volts (``v``, ``Vdc``: files
    an earlier import kept as they were)."""
    if unit in ("", "V"):
        return True
    from labrig.importers.units import parse_unit

    u = parse_unit(unit)
    return u.kind == "voltage" and u.pint_unit is not None and str(u.pint_unit) == "volt"


def unit_issues(records: Sequence[tuple[Path, Record]]) -> list[InputIssue]:
    """Units that make records unfit to fit or score together (each with its file): a voltage
    not in V (the model's input is volts), and strains in more than one unit (one model, one
    NRMSE: ``ue`` beside ``raw`` numbers would mix scales). ``""`` (a unit not stated) counts
    as V and ue, the run file's units."""
    out = []
    for path, r in records:
        if not _in_volts(unit_of(r, "command_voltage")):
            out.append(
                InputIssue(
                    str(path),
                    None,
                    f"{r.name}/command_voltage",
                    f"in {unit_of(r, 'command_voltage')!r}, not V: the model's input is volts "
                    "(labrig import converts mV and kV, and --voltage-scale turns raw numbers "
                    "into volts)",
                )
            )
    strain = {(path, r.name): unit_of(r, "strain") or "ue" for path, r in records}
    if len(set(strain.values())) > 1:
        (p0, n0), u0 = next(iter(strain.items()))
        for (path, name), u in strain.items():
            if u != u0:
                out.append(
                    InputIssue(
                        str(path),
                        None,
                        f"{name}/strain",
                        f"in {u!r}, but {n0!r} ({Path(p0).name}) is in {u0!r}: records fitted "
                        "or scored together need one strain unit (import them with the same "
                        "--strain-units, or convert one with --strain-scale)",
                    )
                )
    return out


#: the magnitude bound of each channel checked by :func:`check_records` (bound, unit)
LIMITS = {"command_voltage": (MAX_ABS_VOLTAGE_V, "V"), "strain": (MAX_ABS_STRAIN_UE, "ue")}


def response_lags(n: int) -> list[int]:
    """The delays (samples) of the voltage :func:`response_share` regresses on for a record of
    ``n`` samples: 0 and the powers of two up to a quarter of the record."""
    lags = [0]
    while 2 * lags[-1] <= n // 4 and n >= 4:
        lags.append(max(1, 2 * lags[-1]))
    return lags


def response_share(voltage: np.ndarray, strain: np.ndarray) -> float:
    """The share of the strain's variance that a linear time-invariant response to the voltage
    explains: the adjusted R^2 of the least-squares fit of ``strain`` by a constant and the
    voltage delayed by each of :func:`response_lags` (an FIR response; before the first sample
    the voltage is held at its first value). The delays let a response that lags the drive (a
    loop's opening, a low-pass, a resonance, a 40 Hz sine through the harmonic relaxor, whose
    strain is uncorrelated with the voltage at the same instant) count in full; adjusted for
    the number of delays, so noise that ignores the drive scores about 0 (it can be slightly
    negative). ``strain`` must not be constant."""
    v = np.asarray(voltage, dtype=np.float64)
    s = np.asarray(strain, dtype=np.float64)
    n = v.size
    v = (v - np.mean(v)) / (float(np.ptp(v)) or 1.0)
    s = (s - np.mean(s)) / float(np.ptp(s))
    lags = response_lags(n)
    k = len(lags) + 1  # the delays and the constant
    gram = np.zeros((k, k))
    cross = np.zeros(k)
    for i0 in range(0, n, RESPONSE_CHUNK):
        i1 = min(n, i0 + RESPONSE_CHUNK)
        x = np.column_stack([np.ones(i1 - i0), *(_delayed(v, d, i0, i1) for d in lags)])
        gram += x.T @ x
        cross += x.T @ s[i0:i1]
    coef = np.linalg.lstsq(gram, cross, rcond=1e-12)[0]
    total = float(s @ s)
    explained = min(float(coef @ cross) / total, 1.0)
    dof = n - k
    if dof <= 0:
        return explained
    return 1.0 - (1.0 - explained) * (n - 1) / dof


def _delayed(v: np.ndarray, d: int, i0: int, i1: int) -> np.ndarray:
    """``v[i - d]`` for ``i`` from ``i0`` to ``i1 - 1``, ``v[0]`` before the first sample."""
    if i0 >= d:
        return v[i0 - d : i1 - d]
    head = np.full(min(d, i1) - i0, v[0])
    return np.concatenate([head, v[: max(i1 - d, 0)]])


def _record_issues(path: Path, r: Record, scored: bool, alone: bool) -> list[InputIssue]:
    """What makes one record unfit to simulate (and, when ``scored``, to fit)."""

    def issue(fld: str, message: str) -> InputIssue:
        return InputIssue(str(path), None, f"{r.name}/{fld}", message)

    lo, hi = RATE_RANGE_HZ
    if not lo <= r.rate_hz <= hi:
        return [issue("sample_rate", f"{r.rate_hz:.4g} Hz is outside {lo:g} to {hi:g} Hz")]
    out = []
    channels = [("time", r.time_s), ("command_voltage", r.voltage_V)]
    for name, x in [*channels, *([("strain", r.strain_ue)] if scored else [])]:
        bad = np.flatnonzero(~np.isfinite(x))
        bound, unit = LIMITS.get(name, (np.inf, ""))
        if bad.size:
            out.append(
                issue(
                    f"data/{name}",
                    f"{bad.size} non-finite sample(s) (first at sample {bad[0]}: {x[bad[0]]}); "
                    "every sample must be a finite number",
                )
            )
        elif (huge := np.flatnonzero(np.abs(x) > bound)).size:
            out.append(
                issue(
                    f"data/{name}",
                    f"{huge.size} sample(s) beyond +-{bound:g} {unit} (first at sample "
                    f"{huge[0]}: {x[huge[0]]:.4g}), far beyond any piezo actuator: a damaged "
                    "value, or a column in other units (labrig import's --*-scale)",
                )
            )
    rest = r.meta.get("rest_after_s", 0.0)
    if not (
        isinstance(rest, int | float) and not isinstance(rest, bool) and 0 <= rest <= MAX_REST_S
    ):
        out.append(
            issue(
                "step_definition",
                f"rest_after_s must be a number of seconds from 0 to {MAX_REST_S:g}, "
                f"got {str(rest)[:40]!r}",
            )
        )
    if out or not scored:
        return out
    if r.n < MIN_SAMPLES:
        out.append(issue("data", f"{r.n} samples; an entry to fit needs at least {MIN_SAMPLES}"))
    elif np.ptp(r.strain_ue) == 0:
        out.append(issue("data/strain", f"the strain is constant ({r.strain_ue[0]:.4g})"))
    elif alone and np.ptp(r.voltage_V) < MIN_VOLTAGE_SPAN_V:
        out.append(
            issue(
                "data/command_voltage",
                f"the voltage spans {np.ptp(r.voltage_V):.3g} V; an entry fitted on its own "
                f"needs at least {MIN_VOLTAGE_SPAN_V:g} V",
            )
        )
    elif np.ptp(r.voltage_V) >= MIN_VOLTAGE_SPAN_V:
        keep = _typical(r.voltage_V) & _typical(r.strain_ue)
        if np.ptp(r.voltage_V[keep]) < MIN_VOLTAGE_SPAN_V or np.ptp(r.strain_ue[keep]) == 0:
            keep = np.ones(r.n, dtype=bool)  # the drive (or the strain) is in the few: all
        share = response_share(r.voltage_V[keep], r.strain_ue[keep])
        if share < MIN_RESPONSE_SHARE:
            out.append(issue("data/strain", _not_following(r, share)))
    return out


#: a sample farther from its channel's median than this many of the channel's 10-90 %
#: spread is an outlier for :func:`response_share` ...
OUTLIER_SPREADS = 10.0
#: ... when such samples are at most this share of the record (a damaged value or a spike
#: that the magnitude bound lets through; more of them are the record)
OUTLIER_SHARE = 0.01


def _typical(x: np.ndarray) -> np.ndarray:
    """The samples of ``x`` that are not lone outliers (:data:`OUTLIER_SPREADS`,
    :data:`OUTLIER_SHARE`): whether the strain follows the voltage is judged without them, so
    one spike of 1e7 ue in a 900 ue record does not read as a strain that ignores its drive
    (the magnitude bound names such a sample when it is past it)."""
    lo, med, hi = np.percentile(x, [10.0, 50.0, 90.0])
    far = np.abs(x - med) > OUTLIER_SPREADS * (hi - lo)
    if np.count_nonzero(far) > max(1, int(OUTLIER_SHARE * x.size)):
        return np.ones(x.size, dtype=bool)
    return ~far


def _not_following(r: Record, share: float) -> str:
    """Why a strain that does not follow its voltage (:func:`response_share`) is refused."""
    unit = unit_of(r, "strain") or "ue"
    return (
        f"the strain does not follow the voltage: a linear response to the voltage (now and up "
        f"to {response_lags(r.n)[-1]} samples earlier) explains {100 * max(share, 0.0):.1f} % "
        f"of the strain's variance; at least {100 * MIN_RESPONSE_SHARE:g} % is needed (the "
        f"voltage spans {np.ptp(r.voltage_V):.3g} V, the strain {np.ptp(r.strain_ue):.3g} "
        f"{unit}). A driven actuator's strain rises and falls with its voltage: a sensor not "
        "connected or not powered, the wrong column (labrig import --strain N, --voltage N) or "
        "a record of noise alone gives this (fit and report: --entries leaves the entry out)"
    )


def _check_entries(path: Path, names: list[str], entries: list[str] | None) -> None:
    """``--entries`` names entries of the file, each once."""
    if not entries:
        return
    missing = [n for n in entries if n not in names]
    if missing:
        raise _issue(
            path,
            f"no entry {', '.join(map(repr, missing))} (entries: {', '.join(names)})",
            "--entries",
        )
    twice = sorted(n for n, k in Counter(entries).items() if k > 1)
    if twice:
        raise _issue(path, f"{', '.join(map(repr, twice))} named twice; name each entry once",
                     "--entries")  # fmt: skip


def _check_scored_samples(path: Path, scored: Sequence[Record], warmup_s: float) -> None:
    """Every scored record keeps at least :data:`MIN_SAMPLES` samples after the warm-up
    (:func:`~labrig.analysis.records.warmup_samples`); else an
    :class:`~labrig.core.errors.InputFileError` naming each that does not, the samples it
    keeps and the minimum."""
    issues = []
    for r in scored:
        left = r.n - warmup_samples(r, warmup_s)
        if left < MIN_SAMPLES:
            issues.append(
                InputIssue(
                    str(path),
                    None,
                    f"{r.name}/data",
                    f"the warm-up of {warmup_s:g} s leaves {max(left, 0)} of its {r.n} samples "
                    f"to score; an entry to fit needs at least {MIN_SAMPLES} (a shorter "
                    "--warmup-s)",
                )
            )
    if issues:
        raise InputFileError(issues)


def _warmup(
    path: Path, records: list[Record], chain: bool, warmup_s: float | None, notes: list[str]
) -> float:
    """The warm-up (s): ``--warmup-s`` when given (checked), else 0 for a chained run and
    :func:`auto_warmup` otherwise; the choice is added to ``notes``."""
    if warmup_s is None:
        if chain:
            return 0.0
        warmup, why = auto_warmup(records)
        if why:
            notes.append(why)
        return float(warmup)
    if warmup_s < 0 or not math.isfinite(warmup_s):
        raise option_error("--warmup-s", f"{warmup_s}: expected seconds >= 0")
    if warmup_s > 0:
        notes.append(f"warm-up: the first {warmup_s:g} s of each record are not scored")
    return float(warmup_s)


def _offset(imported: bool, offset: bool | None, notes: list[str]) -> bool:
    """One strain offset per entry: ``--offset/--no-offset`` when given, else for imported
    data; the choice is added to ``notes``."""
    if offset is None:
        if imported:
            notes.append(
                "imported data: one constant strain offset per entry is fitted (the sensor's "
                "zero is unknown; --no-offset to change)"
            )
        return imported
    if offset:
        notes.append("one constant strain offset per entry is fitted (--offset)")
    return bool(offset)


@dataclass
class DiagnoseSetup:
    """What ``diagnose`` starts from: the records it scores, whether to fit one strain offset
    per entry, and the start parameters (``None``: the diagnosis fits its own)."""

    records: list[Record]
    offset: bool
    start: ModelParams | None


def prepare_diagnosis(
    path: Path,
    params_file: Path | None = None,
    say: Callable[[str], None] = print,
    run: RunFile | None = None,
) -> DiagnoseSetup:
    """Read the run file (and the start parameters,
    :func:`labrig.analysis.params_file.start_params`) for ``diagnose``.

    A file of one entry is cut into :data:`DIAGNOSE_SPLIT` consecutive parts
    (:func:`split_entries`, said through ``say``) for leave-one-entry-out; imported data get an
    offset per entry (the sensor's zero is arbitrary). Fewer than :data:`MIN_DIAGNOSE_ENTRIES`
    entries: an :class:`~labrig.core.errors.InputFileError`. ``run``: the file as already
    read (the snapshot the fit of the same command used), else read now."""
    from labrig.analysis.params_file import start_params

    records = load.records_of(run, path) if run is not None else load.records_from_run(path)
    start = start_params(params_file, say) if params_file is not None else None
    if len(records) == 1 and records[0].duration_s > 0:
        one = records[0]
        if one.n < DIAGNOSE_SPLIT * MIN_SAMPLES:
            raise _issue(
                path,
                f"{one.n} samples: diagnose cuts a file's single entry into {DIAGNOSE_SPLIT} "
                f"parts of at least {MIN_SAMPLES} samples ({DIAGNOSE_SPLIT * MIN_SAMPLES} in "
                "all); record a longer entry, or fit this one (`labrig fit`)",
                f"{one.name}/data",
            )
        # the entry as the file holds it first: a problem is named by the entry, not a part
        check_records(path, records, [one.name], alone="rest_after_s" not in one.meta)
        records = split_entries(records, DIAGNOSE_SPLIT)
        idle = records[0].meta.get("idle_lead_s")
        if idle:
            say(
                f"one entry: its first {idle:.3g} s held at {records[0].rest_V:.3g} V (no drive) "
                "left out: the parts start from rest where the voltage first moves"
            )
        hold = records[-1].meta.get("idle_trail_s")
        if hold:
            say(
                f"one entry: its last {hold:.3g} s held at {records[-1].voltage_V[-1]:.3g} V kept "
                "as the last part's tail: the parts are cut over the driven stretch"
            )
        say(f"one entry: cut into {len(records)} consecutive parts for leave-one-entry-out")
    chained = all("rest_after_s" in r.meta for r in records)
    check_records(path, records, [r.name for r in records], alone=not chained)
    offset = any(r.meta.get("kind") == "import" for r in records)
    if len(records) < MIN_DIAGNOSE_ENTRIES:
        raise _issue(
            path,
            f"diagnose needs at least {MIN_DIAGNOSE_ENTRIES} complete entries "
            f"(leave-one-entry-out), found {len(records)}; a file of one entry is cut into "
            f"{DIAGNOSE_SPLIT} parts, so import each record on its own (`labrig import FILE "
            "--out F.h5 ...`), or identify on one and predict the other (`labrig validate "
            "A.h5 --on B.h5 --diagnose`)",
            "entries",
        )
    return DiagnoseSetup(records, offset, start)
