"""Imports run one way through the hardware side: no cycle through the runner, the rig files,
the simulators, the instruments or the run-file store (``rigfile -> drivers.sim.serve ->
rigspec``, never back), counting imports inside functions too."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: the modules whose imports must not form a cycle (with anything)
HARDWARE_SIDE = (
    "labrig.runner",
    "labrig.run_record",
    "labrig.rigfile",
    "labrig.rigspec",
    "labrig.instruments",
    "labrig.interrupts",
    "labrig.ramp",
    "labrig.limits",
    "labrig.errors",
    "labrig.cli_run",
    "labrig.store",
    "labrig.store_format",
    "labrig.store_reader",
    "labrig.store_writer",
    "labrig.store_space",
    "labrig.drivers",
)


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


def on_hardware_side(module: str) -> bool:
    return any(module == m or module.startswith(m + ".") for m in HARDWARE_SIDE)


def test_no_import_cycle_through_the_hardware_side():
    files = module_files()
    graph = {name: imports_of(name, path, set(files)) for name, path in files.items()}
    # a package's __init__ importing its own submodules is not a cycle of interest
    graph = {n: {t for t in ts if not t.startswith(n + ".")} for n, ts in graph.items()}
    bad = [sorted(c) for c in cycles(graph) if any(on_hardware_side(m) for m in c)]
    assert not bad, bad


def test_the_simulators_do_not_import_the_runner_or_rig_opening():
    code = (
        "import sys, labrig.drivers.sim.serve; "
        "print(sorted(m for m in ('labrig.runner', 'labrig.rigfile') if m in sys.modules))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"
