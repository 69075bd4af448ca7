"""The adversarial corpus of output paths (slow tier): every command that writes a file, asked
to write over one of its own inputs, with the input's path spelled six ways (as given,
``./NAME``, absolute, ``sub/../NAME``, a symbolic link, a hard link) and with and without
``--overwrite``; and the issue's other cases (options that conflict, a file where a folder
goes). Each must exit 2 with one ``error:`` line and no traceback, leave every input byte for
byte as it was and leave no partial file behind.

The bad-input corpora beside it: ``tests/data/bad/`` and ``tests/data/bad_rigs/`` (protocol and
rig files, tests/cli/test_cli_bad_inputs.py), the parser fuzzing of
tests/cli/test_fuzz_parsers.py, the hostile YAML and JSON of tests/cli/test_safety_readers.py.
The issue's cases that need a second process are in tests/cli/test_outputs_one_check.py (a run
file being written), tests/fleet/test_batch_snapshot.py and tests/runner/test_resume_verify.py.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pytest

from labrig.model import PAPER_TABLE1

from helpers import TINY, invoke

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

#: how the output names an input (the input's name -> the path given to --out)
SPELLINGS = ("same", "dot", "absolute", "updown", "symlink", "hardlink")

#: (id, command line with {out} where the spelled input goes, the input it names: a file of
#: the fixture's folder, or a folder of it when it ends with "/")
CASES: list[tuple[str, str, str]] = [
    ("run-protocol", "run P.yaml --seed 1 --out {out}", "P.yaml"),
    ("run-rig", "run P.yaml --rig R.yaml --seed 1 --out {out}", "R.yaml"),
    ("run-live-params", "run P.yaml --live --params F.json --seed 1 --out {out}", "F.json"),
    ("run-csv-source", "run C.yaml --seed 1 --out {out}", "wave.csv"),
    ("check-protocol", "check P.yaml --out {out}", "P.yaml"),
    ("check-rig", "check P.yaml --rig R.yaml --out {out}", "R.yaml"),
    ("info-one", "info A.h5 --out {out}", "A.h5"),
    ("info-several", "info A.h5 B.h5 --out {out}", "B.h5"),
    ("info-folder", "info D --out {out}", "D/A.h5"),
    ("runs-file", "runs A.h5 --out {out}", "A.h5"),
    ("runs-folder", "runs D --out {out}", "D/A.h5"),
    ("fit-run", "fit A.h5 --no-heldout --out {out}", "A.h5"),
    ("report-run", "report A.h5 --no-heldout --out {out}", "A.h5"),
    ("report-params", "report A.h5 --params F.json --no-heldout --out {out}", "F.json"),
    # the folder named: its diagnosis.json is the parameter file
    ("diagnose-params", "diagnose A.h5 --params G/diagnosis.json --out {out}", "G/"),
    ("import-data", "import their.csv --voltage 2 --strain 3 --out {out}", "their.csv"),
]  # fmt: skip

#: the issue's cases that are not about spelling: (id, command line, what stderr names)
OTHER: list[tuple[str, str, str]] = [
    ("export-out-and-csv", "export A.h5 --out E1 --csv E2", "--out and --csv"),
    ("sim-fleet-into-a-file", "sim fleet 2 --out notes.txt", "is a file"),
    ("sim-fleet-over-its-protocol", "sim fleet 1 --protocol S/truth.json --out S --overwrite",
     "is an input"),
    ("runs-new-run-file-in-the-folder", "runs D --out D/new.h5", "is inside"),
    ("info-folder-new-run-file", "info D --out D/sub/new.h5 --overwrite", "is inside"),
    ("fit-into-a-folder", "fit A.h5 --no-heldout --out D", "is a directory"),
]  # fmt: skip


@pytest.fixture
def folder(tiny_run: Path, tmp_path: Path, monkeypatch) -> Path:
    from labrig.rig.rigspec import DEFAULT_RIG_YAML

    (tmp_path / "P.yaml").write_text(TINY)
    (tmp_path / "R.yaml").write_text(DEFAULT_RIG_YAML)
    (tmp_path / "F.json").write_text(json.dumps({"params": PAPER_TABLE1.model_dump()}))
    (tmp_path / "wave.csv").write_text("".join(f"{10 * (k % 5)}\n" for k in range(200)))
    (tmp_path / "C.yaml").write_text(
        "name: c\nrate_hz: 500\nsteps:\n  - kind: csv\n    file: wave.csv\n    column: 1\n"
    )
    for name in ("A.h5", "B.h5", "D/A.h5"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_bytes(tiny_run.read_bytes())
    (tmp_path / "G").mkdir()
    (tmp_path / "G" / "diagnosis.json").write_text('{"params": {}}\n')
    (tmp_path / "S").mkdir()
    (tmp_path / "S" / "truth.json").write_text(TINY)  # a protocol, whatever its name
    (tmp_path / "their.csv").write_text("t,v,s\n" + "".join(f"{k},{k % 7},{3 * (k % 7)}\n"
                                                            for k in range(100)))  # fmt: skip
    (tmp_path / "notes.txt").write_text("notes\n")
    (tmp_path / "sub").mkdir()
    monkeypatch.chdir(tmp_path)
    return tmp_path


def spelled(folder: Path, name: str, how: str) -> str:
    name = name.rstrip("/")
    target = folder / name
    if how == "same":
        return name
    if how == "dot":
        return f"./{name}"
    if how == "absolute":
        return str(target)
    if how == "updown":
        return f"sub/../{name}"
    link = folder / f"{how}-{target.name}"
    if how == "symlink":
        link.symlink_to(target)
    else:
        os.link(target, link)
    return link.name


def snapshot(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and not p.is_symlink() and ".index" not in p.name
    }


def refused(res, folder: Path, before: dict[str, str], *words: str) -> None:
    assert res.exit_code == 2, res.output
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.stderr.startswith("error: ") and "Traceback" not in res.output, res.output
    for w in words:
        assert w in res.stderr, (w, res.stderr)
    after = snapshot(folder)
    assert {k: v for k, v in after.items() if k in before} == before  # every input intact
    assert not [p for p in folder.rglob("*") if ".partial" in p.name]


def _cases() -> list:
    out = []
    for case_id, line, name in CASES:
        for how in SPELLINGS:
            if how == "hardlink" and (name.endswith("/") or case_id.endswith("folder")):
                continue  # no hard link to a folder; one outside a folder is not read there
            for overwrite in (False, True):
                flag = "overwrite" if overwrite else "plain"
                out.append(pytest.param(line, name, how, overwrite, id=f"{case_id}-{how}-{flag}"))
    return out


@pytest.mark.parametrize(("line", "name", "how", "overwrite"), _cases())
def test_an_input_is_never_an_output(folder: Path, line: str, name: str, how: str, overwrite):
    out = spelled(folder, name, how)
    before = snapshot(folder)
    args = line.format(out=out).split()
    res = invoke(*args, *(["--overwrite"] if overwrite else []))
    refused(res, folder, before)


@pytest.mark.parametrize(("line", "words"), [pytest.param(c, w, id=i) for i, c, w in OTHER])
def test_the_issues_other_output_cases(folder: Path, line: str, words: str):
    before = snapshot(folder)
    refused(invoke(*line.split()), folder, before, words)


def test_the_corpus_size():
    """The count the notes report: a case more or less is a change to say."""
    assert len(_cases()) + len(OTHER) == 192
