"""A corpus of corrupted run files against every command that reads run files.

Made in the test (seeded) from a small valid run file (``labrig run`` on the built-in simulated
rig: 3 entries of 501 samples, about 250 kB):

- **truncations** at offsets spread over the whole file;
- **zeroed blocks** of 512 bytes and **byte flips** (1 to 8 bits) at seeded random offsets;
- **wrong types, shapes and attributes** in otherwise valid files, written with h5py: each
  both as another program would leave it (the seals not renewed) and as a writer that gets it
  wrong would (seals renewed, so only the reader's checks can refuse it).

Damage that changes nothing a reader can see (zeroing bytes that are already zero, flipping a
bit in unused space) is not corruption: every drawn zeroed block and byte flip is compared with
the original by an independent reader (plain h5py, every object, attribute and value, in a
child process with a time limit) and redrawn when identical; the redraws are counted.

Every case runs through ``labrig info``, ``export``, ``fit``, ``report`` and ``diagnose``
(in-process, typer's CliRunner): exit code 2, a message naming the file, no traceback, no
output written, each command within :data:`LIMIT_S`. The default suite runs every
:data:`FAST_STRIDE`-th case; ``-m slow`` runs them all.
"""

from __future__ import annotations

import hashlib
import json
import random
import time
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest

from labrig.store.format import SEAL_ATTR
from labrig.store.isolated import IsolatedReadError, call_isolated
from labrig.store.writer import seal_all

from helpers import TINY, invoke

SEED = 16
N_TRUNCATED = 55
N_ZEROED = 55
N_FLIPPED = 55
#: every command on every case must end within this (s)
LIMIT_S = 10.0
#: the default suite runs every FAST_STRIDE-th case: nine, two of each kind but one edit (each
#: case is five commands, each reading the file in an isolated child); the rest in ``-m slow``
FAST_STRIDE = 28
COMMANDS = ["info", "export", "fit", "report", "diagnose"]
E = "sine_80V_2Hz"  # the entry the structured edits change


# -- the independent reader -----------------------------------------------------------------


def _canonical(value: object) -> bytes:
    a = np.asarray(value)
    if a.dtype.kind == "O":
        return repr([bytes(x) if isinstance(x, bytes) else str(x) for x in a.ravel()]).encode()
    return a.dtype.str.encode() + repr(a.shape).encode() + a.tobytes()


def plain_dump(path: str) -> str:
    """SHA-256 of everything plain h5py reads from the file: every object's path, kind,
    attributes, and every dataset's type, shape and values (SEAL attributes included)."""
    h = hashlib.sha256()
    with h5py.File(path, "r", locking=False) as f:
        objects = [("/", f)]
        f.visititems(lambda name, obj: objects.append((name, obj)))
        for name, obj in objects:
            h.update(name.encode() + type(obj).__name__.encode())
            for key in sorted(obj.attrs):
                h.update(key.encode() + _canonical(obj.attrs[key]))
            if isinstance(obj, h5py.Dataset):
                h.update(obj.dtype.str.encode() + repr(obj.shape).encode())
                h.update(_canonical(obj[()]))
    return h.hexdigest()


def dump_or_none(path: Path) -> str | None:
    """The dump, or ``None`` when plain h5py cannot read the file (fails, loops, crashes)."""
    try:
        return call_isolated(plain_dump, str(path), size_bytes=path.stat().st_size)
    except IsolatedReadError:
        return None
    except Exception:
        return None


# -- the cases -------------------------------------------------------------------------------


def _replace(f: h5py.File, name: str, value: object) -> None:
    del f[name]
    f[name] = value


EDITS: dict[str, Callable[[h5py.File], None]] = {
    "strain_scalar": lambda f: _replace(f, f"{E}/data/strain", 3.0),
    "strain_2d": lambda f: _replace(f, f"{E}/data/strain", np.zeros((501, 2))),
    "strain_text": lambda f: _replace(f, f"{E}/data/strain", np.array([b"a"] * 501)),
    "strain_complex": lambda f: _replace(f, f"{E}/data/strain", np.zeros(501, complex)),
    "time_bool": lambda f: _replace(f, f"{E}/data/time", np.zeros(501, bool)),
    "strain_short": lambda f: _replace(f, f"{E}/data/strain", np.zeros(400)),
    "time_missing": lambda f: f[f"{E}/data"].__delitem__("time"),
    "data_a_dataset": lambda f: _replace(f, f"{E}/data", np.zeros(3)),
    "rate_zero": lambda f: _replace(f, f"{E}/sample_rate", 0.0),
    "rate_nan": lambda f: _replace(f, f"{E}/sample_rate", np.nan),
    "rate_negative": lambda f: _replace(f, f"{E}/sample_rate", -500.0),
    "rate_text": lambda f: _replace(f, f"{E}/sample_rate", "500 Hz"),
    "rate_array": lambda f: _replace(f, f"{E}/sample_rate", [500.0, 500.0]),
    "index_text": lambda f: _replace(f, f"{E}/entry_index", "one"),
    "index_repeated": lambda f: _replace(f, f"{E}/entry_index", 0),
    "status_bogus": lambda f: _replace(f, f"{E}/status", "finished"),
    "step_not_json": lambda f: _replace(f, f"{E}/step_definition", "{kind: sine"),
    "step_a_list": lambda f: _replace(f, f"{E}/step_definition", "[1, 2]"),
    "step_deep": lambda f: _replace(f, f"{E}/step_definition", "[" * 100_000 + "]" * 100_000),
    "entry_class": lambda f: f[E].attrs.__setitem__("NX_class", "NXdata"),
    "creator_other": lambda f: f.attrs.__setitem__("creator", "other"),
    "creator_missing": lambda f: f.attrs.__delitem__("creator"),
    "run_a_dataset": lambda f: _replace(f, "run", np.zeros(2)),
    "planned_not_json": lambda f: _replace(f, "run/planned_entries", "[sine"),
    "instrument_deep": lambda f: _replace(
        f, "run/instrument/description_json", '{"a":' * 5000 + "1" + "}" * 5000
    ),
    "signal_missing": lambda f: f[f"{E}/data"].attrs.__setitem__("signal", "displacement"),
    "units_numbers": lambda f: f[f"{E}/data/strain"].attrs.__setitem__("units", [1, 2]),
    "huge_claim": lambda f: f[f"{E}/data"].create_dataset("x", (10**12,), "f8", chunks=(999,)),
    "extra_root_group": lambda f: f.create_group("notes"),
    "exit_code_text": lambda f: _replace(f, "run/exit_code", "zero"),
    "seed_float": lambda f: _replace(f, "run/seed", 1.5),
}
#: edits that add an object: left unsealed ("edited_"), they are another program's additions,
#: not corruption (read, listed, never taken for labrig's: test below); sealed as labrig's
#: ("written_"), the reader's checks refuse them
ADDITIONS = frozenset({"huge_claim", "extra_root_group"})


def _truncated(src: bytes, rng: random.Random, k: int) -> bytes:
    return src[: int(len(src) * (k + rng.random()) / N_TRUNCATED)]


def _zeroed(src: bytes, rng: random.Random) -> bytes:
    while True:
        at = rng.randrange(len(src))
        if any(src[at : at + 512]):
            d = bytearray(src)
            d[at : at + 512] = bytes(len(d[at : at + 512]))
            return bytes(d)


def _flipped(src: bytes, rng: random.Random) -> bytes:
    d = bytearray(src)
    for _ in range(rng.randint(1, 8)):
        d[rng.randrange(len(d))] ^= 1 << rng.randrange(8)
    return bytes(d)


class Corpus:
    """The cases, written lazily under ``folder`` (only the ones a test asks for)."""

    def __init__(self, src: Path, folder: Path):
        self.src, self.folder = src, folder
        self.original = src.read_bytes()
        self.reference = dump_or_none(src)
        assert self.reference is not None
        self.redrawn = 0
        names = [f"truncated_{k:02d}" for k in range(N_TRUNCATED)]
        names += [f"zeroed_{k:02d}" for k in range(N_ZEROED)]
        names += [f"flipped_{k:02d}" for k in range(N_FLIPPED)]
        names += [f"edited_{e}" for e in EDITS if e not in ADDITIONS]
        names += [f"written_{e}" for e in EDITS]
        self.names = names

    def path(self, name: str) -> Path:
        p = self.folder / f"{name}.h5"
        if p.exists():
            return p
        kind, _, rest = name.partition("_")
        if kind in ("edited", "written"):
            p.write_bytes(self.original)
            with h5py.File(p, "r+") as f:
                EDITS[rest](f)
                if kind == "written":
                    seal_all(f)
            return p
        k = int(rest)
        rng = random.Random(f"{SEED}-{kind}-{k}")
        while True:
            if kind == "truncated":
                data = _truncated(self.original, rng, k)
            else:
                data = (_zeroed if kind == "zeroed" else _flipped)(self.original, rng)
            p.write_bytes(data)
            if kind == "truncated" or dump_or_none(p) != self.reference:
                return p
            self.redrawn += 1  # harmless: plain h5py reads exactly the original


@pytest.fixture(scope="module")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> Corpus:
    tmp = tmp_path_factory.mktemp("corpus")
    (tmp / "small.yaml").write_text(TINY)
    src = tmp / "small.h5"
    res = invoke("run", tmp / "small.yaml", "--out", src, "--seed", 1)
    assert res.exit_code == 0, res.output
    with h5py.File(src, "r") as f:
        assert SEAL_ATTR in f.attrs and f[f"{E}/data/strain"].shape == (501,)
    res = invoke("fit", src, "--no-heldout")  # the original is a sound, fittable file
    assert res.exit_code == 0, res.output
    return Corpus(src, tmp)


ALL = (
    [f"truncated_{k:02d}" for k in range(N_TRUNCATED)]
    + [f"zeroed_{k:02d}" for k in range(N_ZEROED)]
    + [f"flipped_{k:02d}" for k in range(N_FLIPPED)]
    + [f"edited_{e}" for e in EDITS if e not in ADDITIONS]
    + [f"written_{e}" for e in EDITS]
)
#: every FAST_STRIDE-th case; zeroed_22 and zeroed_43 (zeroed blocks that make libhdf5 loop
#: until the reader's limit stops it, 40 s each) only in the slow tier's whole corpus
FAST = [n for n in ALL[::FAST_STRIDE] if n not in ("zeroed_22", "zeroed_43")]


def test_the_corpus_is_large_enough():
    assert len(ALL) >= 200
    kinds = {n.split("_")[0] for n in FAST}
    assert kinds == {"truncated", "zeroed", "flipped", "edited", "written"}


def check_case(corpus: Corpus, name: str, tmp_path: Path) -> None:
    path = corpus.path(name)
    before = path.read_bytes()
    for command in COMMANDS:
        extra = {
            "export": ["--csv", tmp_path / "csv"],
            "report": ["--out", tmp_path / "r.html", "--no-heldout"],
            "fit": ["--no-heldout", "--out", tmp_path / "p.json"],
            "diagnose": ["--out", tmp_path / "d"],
        }.get(command, [])
        t0 = time.monotonic()
        res = invoke(command, path, *extra)
        took = time.monotonic() - t0
        where = f"{name} {command}: {res.output[-600:]}"
        assert took < LIMIT_S, f"{where} took {took:.1f} s"
        assert res.exit_code == 2, where
        assert isinstance(res.exception, SystemExit), f"{where} {res.exception!r}"
        assert res.stderr.startswith(f"error: {path}"), where
        assert "Traceback" not in res.output, where
    assert not any(tmp_path.iterdir()), "a command wrote output for a corrupted file"
    assert path.read_bytes() == before, "a command changed its input"


@pytest.mark.timeout(600)
@pytest.mark.parametrize("name", FAST)
def test_corrupted_run_files_fast_subset(corpus: Corpus, name: str, tmp_path: Path):
    check_case(corpus, name, tmp_path)


@pytest.mark.slow
@pytest.mark.timeout(3600)
@pytest.mark.parametrize("name", [n for n in ALL if n not in FAST])
def test_corrupted_run_files_all(corpus: Corpus, name: str, tmp_path: Path):
    check_case(corpus, name, tmp_path)


@pytest.mark.parametrize("edit", sorted(ADDITIONS))
def test_an_object_another_program_added_is_an_addition_not_corruption(
    corpus: Corpus, edit: str, tmp_path: Path
):
    """A dataset claiming 10**12 samples added to an entry's data, a group added beside /run:
    not labrig's (their parents' seals do not name them), so not read as a channel or an
    entry: the file reads, the addition listed."""
    path = tmp_path / "added.h5"
    path.write_bytes(corpus.original)
    with h5py.File(path, "r+") as f:
        EDITS[edit](f)
    res = invoke("info", path, "--json")
    assert res.exit_code == 0, res.output
    added = json.loads(res.stdout)["additions"]
    assert added == ([f"{E}/data/x"] if edit == "huge_claim" else ["notes"])
