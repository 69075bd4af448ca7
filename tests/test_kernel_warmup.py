"""The test session's numba warm-up (tests/conftest.py): when it runs, and that its workload
reaches the kernels it is there for."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from compile_kernels import GROUPS
from conftest import KERNEL_MODULES, kernel_cache_is_cold

from helpers import ROOT


def test_cold_without_an_index_warm_with_a_newer_one_cold_again_after_an_edit(tmp_path: Path):
    """In the ``__pycache__`` beside the module (``cache_dir=""``: no ``NUMBA_CACHE_DIR``)."""
    src = tmp_path / "compiled.py"
    src.write_text("x = 1\n")
    os.utime(src, (1000, 1000))
    assert kernel_cache_is_cold((src,), cache_dir="")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    tag = f"py{sys.version_info.major}{sys.version_info.minor}"
    index = cache / f"compiled.kernel-10.{tag}.nbi"
    index.write_bytes(b"")
    os.utime(index, (999, 999))  # older than its source: numba recompiles
    assert kernel_cache_is_cold((src,), cache_dir="")
    os.utime(index, (1000, 1000))
    assert not kernel_cache_is_cold((src,), cache_dir="")
    os.utime(src, (1001, 1001))  # the kernel edited since
    assert kernel_cache_is_cold((src,), cache_dir="")
    os.utime(src, (1000, 1000))
    other = cache / f"baseline_kernels.k-3.{tag}.nbi"  # another module's index does not count
    other.write_bytes(b"")
    os.utime(other, (2000, 2000))
    older_python = cache / "compiled.kernel-10.py27.nbi"  # nor another Python's
    older_python.write_bytes(b"")
    os.utime(older_python, (2000, 2000))
    index.unlink()
    assert kernel_cache_is_cold((src,), cache_dir="")


def test_with_numba_cache_dir_the_index_is_looked_for_there(tmp_path: Path):
    src = tmp_path / "pkg" / "compiled.py"
    src.parent.mkdir()
    src.write_text("x = 1\n")
    os.utime(src, (1000, 1000))
    elsewhere = tmp_path / "numba-cache"
    tag = f"py{sys.version_info.major}{sys.version_info.minor}"
    (src.parent / "__pycache__").mkdir()
    (src.parent / "__pycache__" / f"compiled.k-1.{tag}.nbi").write_bytes(b"")  # not used
    assert kernel_cache_is_cold((src,), cache_dir=str(elsewhere))
    where = elsewhere / "pkg_abc"
    where.mkdir(parents=True)
    (where / f"compiled.k-1.{tag}.nbi").write_bytes(b"")
    assert not kernel_cache_is_cold((src,), cache_dir=str(elsewhere))


@pytest.mark.slow  # compiles every kernel it reaches from nothing: about 22 s of CPU
def test_the_warm_up_fills_an_empty_cache(tmp_path: Path):
    """Both groups, with numba's cache sent to an empty folder (``NUMBA_CACHE_DIR``), leave
    indexes of both kernel modules' kernels there."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    for group in GROUPS:
        res = subprocess.run(
            [sys.executable, str(ROOT / "tests" / "compile_kernels.py"), group],
            cwd=ROOT, env=env, capture_output=True, text=True, timeout=240,
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
    for src in KERNEL_MODULES:
        assert list(tmp_path.rglob(f"{src.stem}.*.nbi")), src.name
