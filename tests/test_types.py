"""The type check: mypy over ``labrig/`` and ``drivers/`` at the strictness of
``[tool.mypy]`` in pyproject.toml (docs/architecture.md, "Types").

``drivers/`` is installed as ``labrig.drivers`` (a ``package-dir`` mapping), which mypy cannot
follow from the source tree: the check runs on the package as installed, a tree of links
(``labrig/*`` plus ``labrig/drivers -> drivers/``) under ``.mypy_cache/tree``. mypy's
incremental cache is the repository's ``.mypy_cache``: a fresh checkout (CI) checks every
module (about 30 s of CPU), a second run only what changed (about 5 s).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from mypy import api

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / ".mypy_cache"

pytestmark = pytest.mark.timeout(600)


def installed_tree(where: Path) -> Path:
    """``where/labrig``: links to each item of ``labrig/`` and ``drivers/`` as
    ``labrig/drivers``, the package as pip installs it. Returns ``where``."""
    tree = where / "labrig"
    if tree.is_symlink() or tree.is_file():
        tree.unlink()
    elif tree.exists():
        shutil.rmtree(tree)
    tree.mkdir(parents=True)
    for item in sorted((ROOT / "labrig").iterdir()):
        if item.name != "__pycache__":
            (tree / item.name).symlink_to(item)
    (tree / "drivers").symlink_to(ROOT / "drivers")
    return where


def run_mypy(
    cwd: Path, monkeypatch: pytest.MonkeyPatch, *args: str, cache: Path = CACHE
) -> tuple[str, int]:
    """mypy in this process, from ``cwd``, with the project's configuration and ``cache``."""
    monkeypatch.chdir(cwd)
    out, err, status = api.run(
        ["--config-file", str(ROOT / "pyproject.toml"), "--cache-dir", str(cache), *args]
    )
    return out + err, status


def test_labrig_and_its_drivers_type_check(monkeypatch):
    where = installed_tree(CACHE / "tree")
    report, status = run_mypy(where, monkeypatch, "-p", "labrig")
    assert status == 0, report
    assert "Success: no issues found" in report
    checked = int(report.split("found in ")[1].split()[0])
    # every module of labrig/ and drivers/ (the drivers reached only through the link); mypy's
    # count runs a few above the number of files (205 for 202 when this was written)
    expected = len(list((ROOT / "labrig").rglob("*.py"))) + len(
        list((ROOT / "drivers").rglob("*.py"))
    )
    assert expected <= checked <= expected + 5, report


def test_the_check_reports_what_the_configuration_asks_for(tmp_path, monkeypatch):
    """A planted module breaking each rule of the baseline: an error in a function without
    annotations (``check_untyped_defs``), ``None`` as the default of an ``int``
    (``no_implicit_optional``) and an ignore that ignores nothing (``warn_unused_ignores``)."""
    (tmp_path / "planted.py").write_text(
        "def untyped():\n"
        "    count: int = 'one'\n"
        "    return count\n"
        "\n"
        "\n"
        "def implicit(limit: int = None) -> int:\n"
        "    return 0\n"
        "\n"
        "\n"
        "fine: int = 1  # type: ignore[assignment]\n"
    )
    # a cache of its own: the test above may be writing the project's at the same time
    report, status = run_mypy(tmp_path, monkeypatch, "planted.py", cache=tmp_path / "cache")
    assert status == 1, report
    assert "planted.py:2: error" in report and "[assignment]" in report
    assert "planted.py:6: error" in report
    assert 'planted.py:10: error: Unused "type: ignore" comment' in report
    assert "Found 3 errors" in report
