"""Pure numerics of the fractional-order dynamic hysteresis model (no I/O).

Public API: :class:`Relaxor`, :class:`QuasiStaticHysteresis`, :class:`ModelParams` with the
presets :data:`PAPER_TABLE1`, :data:`PAPER_TEXT`, :data:`PAPER_CONTROL`, and
:class:`DynamicHysteresisModel`.

Importing the package imports no numerical package: each name is imported from its module when
first used (``from labrig.model import ModelParams`` works as usual), so the command line can
read the effect registry (:mod:`labrig.model.effects.registry`) when it starts.
"""

from __future__ import annotations

import importlib
from typing import Any

#: each public name and the module of this package it comes from (imported on first use)
LAZY: dict[str, str] = {
    "PAPER_CONTROL": "params",
    "PAPER_TABLE1": "params",
    "PAPER_TEXT": "params",
    "PRESETS": "params",
    "DynamicHysteresisModel": "dynamic",
    "HysteresisState": "hysteresis",
    "ModelParams": "params",
    "ModelStream": "dynamic",
    "QuasiStaticHysteresis": "hysteresis",
    "Relaxor": "relaxor",
    "Shape": "hysteresis",
    "mittag_leffler": "mittag_leffler",
}

__all__ = list(LAZY)


def __getattr__(name: str) -> Any:
    """A public name, imported from its module on first use (PEP 562)."""
    module = LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *LAZY})
