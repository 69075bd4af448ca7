"""One output convention (docs/outputs.md): every command that produces a result takes
``--json`` (only the JSON on stdout) and ``--out`` meaning a file for one document, a folder for
several, as the table of docs/outputs.md says; ``info`` and ``check`` have ``--json``; ``report
--json`` works without ``--out``; ``info`` of several files or a folder is the catalogue's
listing; nothing is replaced without ``--overwrite``."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import typer

from labrig.cli import app

from helpers import invoke as run_cli

pytestmark = pytest.mark.timeout(180)

ROOT = Path(__file__).resolve().parents[2]
SMALL = """\
name: small
rate_hz: 1000
rest_s: 0.2
steps:
  - kind: sweep
    amplitudes_V: [50, 100]
    frequencies_hz: [5, 20]
    cycles: 2
    min_duration_s: 0.5
"""
#: commands whose options belong to another part of the work (labrig/cli/run.py and the
#: import command): their --out is checked by docs only
OTHERS = {("run",), ("import",)}


def invoke(*args: object):
    return run_cli(*args, columns=200)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two small run files in one folder."""
    d = tmp_path_factory.mktemp("runs")
    (d / "small.yaml").write_text(SMALL)
    for seed in (3, 4):
        res = invoke("run", d / "small.yaml", "--seed", seed, "--out", d / f"run{seed}.h5")
        assert res.exit_code == 0, res.stderr
    return d / "run3.h5", d / "run4.h5"


#: a row of the table: the command's words (``batch fit\|diagnose\|report``), then its --out
ROW = re.compile(r"\| `labrig ([a-z][a-z \\|]*?)(?: [A-Z\[].*?)?` \|.*\| (FILE|DIR|—)[:| ]")


def documented_outputs() -> dict[tuple[str, ...], str]:
    """docs/outputs.md's table: command path -> what its ``--out`` is (``FILE``, ``DIR``,
    ``—``)."""
    out = {}
    text = (ROOT / "docs" / "outputs.md").read_text()
    for line in text.splitlines():
        m = ROW.match(line)
        if m:
            words = tuple(m.group(1).replace("\\|", "|").split())
            out.setdefault(words, m.group(2))
    return out


def command(path: tuple[str, ...]):
    cmd = typer.main.get_command(app)
    for name in path:
        cmd = cmd.commands[name]
    return cmd


def test_the_table_covers_every_command() -> None:
    documented = documented_outputs()
    assert len(documented) >= 14, documented
    for path in (("check",), ("fit",), ("report",), ("diagnose",), ("export",), ("info",),
                 ("runs",), ("drivers",), ("model", "demo"), ("model", "figures"),
                 ("sim", "fleet"), ("sim", "serve"), ("run",), ("import",),
                 ("validate",)):  # fmt: skip
        assert path in documented, path
    assert ("batch", "fit|diagnose|report") in documented


def test_every_result_command_takes_json_and_out_as_documented() -> None:
    for path, kind in documented_outputs().items():
        paths = [(*path[:-1], c) for c in path[-1].split("|")]
        for p in paths:
            params = {o: prm for prm in command(p).params for o in getattr(prm, "opts", [])}
            if kind == "—":
                assert "--out" not in params, p
                continue
            assert "--out" in params, p
            if p in OTHERS:
                continue
            assert "--json" in params, p
            assert params["--out"].metavar == kind, (p, params["--out"].metavar, kind)


def test_info_of_a_file_json_and_out(runs: tuple[Path, Path], tmp_path: Path) -> None:
    res = invoke("info", runs[0], "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)  # stdout is the JSON and nothing else
    assert doc["status"] == "complete" and len(doc["entries"]) == 4
    out = tmp_path / "info.json"
    res = invoke("info", runs[0], "--out", out)
    assert res.exit_code == 0 and "complete" in res.stdout  # the text, and the file
    assert json.loads(out.read_text()) == doc
    assert invoke("info", runs[0], "--out", out).exit_code == 2  # exists: --overwrite
    assert invoke("info", runs[0], "--out", out, "--overwrite").exit_code == 0


def test_info_of_several_files_or_a_folder_is_the_listing(runs: tuple[Path, Path]) -> None:
    both = invoke("info", *runs, "--json")
    assert both.exit_code == 0, both.output
    listed = json.loads(both.stdout)
    assert sorted(Path(r["path"]).name for r in listed["runs"]) == ["run3.h5", "run4.h5"]
    same = json.loads(invoke("runs", *runs, "--json").stdout)
    assert [r["path"] for r in same["runs"]] == [r["path"] for r in listed["runs"]]
    folder = invoke("info", runs[0].parent)
    assert folder.exit_code == 0, folder.output
    assert folder.stdout.splitlines()[0].startswith("file ")
    assert "run3.h5" in folder.stdout and "run4.h5" in folder.stdout
    assert "2 runs" in folder.stderr


def test_check_json(tmp_path: Path) -> None:
    (tmp_path / "small.yaml").write_text(SMALL)
    res = invoke("check", tmp_path / "small.yaml", "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert [e["name"] for e in doc["entries"]] == [
        "sine_50V_5Hz",
        "sine_50V_20Hz",
        "sine_100V_5Hz",
        "sine_100V_20Hz",
    ]
    assert all(e["peak_current_A"] > 0 for e in doc["entries"])
    assert [d["role"] for d in doc["drivers"]] == ["daq", "amplifier", "conditioner"]
    assert doc["simulated"] is True


def test_report_json_without_out_is_the_same_table(runs: tuple[Path, Path], tmp_path: Path):
    # two of the four entries: each entry on the page costs a figure
    two = ("--no-heldout", "--entries", "sine_50V_5Hz,sine_100V_20Hz")
    page = tmp_path / "r.html"
    with_page = invoke("report", runs[0], *two, "--json", "--out", page)
    assert with_page.exit_code == 0, with_page.output
    without = invoke("report", runs[0], *two, "--json")
    assert without.exit_code == 0, without.output
    assert json.loads(without.stdout) == json.loads(with_page.stdout)
    assert list(json.loads(without.stdout)) == ["sine_50V_5Hz", "sine_100V_20Hz"]
    assert page.is_file() and list(tmp_path.iterdir()) == [page]
    text = invoke("report", runs[0], *two)
    assert text.exit_code == 0 and "sine_100V_20Hz" in text.stdout
    assert "no page drawn" in text.stderr


def test_export_out_dir_and_its_older_name(runs: tuple[Path, Path], tmp_path: Path) -> None:
    res = invoke("export", runs[0], "--out", tmp_path / "csv", "--json")
    assert res.exit_code == 0, res.output
    files = json.loads(res.stdout)["files"]
    assert sorted(Path(f).name for f in files) == sorted(
        f"{n}.csv" for n in ("sine_50V_5Hz", "sine_50V_20Hz", "sine_100V_5Hz", "sine_100V_20Hz")
    )
    again = invoke("export", runs[0], "--csv", tmp_path / "csv")
    assert again.exit_code == 2 and "--overwrite" in again.stderr
    assert invoke("export", runs[0], "--csv", tmp_path / "csv", "--overwrite").exit_code == 0


def test_model_figures_refuse_to_overwrite_before_drawing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Existing figures are refused before any figure is drawn (the drawing functions are
    replaced by ones that record their calls; the real drawing: tests/report/
    test_model_figures.py), and ``--overwrite`` replaces them without a partial file left."""
    from labrig.report import model_figures

    drawn: list[str] = []

    def fake(name: str):
        def draw(path: Path) -> None:
            drawn.append(name)
            Path(path).write_bytes(b"new " + name.encode())

        return draw

    monkeypatch.setattr(
        model_figures, "FIGURES", [(name, fake(name)) for name, _ in model_figures.FIGURES]
    )
    out = tmp_path / "figs"
    out.mkdir()
    files = [out / name for name, _ in model_figures.FIGURES]
    for f in files:
        f.write_bytes(b"old")
    again = invoke("model", "figures", "--out", out)
    assert again.exit_code == 2, again.output
    assert drawn == []  # refused before any figure was drawn
    assert "exist already; pass --overwrite" in " ".join(again.stderr.split())
    assert all(f.read_bytes() == b"old" for f in files)
    res = invoke("model", "figures", "--out", out, "--overwrite", "--json")
    assert res.exit_code == 0, res.output
    assert [Path(f) for f in json.loads(res.stdout)["files"]] == files
    assert len(drawn) == len(files) == 4
    assert all(f.read_bytes().startswith(b"new ") for f in files)
    assert not [p for p in out.iterdir() if p.name.endswith(".partial")]


def test_model_demo_json_and_out(tmp_path: Path) -> None:
    res = invoke("model", "demo", "--cycles", "3", "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert [r["cycle"] for r in doc["cycles"]] == [1, 2, 3]
    assert all(r["max_strain_ue"] > r["strain_at_0V_ue"] for r in doc["cycles"])
    out = tmp_path / "demo.json"
    text = invoke("model", "demo", "--cycles", "3", "--out", out)
    assert text.exit_code == 0 and "max strain" in text.stdout
    assert json.loads(out.read_text()) == doc


def test_runs_and_drivers_write_what_json_prints(runs: tuple[Path, Path], tmp_path: Path):
    for args in (["runs", runs[0].parent], ["drivers"]):
        printed = invoke(*args, "--json")
        assert printed.exit_code == 0, printed.output
        out = tmp_path / f"{args[0]}.json"
        written = invoke(*args, "--out", out)
        assert written.exit_code == 0, written.output
        a, b = json.loads(printed.stdout), json.loads(out.read_text())
        if args[0] == "runs":  # the second listing reads the index: same runs
            a.pop("indexes"), b.pop("indexes")
        assert a == b, args


def test_counts_take_the_right_number(tmp_path: Path) -> None:
    """One entry, one run, one sample: "1 entry", "1 run" (never "1 entries")."""
    import labrig

    proto = tmp_path / "one.yaml"
    proto.write_text(
        "name: one\nrate_hz: 1000\nsteps:\n  - kind: hold\n    voltage_V: 10\n    duration_s: 0.2\n"
    )
    res = invoke("run", proto, "--seed", 1, "--out", tmp_path / "one.h5")
    assert res.exit_code == 0, res.output
    text = repr(labrig.open(tmp_path / "one.h5"))
    assert "1 entry, " in text and "1 entries" not in text
    listing = invoke("info", tmp_path)
    assert listing.exit_code == 0 and listing.stderr.startswith("1 run;"), listing.stderr
    for res in (invoke("check", proto), listing):
        assert "1 entries" not in res.output and "1 runs" not in res.output
