"""Output files of the commands: the one check of an output path, then written beside the
target and renamed into place.

Every file a command or the Python API writes (``fit --out``, ``report --out``, ``diagnose --out
DIR``, ``export --out DIR``, ``info``/``runs``/``check``/``drivers``/``model demo --out``, the
run file of ``run``, ``sim fleet --out DIR``, ``batch --out DIR``) is checked by
:func:`check_outputs` before any work:

- an output is never an input of the same command, whatever the flags: the same resolved path or
  the same file (:func:`os.path.samefile`, so a hard link or a symbolic link is caught too);
- an output inside an input folder whose files of that kind the command reads
  (:class:`ReadFolder`: ``runs DIR --out DIR/a.h5``) is an input too;
- an existing output that another process is writing now (a run file being recorded: the probe
  ``being_written`` the caller passes, :func:`labrig.store.writing.being_written`) is never
  replaced, even with ``--overwrite``;
- an existing output is replaced only with ``--overwrite``;
- a folder where a file goes, or a file where a folder goes, is refused; so are, even with
  ``--overwrite``, a symbolic link (name the file it points to), a device, pipe or socket, and
  a name that is not UTF-8.

Then :func:`stage` creates a hidden folder ``.<name>.<random>.partial`` beside the targets
(creating their folder if needed), which proves the place writable before the work starts; the
command writes each output there under its own name; :meth:`Staged.commit` renames each written
file onto its target (same folder, so the rename is atomic: a reader sees the old file or the
new one, never a part); without ``--overwrite`` a target that appeared meanwhile is not replaced
(a hard link that fails if it exists); :meth:`Staged.discard` removes the staging folder and the
folders :func:`stage` created, if they are still empty. After a crash the old file is untouched
and the partial folder stays beside it.

Problems are :class:`~labrig.core.errors.InputFileError` (exit code 2) naming the file, the
option and what would be valid.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from labrig.core.errors import InputFileError, InputIssue

#: at most this many existing outputs are named in a refusal
MAX_NAMED = 5


class OutputExistsError(InputFileError, FileExistsError):
    """Outputs that exist already, without ``--overwrite`` (exit code 2; a
    :class:`FileExistsError` for Python callers)."""


class OutputIsFolderError(InputFileError, IsADirectoryError):
    """An output that names a folder where a file goes (exit code 2; an
    :class:`IsADirectoryError` for Python callers)."""


#: ``being_written(path)``: a description of the process writing the existing file ``path``
#: now (``"process 123, last written 0.1 s ago"``), or ``None`` when nobody writes it
WriterProbe = Callable[[Path], str | None]


@dataclass(frozen=True)
class ReadFolder:
    """An input folder from which the command reads every file (searched recursively) whose
    name ends with one of ``suffixes`` (lower case, e.g. ``(".h5", ".hdf5")``)."""

    path: Path
    suffixes: tuple[str, ...]

    def reads(self, target: Path) -> bool:
        """True when ``target`` lies in this folder (at any depth) and is of a kind read."""
        if not target.name.lower().endswith(self.suffixes):
            return False
        try:
            return _resolved(target).is_relative_to(_resolved(self.path))
        except OSError:
            return False


def _resolved(p: Path) -> Path:
    return Path(os.path.abspath(p)).resolve()


def same_file(a: Path, b: Path) -> bool:
    """True when ``a`` and ``b`` are the same file (the same inode when both exist, else the
    same resolved path)."""
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
        return _resolved(a) == _resolved(b)
    except OSError:
        return False


#: the staging folder's name: ``.NAME.`` + tempfile's 8 random characters + this suffix
STAGING_SUFFIX = ".partial"
#: the longest name an output may have (bytes): file systems allow 255 in one name, and an output
#: is first written into ``.NAME.XXXXXXXX.partial`` beside it (18 bytes more)
MAX_OUTPUT_NAME_BYTES = 255 - len("..") - len("XXXXXXXX") - len(STAGING_SUFFIX)


def _refusal(target: Path, option: str, message: str) -> InputIssue:
    return InputIssue(str(target), None, option, message)


def check_outputs(
    targets: Sequence[Path],
    *,
    inputs: Sequence[Path | None] = (),
    folders: Sequence[ReadFolder] = (),
    overwrite: bool = False,
    option: str = "--out",
    being_written: WriterProbe | None = None,
    folder: bool = False,
) -> None:
    """The one check of a command's outputs (module docstring), before the work: refuse an
    output that is an input (``inputs``; or read from one of ``folders``), one that another
    process is writing (``being_written``), a folder where a file goes (a file where a folder
    goes with ``folder``: then ``targets`` are folders), or (without ``overwrite``) an existing
    file. Every problem at once, in one :class:`InputFileError`."""
    issues: list[InputIssue] = []
    folders_given: list[InputIssue] = []
    existing = []
    given = [Path(i) for i in inputs if i is not None]
    for t in (Path(t) for t in targets):
        size = len(os.fsencode(t.name))
        if size > MAX_OUTPUT_NAME_BYTES:
            issues.append(
                _refusal(
                    t,
                    option,
                    f"name too long ({size} bytes; an output's name is at most "
                    f"{MAX_OUTPUT_NAME_BYTES}: it is written beside first, as "
                    ".NAME.XXXXXXXX.partial)",
                )
            )
            continue
        source = next((i for i in given if same_file(t, i)), None)
        reader = next((f for f in folders if f.reads(t)), None)
        unusable = never_an_output(t, folder)
        if source is not None:
            issues.append(
                _refusal(
                    t, option, f"is an input of this command ({source}); choose another {option}"
                )
            )
        elif reader is not None:
            issues.append(
                _refusal(
                    t,
                    option,
                    f"is inside {reader.path}, an input of this command whose "
                    f"{'/'.join(reader.suffixes)} files it reads; choose another {option} "
                    "outside that folder",
                )
            )
        elif unusable:
            issues.append(_refusal(t, option, f"{unusable}; choose another {option}"))
        elif _a_file(t.parent):
            issue = _refusal(t.parent, option, "is a file; give a folder (new, or one to add to)")
            if issue not in issues:  # one line for the outputs that go in it
                issues.append(issue)
        elif folder:
            if t.exists() and not t.is_dir():
                issues.append(
                    _refusal(t, option, "is a file; give a folder (new, or one to add to)")
                )
        elif t.is_dir():
            folders_given.append(
                _refusal(t, option, f"is a directory; give a file name such as {t / 'out'}")
            )
        elif t.exists() or t.is_symlink():
            writer = being_written(t) if being_written is not None and t.is_file() else None
            if writer is not None:
                issues.append(
                    _refusal(
                        t,
                        option,
                        f"is a run file being written now ({writer}); it is never replaced, "
                        f"even with --overwrite: choose another {option}",
                    )
                )
            elif not overwrite:
                existing.append(t)
    if issues:
        raise InputFileError(issues + folders_given)
    if folders_given:
        raise OutputIsFolderError(folders_given)
    if existing:
        # an option of the command line, or a keyword of the Python API (option "out")
        flag = "--overwrite" if option.startswith("--") else "overwrite=True"
        named = ", ".join(str(t) for t in existing[:MAX_NAMED])
        more = f" and {len(existing) - MAX_NAMED} more" if len(existing) > MAX_NAMED else ""
        what = "exists" if len(existing) == 1 else "exist"
        raise OutputExistsError(
            [
                InputIssue(
                    named + more,
                    None,
                    option,
                    f"{what} already; pass {flag} to replace "
                    f"{'it' if len(existing) == 1 else 'them'}, or choose another {option}",
                )
            ]
        )


def _a_folder(p: Path) -> bool:
    try:
        return p.is_dir()
    except OSError:
        return False


def _a_file(p: Path) -> bool:
    try:
        return p.exists() and not p.is_dir()
    except OSError:
        return False


def never_an_output(t: Path, folder: bool = False) -> str:
    """Why ``t`` can never be an output, even with ``--overwrite`` (empty when it can): a name
    that is not UTF-8 (the run file records its own name as text), a symbolic link (replacing
    the link would leave the file it points to as it was), or something that is not a file
    (a device such as ``/dev/null``, a pipe, a socket: renaming onto it would replace it).
    A ``folder`` the outputs go into may be a link to a folder (they are written in it)."""
    try:
        str(t).encode("utf-8")
    except UnicodeEncodeError:
        return "its path is not valid UTF-8 text (a run file records it as text)"
    if t.is_symlink() and not (folder and _a_folder(t)):
        try:
            points = os.readlink(t)
        except OSError:
            points = "?"
        return f"is a symbolic link (to {points}), never replaced (give the path it points to)"
    try:
        mode = t.stat().st_mode
    except OSError:
        return ""  # not there (or not reachable): the staging says so if it matters
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return ""
    return "is not a regular file (a device, a pipe or a socket) and is never replaced"


@dataclass
class Staged:
    """Outputs being written beside their targets (module docstring)."""

    targets: list[Path]
    overwrite: bool
    option: str
    being_written: WriterProbe | None = None
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
        """Rename every written output onto its target; targets not written are left alone. A
        target that another process began to write meanwhile is not replaced (an error)."""
        for t in self.targets:
            staged = self.path(t)
            if staged.exists():
                writer = self.being_written(t) if self.being_written and t.is_file() else None
                if writer is not None:
                    raise self.error(
                        t, f"began to be written while the command ran ({writer}); kept"
                    )
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


def stage(
    targets: Sequence[Path],
    *,
    overwrite: bool = False,
    option: str = "--out",
    being_written: WriterProbe | None = None,
) -> Staged:
    """A staging folder beside each distinct folder of ``targets`` (created as needed); an
    unwritable place is an :class:`InputFileError` naming it. ``being_written``: checked
    again for each target when it is put in place (:meth:`Staged.commit`)."""
    staged = Staged([Path(t) for t in targets], overwrite, option, being_written)
    try:
        for t in staged.targets:
            if t.parent in staged.folders:
                continue
            _make_folder(t.parent, staged.created)
            staged.folders[t.parent] = Path(
                tempfile.mkdtemp(prefix=f".{t.name}.", suffix=STAGING_SUFFIX, dir=t.parent)
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
    folders: Sequence[ReadFolder] = (),
    overwrite: bool = False,
    option: str = "--out",
    being_written: WriterProbe | None = None,
) -> None:
    """:func:`check_outputs`, then prove each target's folder writable (stage, discard): for a
    command that writes its outputs at the end with :func:`write_text_output`."""
    paths = [Path(t) for t in targets]
    check_outputs(
        paths,
        inputs=inputs,
        folders=folders,
        overwrite=overwrite,
        option=option,
        being_written=being_written,
    )
    stage(paths, overwrite=overwrite, option=option).discard()


def write_text_output(
    target: Path,
    text: str,
    *,
    overwrite: bool = False,
    option: str = "--out",
    being_written: WriterProbe | None = None,
) -> None:
    """Write ``text`` to ``target`` beside it, then rename it into place."""
    staged = stage([Path(target)], overwrite=overwrite, option=option, being_written=being_written)
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
    being_written: WriterProbe | None = None,
) -> Iterator[Staged]:
    """:func:`check_outputs`, :func:`stage`, then (when the block ends without an exception)
    :meth:`Staged.commit`; the staging folders go whatever happens."""
    paths = [Path(t) for t in targets]
    check_outputs(
        paths, inputs=inputs, overwrite=overwrite, option=option, being_written=being_written
    )
    staged = stage(paths, overwrite=overwrite, option=option, being_written=being_written)
    try:
        yield staged
        staged.commit()
    finally:
        staged.discard()
