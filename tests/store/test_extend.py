"""The writer's block append (:func:`labrig.store.writer.extend`): blocks of any length, in
any order of sizes, read back as the samples given, from a dataset as the writer makes it
(chunked, resizable, Fletcher-32); the reference is numpy's concatenation of the blocks."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from labrig.store.writer import extend

#: block lengths: one sample, a chunk's length (100 here) and around it, several chunks
LENGTHS = st.lists(st.sampled_from([1, 2, 99, 100, 101, 250, 1000]), min_size=1, max_size=8)


def dataset(f: h5py.File) -> h5py.Dataset:
    return f.create_dataset(
        "x", shape=(0,), maxshape=(None,), chunks=(100,), dtype="f8", fletcher32=True
    )


@settings(max_examples=25, deadline=None)
@given(lengths=LENGTHS, seed=st.integers(0, 2**32 - 1))
def test_blocks_read_back_as_written(tmp_path_factory, lengths, seed):
    rng = np.random.default_rng(seed)
    blocks = [rng.normal(size=m) * 10.0 ** rng.integers(-300, 300) for m in lengths]
    path = Path(tmp_path_factory.mktemp("extend")) / "x.h5"
    with h5py.File(path, "w") as f:
        ds = dataset(f)
        n = 0
        for b in blocks:
            extend(ds, n, b)
            n += len(b)
            assert ds.shape == (n,)
    with h5py.File(path, "r") as f:
        back = f["x"][()]
    assert back.dtype == np.float64
    assert np.array_equal(back, np.concatenate(blocks))  # bit for bit, no rounding


def test_non_float_and_strided_input_is_stored_as_float64(tmp_path):
    with h5py.File(tmp_path / "x.h5", "w") as f:
        ds = dataset(f)
        extend(ds, 0, np.arange(5, dtype=np.int32))
        extend(ds, 5, np.arange(20.0)[::4])  # not contiguous
        extend(ds, 10, np.array([2**53 + 1], dtype=np.int64))  # above 2**53: float rounding
        got = ds[()]
    want = np.concatenate([np.arange(5.0), np.arange(20.0)[::4], [float(2**53 + 1)]])
    assert np.array_equal(got, want)
    assert got[-1] == 2.0**53  # the nearest double, as numpy's own conversion gives


def test_a_block_at_an_earlier_index_cuts_and_rewrites(tmp_path):
    """What the writer does after a failed block: the next block starts where the complete
    ones end, and the dataset is that long."""
    with h5py.File(tmp_path / "x.h5", "w") as f:
        ds = dataset(f)
        extend(ds, 0, np.ones(150))
        extend(ds, 100, np.full(30, 2.0))
        got = ds[()]
    assert np.array_equal(got, np.r_[np.ones(100), np.full(30, 2.0)])
