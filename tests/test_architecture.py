"""The tree reads as the data flow: no import cycle anywhere in labrig/ (counting imports inside
functions, a package's ``__init__`` importing its own submodules excepted) and no private name
(``_x``) imported across modules, in the package, its tests and its benchmarks."""

from __future__ import annotations

import ast
import functools
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def module_files() -> dict[str, Path]:
    """Module name -> file, for labrig/ and drivers/ (installed as labrig.drivers)."""
    out: dict[str, Path] = {}
    for base, prefix in ((ROOT / "labrig", "labrig"), (ROOT / "drivers", "labrig.drivers")):
        for f in base.rglob("*.py"):
            parts = list(f.relative_to(base).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([prefix, *parts])] = f
    return out


def imports_of(name: str, path: Path, known: set[str]) -> set[str]:
    """labrig modules ``name`` imports anywhere in its file (resolved to known modules)."""
    found: set[str] = set()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1])
                base = f"{base}.{node.module}" if node.module else base
            targets = [f"{base}.{a.name}" for a in node.names] + [base]
        else:
            continue
        for t in targets:
            while t and t not in known:
                t = t.rpartition(".")[0]
            if t and t != name:
                found.add(t)
    return found


def cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(comp)

    sys.setrecursionlimit(10_000)
    for v in graph:
        if v not in index:
            visit(v)
    return out


@functools.cache
def _cached_graph() -> dict[str, frozenset[str]]:
    files = module_files()
    graph = {name: imports_of(name, path, set(files)) for name, path in files.items()}
    # a package's __init__ importing its own submodules is not a cycle of interest
    return {n: frozenset(t for t in ts if not t.startswith(n + ".")) for n, ts in graph.items()}


def _graph() -> dict[str, set[str]]:
    """Module -> the labrig modules it imports (a fresh copy: tests plant edges in it)."""
    return {n: set(ts) for n, ts in _cached_graph().items()}


def test_no_import_cycle():
    assert not [sorted(c) for c in cycles(_graph())]


def private_imports_in(text: str) -> list[str]:
    """``from labrig.x import _name`` and ``labrig.x._name`` uses in the source ``text``."""
    out = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("labrig"):
            out += [f"{node.module}.{a.name}" for a in node.names if _private(a.name)]
            out += [node.module] if any(_private(p) for p in node.module.split(".")) else []
        elif (
            isinstance(node, ast.Attribute)
            and _private(node.attr)
            and ast.unparse(node.value).startswith("labrig.")
        ):
            out.append(ast.unparse(node))
    return out


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def test_no_private_import_across_modules():
    files = [*ROOT.joinpath("labrig").rglob("*.py"), *ROOT.joinpath("drivers").rglob("*.py")]
    files += [*ROOT.joinpath("tests").rglob("*.py"), *ROOT.joinpath("benchmarks").rglob("*.py")]
    found = [
        f"{f.relative_to(ROOT)}: {x}" for f in files for x in private_imports_in(f.read_text())
    ]
    assert not found, "\n".join(found)


def test_the_checks_can_fail():
    """A planted cycle and a planted private import are found."""
    graph = _graph()
    graph["labrig.rig.limits"] = {*graph["labrig.rig.limits"], "labrig.runner.execute"}
    assert any("labrig.rig.limits" in c for c in cycles(graph))
    assert private_imports_in("from labrig.analysis.fit import _fit_once\n")
    assert private_imports_in("import labrig.analysis.fit\nlabrig.analysis.fit._fit_once()\n")
    assert not private_imports_in("from labrig import __version__\n")


def test_the_simulators_do_not_import_the_runner_or_rig_opening():
    """``labrig sim serve`` loads the simulators without the runner: imports run one way
    (``rigfile -> drivers.sim.serve -> rigspec``)."""
    code = (
        "import sys, labrig.drivers.sim.serve; "
        "print(sorted(m for m in ('labrig.runner.execute', 'labrig.runner.rigfile') "
        "if m in sys.modules))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"


# -- the layers: the folders of docs/architecture.md, each importing only from the rows below --

ARCHITECTURE = ROOT / "docs" / "architecture.md"


def documented_layers() -> list[list[str]]:
    """The rows of the ``layers`` block of docs/architecture.md, top first: each row's folders
    (``analysis/diagnose`` as ``analysis.diagnose``, ``drivers/sim`` as ``drivers.sim``)."""
    text = ARCHITECTURE.read_text()
    block = text.split("<!-- layers -->", 2)[1]
    rows = []
    for line in block.splitlines():
        line = line.strip()
        if not line or line.startswith("```"):
            continue
        folders = line.split("#")[0].split()
        rows.append([f.strip("/").replace("/", ".") for f in folders])
    return [r for r in rows if r]


def folder_of(module: str, layers: list[list[str]]) -> str:
    """The documented folder a module lives in (the longest documented prefix)."""
    parts = module.split(".")[1:]  # without "labrig"
    known = {f for row in layers for f in row}
    for k in range(len(parts), 0, -1):
        if ".".join(parts[:k]) in known:
            return ".".join(parts[:k])
    return "<root>"


def layer_violations(graph: dict[str, set[str]], layers: list[list[str]]) -> list[str]:
    """Imports from a folder to one in the same row or a row above (``a -> b``)."""
    rank = {f: i for i, row in enumerate(layers) for f in row}
    out = []
    for a, targets in graph.items():
        fa = folder_of(a, layers)
        if fa == "<root>":
            continue  # the package's face (labrig/__init__.py) hands the API on
        for b in targets:
            fb = folder_of(b, layers)
            if fa == fb:
                continue
            if fb == "<root>" or rank[fb] <= rank[fa]:
                out.append(f"{a} -> {b} ({fa} may not import {fb})")
    return sorted(out)


def test_every_folder_is_in_one_documented_layer():
    layers = documented_layers()
    listed = [f for row in layers for f in row]
    assert len(listed) == len(set(listed)), "a folder is listed twice in docs/architecture.md"
    on_disk = {
        ".".join(p.parent.relative_to(ROOT / "labrig").parts)
        for p in (ROOT / "labrig").rglob("__init__.py")
        if p.parent != ROOT / "labrig"
    }
    on_disk |= {"drivers", "drivers.sim"}
    missing = sorted(f for f in on_disk if folder_of("labrig." + f, layers) == "<root>")
    assert not missing, f"folders not in docs/architecture.md's layers: {missing}"
    stale = sorted(set(listed) - on_disk)
    assert not stale, f"docs/architecture.md lists folders that do not exist: {stale}"


def test_no_module_at_the_package_root():
    """The folder says the layer: labrig/ holds only its face (``__init__``, ``__main__``)."""
    face = ("__init__.py", "__main__.py")
    loose = sorted(p.name for p in (ROOT / "labrig").glob("*.py") if p.name not in face)
    assert not loose, f"modules at labrig/'s root, outside every layer: {loose}"


def test_imports_follow_the_layers():
    """Every import (inside functions too) goes to a folder in a lower row of the layers."""
    assert not layer_violations(_graph(), documented_layers())


def test_the_layer_check_can_fail():
    layers = documented_layers()
    graph = _graph()
    up = {**graph, "labrig.model.hysteresis": {"labrig.analysis.fit"}}
    assert layer_violations(up, layers) == [
        "labrig.model.hysteresis -> labrig.analysis.fit (model may not import analysis)"
    ]
    row = next(r for r in layers if len(r) > 1)
    sideways = {**graph, f"labrig.{row[0]}.x": {f"labrig.{row[1]}.y"}}
    assert any("may not import" in v for v in layer_violations(sideways, layers))
    # an import inside a function is an import
    src = "def f():\n    from labrig.analysis.fit import fit_model\n"
    mod = ROOT / "labrig" / "model" / "hysteresis.py"
    names = set(module_files())
    tmp = ROOT / "tests" / "_planted_module.py"
    try:
        tmp.write_text(src)
        found = imports_of("labrig.model.planted", tmp, names)
    finally:
        tmp.unlink()
    assert "labrig.analysis.fit" in found and mod.exists()
