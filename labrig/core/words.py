"""Words for people: a count and its noun in the number it takes."""

from __future__ import annotations

__all__ = ["plural"]


def plural(n: int, singular: str, plural_form: str | None = None) -> str:
    """``"1 entry"``, ``"2 entries"``: ``n`` and the noun in the number it takes."""
    many = plural_form or (singular[:-1] + "ies" if singular.endswith("y") else singular + "s")
    return f"{n} {singular if n == 1 else many}"
