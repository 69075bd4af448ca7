"""MATLAB ``.mat`` files as a plain tree: numeric arrays (float64, MATLAB's shape with singleton
dimensions squeezed), text (``str``), structs (``dict``), struct and cell arrays (``list``).

- v4 to v7 files (``MATLAB 5.0 MAT-file`` header): scipy.io.loadmat.
- v7.3 files (HDF5 inside, ``MATLAB 7.3 MAT-file`` header): h5py, following MATLAB's layout
  (arrays stored transposed; ``MATLAB_class`` attributes; struct arrays and cells as object
  references).

Both run in a child process with a time limit (:mod:`labrig.importers.isolated`): a malformed
file cannot hang or crash the command. What is read is bounded: the values
(:data:`~labrig.importers.limits.MAX_MAT_VALUES`), struct/cell elements
(:data:`~labrig.importers.limits.MAX_MAT_ELEMENTS`) and nesting
(:data:`~labrig.importers.limits.MAX_STRUCT_DEPTH`). Complex, logical and object values are left
out (as the string ``"<complex>"`` etc.).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from labrig.importers.isolated import ReaderError, call_isolated
from labrig.importers.limits import (
    MAT_READ_TIMEOUT_S,
    MAX_MAT_ELEMENTS,
    MAX_MAT_VALUES,
    MAX_STRUCT_DEPTH,
)
from labrig.importers.table import EXACT_INTEGER, bad

#: a MATLAB file's tree: variable name -> value
Tree = dict[str, Any]

V73_MAGIC = b"MATLAB 7.3 MAT-file"
V5_MAGIC = b"MATLAB 5.0 MAT-file"


class _Budget:
    """What is left of the bounds while a tree is built."""

    def __init__(self) -> None:
        self.values = MAX_MAT_VALUES
        self.elements = MAX_MAT_ELEMENTS

    def take(self, path: str, values: int = 0, elements: int = 0) -> None:
        self.values -= values
        self.elements -= elements
        if self.values < 0:
            raise ValueError(f"{path}: more than {MAX_MAT_VALUES} values in the file")
        if self.elements < 0:
            raise ValueError(f"{path}: more than {MAX_MAT_ELEMENTS} struct or cell elements")


def _depth(path: str, depth: int) -> None:
    if depth > MAX_STRUCT_DEPTH:
        raise ValueError(f"{path}: structs or cells nested more than {MAX_STRUCT_DEPTH} deep")


def _numeric(a: np.ndarray) -> np.ndarray:
    """float64, except integers past 2**53 (kept as they are, so that
    :class:`~labrig.importers.table.Column` counts them exactly from their first value)."""
    if a.dtype.kind in "iu" and a.size and max(int(a.max()), -int(a.min())) > EXACT_INTEGER:
        return a
    return np.asarray(a, dtype=np.float64)


def _plain(value: Any, path: str, depth: int, budget: _Budget) -> Any:
    """scipy's simplified value -> tree node."""
    _depth(path, depth)
    if isinstance(value, str):
        return value[:1000]
    if isinstance(value, dict):
        budget.take(path, elements=len(value))
        return {str(k): _plain(v, f"{path}.{k}", depth + 1, budget) for k, v in value.items()}
    if isinstance(value, list | tuple) or (isinstance(value, np.ndarray) and value.dtype == object):
        items = (
            list(np.asarray(value, dtype=object).ravel())
            if isinstance(value, np.ndarray)
            else value
        )
        budget.take(path, elements=len(items))
        return [_plain(v, f"{path}({i + 1})", depth + 1, budget) for i, v in enumerate(items)]
    if isinstance(value, bool | np.bool_) or (
        isinstance(value, np.ndarray) and value.dtype.kind == "b"
    ):
        return "<logical>"
    if isinstance(value, int | float | np.integer | np.floating):
        return np.asarray(float(value))
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiu":
        budget.take(path, values=int(value.size))
        return _numeric(value)
    if (isinstance(value, np.ndarray) and value.dtype.kind == "c") or isinstance(value, complex):
        return "<complex>"
    return f"<{type(value).__name__}>"


def load_v5(path: str) -> Tree:
    """A v4-v7 MAT-file as a tree (runs in the child)."""
    from scipy.io import loadmat, whosmat

    declared = sum(math.prod(shape) for _, shape, _ in whosmat(path))
    if declared > MAX_MAT_VALUES:
        raise ValueError(f"the variables hold {declared} values: at most {MAX_MAT_VALUES} are read")
    # mat_dtype: each array in the class MATLAB gives it (logical arrays as bool, not as the
    # uint8 they are stored in: a logical is left out, as for v7.3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mat = loadmat(path, simplify_cells=True, mat_dtype=True)
    budget = _Budget()
    tree = {k: _plain(v, k, 0, budget) for k, v in mat.items() if not k.startswith("__")}
    if any(issubclass(w.category, np.exceptions.ComplexWarning) for w in caught):
        # mat_dtype casts a complex double to double (keeping the real part): read the file
        # again in its stored types to find the complex variables, which are left out
        stored = loadmat(path, simplify_cells=True)
        again = _Budget()
        raw = {k: _plain(v, k, 0, again) for k, v in stored.items() if not k.startswith("__")}
        tree = _complex_marked(tree, raw)
    return tree


def _complex_marked(node: Any, raw: Any) -> Any:
    """``node`` with each value that is ``"<complex>"`` in ``raw`` (the same tree read in the
    file's stored types) marked so."""
    if isinstance(raw, str) and raw == "<complex>":
        return raw
    if isinstance(node, dict) and isinstance(raw, dict):
        return {k: _complex_marked(v, raw.get(k)) for k, v in node.items()}
    if isinstance(node, list) and isinstance(raw, list) and len(node) == len(raw):
        return [_complex_marked(a, b) for a, b in zip(node, raw, strict=True)]
    return node


def _h5_text(ds: Any) -> str:
    codes = np.asarray(ds[()]).ravel()
    return "".join(chr(int(c)) for c in codes[:1000] if 0 < int(c) < 0x110000)


def _h5_node(f: Any, obj: Any, path: str, depth: int, budget: _Budget) -> Any:
    """An h5py object of a v7.3 file -> tree node (MATLAB's layout)."""
    import h5py

    _depth(path, depth)
    cls = obj.attrs.get("MATLAB_class", b"")
    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
    if isinstance(obj, h5py.Group):
        return _h5_struct(f, obj, path, depth, budget)
    if obj.attrs.get("MATLAB_empty", 0):
        return "" if cls == "char" else np.zeros(0)
    if cls == "char":
        return _h5_text(obj)
    if obj.dtype == h5py.ref_dtype:
        refs = np.asarray(obj[()]).ravel()
        budget.take(path, elements=refs.size)
        return [
            _h5_node(f, f[r], f"{path}{{{i + 1}}}", depth + 1, budget) for i, r in enumerate(refs)
        ]
    if cls == "logical":
        return "<logical>"
    if obj.dtype.kind not in "fiu":
        return f"<{cls or obj.dtype}>"
    budget.take(path, values=int(obj.size))
    return np.squeeze(_numeric(np.asarray(obj[()])).T)


def _h5_struct(f: Any, group: Any, path: str, depth: int, budget: _Budget) -> Any:
    """A struct group: a dict, or a list of dicts for a struct array (fields as references)."""
    import h5py

    fields = {k: v for k, v in group.items() if not k.startswith("#")}
    budget.take(path, elements=len(fields))
    refs = {
        k: np.asarray(v[()]).ravel()
        for k, v in fields.items()
        if isinstance(v, h5py.Dataset)
        and v.dtype == h5py.ref_dtype
        and v.attrs.get("MATLAB_class", b"") not in (b"cell", "cell")
    }
    if refs and len(refs) == len(fields):
        n = max(r.size for r in refs.values())
        budget.take(path, elements=n * len(refs))
        return [
            {
                k: _h5_node(f, f[r[i]], f"{path}({i + 1}).{k}", depth + 2, budget)
                for k, r in refs.items()
                if i < r.size
            }
            for i in range(n)
        ]
    return {k: _h5_node(f, v, f"{path}.{k}", depth + 1, budget) for k, v in fields.items()}


def load_v73(path: str) -> Tree:
    """A v7.3 MAT-file (HDF5) as a tree (runs in the child)."""
    import h5py

    budget = _Budget()
    with h5py.File(path, "r") as f:
        return {k: _h5_node(f, v, k, 0, budget) for k, v in f.items() if not k.startswith("#")}


def mat_version(path: Path) -> str:
    """``"7.3"``, ``"5"`` or ``"4"`` (no header: scipy tries it as v4) from the file's start."""
    with path.open("rb") as fh:
        head = fh.read(128)
    if head.startswith(V73_MAGIC):
        return "7.3"
    if head.startswith(V5_MAGIC) or head[:6] == b"MATLAB":
        return "5"
    return "4"


def read_tree(path: Path) -> tuple[Tree, str]:
    """The file's tree and its MAT version; raises InputFileError naming the file and what
    failed (malformed file, too large, too deep, too slow)."""
    version = mat_version(path)
    loader = load_v73 if version == "7.3" else load_v5
    try:
        tree = call_isolated(loader, str(path), timeout_s=MAT_READ_TIMEOUT_S)
    except ReaderError as e:
        what = "MATLAB v7.3 (HDF5)" if version == "7.3" else "MATLAB"
        raise bad(path, f"cannot read as a {what} file: {str(e)[:300]}") from None
    return tree, version
