"""What a run file says about itself, for the fleet table: protocol, start time, seed, rig and
the actuator (sample) it was run on.

The actuator's identity is taken from the first of these the file has:

1. an ``NXsample`` group in ``/run`` or in the first entry (its ``sample_id``,
   ``serial_number`` or ``name``, as a dataset or an attribute);
2. the protocol text's ``metadata:`` mapping (``sample``, ``actuator``, ``serial`` or
   ``sample_id``);
3. ``actuator ID`` (or ``actuator: ID``) in the protocol's ``description`` (what
   ``labrig sim fleet`` writes).

Otherwise the column stays empty and the run is named by its file.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import h5py

from labrig.core.errors import InputFileError
from labrig.core.yamlio import load_text
from labrig.store import RunFile, read_run

#: keys naming the actuator in an NXsample group or a protocol's ``metadata:``
SAMPLE_KEYS = ("sample_id", "serial_number", "actuator", "sample", "serial", "name")
DESCRIPTION_ID = re.compile(r"\bactuator[:\s]+([A-Za-z0-9][A-Za-z0-9._#/-]*)", re.IGNORECASE)


def _text(v: Any) -> str:
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if hasattr(v, "shape") and getattr(v, "shape", None) == ():
        return _text(v[()])
    return str(v)


def _safe_yaml(text: str) -> Any:
    """The recorded text's YAML (bounded like a protocol file), ``None`` when unreadable."""
    try:
        return load_text(text) if text else None
    except InputFileError:
        return None


def sample_from_hdf5(path: Path | str) -> str:
    """The ``NXsample`` identity in ``/run`` or the first entry ("" when there is none)."""
    try:
        with h5py.File(path, "r", locking=False) as f:
            places = [f["run"]] if "run" in f else []
            places += [g for n, g in f.items() if n != "run" and isinstance(g, h5py.Group)][:1]
            for place in places:
                for g in place.values():
                    if not isinstance(g, h5py.Group) or _text(g.attrs.get("NX_class", "")) != (
                        "NXsample"
                    ):
                        continue
                    for k in SAMPLE_KEYS:
                        if k in g and isinstance(g[k], h5py.Dataset):
                            return _text(g[k][()])
                        if k in g.attrs:
                            return _text(g.attrs[k])
    except (OSError, KeyError):
        return ""
    return ""


def sample_from_protocol(protocol_text: str) -> str:
    """The actuator named by the protocol text's ``metadata:`` or its ``description``."""
    doc = _safe_yaml(protocol_text)
    if not isinstance(doc, dict):
        return ""
    meta = doc.get("metadata")
    if isinstance(meta, dict):
        for k in SAMPLE_KEYS:
            if meta.get(k) not in (None, ""):
                return str(meta[k])
    m = DESCRIPTION_ID.search(str(doc.get("description") or ""))
    return m.group(1) if m else ""


def rig_name(run: RunFile) -> str:
    """The rig's ``name`` from the rig text recorded in the run file (``sim`` for the built-in
    rig, whose text is not recorded)."""
    doc = _safe_yaml(run.rig_text)
    if isinstance(doc, dict) and doc.get("name"):
        return str(doc["name"])
    return "sim" if not run.rig_file else Path(run.rig_file).stem


def run_identity(path: Path | str, run: RunFile | None = None) -> dict[str, Any]:
    """The run file's metadata columns of the fleet table (``docs/fleet.md``); ``run``: the
    file as the task read it (else read now)."""
    run = read_run(path, load_data=False) if run is None else run
    actuator = sample_from_hdf5(path) or sample_from_protocol(run.protocol_text)
    return {
        "actuator": actuator,
        "rig": rig_name(run),
        "protocol": run.protocol_name,
        "start_time": run.start_time,
        "seed": run.seed,
        "run_status": run.status,
        "recorded_by": run.software_version,
        "n_entries": len(run),
    }
