"""Run files to analysis records: the one place the analysis reads HDF5 (via labrig.store)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from labrig.analysis.records import Record
from labrig.core.errors import InputFileError, InputIssue
from labrig.store import RunEntry, RunFile, read_run

_CORE = {"time", "command_voltage", "strain"}


def records_from_run(path: Path | str, entries: list[str] | None = None) -> list[Record]:
    """Entries of a run file as :class:`Record` objects, in file order.

    The voltage is ``command_voltage`` (the DAQ's ZOH drive for a run, hold ``"zoh"``; a
    measured voltage for imported data, hold ``"linear"`` as its step definition says). Other
    channels (``amplifier_voltage``, ``temperature``, ``gauge_raw``, ...) go to ``aux``; the
    step definition (``frequency_hz``, ``amplitude_V``, ``kind``...) goes to ``meta``.
    Entries that did not complete are skipped unless named explicitly.
    """
    return records_of(read_run(path), path, entries)


def record_of(e: RunEntry) -> Record | None:
    """One entry as a :class:`Record` (``None`` without voltage and strain, or under 2
    samples): the step definition in ``meta`` (with the channels' ``units``), the other
    channels in ``aux``."""
    if "strain" not in e.data or "command_voltage" not in e.data or e.n_samples < 2:
        return None
    meta = dict(e.step)
    meta["units"] = dict(e.units)
    hold = meta.get("hold", "zoh")
    return Record(
        name=e.name,
        rate_hz=e.rate_hz,
        time_s=e.time,
        voltage_V=e["command_voltage"],
        strain_ue=e["strain"],
        aux={k: v for k, v in e.data.items() if k not in _CORE},
        hold=hold if hold in ("zoh", "linear") else "zoh",
        meta=meta,
    )


def as_records(target: Any) -> tuple[list[Record], bool]:
    """What a fitted model can predict, as records, and whether it was one record: a
    :class:`Record` or a run file's entry (one), or a run (``labrig.Run`` or anything with a
    ``records()`` method; a :class:`~labrig.store.RunFile`: its complete entries)."""
    if isinstance(target, Record):
        return [target], True
    if isinstance(target, RunEntry):
        r = record_of(target)
        if r is None:
            raise ValueError(f"entry {target.name!r} has no voltage and strain to predict")
        return [r], True
    if isinstance(target, RunFile):
        return records_of(target, target.path), False
    records = getattr(target, "records", None)
    if callable(records):
        return list(records()), False
    raise TypeError(
        f"cannot predict a {type(target).__name__}: give a labrig.Run, one of its entries "
        "(run[name]) or a Record"
    )


def records_of(run: RunFile, path: Path | str, entries: list[str] | None = None) -> list[Record]:
    """:func:`records_from_run` of a run file already read (``run``, read from ``path``): a
    command that reads a file once passes the same snapshot to every step."""
    names = [e.name for e in run]
    if entries:
        missing = [n for n in entries if n not in names]
        if missing:
            raise InputFileError(
                [
                    InputIssue(str(path), None, "entries", f"no entry {m!r} (entries: {names})")
                    for m in missing
                ]
            )
        chosen = [run[n] for n in entries]
    else:
        chosen = [e for e in run if e.complete]
    out = [r for r in (record_of(e) for e in chosen) if r is not None]
    if not out:
        raise InputFileError(
            [InputIssue(str(path), None, "", "no complete entry with voltage and strain")]
        )
    return out
