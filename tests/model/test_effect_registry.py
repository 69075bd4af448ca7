"""The effect registry (labrig.model.effects.registry): every registered module defines its
effect, every effect class of the package is registered, names are unique, everything that lists
effects is derived from it (names, ``library()``, the command line's choices, the docs' table),
and reading it loads no numerical package."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import subprocess
import sys
import types
from pathlib import Path

import pytest

import labrig.model.effects as effects_pkg
from labrig.model.effects import table
from labrig.model.effects.base import Effect
from labrig.model.effects.registry import (
    BUILT_FROM_DATA,
    CREEP_EFFECTS,
    EFFECT_NAMES,
    FIT_EFFECT_NAMES,
    INVERTIBLE_EFFECTS,
    REGISTRY,
    STRUCTURAL_EFFECT_NAMES,
    Registration,
    RunContext,
    library,
    registration,
)

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs" / "diagnose.md"
#: modules of the package that are not an effect
NOT_EFFECTS = {"base", "empirical", "registry", "table"}


def registration_problems(registrations: tuple[Registration, ...]) -> list[str]:
    """What is wrong with ``registrations``: a module without its class, a class whose name or
    ``where`` differ from its registration, a constructor that does not take exactly the
    registered context fields, an empty docs cell, a repeated name."""
    out = []
    names = [r.name for r in registrations]
    out += [f"{n}: registered twice" for n in sorted({n for n in names if names.count(n) > 1})]
    context_fields = set(RunContext.types())
    for r in registrations:
        try:
            cls = r.effect_class()
        except (ImportError, AttributeError) as e:
            out.append(f"{r.name}: {r.module} does not define {r.cls} ({e})")
            continue
        if not (isinstance(cls, type) and issubclass(cls, Effect)):
            out.append(f"{r.name}: {r.cls} is not an Effect")
            continue
        if cls.__module__ != r.module:
            out.append(f"{r.name}: {r.cls} is defined in {cls.__module__}, not {r.module}")
        if cls.name != r.name or cls.where != r.where:
            out.append(f"{r.name}: class says name {cls.name!r}, where {cls.where!r}")
        taken = list(inspect.signature(cls).parameters)
        if taken != list(r.context) or not set(r.context) <= context_fields:
            out.append(f"{r.name}: constructor takes {taken}, registered context {r.context}")
        if not (cls.acts_on and cls.params_doc and cls.form and cls.signature and cls.physics):
            out.append(f"{r.name}: a cell of the docs' table is empty")
    return out


def effect_classes(modules: list[types.ModuleType]) -> dict[str, str]:
    """Effect name -> module, for every ``Effect`` subclass defined in ``modules``."""
    found = {}
    for m in modules:
        for obj in vars(m).values():
            if (
                isinstance(obj, type)
                and issubclass(obj, Effect)
                and obj is not Effect
                and obj.__module__ == m.__name__
            ):
                found[obj.name] = m.__name__
    return found


def unregistered(modules: list[types.ModuleType]) -> list[str]:
    """Effects defined in ``modules`` that are neither registered nor built from data, and
    effect modules that are not a registered effect's."""
    known = {r.name for r in REGISTRY} | set(BUILT_FROM_DATA)
    out = [f"{n} ({m})" for n, m in effect_classes(modules).items() if n not in known]
    registered = {r.module for r in REGISTRY}
    for m in modules:
        short = m.__name__.rpartition(".")[2]
        if short not in NOT_EFFECTS and m.__name__ not in registered:
            out.append(f"module {m.__name__} is not a registered effect's")
    return out


def package_modules() -> list[types.ModuleType]:
    return [
        importlib.import_module(f"{effects_pkg.__name__}.{m.name}")
        for m in pkgutil.iter_modules(effects_pkg.__path__)
    ]


def test_every_registered_module_defines_its_effect():
    assert registration_problems(REGISTRY) == []


def test_every_effect_class_in_the_package_is_registered():
    modules = package_modules()
    assert unregistered(modules) == []
    assert set(effect_classes(modules)) == {r.name for r in REGISTRY} | set(BUILT_FROM_DATA)


def test_the_checks_can_fail():
    """A planted unregistered effect, a registration without its class, a repeated name, a
    registration whose where or context differ from its class are all found."""

    class Planted(Effect):
        name = "planted_effect"
        where = "output"

    fake = types.ModuleType("labrig.model.effects.planted_effect")
    Planted.__module__ = fake.__name__
    fake.Planted = Planted  # type: ignore[attr-defined]
    found = unregistered([*package_modules(), fake])
    assert found == [
        "planted_effect (labrig.model.effects.planted_effect)",
        "module labrig.model.effects.planted_effect is not a registered effect's",
    ]
    creep = registration("creep")
    bad = (
        creep,
        Registration("creep", "Creep", "output"),  # twice
        Registration("no_such_effect", "NoSuchEffect", "output"),
        Registration("time_delay", "TimeDelay", "voltage"),
        Registration("quadratic_term", "QuadraticTerm", "voltage"),  # context missing
    )
    problems = registration_problems(bad)
    assert problems[0] == "creep: registered twice"
    assert any(p.startswith("no_such_effect: ") for p in problems)
    assert any(p.startswith("time_delay: class says") for p in problems)
    assert any(p.startswith("quadratic_term: constructor takes ['v_ref']") for p in problems)


def test_names_and_classes_are_unique():
    names = [r.name for r in REGISTRY]
    assert len(names) == len(set(names))
    assert len({r.cls for r in REGISTRY}) == len(REGISTRY)
    assert not set(names) & set(BUILT_FROM_DATA)


def in_order(names: tuple[str, ...], expected: tuple[str, ...]) -> bool:
    """``expected`` are all in ``names``, in that order (other names may come between)."""
    return [n for n in names if n in expected] == list(expected)


def test_the_name_lists_are_derived_in_registry_order():
    """The report's order (EFFECT_NAMES) of the effects it has always had is kept: a reordered
    registry would reorder reports (a new effect may come anywhere)."""
    assert in_order(
        EFFECT_NAMES,
        (
            "thermal_drift",
            "amplifier_current_limit",
            "sensor_lowpass",
            "mains_pickup",
            "offset_drift",
            "creep",
            "viscoelastic_creep",
            "time_delay",
            "quadratic_term",
            "field_saturation",
        ),
    )
    assert "remanence" not in EFFECT_NAMES
    assert tuple(r.name for r in REGISTRY if r.candidate) == EFFECT_NAMES
    assert in_order(STRUCTURAL_EFFECT_NAMES, ("viscoelastic_creep", "remanence"))
    assert in_order(CREEP_EFFECTS, ("creep", "viscoelastic_creep"))
    assert in_order(INVERTIBLE_EFFECTS, ("viscoelastic_creep", "remanence"))
    assert not in_order(EFFECT_NAMES, ("creep", "thermal_drift"))  # the check can fail
    lib = library()
    assert list(lib) == [r.name for r in REGISTRY]
    assert tuple(n for n, e in lib.items() if e.where != "nuisance") == FIT_EFFECT_NAMES


def test_the_package_and_its_users_read_the_registry():
    from labrig.analysis.fit_effects import known_effects
    from labrig.analysis.params_file import CONTEXT_TYPES
    from labrig.control import INVERTIBLE_EFFECTS as CONTROL_INVERTIBLE

    assert effects_pkg.EFFECT_NAMES is EFFECT_NAMES
    assert effects_pkg.library is library
    assert known_effects() == list(FIT_EFFECT_NAMES)
    assert CONTROL_INVERTIBLE == INVERTIBLE_EFFECTS
    assert {
        "temperature": bool,
        "amplifier_voltage": bool,
        "mains_hz": float,
        "v_ref": float,
        "rate_hz": float,
    } == CONTEXT_TYPES
    # every registered class is importable from the package, as it was before the registry
    for r in REGISTRY:
        assert getattr(effects_pkg, r.cls) is r.effect_class()
    with pytest.raises(AttributeError, match="no attribute 'NoSuchEffect'"):
        _ = effects_pkg.NoSuchEffect


def test_library_is_configured_from_the_run_context():
    lib = library(temperature=True, amplifier_voltage=True, mains_hz=60.0, v_ref=150.0)
    assert [q.name for q in lib["thermal_drift"].params] == ["k_per_K"]
    assert lib["amplifier_current_limit"].params == ()
    assert lib["mains_pickup"].f_hz == 60.0
    assert lib["quadratic_term"].v_ref == lib["field_saturation"].v_ref == 150.0
    plain = library()
    assert [q.name for q in plain["thermal_drift"].params] == ["k_rel", "tau_th_s"]
    assert [q.name for q in plain["amplifier_current_limit"].params] == ["inv_slew_ms_per_V"]
    assert plain["mains_pickup"].f_hz == 50.0 and plain["quadratic_term"].v_ref == 100.0
    with pytest.raises(TypeError):
        library(humidity=True)


def test_the_cli_choices_are_the_registry():
    from labrig.cli.common import FitEffect, StructuralEffect

    assert [e.value for e in FitEffect] == list(FIT_EFFECT_NAMES)
    assert [e.value for e in StructuralEffect] == list(STRUCTURAL_EFFECT_NAMES)


def test_reading_the_registry_loads_no_numerical_package():
    code = (
        "import sys, labrig.model.effects, labrig.model.effects.registry as r; "
        "r.EFFECT_NAMES; "
        "print(' '.join(m for m in ('numpy', 'scipy') if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    )
    assert out.stdout.strip() == ""


def test_the_docs_carry_the_current_table_of_effects():
    text = DOCS.read_text(encoding="utf-8")
    assert table.with_table(text) == text, (
        "docs/diagnose.md's table of effects is not the registry's: rewrite it with "
        "`python -m labrig.model.effects.table docs/diagnose.md`"
    )
    for r in REGISTRY:
        assert f"| `{r.name}` |" in text


def test_a_stale_table_is_found(monkeypatch):
    text = DOCS.read_text(encoding="utf-8")
    lines = text.splitlines(keepends=True)
    stale = "".join(ln for ln in lines if not ln.startswith("| `creep` |"))
    assert stale != text and table.with_table(stale) == text
    # a registration the docs lack changes the rendering
    monkeypatch.setattr(table, "REGISTRY", REGISTRY[:-1])
    assert table.with_table(text) != text
    with pytest.raises(ValueError, match="needs the lines"):
        table.with_table("no table here\n")


def test_the_table_escapes_pipes_and_lists_who_uses_each_effect():
    rendered = table.effect_table()
    rows = {ln.split(" | ")[0][2:].strip("`"): ln for ln in rendered.splitlines()[2:]}
    assert list(rows) == [*(r.name for r in REGISTRY), "empirical_terms"]
    assert all(ln.count(" | ") == len(table.COLUMNS) - 1 for ln in rows.values())
    assert "`\\|dV/dt\\| <= I/C`" in rows["amplifier_current_limit"]
    assert rows["remanence"].endswith("| `diagnose --also`, `fit --effect`, control (inverted) |")
    assert rows["mains_pickup"].endswith("| `diagnose` |")
