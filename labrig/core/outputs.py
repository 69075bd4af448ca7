"""Output files of the commands, written beside their target and renamed into place.

Every file a command writes (``fit --out``, ``report --out``, ``diagnose --out DIR``,
``export --csv DIR``, the run file of ``run --overwrite``) goes through here:

- :func:`check_outputs`, before any computation: an output that is one of the command's input
  files is refused whatever the flags; an existing output is refused unless ``--overwrite``;
  an output that names a folder is refused;
- :func:`stage` then creates a hidden folder ``.<name>.<random>.partial`` beside the targets
  (creating their folder if needed), which proves the place writable before the work starts;
  the command writes each output there under its own name;
- :meth:`Staged.commit` renames each written file onto its target (same folder, so the rename
  is atomic: a reader sees the old file or the new one, never a part); without ``--overwrite``
  a target that appeared meanwhile is not replaced (a hard link that fails if it exists);
- :meth:`Staged.discard` removes the staging folder and the folders :func:`stage` created, if
  they are still empty. After a crash the old file is untouched and the partial folder stays
  beside it.

Problems are :class:`~labrig.core.errors.InputFileError` (exit code 2) naming the file and the
option.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from labrig.core.errors import InputFileError, InputIssue

#: at most this many existing outputs are named in a refusal
MAX_NAMED = 5


def same_file(a: Path, b: Path) -> bool:
    """True when ``a`` and ``b`` are the same file (the same inode when both exist, else the
    same resolved path)."""
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
        return a.resolve() == b.resolve()
    except OSError:
        return False


def check_outputs(
    targets: Sequence[Path],
    *,
    inputs: Sequence[Path | None] = (),
    overwrite: bool = False,
    option: str = "--out",
) -> None:
    """Refuse outputs that are inputs, folders, or (without ``overwrite``) existing files."""
    issues = []
    existing = []
    for t in targets:
        for i in inputs:
            if i is not None and same_file(t, Path(i)):
                issues.append(
                    InputIssue(
                        str(t),
                        None,
                        option,
                        f"is an input of this command; choose another {option}",
                    )
                )
                break
        else:
            if t.is_dir():
                issues.append(
                    InputIssue(str(t), None, option, "is a directory; give a file name to write")
                )
            elif (t.exists() or t.is_symlink()) and not overwrite:
                existing.append(t)
    if existing:
        named = ", ".join(str(t) for t in existing[:MAX_NAMED])
        more = f" and {len(existing) - MAX_NAMED} more" if len(existing) > MAX_NAMED else ""
        what = "exists" if len(existing) == 1 else "exist"
        issues.append(
            InputIssue(
                named + more,
                None,
                option,
                f"{what} already; pass --overwrite to replace "
                f"{'it' if len(existing) == 1 else 'them'}, or choose another {option}",
            )
        )
    if issues:
        raise InputFileError(issues)


@dataclass
class Staged:
    """Outputs being written beside their targets (module docstring)."""

    targets: list[Path]
    overwrite: bool
    option: str
    folders: dict[Path, Path] = field(default_factory=dict)  # target's folder -> staging
    created: list[Path] = field(default_factory=list)  # folders made for the targets

    def path(self, target: Path) -> Path:
        """Where to write ``target`` until :meth:`commit` (same name, in the staging folder)."""
        return self.folders[target.parent] / target.name

    def folder(self, target_dir: Path) -> Path:
        """The staging folder for outputs in ``target_dir`` (write them under their names)."""
        return self.folders[target_dir]

    def write_text(self, target: Path, text: str) -> None:
        """Write ``text`` (UTF-8) for ``target`` (into the staging folder)."""
        try:
            self.path(target).write_text(text, encoding="utf-8")
        except OSError as e:
            raise self.error(target, f"cannot write it: {e.strerror or e}") from None

    def error(self, target: Path, message: str) -> InputFileError:
        """An :class:`InputFileError` about ``target`` (named with the option)."""
        return InputFileError([InputIssue(str(target), None, self.option, message)])

    def commit(self) -> None:
        """Rename every written output onto its target; targets not written are left alone."""
        for t in self.targets:
            staged = self.path(t)
            if staged.exists():
                try:
                    _rename(staged, t, self.overwrite, self.option)
                except OSError as e:
                    raise self.error(t, f"cannot put it in place: {e.strerror or e}") from None

    def discard(self) -> None:
        """Remove the staging folders (with what is left in them) and the folders made for
        the targets when they are still empty."""
        for folder in self.folders.values():
            shutil.rmtree(folder, ignore_errors=True)
        for d in reversed(self.created):
            with contextlib.suppress(OSError):
                d.rmdir()
        self.folders.clear()
        self.created.clear()


def _rename(staged: Path, target: Path, overwrite: bool, option: str) -> None:
    if not overwrite:
        try:
            os.link(staged, target)  # fails if the target appeared since the check
            staged.unlink()
            return
        except FileExistsError:
            raise InputFileError(
                [InputIssue(str(target), None, option, "appeared while the command ran; kept")]
            ) from None
        except OSError as e:
            if e.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.EMLINK, errno.EXDEV):
                raise
            if target.exists():  # no hard links on this file system
                raise InputFileError(
                    [InputIssue(str(target), None, option, "appeared while the command ran")]
                ) from None
    os.replace(staged, target)


def _make_folder(folder: Path, created: list[Path]) -> None:
    """``mkdir -p folder``, adding the folders it made to ``created`` (outermost first)."""
    missing = []
    d = folder
    while not d.exists() and d != d.parent:
        missing.append(d)
        d = d.parent
    folder.mkdir(parents=True, exist_ok=True)
    created.extend(reversed(missing))


def stage(targets: Sequence[Path], *, overwrite: bool = False, option: str = "--out") -> Staged:
    """A staging folder beside each distinct folder of ``targets`` (created as needed); an
    unwritable place is an :class:`InputFileError` naming it."""
    staged = Staged([Path(t) for t in targets], overwrite, option)
    try:
        for t in staged.targets:
            if t.parent in staged.folders:
                continue
            _make_folder(t.parent, staged.created)
            staged.folders[t.parent] = Path(
                tempfile.mkdtemp(prefix=f".{t.name}.", suffix=".partial", dir=t.parent)
            )
    except OSError as e:
        staged.discard()
        why = e.strerror or str(e)
        raise InputFileError(
            [InputIssue(str(t), None, option, f"cannot write there: {why}")]
        ) from None
    return staged


def check_writable(
    targets: Sequence[Path],
    *,
    inputs: Sequence[Path | None] = (),
    overwrite: bool = False,
    option: str = "--out",
) -> None:
    """:func:`check_outputs`, then prove each target's folder writable (stage, discard): for a
    command that writes its outputs at the end with :func:`write_text_output`."""
    paths = [Path(t) for t in targets]
    check_outputs(paths, inputs=inputs, overwrite=overwrite, option=option)
    stage(paths, overwrite=overwrite, option=option).discard()


def write_text_output(
    target: Path, text: str, *, overwrite: bool = False, option: str = "--out"
) -> None:
    """Write ``text`` to ``target`` beside it, then rename it into place."""
    staged = stage([Path(target)], overwrite=overwrite, option=option)
    try:
        staged.write_text(Path(target), text)
        staged.commit()
    finally:
        staged.discard()


@contextlib.contextmanager
def staged_outputs(
    targets: Sequence[Path],
    *,
    inputs: Sequence[Path | None] = (),
    overwrite: bool = False,
    option: str = "--out",
) -> Iterator[Staged]:
    """:func:`check_outputs`, :func:`stage`, then (when the block ends without an exception)
    :meth:`Staged.commit`; the staging folders go whatever happens."""
    paths = [Path(t) for t in targets]
    check_outputs(paths, inputs=inputs, overwrite=overwrite, option=option)
    staged = stage(paths, overwrite=overwrite, option=option)
    try:
        yield staged
        staged.commit()
    finally:
        staged.discard()
