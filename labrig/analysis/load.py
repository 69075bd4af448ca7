"""Run files to analysis records: the one place the analysis reads HDF5 (via labrig.store)."""

from __future__ import annotations

from pathlib import Path

from labrig.analysis.records import Record
from labrig.core.errors import InputFileError, InputIssue
from labrig.store import RunFile, read_run

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
    out = []
    for e in chosen:
        if "strain" not in e.data or "command_voltage" not in e.data or e.n_samples < 2:
            continue
        meta = dict(e.step)
        meta["units"] = dict(e.units)
        hold = meta.get("hold", "zoh")
        out.append(
            Record(
                name=e.name,
                rate_hz=e.rate_hz,
                time_s=e.time,
                voltage_V=e["command_voltage"],
                strain_ue=e["strain"],
                aux={k: v for k, v in e.data.items() if k not in _CORE},
                hold=hold if hold in ("zoh", "linear") else "zoh",
                meta=meta,
            )
        )
    if not out:
        raise InputFileError(
            [InputIssue(str(path), None, "", "no complete entry with voltage and strain")]
        )
    return out
