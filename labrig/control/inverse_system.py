"""The inverse recursion of a relaxor's modal bank, and the zeros outside the unit circle.

A relaxor realised as a modal bank (:meth:`labrig.model.Relaxor.bank`) maps its input ``v`` to its
output ``y = Re(c . x)``, ``x[n] = a x[n-1] + b0 v[n-1] + b1 v[n]`` (one state per mode). Solved
for the input, the same bank runs backwards as the recursion

    z[n] = A z[n-1] + B y[n],        z = [Re x, Im x (complex modes only), v]

whose eigenvalues outside the unit circle are the zeros of the bank's sampled kernel outside it
(the hold's zeros, :func:`outside_zeros`). :func:`inverse_system` gives ``A``'s pieces and those
unstable eigen-directions (left and right eigenvectors), which the offline inverse uses as starting
guesses and the per-sample inverse (:class:`~labrig.control.bank_inverse.BankInverse`) splits off.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from labrig.model import Relaxor
from labrig.model.modal import DiscreteBank

__all__ = ["OUTSIDE", "InverseSystem", "inverse_system", "outside_zeros"]

#: an eigenvalue farther than this from the origin counts as outside the unit circle
OUTSIDE = 1.0 + 1e-6


def _real_layout(bank: DiscreteBank, zoh: bool):
    """Modes of ``bank`` as one complex array each (a, b0, b1, c, complex flag).

    ``zoh=True`` gives the one-sample-shifted zero-order-hold bank (``x'[n] = x[n+1]``,
    ``y'[n] = y[n+1]``): its input enters with no delay, like the linear hold's ``b1``.
    """
    a = np.concatenate([g.a for g in bank.groups]).astype(complex)
    b0 = np.concatenate([g.b0 for g in bank.groups]).astype(complex)
    b1 = np.concatenate([g.b1 for g in bank.groups]).astype(complex)
    c = np.concatenate([g.c for g in bank.groups]).astype(complex)
    cplx = np.concatenate([np.full(g.size, np.iscomplexobj(g.a)) for g in bank.groups])
    if zoh:
        b0, b1 = np.zeros_like(b0), b0
    return a, b0, b1, c, cplx


@dataclass(frozen=True)
class InverseSystem:
    """The inverse recursion of a bank in real coordinates ``z = [Re x, Im x (complex modes),
    v_prev]`` and its unstable eigen-directions (used by
    :class:`~labrig.control.bank_inverse.BankInverse`)."""

    a: NDArray[np.complex128]
    b0: NDArray[np.complex128]
    b1: NDArray[np.complex128]
    c: NDArray[np.complex128]
    cplx: NDArray[np.bool_]
    gain: float  # Re(c . b1): the input's immediate effect on the output
    cb0: float  # Re(c . b0)
    lam: NDArray[np.complex128]  # unstable eigenvalues (one of each conjugate pair)
    left: NDArray[np.complex128]  # (k, R) left eigenvectors, left[k] . right[k] = 1
    right: NDArray[np.complex128]  # (k, R)
    weight: NDArray[np.float64]  # 1 for a real eigenvalue, 2 for a pair


def _inverse_matrix(a, b0, b1, c, cplx) -> tuple[NDArray, float, float]:
    """Dense real matrix of ``z[n] = A z[n-1] + B y[n]`` (for the eigen-analysis only)."""
    m = a.size
    ci = np.flatnonzero(cplx)
    r = m + ci.size + 1
    g = float(np.sum(c * b1).real)
    if not g > 0:
        raise ValueError("the bank has no immediate response to its input; cannot invert")
    cb0 = float(np.sum(c * b0).real)
    # v = (y - Re(c.(a x)) - cb0 v_prev) / g ; kx = -(c a)/g acting on x = xr + i xi
    k = -(c * a) / g
    row_v = np.zeros(r)
    row_v[:m] = k.real
    row_v[m : m + ci.size] = -k.imag[ci]
    row_v[-1] = -cb0 / g
    A = np.zeros((r, r))
    A[-1] = row_v
    # Re x' = Re(a) Re x - Im(a) Im x + Re(b0) v_prev + Re(b1) v
    idx = np.arange(m)
    A[idx, idx] = a.real
    A[idx, -1] += b0.real
    A[:m] += np.outer(b1.real, row_v)
    for j, i in enumerate(ci):
        ri = m + j
        A[i, ri] += -a[i].imag
        A[ri, i] += a[i].imag
        A[ri, ri] += a[i].real
        A[ri, -1] += b0[i].imag
        A[ri] += b1[i].imag * row_v
    return A, g, cb0


@lru_cache(maxsize=32)
def inverse_system(tau_s: float, lam: float, rate_hz: float, hold: str) -> InverseSystem:
    bank = Relaxor(tau_s, lam).bank(rate_hz, "zoh" if hold == "zoh" else "linear")
    a, b0, b1, c, cplx = _real_layout(bank, zoh=hold == "zoh")
    A, g, cb0 = _inverse_matrix(a, b0, b1, c, cplx)
    w, vl, vr = linalg.eig(A, left=True, right=True)
    out = np.flatnonzero((np.abs(w) > OUTSIDE) & (w.imag >= 0))
    lam_u = w[out]
    left = np.conj(vl[:, out]).T  # scipy: vl^H A = w vl^H  ->  left = conj(vl)
    right = vr[:, out].T
    for k in range(out.size):
        left[k] /= left[k] @ right[k]
    weight = np.where(np.abs(lam_u.imag) > 0, 2.0, 1.0)
    return InverseSystem(a, b0, b1, c, cplx, g, cb0, lam_u, left, right, weight)


def outside_zeros(tau_s: float, lam: float, rate_hz: float, hold: str) -> list[complex]:
    """Zeros outside the unit circle of the relaxor's sampled kernel for ``hold``.

    ``"zoh"``: the kernel shifted by the hold's one-sample delay (``k[1:]``), the one a drive
    with one sample of preview inverts; ``"linear"``: the kernel as it is. Found as the
    unstable eigenvalues of the modal bank's inverse recursion (one of each conjugate pair).
    ``[]`` for the relaxors of the paper's ``G_t``; one negative real zero for ``G_d`` with
    ``lam > 1`` under the linear hold.
    """
    return [complex(z) for z in inverse_system(tau_s, lam, float(rate_hz), hold).lam]
