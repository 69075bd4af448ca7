"""What ``fit`` and ``report`` show on stderr while they work: the setup line and its notes, rich
progress bars for the fits, a spinner for the figures (a
:class:`~labrig.commands.fit.CommandUI`)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
)

from labrig.commands.prepare import Setup
from labrig.core.words import plural

#: what the bars say for the stages the fits report (labrig.commands.fit.Progress)
BASELINE_BARS = {
    "prandtl_ishlinskii": "Prandtl-Ishlinskii: fit (and leave-one-out)",
    "bouc_wen": "Bouc-Wen: fit (and leave-one-out)",
}
EFFECTS_BARS = {"effects": "model + effects: fit from each start", "heldout": "leave-one-out"}


def print_setup(err: Console, setup: Setup) -> None:
    """How the run file's records will be fitted, and the notes on that choice."""
    how = "chained as one run" if setup.chain else "each on its own, from rest"
    err.print(
        f"[bold]{escape(str(setup.path))}[/]: {plural(len(setup.scored), 'entry')} to fit "
        f"({how}; warm-up {setup.warmup_s:g} s; offset {'on' if setup.offset else 'off'})"
    )
    for n in setup.notes:
        err.print(f"[yellow]note:[/] {escape(n)}")


class FitBars:
    """Rich progress bars on stderr, one per stage, added as the fits report them."""

    def __init__(self, console: Console, n_scored: int):
        self.n_scored = n_scored
        self.bar = Progress(
            SpinnerColumn(),
            TextColumn("{task.description}"),
            BarColumn(bar_width=30),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=console,
            transient=False,
        )
        self._tasks: dict[str, Any] = {}

    def _update(self, key: str, description: str, total: int, done: int) -> None:
        if key not in self._tasks:
            self._tasks[key] = self.bar.add_task(description, total=total)
        self.bar.update(self._tasks[key], completed=done)

    def __call__(self, stage: str, done: int, total: int) -> None:
        """The ``progress(stage, done, total)`` callback of the fits."""
        group, _, sub = stage.partition(":")
        if group == "model" and sub == "fit":
            self._update(stage, f"model: fit on {plural(self.n_scored, 'entry')}", 1, done)
        elif group == "model":
            self._update("model:heldout", "model: leave-one-entry-out", total, done)
        elif group == "effects":
            self._update(stage, EFFECTS_BARS.get(sub, sub), total, done)
        else:
            self._update(stage, BASELINE_BARS.get(stage, stage), total, done)


class RichUI:
    """The command line's :class:`~labrig.commands.fit.CommandUI`: everything on stderr."""

    def __init__(self) -> None:
        self.err = Console(stderr=True)
        self.n_scored = 0

    def announce(self, setup: Setup) -> None:
        self.n_scored = len(setup.scored)
        print_setup(self.err, setup)

    @contextmanager
    def fitting(self) -> Iterator[Callable[[str, int, int], None]]:
        bars = FitBars(self.err, self.n_scored)
        with bars.bar:
            yield bars

    @contextmanager
    def busy(self, what: str) -> Iterator[None]:
        with self.err.status(what):
            yield
