"""A fingerprint of a record's samples, to tell the same data under two names or two files, and
where one record's samples lie inside another's (a slice, or a copy written out as text and
read back)."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "ANCHORS",
    "EXPORT_DIGITS",
    "EXPORT_ROUNDING",
    "Containment",
    "contained_at",
    "containment",
    "samples_digest",
]

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


class Containment(NamedTuple):
    """What :func:`containment` found, and what it cost."""

    #: the first sample of the outer record from which the inner one is contained, or ``None``
    at: int | None
    #: the candidate starts left by the anchors (:data:`ANCHORS`)
    candidates: int
    #: the candidates compared beyond the anchors: each until its first disagreement, the one
    #: found (if any) whole
    compared: int
    #: the inner samples those comparisons read (of each channel)
    samples: int


def contained_at(outer: Sequence[ArrayLike], inner: Sequence[ArrayLike]) -> int | None:
    """The first sample of ``outer`` from which every channel of ``inner`` equals a contiguous
    stretch of the same channel of ``outer`` (channels given in the same order, e.g. voltage
    and strain); ``None`` when there is none or ``inner`` is longer or empty.

    Equal means to within the rounding of ``labrig export``, sample by sample:
    ``|a - b| <= EXPORT_ROUNDING max(|a|, |b|)`` (:data:`EXPORT_ROUNDING`, 5e-10: ten
    significant digits), so a record, a slice of it, and either written out by ``labrig
    export`` and imported again all agree, while another capture of the same drive differs by
    its noise, which is far larger (a 20-bit converter's step is 1e-6 of its full scale).

    How, and the cost: :func:`containment`."""
    return containment(outer, inner).at


def containment(outer: Sequence[ArrayLike], inner: Sequence[ArrayLike]) -> Containment:
    """:func:`contained_at` (``at``), with what the search cost (:class:`Containment`).

    The candidate starts are those where the inner record's most distinctive sample agrees
    (one vectorised pass over ``outer``), sifted by a few more samples spread over the inner
    record (:data:`ANCHORS`). The first candidate left is compared in growing blocks (64
    samples, then doubling) up to the first inner sample ``j`` that disagrees (or whole: it is
    the start found), and that ``j`` sifts every candidate left at once: on a periodic record
    one disagreement removes every copy shifted by whole periods, and no later candidate
    disagrees at a ``j`` already used.

    Cost, for ``C`` channels, ``M`` samples of ``outer`` and ``n`` of ``inner``: ``O(C M)`` for
    the anchors, then ``O(C (M + n))`` for each candidate that disagrees (its blocks, and the
    sift over every candidate left), each at an inner sample of its own: at most
    ``F <= min(candidates, n - anchors)`` of them, ``O(C (M + n) F)`` in all: never more than
    twice the samples compared by comparing every candidate whole (``C n candidates``, how it
    was done before). Measured (CPU seconds, ``time.process_time``, a shared 2-core VM,
    2026-11-30): a million samples in two million, found or not, 0.01-0.08 s, on a noisy record,
    a quantised one, and a quantised one repeating every 20, 100 or 1000 samples whose copy is
    one step off at one sample (every copy a whole number of periods in a candidate: 9 s for a
    hundred thousand in two hundred thousand, 15 s and 170 s for a million in two million with
    periods of 1000 and 100, before). The worst case, constructed: an inner record all zero
    (constant: ``labrig validate`` does not compare such a record as a stretch) in an outer one
    zero but for one sample in every ``n``, where every start but those the anchors hit is a
    candidate and each residue modulo ``n`` fails at a sample of its own (``F = n - 33``):
    0.3-0.8 s for a thousand samples in a hundred thousand, 5-8 s in a million (10 s before);
    0.6 s for a hundred in a million (5 s before)."""
    big = [np.asarray(x, dtype=float) for x in outer]
    small = [np.asarray(x, dtype=float) for x in inner]
    n, total = small[0].size, big[0].size
    if n == 0 or n > total:
        return Containment(None, 0, 0, 0)
    anchors = _anchors(small)
    j = anchors[0]
    ok = np.ones(total - n + 1, dtype=bool)
    for b, s in zip(big, small, strict=True):
        ok &= _close(b[j : j + ok.size], s[j])
    starts = np.flatnonzero(ok)
    for j in anchors[1:]:
        starts = _sift(big, small, starts, j)
    candidates, compared, read = starts.size, 0, 0
    while starts.size:
        k = int(starts[0])
        compared += 1
        off, seen = _first_disagreement(big, small, k)
        read += seen
        if off is None:
            return Containment(k, candidates, compared, read)
        starts = _sift(big, small, starts[1:], off)
    return Containment(None, candidates, compared, read)


def _sift(
    big: Sequence[NDArray[np.float64]],
    small: Sequence[NDArray[np.float64]],
    starts: NDArray[np.intp],
    j: int,
) -> NDArray[np.intp]:
    """The ``starts`` from which every channel's inner sample ``j`` agrees."""
    if not starts.size:
        return starts
    keep = np.ones(starts.size, dtype=bool)
    for b, s in zip(big, small, strict=True):
        keep &= _close(b[starts + j], s[j])
    return starts[keep]


def _first_disagreement(
    big: Sequence[NDArray[np.float64]], small: Sequence[NDArray[np.float64]], k: int
) -> tuple[int | None, int]:
    """The first inner sample at which some channel disagrees with ``outer`` from ``k``
    (``None``: none does), and how many inner samples were read to find it (in blocks of 64,
    then doubling)."""
    n = small[0].size
    lo, size = 0, 64
    while lo < n:
        hi = min(n, lo + size)
        ok = _close(big[0][k + lo : k + hi], small[0][lo:hi])
        for b, s in zip(big[1:], small[1:], strict=True):
            ok &= _close(b[k + lo : k + hi], s[lo:hi])
        if not ok.all():
            return lo + int(np.argmin(ok)), hi
        lo, size = hi, 2 * size
    return None, n
