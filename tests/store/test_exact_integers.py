"""Integers a run file stores stay exact end to end: a 63-bit seed that ``labrig run`` drew (or
was given) is printed by ``labrig info`` (text and ``--json``), ``labrig runs --json`` and
``Run.seed`` with every digit, and running again with the printed seed gives the same data.
Integers above 2**53 are the case: a float holds 53 bits, so reading one through a float rounds
it (5400616385192348103 -> 5400616385192347648)."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

import labrig
from labrig.catalogue.read import read_metadata_here
from labrig.core.metadata import RunMetadata
from labrig.store import RunWriter, read_run

from helpers import invoke

ONE_SINE = """\
name: one sine
rate_hz: 500
steps:
  - kind: sine
    amplitude_V: 60
    frequency_hz: 2
    cycles: 1
"""
#: the seed of the issue, and the largest a 63-bit draw can give but 24
SEEDS = (5400616385192348103, 2**63 - 25)


def run_with(tmp: Path, seed: int | str, name: str) -> Path:
    proto = tmp / "one.yaml"
    proto.write_text(ONE_SINE)
    out = tmp / name
    result = invoke("run", proto, "--seed", seed, "--out", out)
    assert result.exit_code == 0, result.output
    return out


@pytest.mark.parametrize(
    "seed", [SEEDS[0], pytest.param(SEEDS[1], marks=pytest.mark.slow)], ids=str
)
def test_every_command_prints_every_digit_of_the_seed(tmp_path: Path, seed: int):
    assert int(float(seed)) != seed  # the case at hand: a float would not hold it
    first = run_with(tmp_path, seed, "first.h5")
    info = invoke("info", first, "--json")
    assert info.exit_code == 0, info.output
    assert json.loads(info.stdout)["seed"] == seed and f'"seed": {seed},' in info.stdout
    assert f"seed {seed}," in invoke("info", first).stdout
    assert f'"seed": {seed},' in invoke("runs", tmp_path, "--json").stdout
    assert labrig.open(first).seed == seed and read_run(first).seed == seed


@pytest.mark.slow
@pytest.mark.parametrize("seed", SEEDS, ids=str)
def test_running_again_with_the_printed_seed_gives_the_same_data(tmp_path: Path, seed: int):
    first = run_with(tmp_path, seed, "first.h5")
    printed = json.loads(invoke("info", first, "--json").stdout)["seed"]
    again = run_with(tmp_path, printed, "again.h5")
    rounded = run_with(tmp_path, int(float(seed)), "rounded.h5")
    a, b, c = (read_run(p) for p in (first, again, rounded))
    for name in ("strain", "amplifier_voltage", "gauge_raw"):
        np.testing.assert_array_equal(a["sine_60V_2Hz"][name], b["sine_60V_2Hz"][name])
    # what running again with the rounded seed the issue saw printed gives: other noise
    assert not np.array_equal(a["sine_60V_2Hz"]["strain"], c["sine_60V_2Hz"]["strain"])


def test_integers_in_the_instrument_and_metadata_are_stored_and_read_exactly(tmp_path: Path):
    big = 2**63 - 1
    description = {"daq": {"serial": big, "channel_ids": [1, 2**53 + 1, big], "gain": 2.5}}
    meta = RunMetadata({"batch_id": 2**62 + 3})
    path = tmp_path / "ids.h5"
    with RunWriter(path, "name: p\n", "", description, big, metadata=meta) as w:
        e = w.begin_entry("e0", {"kind": "hold", "n": 2**60 + 1}, 100.0, ["strain"])
        e.append({"strain": np.zeros(3)})
    with h5py.File(path, "r") as f:
        assert f["run/instrument/daq/channel_ids"].dtype.kind == "i"
        assert f["run/seed"][()] == big
    metadata, _ = read_metadata_here(path)
    assert metadata["instrument/daq/serial"] == big
    assert metadata["instrument/daq/channel_ids"] == [1, 2**53 + 1, big]
    run = read_run(path)
    assert metadata["metadata/batch_id"] == 2**62 + 3 and run.metadata["batch_id"] == 2**62 + 3
    assert run.seed == big and run["e0"].step["n"] == 2**60 + 1
    assert run.instrument["daq"]["channel_ids"] == [1, 2**53 + 1, big]
