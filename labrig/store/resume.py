"""Continuing an aborted or interrupted run file (``labrig run PROTOCOL --resume FILE``).

:func:`check_resume` decides, before anything is opened or energised, whether a file can be
resumed with a protocol and which entries remain: the file must not be complete nor being
written now, the protocol must be the one it recorded (the same text), and every stored sample
must pass its checksum and every object its seal (:func:`verify_samples`): a resume appends to
the file, so a damaged one would take the new entries down with it. The runner then
works on a copy written beside the file (:mod:`labrig.core.outputs`), opened by
:meth:`labrig.store.writer.RunWriter.reopen`, and renames the copy over the file only once the
copy is closed: a resume that fails, or is killed, leaves the file as it was.

:func:`record_resume` writes, in the copy, what the resume changes and what it replaces
(docs/runfile.md, "Resume"):

- an entry of the plan that is in the file but not complete (aborted, failed, cut short by a
  crash) keeps its samples under a new name, ``<name>_partial<k>``, and the resume records it
  again under its planned name; complete entries are kept as they are;
- an entry still ``running`` (its writer was killed or crashed while writing it: the file is
  not being written, :func:`check_resume`) is ended ``aborted`` with the reason
  :data:`ABANDONED`, its samples kept as recorded and sealed as final, and the ``duration``
  and ``end_time`` an ended entry has, reconstructed from its samples and ``start_time``
  (``@reconstructed``; :func:`labrig.store.writer.end_abandoned_entry`): until a resume
  takes the file over, a killed run's entry keeps reading ``running`` (incomplete), as a
  live writer's does;
- ``/run/resumes/resume_<k>`` (NXcollection): ``number``, ``time``, ``entries`` (JSON list of
  the entries it runs), ``superseded`` (JSON: planned name -> the partial entry's new name),
  ``seed`` (the simulated rig's new seed, -1 none), ``software_version``, ``writer_pid``,
  ``previous_status``, ``previous_reason``, ``previous_end_time``, ``previous_exit_code`` and
  ``previous_final_amplifier_voltage_V`` (how the run had ended), ``previous_ramp_to_zero``
  (that ending's ramp record, moved here), ``description_json`` (the rig's description at the
  resume: instrument identities may differ), ``metadata`` (the options given to the resume);
- ``/run`` is ``running`` again, without the previous ending's records; the run's end is
  recorded as for any run.
"""

from __future__ import annotations

import difflib
import json
from dataclasses import dataclass, field
from pathlib import Path

import h5py

from labrig.core.errors import InputFileError, InputIssue
from labrig.core.metadata import RunMetadata
from labrig.store.format import now_iso
from labrig.store.isolated import IsolatedReadError, call_isolated
from labrig.store.nexus import set_str, write_metadata_collection
from labrig.store.parse import read_run_here
from labrig.store.reader import read_run
from labrig.store.writer import end_abandoned_entry

#: records of earlier endings moved into the resume record: /run name -> name in the record
_PREVIOUS = {
    "exit_code": "previous_exit_code",
    "final_amplifier_voltage_V": "previous_final_amplifier_voltage_V",
    "ramp_to_zero": "previous_ramp_to_zero",
}


#: why an entry a resume finds ``running`` ended (its writer is gone: :func:`record_resume`)
ABANDONED = (
    "the run's process ended while this entry was being written (killed or crashed, or its "
    "end could not be recorded); the entry is kept as recorded"
)


@dataclass
class ResumePlan:
    """What a resume will do to a run file (:func:`check_resume`)."""

    path: Path
    number: int
    previous_status: str
    previous_reason: str
    previous_end_time: str
    rig_text: str
    size_bytes: int
    #: the planned entries to record, in plan order
    to_run: list[str] = field(default_factory=list)
    #: planned name -> new name of the partial entry it replaces
    superseded: dict[str, str] = field(default_factory=dict)
    #: the run's metadata as recorded (``/run/metadata``)
    metadata: dict = field(default_factory=dict)


def _refuse(path: Path, message: str, option: str = "--resume") -> InputFileError:
    return InputFileError([InputIssue(str(path), None, option, message)])


def _first_difference(recorded: str, given: str) -> str:
    """Where two protocol texts first differ, for a person (``line 7: 'rate_hz: 1000' in the
    run file, 'rate_hz: 2000' given``)."""
    a, b = recorded.splitlines(), given.splitlines()
    for op, i1, _i2, j1, _j2 in difflib.SequenceMatcher(a=a, b=b).get_opcodes():
        if op != "equal":
            was = repr(a[i1][:60]) if i1 < len(a) else "(end of text)"
            now = repr(b[j1][:60]) if j1 < len(b) else "(end of text)"
            return f"line {j1 + 1}: {now} given, {was} in the run file"
    return "the same lines, other line endings or spacing"


def _verify_here(path: Path) -> None:
    read_run_here(path, load_data=True)  # every chunk's checksum, every seal; nothing sent back


def verify_samples(path: Path, option: str = "--resume") -> None:
    """Read every sample of ``path`` (Fletcher-32 checksums) and every object's seal, in a
    child process with the reader's limits (:mod:`labrig.store.isolated`); damage is an
    :class:`InputFileError` (exit 2) naming the file, the object and the option."""
    try:
        call_isolated(_verify_here, path, size_bytes=path.stat().st_size)
    except InputFileError as e:
        raise _refuse(path, f"cannot be resumed, the file is damaged: {e}", option) from None
    except (IsolatedReadError, OSError) as e:
        raise _refuse(path, f"cannot be resumed, the file is damaged: {e}", option) from None


def check_resume(
    path: Path, protocol_text: str, planned: list[str], protocol_file: str
) -> ResumePlan:
    """Whether ``path`` can be resumed with the protocol of text ``protocol_text`` (from
    ``protocol_file``) whose plan has the entries ``planned``; an :class:`InputFileError`
    (exit 2) saying why not."""
    run = read_run(path, load_data=False)
    if run.being_written:
        raise _refuse(path, f"is being written now ({run.writer}); wait for that run to end")
    complete = {e.name for e in run if e.complete}
    to_run = [n for n in planned if n not in complete]
    if run.protocol_text != protocol_text:
        name = run.protocol_name or "?"
        raise _refuse(
            path,
            f"was recorded with another protocol ({name!r}, {run.protocol_file or 'no file'}); "
            f"{protocol_file} differs at {_first_difference(run.protocol_text, protocol_text)}. "
            "Resume with the protocol as recorded (its text is in the run file, "
            "/run/protocol/data)",
        )
    if not to_run:
        raise _refuse(
            path, f"every planned entry is complete (status {run.status}): nothing to resume"
        )
    verify_samples(path)
    names = {e.name for e in run}
    superseded: dict[str, str] = {}
    for n in to_run:
        if n in names:
            k = 1
            while f"{n[:50]}_partial{k}" in names or f"{n[:50]}_partial{k}" in superseded.values():
                k += 1
            superseded[n] = f"{n[:50]}_partial{k}"
    return ResumePlan(
        path=path,
        number=len(run.resumes) + 1,
        previous_status="incomplete" if run.status == "running" else run.status,
        previous_reason=run.reason,
        previous_end_time=run.end_time,
        rig_text=run.rig_text,
        size_bytes=path.stat().st_size,
        to_run=to_run,
        superseded=superseded,
        metadata=dict(run.metadata),
    )


def check_same_rig(plan: ResumePlan, rig_text: str, rig_file: str) -> None:
    """Refuse (exit 2) a resume on another rig than the run's (the rig file's text differs)."""
    if plan.rig_text != rig_text:
        what = rig_file or "the built-in rig"
        raise _refuse(
            plan.path,
            f"was recorded on another rig: {what} differs at "
            f"{_first_difference(plan.rig_text, rig_text)}. Resume on the rig the run used",
            "--rig",
        )


def record_resume(
    f: h5py.File,
    plan: ResumePlan,
    seed: int | None,
    version: str,
    pid: int,
    description: dict,
    options: RunMetadata,
) -> h5py.Group:
    """Write the resume into the open copy ``f`` (module docstring); the caller seals and
    flushes. Returns the resume record."""
    run = f["run"]
    _end_abandoned(f, plan.number)
    for old, new in plan.superseded.items():
        f.move(old, new)
        set_str(f[new], "title", f"{_text(f[new], 'title') or old} (replaced by a resume)")
        if f.attrs.get("default") == old:
            f.attrs["default"] = new
    resumes = run.require_group("resumes")
    resumes.attrs["NX_class"] = "NXcollection"
    g = resumes.create_group(f"resume_{plan.number}", track_order=True)
    g.attrs["NX_class"] = "NXcollection"
    g.create_dataset("number", data=plan.number)
    set_str(g, "time", now_iso())
    set_str(g, "entries", json.dumps(plan.to_run))
    set_str(g, "superseded", json.dumps(plan.superseded))
    ds = g.create_dataset("seed", data=-1 if seed is None else int(seed))
    ds.attrs["long_name"] = "random seed of the simulated rig for the resumed entries (-1: none)"
    set_str(g, "software_version", version)
    g.create_dataset("writer_pid", data=pid)
    set_str(g, "previous_status", plan.previous_status)
    set_str(g, "previous_reason", plan.previous_reason)
    set_str(g, "previous_end_time", plan.previous_end_time)
    for name, new in _PREVIOUS.items():
        if name in run:
            run.move(name, f"{g.name}/{new}")
    set_str(g, "description_json", json.dumps(description, default=str))
    if options:
        write_metadata_collection(g, "metadata", options)
    return g


def _end_abandoned(f: h5py.File, number: int) -> None:
    """End every entry of ``f`` still ``running`` as abandoned by its writer
    (:data:`ABANDONED`), saying which resume found it so (its end time and duration
    reconstructed, :func:`labrig.store.writer.end_abandoned_entry`)."""
    for name, g in f.items():
        if name != "run" and isinstance(g, h5py.Group) and _text(g, "status") == "running":
            end_abandoned_entry(g, f"{ABANDONED} (found so by resume {number})")


def _text(g: h5py.Group, name: str) -> str:
    v = g[name][()] if name in g else b""
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)
