"""Option values at and beyond their bounds: a usage error (exit 64) naming the option, no
traceback and nothing written, for seeds, ports, fleet sizes and the model demo's sine; each
bound also tried just inside. An empty path (``""``, which typer reads as ``.``) is a usage
error for every path parameter of every command."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

import labrig
from labrig.cli.model import DEMO_MAX_SAMPLES, check_demo_sine
from labrig.core.errors import InputFileError
from labrig.core.seeds import MAX_SEED
from labrig.fleet.simfleet import MAX_FLEET, draw_fleet

from helpers import TINY, invoke, rig_path, run_protocol


def _usage_error(res, option: str) -> None:
    assert res.exit_code == 64, res.output
    assert "Traceback" not in res.output
    assert option in res.output, res.output


@pytest.mark.parametrize("seed", [-1, MAX_SEED + 1, 2**65 + 1])
def test_a_seed_outside_0_to_2_63_is_refused_before_a_file_exists(tmp_path, seed):
    proto = tmp_path / "p.yaml"
    proto.write_text(TINY)
    res = invoke("run", proto, "--seed", seed, "--out", tmp_path / "r.h5")
    _usage_error(res, "--seed")
    assert not (tmp_path / "r.h5").exists()


def test_the_largest_seed_is_recorded_exactly(tmp_path):
    assert MAX_SEED == 2**63 - 1 and MAX_SEED > 2**53  # not representable as a float
    out = run_protocol(TINY, tmp_path, MAX_SEED)
    with h5py.File(out) as f:
        assert int(f["run/seed"][()]) == 2**63 - 1
    info = invoke("info", out, "--json")
    assert json.loads(info.stdout)["seed"] == 2**63 - 1
    assert labrig.open(out).seed == 2**63 - 1


def test_the_python_api_refuses_a_negative_seed_before_the_rig(tmp_path):
    proto = tmp_path / "p.yaml"
    proto.write_text(TINY)
    with pytest.raises(InputFileError, match="seed"):
        labrig.run(proto, out=tmp_path / "r.h5", seed=-1, progress=False)
    assert not (tmp_path / "r.h5").exists()


@pytest.mark.parametrize("seed", [-1, MAX_SEED + 1])
def test_a_rig_files_seed_outside_the_range_is_a_bad_input(tmp_path, seed):
    rig = rig_path(tmp_path, simulator={"seed": seed})
    proto = tmp_path / "p.yaml"
    proto.write_text(TINY)
    res = invoke("run", proto, "--rig", rig, "--out", tmp_path / "r.h5")
    assert res.exit_code == 2, res.output
    assert "seed" in res.stderr and str(rig) in res.stderr and "Traceback" not in res.output


@pytest.mark.parametrize("port", [-1, 65536])
def test_ports_outside_0_to_65535_are_usage_errors(tiny_run, tmp_path, port):
    _usage_error(invoke("watch", tiny_run, "--port", port), "--port")
    proto = tmp_path / "protocol.yaml"
    proto.write_text(TINY)
    res = invoke("run", proto, "--live-port", port, "--out", tmp_path / "x.h5")
    _usage_error(res, "--live-port")
    assert not (tmp_path / "x.h5").exists()


def test_a_fleet_beyond_its_bound_or_a_negative_seed_is_refused(tmp_path):
    res = invoke("sim", "fleet", MAX_FLEET + 1, "--out", tmp_path / "fleet")
    _usage_error(res, "100,000")
    assert not (tmp_path / "fleet").exists()
    _usage_error(invoke("sim", "fleet", 2, "--out", tmp_path / "f", "--seed", -1), "--seed")


def test_draw_fleet_takes_its_bound_and_not_one_more(monkeypatch):
    import labrig.fleet.simfleet as simfleet

    assert MAX_FLEET == 100_000
    monkeypatch.setattr(simfleet, "MAX_FLEET", 12)  # the comparison, without 100 000 draws
    assert len(draw_fleet(12, 0, 0.05)) == 12
    with pytest.raises(ValueError, match="1 to 12"):
        draw_fleet(13, 0, 0.05)


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("--frequency-hz", "0"),
        ("--frequency-hz", "nan"),
        ("--amplitude-v", "-5"),
        ("--amplitude-v", "10000.001"),  # just past DEMO_MAX_AMPLITUDE_V
        ("--amplitude-v", "1e306"),  # a trial's: a loop width of -6e306 ue, exit 0
        ("--rate-hz", "7.99"),  # 8 samples a period of 1 Hz is the least
        ("--rate-hz", "inf"),
        ("--cycles", "0"),
    ],
)
def test_the_demo_sine_refuses_what_it_cannot_draw(option, value):
    _usage_error(invoke("model", "demo", option, value), option)


def test_the_demo_sine_at_its_bounds():
    res = invoke("model", "demo", "--rate-hz", "8", "--cycles", "1", "--json")
    assert res.exit_code == 0, res.output
    assert len(json.loads(res.stdout)["cycles"]) == 1
    # the size bound: exactly DEMO_MAX_SAMPLES passes the check, one cycle more does not
    check_demo_sine(100.0, 1.0, DEMO_MAX_SAMPLES // 1000, 1000.0)
    with pytest.raises(Exception, match="samples in all"):
        check_demo_sine(100.0, 1.0, DEMO_MAX_SAMPLES // 1000 + 1, 1000.0)
    # the amplitude bound: 10 000 V draws finite loops, its strain growing with the drive
    top = invoke("model", "demo", "--amplitude-v", "10000", "--cycles", "1", "--json")
    assert top.exit_code == 0, top.output
    (cycle,) = json.loads(top.stdout)["cycles"]
    assert all(np.isfinite(v) and v > 0 for k, v in cycle.items() if k != "cycle"), cycle


def _path_params() -> list[tuple[list[str], str, bool]]:
    """Every command's path parameters: (the command's words, the parameter's option or
    metavar, whether it is an argument), found by walking the command line."""
    import typer.main

    from labrig.cli import app
    from labrig.cli.help_format import is_argument
    from labrig.cli.typer_app import value_type

    found = []

    def walk(words: list[str], command) -> None:
        for name, sub in getattr(command, "commands", {}).items():
            walk([*words, name], sub)
        for p in getattr(command, "params", []) if words else []:
            if value_type(p) is Path or p.name == "run_files":  # batch's: paths or globs
                arg = is_argument(p)
                found.append((words, p.metavar if arg else p.opts[0], arg))

    walk([], typer.main.get_command(app))
    return found


PATH_PARAMS = _path_params()


def test_every_command_with_files_has_path_parameters_found():
    commands = {" ".join(words) for words, _, _ in PATH_PARAMS}
    assert {"info", "export", "run", "fit", "report", "diagnose", "batch fit"} <= commands
    assert ["batch", "report"] in [words for words, param, _ in PATH_PARAMS if param == "RUN_FILES"]


@pytest.mark.parametrize(
    ("words", "param", "argument"),
    PATH_PARAMS,
    ids=[f"{' '.join(w)} {p}" for w, p, _ in PATH_PARAMS],
)
def test_an_empty_path_is_a_usage_error_naming_it(tmp_path, monkeypatch, words, param, argument):
    """``""`` is not taken for the current folder (typer's reading of it): exit 64 naming the
    parameter, before anything is read or written."""
    monkeypatch.chdir(tmp_path)
    res = invoke(*words, *([""] if argument else [param, ""]))
    _usage_error(res, param)
    assert "an empty path" in res.output
    assert list(tmp_path.iterdir()) == []


def test_a_path_that_is_not_empty_is_still_taken(tmp_path, monkeypatch):
    """Just beside the refusal: ``.`` (the folder said as such) is a path like any other."""
    monkeypatch.chdir(tmp_path)
    res = invoke("runs", ".")
    assert res.exit_code == 0, res.output


@pytest.mark.parametrize(("words", "option"), [(["fit"], "--out"), (["info"], "--out")])
def test_a_file_path_ending_with_a_slash_is_a_usage_error(tiny_run, tmp_path, words, option):
    """pathlib drops the slash: ``--out new/`` wrote a file named ``new``."""
    res = invoke(*words, tiny_run, option, f"{tmp_path}/new/")
    _usage_error(res, option)
    assert "ends with /" in res.output and list(tmp_path.iterdir()) == []
    # just beside: a folder's path may end with one
    res = invoke("export", tiny_run, "--out", f"{tmp_path}/csv/")
    assert res.exit_code == 0, res.output
    assert len(list((tmp_path / "csv").glob("*.csv"))) == 3


@pytest.mark.parametrize("entries", ["", " ", " , ,"])
def test_entries_that_name_none_are_a_usage_error(tiny_run, entries):
    """``--entries " "`` fitted every entry; it names none."""
    for command in ("fit", "report"):
        res = invoke(command, tiny_run, "--entries", entries, "--json")
        _usage_error(res, "--entries")
        assert "names no entry" in res.output
