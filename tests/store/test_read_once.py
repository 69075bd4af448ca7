"""What a reader and a run read once (labrig.store.parse, labrig.rig.rigspec).

- The checked read of a run file reads each object's attributes once and each scalar dataset
  once: the seal check reads them and the parsing after it uses what it read (h5py's Python
  layer costs about 0.1 ms per attribute or value read, hundreds per file). Counted by
  wrapping h5py's own readers; the file read is also the same as a read that re-reads.
- The virtual bench's entry point, and the drivers' entry points, are looked up once per
  process (each look-up reads every installed package's entry points; a ``check`` needed the
  drivers' four times); a failed look-up is not kept.
"""

from __future__ import annotations

from collections import Counter
from importlib import metadata
from pathlib import Path

import h5py
import numpy as np
import pytest

from labrig.core.errors import DeviceError
from labrig.rig import driver_check, rigspec
from labrig.runner.rigfile import load_rig
from labrig.store import parse


def counting_reads(monkeypatch: pytest.MonkeyPatch) -> tuple[Counter, Counter]:
    """Wrap h5py's attribute and dataset readers; count reads by (object, attribute) and by
    scalar dataset."""
    attrs: Counter = Counter()
    values: Counter = Counter()
    get_attr = h5py.AttributeManager.__getitem__
    get_value = h5py.Dataset.__getitem__

    def attr(self, name):
        attrs[(h5py.h5i.get_name(self._id), name)] += 1  # the object's path, the attribute
        return get_attr(self, name)

    def value(self, args, *more, **kw):
        if self.shape == ():
            values[self.name] += 1
        return get_value(self, args, *more, **kw)

    monkeypatch.setattr(h5py.AttributeManager, "__getitem__", attr)
    monkeypatch.setattr(h5py.Dataset, "__getitem__", value)
    return attrs, values


def test_a_checked_read_reads_each_attribute_and_scalar_once(tiny_run: Path, monkeypatch):
    before = parse.read_run_here(tiny_run)
    attrs, values = counting_reads(monkeypatch)
    run, shapes = parse.read_run_here(tiny_run)
    assert attrs and values  # the wrappers saw the reads
    twice = {k: n for k, n in (attrs + values).items() if n > 1}
    assert not twice, f"read more than once: {sorted(twice.items())[:10]}"
    # and what was read is what a read before the counting gave
    assert shapes == before[1]
    assert run.seed == before[0].seed and list(run.entries) == list(before[0].entries)
    for name, entry in run.entries.items():
        old = before[0].entries[name]
        assert (entry.units, entry.step, entry.rate_hz) == (old.units, old.step, old.rate_hz)
        assert all(np.array_equal(entry.data[c], old.data[c]) for c in entry.data)


def counting_entry_points(monkeypatch: pytest.MonkeyPatch) -> list[dict]:
    """Wrap ``importlib.metadata.entry_points``; the list of the calls' keyword arguments."""
    calls: list[dict] = []
    look_up = metadata.entry_points

    def counted(**kw):
        calls.append(kw)
        return look_up(**kw)

    monkeypatch.setattr(metadata, "entry_points", counted)
    return calls


def test_the_benchs_entry_point_is_looked_up_once(monkeypatch):
    calls = counting_entry_points(monkeypatch)
    rigspec._simulator.cache_clear()
    try:
        first = rigspec.simulator()
        assert rigspec.simulator() is first and rigspec.simulator("bench") is first
        assert len(calls) == 1, calls
        for _ in range(2):  # not kept: a second try looks again, and fails again
            with pytest.raises(DeviceError, match="no 'no_such_bench' entry point"):
                rigspec.simulator("no_such_bench")
        assert len(calls) == 3, calls
    finally:
        rigspec._simulator.cache_clear()


def test_the_drivers_entry_points_are_read_once(monkeypatch, caplog):
    look_up = metadata.entry_points
    calls = counting_entry_points(monkeypatch)
    rigspec._driver_entries.cache_clear()
    try:
        names = rigspec.driver_names()
        # what a check of the built-in rig asks for: the names, the providers, the drivers
        spec = load_rig(None)
        reports = driver_check.load_rig_drivers(spec)
        listed = driver_check.installed_drivers()
        drivers = [c for c in calls if c.get("group") == rigspec.ENTRY_POINT_GROUP]
        assert len(drivers) == 1, calls
        # the same answers as a direct read of the entry points
        direct = look_up(group=rigspec.ENTRY_POINT_GROUP)
        assert names == {ep.name: ep.value for ep in direct}
        assert {"sim_daq", "pi_e503", "strain_modbus", "nidaqmx"} <= names.keys()
        assert all(r.provided_by.startswith("labrig ") for r in reports)
        assert {r.name for r in listed} == names.keys()

        def broken(**kw):
            calls.append(kw)
            raise OSError("a damaged METADATA file")

        monkeypatch.setattr(metadata, "entry_points", broken)
        rigspec._driver_entries.cache_clear()
        calls.clear()
        for _ in range(2):  # not kept: a second call reads again, and fails again
            assert rigspec.driver_names() == {}
        assert len(calls) == 2, calls
        assert "a damaged METADATA file" in caplog.text
    finally:
        rigspec._driver_entries.cache_clear()
