"""The docstrings of the Python API (``labrig``, ``labrig.api``) and of the model
(``labrig/model/*.py``): numpydoc ``Parameters`` and ``Returns`` on every public function,
method and class (checked by numpydoc's own validator, so the rule holds as the code grows),
only the Sphinx roles of the Python domain, and the ``Examples`` run as doctests.

Left out: ``labrig/model/effects/`` (the effect library, documented by its registry and the
table in docs/diagnose.md) and ``labrig/model/compiled.py`` (the numba kernels behind
``labrig.model.accel.kernels()``, called only by the model's own modules).
"""

from __future__ import annotations

import doctest
import importlib
import inspect
import re
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest
from numpydoc.validate import validate

ROOT = Path(__file__).resolve().parents[1]
MODEL = sorted(
    f"labrig.model.{p.stem}"
    for p in (ROOT / "labrig" / "model").glob("*.py")
    if p.stem not in ("__init__", "compiled")
)
MODULES = ["labrig", "labrig.api", "labrig.api.runs", "labrig.api.frames", *MODEL]
#: numpydoc's codes for what the rule asks: no docstring (GL08), parameters missing (PR01) or
#: unknown (PR02), a value returned without a Returns section (RT01), yielded without a Yields
#: section (YD01)
RULE = ("GL08", "PR01", "PR02", "RT01", "YD01")
#: the Sphinx roles a docstring may use (the Python domain's cross-references)
ROLES = {"func", "class", "meth", "mod", "data", "attr", "exc", "obj"}


def public_names(modname: str) -> Iterator[str]:
    """The import paths of the public functions and classes ``modname`` defines (or, for a
    package, exports through ``__all__``), and of their public methods."""
    module = importlib.import_module(modname)
    names = getattr(module, "__all__", None) or [n for n in vars(module) if n[0] != "_"]
    for name in names:
        obj = getattr(module, name)
        if not (inspect.isfunction(obj) or inspect.isclass(obj)):
            continue
        if obj.__module__ != modname and not hasattr(module, "__path__"):
            continue  # imported from elsewhere
        path = f"{obj.__module__}.{obj.__qualname__}"
        yield path
        if inspect.isclass(obj):
            for attr, value in vars(obj).items():
                if attr[0] != "_" and (
                    inspect.isfunction(value) or isinstance(value, classmethod | staticmethod)
                ):
                    yield f"{path}.{attr}"


def rule_errors(path: str) -> list[str]:
    """What the rule finds wrong with the docstring of ``path`` (numpydoc's messages)."""
    return [f"{path}: {code} {msg}" for code, msg in validate(path)["errors"] if code in RULE]


def test_the_modules_have_public_names():
    found = {p for m in MODULES for p in public_names(m)}
    assert "labrig.api.runs.open" in found and "labrig.api.runs.Run.fit" in found
    assert "labrig.model.relaxor.Relaxor.filter" in found
    assert len(found) >= 80  # 90 when this was written


def test_every_public_function_and_class_states_parameters_and_returns():
    paths = sorted({p for m in MODULES for p in public_names(m)})
    errors = [e for p in paths for e in rule_errors(p)]
    assert not errors, "\n".join(errors)


def test_the_rule_finds_missing_sections(tmp_path, monkeypatch):
    """A planted module: a function with no sections, one with a parameter left out and no
    Returns, a documented one, and one returning nothing (which needs no Returns)."""
    (tmp_path / "planted_docs.py").write_text(
        textwrap.dedent(
            '''
            """Planted."""


            def bare(x):
                """Twice x."""
                return 2 * x


            def half(x, y):
                """The sum.

                Parameters
                ----------
                x : float
                    A number.
                """
                return x + y


            def full(x):
                """Twice x.

                Parameters
                ----------
                x : float
                    A number.

                Returns
                -------
                float
                    Twice ``x``.
                """
                return 2 * x


            def quiet(x):
                """Nothing back.

                Parameters
                ----------
                x : float
                    Ignored.
                """
            '''
        )
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        assert {e.split()[1] for e in rule_errors("planted_docs.bare")} == {"PR01", "RT01"}
        assert {e.split()[1] for e in rule_errors("planted_docs.half")} == {"PR01", "RT01"}
        assert rule_errors("planted_docs.full") == []
        assert rule_errors("planted_docs.quiet") == []
    finally:
        sys.modules.pop("planted_docs", None)


def test_docstrings_use_only_python_domain_roles():
    bad = []
    for modname in MODULES:
        text = Path(importlib.import_module(modname).__file__).read_text(encoding="utf-8")
        for m in re.finditer(r"(?<![\w`]):([a-z]+):`", text):
            if m.group(1) not in ROLES:
                line = text.count("\n", 0, m.start()) + 1
                bad.append(f"{modname}:{line}: :{m.group(1)}:")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("modname", MODULES)
def test_the_examples_run(modname):
    module = importlib.import_module(modname)
    flags = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
    result = doctest.testmod(module, optionflags=flags, verbose=False, report=True)
    assert result.failed == 0


def test_the_examples_are_there():
    """The doctests above run examples (a module that lost its Examples would pass them)."""
    finder = doctest.DocTestFinder()
    counts = {
        m: sum(len(t.examples) for t in finder.find(importlib.import_module(m))) for m in MODULES
    }
    with_examples = [m for m, n in counts.items() if n]
    assert "labrig.model.hysteresis" in with_examples and "labrig.api.frames" in with_examples
    assert sum(counts.values()) >= 40, counts
