"""Words for people: a count and its noun in the number it takes; text from a file as a
terminal may print it."""

from __future__ import annotations

__all__ = ["plural", "shown"]


def plural(n: int, singular: str, plural_form: str | None = None) -> str:
    """``"1 entry"``, ``"2 entries"``: ``n`` and the noun in the number it takes."""
    many = plural_form or (singular[:-1] + "ies" if singular.endswith("y") else singular + "s")
    return f"{n} {singular if n == 1 else many}"


def shown(text: object) -> str:
    """``text`` (from a file: a name another program wrote) with every character that is not
    printable written as its Python escape (``"a\\nb"``, ``"\\x1b[2J"``): a newline cannot
    forge a line of output, nor an escape sequence reach the terminal."""
    s = str(text)
    if s.isprintable():
        return s
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in s)
