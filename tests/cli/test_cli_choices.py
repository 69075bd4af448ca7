"""Options with a fixed set of values: their choices are the library's, ``--help`` lists them,
and a bad value is a usage error (exit code 64, EX_USAGE) that names the option, the value and
every valid choice, before any file is read. Also: ``labrig --help`` stays light (no numerical
stack), flags show no ``<bool>``, counts take the right number ("1 entry")."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from labrig.cli.common import (
    FitEffect,
    Memory,
    Method,
    Model,
    Preset,
    StructuralEffect,
    plural,
)
from labrig.cli.typer_app import EXIT_USAGE

from helpers import invoke as run_cli

pytestmark = pytest.mark.timeout(120)


def invoke(*args: object):
    return run_cli(*args, columns=400)


def test_choices_are_the_librarys() -> None:
    from labrig.analysis.fit import fit_model
    from labrig.analysis.fit_effects import known_effects
    from labrig.commands.fit import MODELS
    from labrig.model import PRESETS
    from labrig.model.effects import STRUCTURAL_EFFECT_NAMES
    from labrig.model.hysteresis import MEMORY_RULES

    assert list(Model) == list(MODELS)
    assert list(Memory) == list(MEMORY_RULES)
    assert list(FitEffect) == known_effects()  # the registry's, in its order
    assert list(StructuralEffect) == list(STRUCTURAL_EFFECT_NAMES)
    assert list(Preset) == list(PRESETS)
    # fit_model checks the method before the records: a known method gets as far as those
    for m in Method:
        with pytest.raises(ValueError, match="no records"):
            fit_model([], method=m.value)
    with pytest.raises(ValueError, match="method must be"):
        fit_model([], method="newton")


OPTION_CHOICES = [
    (["fit"], "--method", Method),
    (["fit"], "--model", Model),
    (["fit"], "--memory", Memory),
    (["fit"], "--effect", FitEffect),
    (["report"], "--method", Method),
    (["diagnose"], "--also", StructuralEffect),
    (["model", "demo"], "--preset", Preset),
]


@pytest.mark.parametrize(("command", "option", "choices"), OPTION_CHOICES)
def test_help_lists_every_choice(command: list[str], option: str, choices: type) -> None:
    res = invoke(*command, "--help")
    assert res.exit_code == 0, res.output
    (line,) = [ln for ln in res.stdout.splitlines() if f" {option} " in ln]
    for c in choices:
        assert c.value in line, (c, line)


@pytest.mark.parametrize(("command", "option", "choices"), OPTION_CHOICES)
def test_a_bad_choice_is_a_usage_error(
    command: list[str], option: str, choices: type, tmp_path: Path
) -> None:
    missing = tmp_path / "missing.h5"  # never read: the option is refused first
    args = [*command] if command == ["model", "demo"] else [*command, missing]
    if command == ["report"]:
        args += ["--out", tmp_path / "r.html"]
    res = invoke(*args, option, "bogus_value")
    assert res.exit_code == EXIT_USAGE, res.output
    err = " ".join(res.stderr.split())
    assert f"'{option}'" in err and "bogus_value: not " in err
    assert "choose from " + ", ".join(c.value for c in choices) in err
    assert "Traceback" not in res.output and "not found" not in res.output
    assert res.stdout == ""


def test_also_names_what_else_is_tried(tmp_path: Path) -> None:
    res = invoke("diagnose", tmp_path / "run.h5", "--also", "mains")
    assert res.exit_code == EXIT_USAGE
    assert "the other effects are always tried" in " ".join(res.stderr.split())


def test_a_good_choice_arrives_as_its_value(tmp_path: Path) -> None:
    """The parsed choice reaches the library as the plain value (past the option checks: the
    run file is then reported missing)."""
    res = invoke("fit", tmp_path / "missing.h5", "--model", "bouc_wen", "--memory",
                 "last_reversal", "--method", "staged")  # fmt: skip
    assert res.exit_code == 2
    assert "run file not found" in res.stderr


def test_flags_show_no_bool_placeholder() -> None:
    for command in (["fit"], ["report"], ["run"], ["diagnose"], ["import"]):
        res = invoke(*command, "--help")
        flags = [ln for ln in res.stdout.splitlines() if "--json" in ln or "--overwrite" in ln]
        flags += [ln for ln in res.stdout.splitlines() if "--heldout" in ln]
        assert flags, command
        assert not any("<bool>" in ln for ln in flags), flags


def test_plural() -> None:
    assert plural(1, "entry") == "1 entry"
    assert plural(0, "entry") == "0 entries"
    assert plural(2, "entry") == "2 entries"
    assert plural(3, "record") == "3 records"
    assert plural(2, "axis", "axes") == "2 axes"


def test_check_counts_one_entry(tmp_path: Path) -> None:
    proto = tmp_path / "one.yaml"
    proto.write_text(
        "name: one\nrate_hz: 1000\nsteps:\n  - kind: hold\n    voltage_V: 10\n    duration_s: 1\n"
    )
    res = invoke("check", proto)
    assert res.exit_code == 0, res.output
    assert "OK, 1 entry, " in res.stdout


def test_help_does_not_load_the_numerical_stack() -> None:
    code = (
        "import sys, labrig.cli; "
        "print(' '.join(m for m in ('numpy', 'scipy', 'h5py', 'matplotlib') if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    )
    assert out.stdout.strip() == ""


def test_warmup_note_counts_records() -> None:
    import numpy as np

    from labrig.analysis.records import Record
    from labrig.commands.prepare import auto_warmup

    t = np.arange(4000) / 1000.0
    late = Record.from_arrays("late", 1000.0, 50 + 50 * np.sin(2 * np.pi * t), np.zeros(t.size))
    rest = Record.from_arrays("rest", 1000.0, 50 - 50 * np.cos(2 * np.pi * t), np.zeros(t.size))
    w, why = auto_warmup([late])
    assert w == 1.0  # two periods of 1 Hz, at most a quarter of the 4 s record
    assert why is not None and why.startswith("late does not start at rest (it starts at 50 V)")
    _, why = auto_warmup([late, rest])
    assert why is not None and why.startswith("1 of 2 records do not start at rest (e.g. late")
    assert auto_warmup([rest]) == (0.0, None)
