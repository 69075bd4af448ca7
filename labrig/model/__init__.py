"""Pure numerics of the fractional-order dynamic hysteresis model (no I/O).

Public API: :class:`Relaxor`, :class:`QuasiStaticHysteresis`, :class:`ModelParams` with the
presets :data:`PAPER_TABLE1`, :data:`PAPER_TEXT`, :data:`PAPER_CONTROL`, and
:class:`DynamicHysteresisModel`.
"""

from labrig.model.dynamic import DynamicHysteresisModel, ModelStream
from labrig.model.hysteresis import HysteresisState, QuasiStaticHysteresis, Shape
from labrig.model.mittag_leffler import mittag_leffler
from labrig.model.params import PAPER_CONTROL, PAPER_TABLE1, PAPER_TEXT, PRESETS, ModelParams
from labrig.model.relaxor import Relaxor

__all__ = [
    "PAPER_CONTROL",
    "PAPER_TABLE1",
    "PAPER_TEXT",
    "PRESETS",
    "DynamicHysteresisModel",
    "HysteresisState",
    "ModelParams",
    "ModelStream",
    "QuasiStaticHysteresis",
    "Relaxor",
    "Shape",
    "mittag_leffler",
]
