"""What the command modules share: the ``friendly`` error wrapper, options used by several
commands, the choices of options with a fixed set of values, and small output helpers.

The choices are :class:`~enum.StrEnum` so ``--help`` lists them; they repeat names the library
defines (tests/test_cli_choices.py checks they match) so that ``labrig --help`` does not import
the numerical stack.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from enum import StrEnum
from typing import Any, TypeVar

import typer

from labrig.errors import LabrigError

E = TypeVar("E", bound=StrEnum)


def friendly(fn: Callable) -> Callable:
    """Expected failures print one clear message (no traceback) and exit with their code."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except LabrigError as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(e.exit_code) from None
        except FileExistsError as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(2) from None
        except KeyboardInterrupt:
            typer.echo("interrupted", err=True)
            raise typer.Exit(130) from None

    return wrapper


def plural(n: int, singular: str, plural_form: str | None = None) -> str:
    """``"1 entry"``, ``"2 entries"``: ``n`` and the noun in the number it takes."""
    many = plural_form or (singular[:-1] + "ies" if singular.endswith("y") else singular + "s")
    return f"{n} {singular if n == 1 else many}"


# -- choices -------------------------------------------------------------------------------------


class Method(StrEnum):
    """How ``fit`` identifies the model (labrig.analysis.fit)."""

    GLOBAL = "global"
    STAGED = "staged"


class Model(StrEnum):
    """What ``fit`` identifies: our model or a baseline (labrig.analysis.fit_run.MODELS)."""

    DYNAMIC = "dynamic"
    PRANDTL_ISHLINSKII = "prandtl_ishlinskii"
    BOUC_WEN = "bouc_wen"
    SINDY = "sindy"


class Memory(StrEnum):
    """The hysteresis operator's memory rule (labrig.model.hysteresis.MEMORY_RULES)."""

    RETURN_POINT = "return_point"
    LAST_REVERSAL = "last_reversal"


class FitEffect(StrEnum):
    """Effects ``fit --effect`` adds to the model (labrig.analysis.fit_effects.known_effects)."""

    THERMAL_DRIFT = "thermal_drift"
    AMPLIFIER_CURRENT_LIMIT = "amplifier_current_limit"
    SENSOR_LOWPASS = "sensor_lowpass"
    CREEP = "creep"
    VISCOELASTIC_CREEP = "viscoelastic_creep"
    REMANENCE = "remanence"
    TIME_DELAY = "time_delay"
    QUADRATIC_TERM = "quadratic_term"


class StructuralEffect(StrEnum):
    """Effects ``diagnose --also`` tries beside its default candidates
    (labrig.model.effects.STRUCTURAL_EFFECT_NAMES)."""

    REMANENCE = "remanence"
    VISCOELASTIC_CREEP = "viscoelastic_creep"


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
ENTRIES_HELP = "{}, comma-separated (default: every complete one)."
RIG_OPTION_HELP = "Rig file (default: the protocol's `rig`, else the built-in simulated rig)."
