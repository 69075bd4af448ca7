"""A fingerprint of a record's samples, to tell the same data under two names or two files, and
where one record's samples lie inside another's (a slice, or a copy written out as text and
read back)."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["ANCHORS", "EXPORT_DIGITS", "EXPORT_ROUNDING", "contained_at", "samples_digest"]

#: ``labrig export`` writes every sample with ``%.10g`` (:func:`labrig.store.reader.export_csv`):
#: ten significant digits
EXPORT_DIGITS = 10
#: the largest difference between a sample and its copy written with :data:`EXPORT_DIGITS`
#: significant digits and read back, relative to the sample's magnitude: half a unit of the
#: last digit kept (5e-10 of the value) and a few float64 roundings (the text's parse)
EXPORT_ROUNDING = 0.5 * 10.0 ** (1 - EXPORT_DIGITS) + 4 * float(np.finfo(float).eps)
#: how many samples of the inner record, spread over it, sift the candidate starts before any
#: candidate is compared whole (:func:`contained_at`)
ANCHORS = 32


def samples_digest(*channels: ArrayLike) -> bytes:
    """SHA-256 of ``channels`` (each as float64, little-endian, in the order given), with each
    channel's length, so that two records agree only when every sample does."""
    h = hashlib.sha256()
    for x in channels:
        a = np.ascontiguousarray(x, dtype="<f8")
        h.update(a.size.to_bytes(8, "little"))
        h.update(a.tobytes())
    return h.digest()


def _close(a: NDArray[np.float64], b: NDArray[np.float64] | float) -> NDArray[np.bool_]:
    """Sample by sample: ``a`` and ``b`` equal to within :data:`EXPORT_ROUNDING` of the larger
    magnitude (the same unit, any unit)."""
    return np.abs(a - b) <= EXPORT_ROUNDING * np.maximum(np.abs(a), np.abs(b))


def _anchors(inner: Sequence[NDArray[np.float64]]) -> list[int]:
    """Where to sift the candidate starts: first the inner record's most distinctive sample
    (the last channel's farthest from its median: on a noisy record a value few other samples
    share), then :data:`ANCHORS` samples spread evenly over the record."""
    last = inner[-1]
    first = int(np.argmax(np.abs(last - np.median(last))))
    spread = np.linspace(0, last.size - 1, min(ANCHORS, last.size)).round().astype(int)
    return [first, *(int(j) for j in spread if j != first)]


def contained_at(outer: Sequence[ArrayLike], inner: Sequence[ArrayLike]) -> int | None:
    """The first sample of ``outer`` from which every channel of ``inner`` equals a contiguous
    stretch of the same channel of ``outer`` (channels given in the same order, e.g. voltage
    and strain); ``None`` when there is none or ``inner`` is longer or empty.

    Equal means to within the rounding of ``labrig export``, sample by sample:
    ``|a - b| <= EXPORT_ROUNDING max(|a|, |b|)`` (:data:`EXPORT_ROUNDING`, 5e-10: ten
    significant digits), so a record, a slice of it, and either written out by ``labrig
    export`` and imported again all agree, while another capture of the same drive differs by
    its noise, which is far larger (a 20-bit converter's step is 1e-6 of its full scale).

    Cost: the candidate starts are those where the inner record's most distinctive sample
    agrees (one vectorised pass over ``outer``), sifted by a few more samples spread over the
    inner record (:data:`ANCHORS`), and the survivors compared whole, the first that agrees
    returned: a few milliseconds for a million samples."""
    big = [np.asarray(x, dtype=float) for x in outer]
    small = [np.asarray(x, dtype=float) for x in inner]
    n, total = small[0].size, big[0].size
    if n == 0 or n > total:
        return None
    anchors = _anchors(small)
    j = anchors[0]
    ok = np.ones(total - n + 1, dtype=bool)
    for b, s in zip(big, small, strict=True):
        ok &= _close(b[j : j + ok.size], s[j])
    starts = np.flatnonzero(ok)
    for j in anchors[1:]:
        if not starts.size:
            return None
        keep = np.ones(starts.size, dtype=bool)
        for b, s in zip(big, small, strict=True):
            keep &= _close(b[starts + j], s[j])
        starts = starts[keep]
    for k in starts.tolist():
        if all(_close(b[k : k + n], s).all() for b, s in zip(big, small, strict=True)):
            return int(k)
    return None
