"""Imported entries into a run file, written beside the target and renamed over it only when
complete: an existing file is replaced (with ``--overwrite``) by a whole new one or not at all.

The new file is written as ``.<name>.<random>.partial/<name>`` in the target's folder
(:func:`labrig.core.outputs.stage`: same file system, so putting it in place is atomic; the file
records its own name) and the temporary folder is removed whatever happens. Without
``--overwrite`` a file that appeared at the target while the import ran is kept and the import
refused (:meth:`~labrig.core.outputs.Staged.commit`); a write that fails (a full disk) leaves
the target as it was.
"""

from __future__ import annotations

import json
from pathlib import Path

from labrig.core.errors import StorageError
from labrig.core.metadata import RunMetadata
from labrig.core.outputs import stage
from labrig.core.version import __version__
from labrig.importers.entry import ImportedEntry
from labrig.store import Channel, RunWriter


def _channels(e: ImportedEntry) -> list[Channel]:
    chans = [
        Channel("command_voltage", e.meta["channels"]["command_voltage"]["unit"],
                "measured actuator voltage"),
        Channel("strain", e.strain_unit, "strain"),
    ]  # fmt: skip
    for name, (_, unit) in e.aux.items():
        source = e.meta["channels"][name]["from"]
        chans.append(Channel(name, unit, f"{name} (imported from {source})"))
    return chans


def write_entries(
    path: Path,
    entries: list[ImportedEntry],
    description: dict,
    metadata: RunMetadata | None = None,
) -> None:
    """Write a run file of ``entries`` at ``path`` directly (write_run puts it beside first),
    with ``metadata`` (``/run/metadata``, each entry's NXuser and NXsample)."""
    with RunWriter(
        path,
        protocol_text=json.dumps(description, indent=2, default=str),
        rig_text="",
        instrument_description=description,
        seed=None,
        protocol_name="import",
        protocol_file="",
        planned_entries=[e.name for e in entries],
        metadata=metadata,
    ) as w:
        for e in entries:
            ew = w.begin_entry(
                e.name, e.meta, e.rate_hz, _channels(e), title=f"imported {e.source.name}"
            )
            block = {"time": e.time_s, "command_voltage": e.voltage_V, "strain": e.strain}
            block.update({k: a for k, (a, _) in e.aux.items()})
            ew.append(block)
            ew.finish("complete")
        w.finish("complete")


def write_run(
    out: Path,
    entries: list[ImportedEntry],
    description: dict,
    metadata: RunMetadata | None = None,
    overwrite: bool = False,
) -> None:
    """Write ``entries`` to ``out`` (beside it first, then put in place; an existing ``out``
    is replaced only with ``overwrite``, even one that appeared while this ran)."""
    from labrig.store.reader import being_written

    staged = stage([out], overwrite=overwrite, being_written=being_written)
    try:
        try:
            write_entries(staged.path(out), entries, description, metadata)
        except StorageError as e:  # the partial file is removed below: say what is left
            kept = "kept as it was" if out.exists() else "not written"
            raise StorageError(
                str(out), e.operation, f"{e.detail.split(';')[0]}; {out} {kept}"
            ) from None
        staged.commit()
    finally:
        staged.discard()


def import_description(files: list[Path], options: dict) -> dict:
    """What the run file records about the import (its ``protocol`` note and ``instrument``)."""
    return {
        "import": {
            "software": f"labrig {__version__}",
            "files": [str(f) for f in files],
            "options": options,
        }
    }
