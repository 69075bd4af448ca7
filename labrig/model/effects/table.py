"""The table of effects in docs/diagnose.md, rendered from the registry.

One row per registered effect in registry order (:data:`~labrig.model.effects.registry.
REGISTRY`), then the empirical terms: its name; where it acts, its parameters and its form (the
class's :attr:`~labrig.model.effects.base.Effect.acts_on`, ``params_doc`` and ``form``); its
residual signature (``signature``, the words the diagnosis report uses); and which commands use
it (from the registration). The docs carry the table between :data:`BEGIN` and :data:`END`;
after adding or changing an effect, rewrite it with

    python -m labrig.model.effects.table docs/diagnose.md

(a test fails while the docs carry another table).
"""

from __future__ import annotations

import sys
from pathlib import Path

from labrig.model.effects.registry import REGISTRY, Registration

__all__ = ["BEGIN", "END", "effect_table", "used_by", "with_table"]

BEGIN = (
    "<!-- effect table: rendered from labrig/model/effects/ by "
    "`python -m labrig.model.effects.table docs/diagnose.md`; do not edit by hand -->"
)
END = "<!-- end of the effect table -->"

COLUMNS = ("effect", "acts on", "parameters (null)", "form", "residual signature", "used by")


def used_by(r: Registration) -> str:
    """Which commands use the effect: ``labrig diagnose`` (a default candidate), ``diagnose
    --also``, ``labrig fit --effect`` and the compensation controller."""
    uses = [
        "`diagnose`" if r.candidate else "",
        "`diagnose --also`" if r.also else "",
        "`fit --effect`" if r.fit else "",
        "control (inverted)" if r.invertible else "",
    ]
    return ", ".join(u for u in uses if u)


def _cell(text: str) -> str:
    """A Markdown table cell: ``|`` escaped (also inside code spans), one line."""
    return " ".join(text.replace("|", "\\|").split())


def _row(cells: tuple[str, ...]) -> str:
    return "| " + " | ".join(_cell(c) for c in cells) + " |"


def effect_table() -> str:
    """The Markdown table of the library's effects (module docstring), without the markers."""
    from labrig.model.effects.empirical import EmpiricalTerms

    lines = [_row(COLUMNS), "|" + "---|" * len(COLUMNS)]
    for r in REGISTRY:
        cls = r.effect_class()
        lines.append(
            _row((f"`{r.name}`", cls.acts_on, cls.params_doc, cls.form, cls.signature, used_by(r)))
        )
    e = EmpiricalTerms
    lines.append(
        _row(
            (
                f"`{e.name}`",
                e.acts_on,
                e.params_doc,
                e.form,
                e.signature,
                "`diagnose`, when no named effect passes (never a physical attribution)",
            )
        )
    )
    return "\n".join(lines) + "\n"


def with_table(text: str) -> str:
    """``text`` (a Markdown page) with the current table between :data:`BEGIN` and :data:`END`
    (``ValueError`` when the page lacks either marker)."""
    head, begin, rest = text.partition(BEGIN + "\n")
    _, end, tail = rest.partition(END)
    if not begin or not end:
        raise ValueError(f"the page needs the lines {BEGIN!r} and {END!r} around the table")
    return head + BEGIN + "\n" + effect_table() + END + tail


if __name__ == "__main__":
    page = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/diagnose.md")
    page.write_text(with_table(page.read_text(encoding="utf-8")), encoding="utf-8")
    print(f"rewrote the table of effects in {page}")
