"""The command classes every ``labrig`` command and group is built with: usage errors exit with
:data:`EXIT_USAGE`, parameters show plain metavars (``RUN_FILE``, ``--out FILE``, no
``<bool>``, ``<list[Path]>`` or ``{protocol}``), and ``--help`` is drawn by
:func:`labrig.cli.help_format.render_help`.

:class:`LabrigTyper` is a :class:`typer.Typer` whose commands are :class:`LabrigCommand` and
whose groups are :class:`LabrigGroup` unless told otherwise, so a command registered with
``app.command("name")(fn)`` gets them without asking.
"""

from __future__ import annotations

import atexit
import enum
import functools
import gc
import typing
from pathlib import Path
from typing import Any

import typer
from typer.core import TyperCommand, TyperGroup

from labrig.cli.help_format import is_argument, render_help

#: exit code of a usage error (a bad option, a bad choice, a missing argument): EX_USAGE of
#: BSD's sysexits.h, distinct from 2 (bad input file) and 3 (device fault)
EXIT_USAGE = 64

#: click's UsageError as typer raises it (typer 0.2x runs a copy of click of its own; its
#: BadParameter, a public name, derives from that UsageError)
USAGE_ERROR: type[Exception] = next(
    c for c in typer.BadParameter.__mro__ if c.__name__ == "UsageError"
)

#: the metavar of an option's value by its Python type (options that set none)
TYPE_METAVARS: dict[type, str] = {Path: "PATH", str: "TEXT", float: "NUMBER", int: "INTEGER"}


def value_type(param: Any) -> Any:
    """The Python type of one value of ``param`` (``list[Path]`` -> ``Path``)."""
    desc = getattr(param, "type_descriptor", None)
    annotation = getattr(desc, "annotation", None)
    while typing.get_origin(annotation) in (list, tuple, typing.Union):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        annotation = args[0] if args else None
    return annotation


def default_metavar(param: Any) -> str:
    """The metavar a parameter shows when its definition gives none: an argument's name in
    capitals (``RUN_FILE``), nothing for a flag, else its type's (:data:`TYPE_METAVARS`; an
    enumeration's class name)."""
    if is_argument(param):
        return (param.name or "value").upper()
    if getattr(param, "is_flag", False) or getattr(param, "count", False):
        return ""
    t = value_type(param)
    if isinstance(t, type) and issubclass(t, enum.Enum):
        return t.__name__.upper()
    if t in TYPE_METAVARS:
        return TYPE_METAVARS[t]
    click_type = getattr(getattr(param, "type", None), "name", "")  # typer before 0.2x
    return {"path": "PATH", "text": "TEXT", "float": "NUMBER", "integer": "INTEGER"}.get(
        click_type, "VALUE"
    )


def name_params(params: list[Any]) -> None:
    """Give every parameter without a metavar its :func:`default_metavar` (also what usage
    errors show: ``Missing argument 'RUN_FILE'``)."""
    for p in params:
        if p.metavar is None:
            p.metavar = default_metavar(p)


def check_path_params(params: list[Any]) -> None:
    """Make an empty path (``labrig info ""``, ``--out ""``) a usage error naming the
    parameter: typer would take it for ``.``, the current folder. So is a file's path that
    ends with ``/`` (``--out FILE`` given ``new/``: pathlib drops the slash, and a file named
    ``new`` would be written)."""
    for p in params:
        if value_type(p) is Path:
            p.process_value = functools.partial(_checked_path, p, p.process_value)


def _given(value: Any) -> list[Any]:
    """One value or several (``nargs=-1``, ``multiple``) as a list."""
    return list(value) if isinstance(value, list | tuple) else [value]


def _checked_path(param: Any, process: Any, ctx: ClickContext, value: Any) -> Any:
    value = nonempty_paths(ctx, param, value)
    slashed = any(isinstance(v, str) and v.endswith("/") for v in _given(value))
    if param.metavar == "FILE" and slashed:
        raise typer.BadParameter(
            "ends with /, which names a folder: give a file name", ctx=ctx, param=param
        )
    return process(ctx, value)


def nonempty_paths(ctx: typer.Context, param: typer.CallbackParam, value: Any) -> Any:
    """``value`` (one text or several) unless one is empty: then a usage error naming ``param``.
    The callback of parameters that take paths as text (globs: ``batch``'s run files)."""
    if any(isinstance(v, str) and not v for v in _given(value)):
        named: Any = param  # typer's BadParameter is typed for its own parameter classes
        raise typer.BadParameter("an empty path: give a file or folder name", ctx=ctx, param=named)
    return value


def usage_pieces(command: TyperCommand | TyperGroup, ctx: typer.Context) -> list[str]:
    """``[OPTIONS] RUN_FILE [PATHS]...``: the usage line after the command's name."""
    params = command.get_params(ctx)
    pieces = ["[OPTIONS]"] if any(not is_argument(p) for p in params) else []
    for p in params:
        if is_argument(p):
            name = p.metavar or default_metavar(p)
            name = name if p.required else f"[{name}]"
            pieces.append(name + ("..." if p.nargs != 1 else ""))
    return pieces


#: the Context typer's base classes take and give: its vendored click's (``typer.Context``
#: subclasses it), whose module is private to typer, so the overrides below name it ``Any``
ClickContext = Any


class LabrigCommand(TyperCommand):
    """A command with plain metavars and labrig's help layout."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        name_params(self.params)
        check_path_params(self.params)

    def collect_usage_pieces(self, ctx: ClickContext) -> list[str]:
        return usage_pieces(self, ctx)

    def format_help(self, ctx: ClickContext, formatter: Any) -> None:
        formatter.write(render_help(self, ctx))


class LabrigGroup(TyperGroup):
    """A group with plain metavars and labrig's help layout; every usage error raised while
    parsing its command line, or its subcommands', exits with :data:`EXIT_USAGE`."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        name_params(self.params)

    def collect_usage_pieces(self, ctx: ClickContext) -> list[str]:
        return [*usage_pieces(self, ctx), "COMMAND [ARGS]..."]

    def format_help(self, ctx: ClickContext, formatter: Any) -> None:
        formatter.write(render_help(self, ctx))

    def make_context(self, *args: Any, **kwargs: Any) -> ClickContext:
        try:
            return super().make_context(*args, **kwargs)
        except USAGE_ERROR as e:
            e.exit_code = EXIT_USAGE  # type: ignore[attr-defined]
            raise

    def invoke(self, ctx: ClickContext) -> Any:
        try:
            return super().invoke(ctx)
        except USAGE_ERROR as e:
            e.exit_code = EXIT_USAGE  # type: ignore[attr-defined]
            raise


class LabrigTyper(typer.Typer):
    """A :class:`typer.Typer` building :class:`LabrigGroup` and :class:`LabrigCommand`."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("cls", LabrigGroup)
        kwargs.setdefault("pretty_exceptions_enable", False)
        super().__init__(*args, **kwargs)

    def command(self, *args: Any, **kwargs: Any) -> Any:
        kwargs["cls"] = kwargs.get("cls") or LabrigCommand
        return super().command(*args, **kwargs)

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        """The command line as a process runs it (the ``labrig`` script, ``python -m labrig``),
        which ends when the command does: at exit, after the exit handlers registered before
        this call, every object is moved to the collector's permanent generation
        (``gc.freeze``), so the interpreter's last collections do not walk the heap the
        command built (scipy, numba, matplotlib and the data; what that saves is in
        benchmarks/RESULTS.md). Files, locks and children are closed by the
        command itself and by exit handlers, never by the collector. The tests' in-process
        runner invokes the click command and does not pass here."""
        atexit.register(gc.freeze)
        return super().__call__(*args, **kwargs)
