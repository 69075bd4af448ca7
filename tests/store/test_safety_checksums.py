"""Fletcher32 checksums in new run files: present (read with h5py's own property list calls),
damage detected as an input error naming entry and channel, and older files without them still
read the same."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from labrig.core.errors import InputFileError
from labrig.store import RunWriter, read_run

CHANNELS = ["command_voltage", "strain"]


def write_run(path: Path, n: int = 5000) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(3)
    data = {c: rng.normal(size=n) for c in CHANNELS}
    with RunWriter(path, "name: p", "", {}, 1, protocol_name="p") as w:
        e = w.begin_entry("e0", {}, 1000.0, CHANNELS)
        for k in range(0, n, 700):
            e.append({c: v[k : k + 700] for c, v in data.items()})
        e.finish("complete")
        w.add_run_collection("ramp_to_zero", {"voltage": ([3.0, 1.0, 0.0], "V", "volts")})
    data["time"] = np.arange(n) / 1000.0
    return data


def filters(ds: h5py.Dataset) -> list[int]:
    plist = ds.id.get_create_plist()
    return [plist.get_filter(i)[0] for i in range(plist.get_nfilters())]


def test_every_sample_dataset_carries_fletcher32(tmp_path):
    path = tmp_path / "run.h5"
    write_run(path)
    with h5py.File(path, "r") as f:
        data = f["e0/data"]
        assert set(data) == {"time", *CHANNELS}
        for name in data:
            assert filters(data[name]) == [h5py.h5z.FILTER_FLETCHER32], name
        assert filters(f["run/ramp_to_zero/voltage"]) == [h5py.h5z.FILTER_FLETCHER32]


def flip_bytes_in_chunk(path: Path, dataset: str, chunk: int) -> None:
    """Damage one stored chunk in place (16 bytes in its middle), as a bad sector would."""
    with h5py.File(path, "r") as f:
        info = f[dataset].id.get_chunk_info(chunk)
    with open(path, "r+b") as fh:
        fh.seek(info.byte_offset + info.size // 2)
        raw = bytearray(fh.read(16))
        fh.seek(info.byte_offset + info.size // 2)
        fh.write(bytes(b ^ 0xFF for b in raw))


def test_a_damaged_chunk_is_an_input_error_not_data(tmp_path):
    path = tmp_path / "run.h5"
    write_run(path)
    flip_bytes_in_chunk(path, "e0/data/strain", 1)
    with pytest.raises(InputFileError) as ei:
        read_run(path)
    msg = str(ei.value)
    assert str(path) in msg and "e0/data/strain" in msg and "checksum" in msg
    assert ei.value.exit_code == 2
    read_run(path, load_data=False)  # the metadata is still there to see


def test_files_without_checksums_still_read(tmp_path):
    """A run file as labrig wrote it before checksums: the same datasets without the filter."""
    path = tmp_path / "old.h5"
    data = write_run(path)
    with h5py.File(path, "r+") as f:
        g = f["e0/data"]
        for name in list(g):
            values, attrs = g[name][()], dict(g[name].attrs)
            del g[name]
            ds = g.create_dataset(name, data=values, chunks=(1024,), maxshape=(None,))
            ds.attrs.update(attrs)
            assert filters(ds) == []
    run = read_run(path)
    for name, values in data.items():
        np.testing.assert_array_equal(run["e0"][name], values)
