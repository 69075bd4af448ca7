"""``--help`` of every labrig command, drawn with rich: the usage line, the command's text, then
panels of arguments, options and subcommands, each parameter with its plain metavar
(``--out FILE``; a flag shows none) and its help with the default, range and ``required``
that click states (``[default: global]``).

Texts are printed as they are (no rich markup is read from them), so help that mentions
``[brackets]`` shows them.
"""

from __future__ import annotations

import inspect
import io
import shutil
import sys
from typing import Any

import typer
from rich.console import Console, Group
from rich.padding import Padding
from rich.panel import Panel
from rich.table import Table
from rich.text import Text


def is_argument(param: Any) -> bool:
    """True for a positional argument (click's ``param_type_name``)."""
    return getattr(param, "param_type_name", "") == "argument"


def declaration(param: Any) -> str:
    """``--out FILE``, ``--heldout / --no-heldout``, ``RUN_FILE``, ``[PATHS]...``."""
    metavar = param.metavar or ""
    if is_argument(param):
        name = metavar or (param.name or "").upper()
        return (name if param.required else f"[{name}]") + ("..." if param.nargs != 1 else "")
    names = ", ".join(sorted(param.opts, key=lambda o: (not o.startswith("--"), o)))
    if param.secondary_opts:
        names += " / " + ", ".join(param.secondary_opts)
    return f"{names} {metavar}".rstrip()


def help_text(param: Any, ctx: typer.Context) -> str:
    """The parameter's help with what click adds (default, range, required)."""
    record = param.get_help_record(ctx)
    return (record[1] if record else "") or ""


def _panel(title: str, rows: list[tuple[str, str]]) -> Panel | None:
    if not rows:
        return None
    grid = Table.grid(padding=(0, 2))
    grid.add_column(no_wrap=True, style="bold cyan")
    grid.add_column(overflow="fold")
    for name, text in rows:
        grid.add_row(Text(name), Text(text))
    return Panel(grid, title=title, title_align="left", border_style="dim")


def command_rows(group: Any, ctx: typer.Context) -> list[tuple[str, str]]:
    """A group's subcommands with their one-line help."""
    rows = []
    for name in group.list_commands(ctx):
        cmd = group.get_command(ctx, name)
        if cmd is not None and not cmd.hidden:
            rows.append((name, cmd.get_short_help_str(limit=300)))
    return rows


def render_help(command: Any, ctx: typer.Context) -> str:
    """The help page of ``command`` as text (with colour codes when stdout is a terminal)."""
    width = shutil.get_terminal_size((100, 24)).columns
    buf = io.StringIO()
    con = Console(file=buf, width=width, force_terminal=sys.stdout.isatty(), highlight=False)
    parts: list = [Padding(Text("Usage: " + ctx.command_path + " " + " ".join(
        command.collect_usage_pieces(ctx)), style="bold"), (1, 1))]  # fmt: skip
    if command.help:
        parts.append(Padding(Text(inspect.cleandoc(command.help)), (0, 1, 1, 1)))
    params = [p for p in command.get_params(ctx) if not getattr(p, "hidden", False)]
    rows = [(declaration(p), help_text(p, ctx), is_argument(p)) for p in params]
    panels = [
        _panel("Arguments", [(d, h) for d, h, arg in rows if arg]),
        _panel("Options", [(d, h) for d, h, arg in rows if not arg]),
    ]
    if hasattr(command, "list_commands"):
        panels.append(_panel("Commands", command_rows(command, ctx)))
    parts += [p for p in panels if p is not None]
    con.print(Group(*parts))
    return "\n".join(line.rstrip() for line in buf.getvalue().splitlines()).strip("\n")
