"""What the command modules share: the ``friendly`` error wrapper, options used by several
commands, the choices of options with a fixed set of values, and the output convention
(docs/outputs.md): ``--json`` prints the result as JSON on stdout (progress and notes go to
stderr); ``--out FILE`` writes a command's one document, ``--out DIR`` a folder for several;
nothing existing is replaced without ``--overwrite``.

The choices are :class:`~enum.StrEnum` so ``--help`` lists them. The effects' are built from the
effect registry (:mod:`labrig.model.effects.registry`, plain data); the others repeat names the
library defines (tests/cli/test_cli_choices.py checks they match) so that ``labrig --help`` does
not import the numerical stack.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import json
import os
import sys
from collections.abc import Callable, Sequence
from enum import StrEnum
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, NoReturn, TypeVar

import typer

from labrig.core.errors import LabrigError
from labrig.core.words import plural as plural  # re-exported for the commands
from labrig.model.effects.registry import FIT_EFFECT_NAMES, STRUCTURAL_EFFECT_NAMES

if TYPE_CHECKING:
    from labrig.core.outputs import ReadFolder

E = TypeVar("E", bound=StrEnum)


#: what writing the standard output can fail with (a full disk or ``/dev/full``, a closed pipe,
#: an I/O error): one message and exit 2, not a traceback
OUTPUT_ERRNOS = frozenset({errno.ENOSPC, errno.EPIPE, errno.EIO, errno.EFBIG, errno.EDQUOT})


def to_devnull(*streams: IO[Any]) -> None:
    """Point ``streams`` (``sys.stdout``, ``sys.stderr``) at /dev/null when one cannot be
    written (full, closed, a terminal gone), so that later writes, and Python's last flush at
    the exit (exit 120 when it fails on what is still buffered), cannot fail and change the
    exit code. A stream that is no file descriptor (a test's) is left as it is."""
    for stream in streams:
        with contextlib.suppress(OSError, ValueError, AttributeError):
            null = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(null, stream.fileno())
            finally:
                os.close(null)


def echo_error(text: str) -> None:
    """A line on the standard error; when that cannot be written, it is dropped
    (:func:`to_devnull`): the command's exit code stays its own."""
    try:
        typer.echo(text, err=True)
    except OSError:
        to_devnull(sys.stderr)


def _symlink_loop(where: object) -> NoReturn:
    """The one message of a loop of symbolic links (an ``OSError`` ELOOP, or pathlib's
    ``RuntimeError`` from ``resolve()``): exit 2."""
    echo_error(f"error: {where}: a loop of symbolic links (no file at its end)")
    raise typer.Exit(2)


def friendly(fn: Callable) -> Callable:
    """Expected failures print one clear message (no traceback) and exit with their code."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            result = fn(*args, **kwargs)
            sys.stdout.flush()  # a full or closed output fails here, not at the exit
            return result
        except LabrigError as e:
            echo_error(f"error: {e}")
            raise typer.Exit(e.exit_code) from None
        except FileExistsError as e:
            echo_error(f"error: {e}")
            raise typer.Exit(2) from None
        except OSError as e:
            if e.errno == errno.ELOOP:
                _symlink_loop(e.filename)
            if e.filename is None and e.errno in OUTPUT_ERRNOS:  # stdout: full, closed, failing
                to_devnull(sys.stdout)
                echo_error(f"error: the standard output cannot be written: {e.strerror}")
                raise typer.Exit(2) from None
            # a path the system cannot even look up (Python 3.11's Path.exists() raises it)
            if e.errno != errno.ENAMETOOLONG:
                raise
            name = Path(str(e.filename)).name
            echo_error(
                f"error: {e.filename}: file name too long ({len(os.fsencode(name))} bytes in one "
                "name; file systems allow 255)"
            )
            raise typer.Exit(2) from None
        except RuntimeError as e:  # pathlib's resolve() on a loop of symbolic links
            if not str(e).startswith("Symlink loop from "):
                raise
            _symlink_loop(str(e).removeprefix("Symlink loop from ").strip("'\""))
        except KeyboardInterrupt:
            echo_error("interrupted")
            raise typer.Exit(130) from None

    return wrapper


def entries_option(what: str) -> Any:
    """``--entries a,b``: entry names separated by commas; one that names none (``""``,
    ``" , "``) is a usage error, not every entry."""

    def named(value: str | None) -> str | None:
        if value is not None and not any(n.strip() for n in value.split(",")):
            raise typer.BadParameter("names no entry: give names separated by commas, or leave "
                                     "the option out for every complete entry")  # fmt: skip
        return value

    return typer.Option(None, "--entries", help=ENTRIES_HELP.format(what), callback=named)


# -- choices -------------------------------------------------------------------------------------


class Method(StrEnum):
    """How ``fit`` identifies the model (labrig.analysis.fit)."""

    GLOBAL = "global"
    STAGED = "staged"


class Model(StrEnum):
    """What ``fit`` identifies: our model or a baseline (labrig.commands.fit.MODELS)."""

    DYNAMIC = "dynamic"
    PRANDTL_ISHLINSKII = "prandtl_ishlinskii"
    BOUC_WEN = "bouc_wen"
    SINDY = "sindy"


class Memory(StrEnum):
    """The hysteresis operator's memory rule (labrig.model.hysteresis.MEMORY_RULES)."""

    RETURN_POINT = "return_point"
    LAST_REVERSAL = "last_reversal"
    RETURN_POINT_OPEN = "return_point_open"


def names_enum(name: str, values: Sequence[str], doc: str) -> type[StrEnum]:
    """A :class:`~enum.StrEnum` of ``values`` (members named by the upper-cased value), for
    choices whose names the library lists."""
    # mypy reads the functional API only with literal members; these come from the registry
    enum = StrEnum(name, [(v.upper(), v) for v in values])  # type: ignore[misc]
    enum.__doc__ = doc
    return enum


if TYPE_CHECKING:  # enums made at run time: to the checker, StrEnums (valid in annotations)
    FitEffect = StrEnum
    StructuralEffect = StrEnum
else:
    #: effects ``fit --effect`` adds to the model (the registry's, labrig.model.effects.registry)
    FitEffect = names_enum(
        "FitEffect",
        FIT_EFFECT_NAMES,
        "Effects ``fit --effect`` adds to the model (the registry's).",
    )
    #: effects ``diagnose --also`` tries beside its default candidates (the registry's)
    StructuralEffect = names_enum(
        "StructuralEffect",
        STRUCTURAL_EFFECT_NAMES,
        "Effects ``diagnose --also`` tries beside its default candidates (the registry's).",
    )


class Preset(StrEnum):
    """Parameter presets of ``model demo`` (labrig.model.PRESETS)."""

    PAPER_TABLE1 = "PAPER_TABLE1"
    PAPER_TEXT = "PAPER_TEXT"
    PAPER_CONTROL = "PAPER_CONTROL"


def one_of(enum: type[StrEnum]) -> str:
    """The values of ``enum`` for a help text: ``a, b or c``."""
    values = [str(v) for v in enum]
    return ", ".join(values[:-1]) + " or " + values[-1] if len(values) > 1 else values[0]


def choice(enum: type[E], what: str, hint: str = "") -> Callable[[Any], E]:
    """A typer ``parser`` for an option of ``enum``'s values: a bad value is a usage error
    (exit code 2) saying ``VALUE: not WHAT; choose from A, B`` and then ``hint``."""

    def parse(value: Any) -> E:
        if isinstance(value, enum):
            return value
        try:
            return enum(value)
        except ValueError:
            raise typer.BadParameter(
                f"{value}: not {what}; choose from {', '.join(enum)}" + (f" {hint}" if hint else "")
            ) from None

    return parse


# -- options -------------------------------------------------------------------------------------


def flag(default: bool | None, *decls: str, help: str) -> Any:
    """A boolean option; ``metavar=""`` keeps ``<bool>`` out of its ``--help`` line."""
    return typer.Option(default, *decls, help=help, metavar="")


def json_text(doc: Any) -> str:
    """``doc`` as the commands print and write JSON: strict (undefined numbers ``null``),
    indented by 2."""
    from labrig.core.jsonsafe import json_safe

    return json.dumps(json_safe(doc), indent=2, allow_nan=False)


def json_option(what: str = "the result") -> Any:
    """``--json``: print ``what`` as JSON on stdout, nothing else."""
    return flag(False, "--json", help=f"Print {what} as JSON on stdout (notes go to stderr).")


def out_file_option(what: str, default: Path | None = None) -> Any:
    """``--out FILE``: the file a command's one document is written to."""
    return typer.Option(default, "--out", metavar="FILE", help=f"Write {what} to this file.")


def out_dir_option(what: str, required: bool = False) -> Any:
    """``--out DIR``: the folder a command's several output files go to."""
    return typer.Option(
        ... if required else None, "--out", metavar="DIR", help=f"Folder for {what}."
    )


OVERWRITE_OPTION = flag(False, "--overwrite", help="Replace existing --out files.")


def check_out(
    out: Path | None,
    inputs: Sequence[Path | None],
    overwrite: bool,
    folders: Sequence[ReadFolder] = (),
) -> None:
    """Before the work, the one output check (:func:`labrig.core.outputs.check_outputs`, exit
    2): ``--out`` is not an input (nor read from an input folder of ``folders``), not a run
    file being written, not a folder, not (without ``--overwrite``) an existing file, and its
    place is writable."""
    if out is not None:
        from labrig.core.outputs import check_writable
        from labrig.store.reader import being_written

        check_writable(
            [out],
            inputs=list(inputs),
            folders=folders,
            overwrite=overwrite,
            being_written=being_written,
        )


def one_option(option: str, values: dict[str, Any]) -> Any:
    """The value of an option that has several names (``{"--out": a, "--csv": b}``): the one
    given; two names given are refused (exit 2 naming both), whatever their values."""
    from labrig.core.errors import InputFileError, InputIssue

    given = {k: v for k, v in values.items() if v is not None}
    if len(given) > 1:
        names = " and ".join(given)
        raise InputFileError(
            [
                InputIssue(
                    ", ".join(str(v) for v in given.values()),
                    None,
                    option,
                    f"{names} are names of one option: give {option} once",
                )
            ]
        )
    return next(iter(given.values()), None)


def deliver_json(doc: Any, *, as_json: bool, out: Path | None, overwrite: bool) -> bool:
    """The JSON result of a one-document command: written to ``out`` (beside it, then renamed;
    said on stderr) and printed when ``as_json``. Returns True when the caller should print
    its text form (neither ``--json`` given)."""
    text = json_text(doc)
    if out is not None:
        from labrig.core.outputs import write_text_output
        from labrig.store.reader import being_written

        write_text_output(out, text + "\n", overwrite=overwrite, being_written=being_written)
        typer.echo(f"wrote {out}", err=True)
    if as_json:
        typer.echo(text)
    return not as_json


# shared by `fit` and `report`
WARMUP_OPTION = typer.Option(
    None, "--warmup-s", help="Seconds of each record simulated but not scored (default: auto)."
)
HELDOUT_OPTION = flag(
    True, "--heldout/--no-heldout", help="Leave-one-entry-out NRMSE (the slow part)."
)
OFFSET_OPTION = flag(
    None,
    "--offset/--no-offset",
    help="Fit one strain offset per entry (default: on for imported data).",
)
#: the baselines a report can fit (labrig.analysis.baselines.KINDS, without importing it here)
PEERS = ("prandtl_ishlinskii", "bouc_wen", "sindy")


def _names(text: str) -> list[str]:
    return [n.strip() for n in text.split(",") if n.strip()]


def peer_list(text: str) -> tuple[str, ...]:
    """``--peers a,b``: the names given (``none``: no peer)."""
    names = _names(text)
    return () if names == ["none"] else tuple(names)


def _peer_names(value: str) -> str:
    """``--peers``' check: names of :data:`PEERS`, or ``none``; else a usage error."""
    names = _names(value)
    unknown = [n for n in names if n not in PEERS]
    if not names or (unknown and names != ["none"]):
        raise typer.BadParameter(
            f"{value!r}: choose from {', '.join(PEERS)}, comma-separated, or none"
        )
    return value


PEERS_OPTION = typer.Option(
    ",".join(PEERS),
    "--peers",
    metavar="NAMES",
    callback=_peer_names,
    help=f"Baselines fitted beside our model, comma-separated: {', '.join(PEERS)}, or none "
    "(our model alone: faster).",
)
ENTRIES_HELP = "{}, comma-separated (default: every complete one)."
RIG_OPTION_HELP = (
    "Rig file, or a shipped rig's name such as hybrid (default: the protocol's `rig`, else the "
    "built-in simulated rig)."
)
