"""The example protocols and rig files shipped with labrig (``experiments/`` in the repository,
installed as the package data ``labrig.experiments``), addressable by name from any folder:
``labrig run paper`` runs ``paper.yaml``, ``--rig hybrid`` is ``rigs/hybrid.yaml``.

A name is looked up only when no file of that name exists (a file in the working folder always
wins) and it has no folder part; ``paper`` and ``paper.yaml`` are the same name.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from labrig.core.errors import InputFileError, InputIssue

#: the package that holds the examples (``experiments/`` installed)
PACKAGE = "labrig.experiments"


def examples_folder() -> Path | None:
    """The folder of the shipped examples (``None`` if labrig was installed without them)."""
    try:
        folder = Path(str(resources.files(PACKAGE)))
    except (ModuleNotFoundError, TypeError):
        return None
    return folder if folder.is_dir() else None


def example_names(kind: str = "protocol") -> list[str]:
    """The names of the shipped protocols (``kind="protocol"``) or rig files (``"rig"``)."""
    folder = examples_folder()
    if folder is None:
        return []
    where = folder / "rigs" if kind == "rig" else folder
    return sorted(p.stem for p in where.glob("*.yaml"))


def _a_name(path: Path) -> bool:
    """Whether ``path`` could name a shipped example: not an existing file, no folder part, no
    suffix other than ``.yaml``."""
    return not path.exists() and path.parent == Path(".") and path.suffix in ("", ".yaml")


def resolve(given: Path | str, kind: str = "protocol") -> Path:
    """``given`` when it exists or names a folder; else the shipped example of that name when
    there is one; else ``given`` unchanged (its reader then says it is not found)."""
    path = Path(given)
    folder = examples_folder()
    if not _a_name(path) or folder is None:
        return path
    candidate = (folder / "rigs" if kind == "rig" else folder) / f"{path.stem}.yaml"
    return candidate if candidate.is_file() else path


def resolve_existing(given: Path | str, kind: str = "protocol") -> Path:
    """:func:`resolve`, and when ``given`` is a bare name (no folder, no suffix other than
    ``.yaml``) that is neither a file nor a shipped example, an
    :class:`~labrig.core.errors.InputFileError` (exit 2) listing the shipped ones of ``kind``
    (a path with a folder is left to its reader, which says it is not found)."""
    path = resolve(given, kind)
    if not _a_name(path):
        return path
    names = ", ".join(example_names(kind)) or "none installed"
    what = (
        "rig file, nor a shipped rig" if kind == "rig" else "protocol file, nor a shipped example"
    )
    label = "rigs" if kind == "rig" else "examples"
    raise InputFileError(
        [InputIssue(str(path), None, "", f"no such {what} of that name ({label}: {names})")]
    )
