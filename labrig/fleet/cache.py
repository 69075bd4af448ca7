"""The per-run outputs of a batch and the content-hash skip of a rerun.

Each run has a folder ``DIR/runs/<key>/`` holding the documents its task produced and
``result-<command>.json`` (the task's row, entries, error and identity), written last, so a
folder with a result file is a finished task. A rerun skips a run when its result file says the task
succeeded with the same **identity**: the command, the options, the labrig version and the
SHA-256 of the run file's bytes. Anything else (a changed file, other options, another labrig
version, a run that failed) is computed again and its folder's files replaced.

Every file is written beside its final name and renamed into place, so an interrupted batch
leaves whole files only.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

from labrig.core.jsonsafe import json_safe
from labrig.core.version import __version__
from labrig.fleet.tasks import TaskResult, TaskSpec, file_sha256

#: marks a folder as a batch's output (a batch writes only into a new, empty or marked folder)
MANIFEST = "fleet-manifest.json"


def result_name(command: str) -> str:
    """The result file of a command's task (``result-fit.json``, ...): batches of different
    commands into one folder keep their results apart."""
    return f"result-{command}.json"


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file beside it and a rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def run_keys(paths: list[Path]) -> list[str]:
    """A folder name per run file: its stem, with 8 hex digits of its absolute path's hash
    added when two run files share a stem."""
    stems = [p.stem for p in paths]
    out = []
    for p, s in zip(paths, stems, strict=True):
        if stems.count(s) > 1:
            s += "-" + hashlib.sha1(str(p.resolve()).encode()).hexdigest()[:8]
        out.append(s)
    return out


def identity(spec: TaskSpec, sha256: str) -> dict[str, Any]:
    """What must not change for a run to be skipped."""
    return {
        "command": spec.command,
        "options": spec.options.to_json(),
        "labrig_version": __version__,
        "input_sha256": sha256,
    }


def result_identity(res: TaskResult, spec: TaskSpec) -> dict[str, Any]:
    return {**identity(spec, res.input_sha256), "labrig_version": res.labrig_version}


def run_dir(out: Path, key: str) -> Path:
    return out / "runs" / key


def cached_result(out: Path, spec: TaskSpec) -> TaskResult | None:
    """The stored result of ``spec`` when it succeeded with the same identity (the run file is
    hashed again to compare), else ``None``."""
    f = run_dir(out, spec.key) / result_name(spec.command)
    try:
        doc = json.loads(f.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or not doc.get("ok") or doc.get("identity") is None:
        return None
    try:
        sha = file_sha256(spec.path)
    except OSError:
        return None
    if doc["identity"] != identity(spec, sha) or doc.get("path") != spec.path:
        return None
    fields = {k: doc[k] for k in TaskResult.__dataclass_fields__ if k in doc}
    return TaskResult(**fields)


def store_result(out: Path, spec: TaskSpec, res: TaskResult) -> None:
    """The task's documents, then its result file (last: it marks the task done)."""
    d = run_dir(out, spec.key)
    d.mkdir(parents=True, exist_ok=True)
    for name, text in res.documents.items():
        write_atomic(d / name, text)
    doc = {**res.to_json(), "identity": result_identity(res, spec) if res.ok else None}
    text = json.dumps(json_safe(doc), indent=2, allow_nan=False) + "\n"
    write_atomic(d / result_name(spec.command), text)
