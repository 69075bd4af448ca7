"""Per-sample inverse of one relaxor's modal bank, with its outside zeros handled anti-causally.

The offline inverse (:mod:`labrig.control.inversion`) realised on the relaxor's modal bank
(:meth:`labrig.model.Relaxor.bank`, the ``"fast"`` method). The inverse of the bank is the
recursion ``z[n] = A z[n-1] + B y[n]`` (one state per mode, plus the last output,
:mod:`labrig.control.inverse_system`) whose matrix has the sampled kernel's outside zeros as
eigenvalues. Their eigen-directions are split off and solved anti-causally over a look-ahead
window (``preview`` samples, cut where the weights ``|zeta|^-m`` fall below ``tol``); the rest runs
forward and is re-projected every :data:`REPROJECT` samples so rounding cannot build up in the
unstable direction. Cost O(modes + preview) per sample, no history kept. It agrees with the offline
inverse to the quadrature error of the banks plus ``tol``.
"""

from __future__ import annotations

import math

import numpy as np

from labrig.control.inverse_system import inverse_system

__all__ = ["PREVIEW_TOL", "REPROJECT", "BankInverse"]

#: look-ahead window of the per-sample controller: anti-causal weights are cut below this
PREVIEW_TOL = 1e-9
#: the per-sample inverse removes rounding's unstable components every this many samples
#: (they grow like |zeta|^n: by at most 1.7^16 ~ 5e3 in between, from 1e-16)
REPROJECT = 16


class BankInverse:
    """Per-sample inverse of a relaxor bank with anti-causal handling of its outside zeros.

    The bank's inverse recursion in real coordinates ``z = [Re x, Im x (complex modes), v]``
    is ``z[n] = A z[n-1] + B y[n]``, output ``v[n]``. For each unstable eigenvalue ``lam`` (left
    and right eigenvectors ``l``, ``r``, ``l . r = 1``) the component ``xi = l . z`` obeys
    ``xi[n] = lam xi[n-1] + (l . B) y[n]`` and is taken as its bounded (anti-causal) solution
    ``xi[n] = -sum_{m>=1} lam^-m (l . B) y[n+m]``, truncated at ``preview`` terms; the rest,
    ``z_s = z - sum r xi``, runs forward with the projected input ``P B`` and is re-projected
    each sample (rounding would otherwise grow like ``lam^n``). Starting from rest, the first
    target samples get the defect that zeroes every ``xi`` before ``t_0`` (as the offline
    inverse does). Feed the wanted output with :meth:`push`; once ``preview`` samples are ahead,
    each push returns the input for the sample ``preview`` earlier. For ``"zoh"`` the wanted
    output is ``y[n] = vt[n+1]`` (the shifted bank).

    Arithmetic: real modes in float arrays, complex modes (the pole pair of ``lam > 1``) in a
    small complex array; real unstable eigenvalues (the only kind the relaxors produce) use
    real eigenvectors, a conjugate pair is carried as one complex direction with weight 2.
    """

    def __init__(self, tau_s: float, lam: float, rate_hz: float, hold: str, tol: float):
        sysm = inverse_system(tau_s, lam, float(rate_hz), hold)
        self.sys = sysm
        a, b0, b1, c, cplx = sysm.a, sysm.b0, sysm.b1, sysm.c, sysm.cplx
        m = a.size
        ci = np.flatnonzero(cplx)
        ri = np.flatnonzero(~cplx)
        self.g, self.cb0 = sysm.gain, sysm.cb0
        # real modes
        self._ar = np.ascontiguousarray(a[ri].real)
        self._car = np.ascontiguousarray((c[ri] * a[ri]).real)
        # complex modes (y = Re(c x): their contribution is Re(c a x))
        self._acl = [complex(x) for x in a[ci]]
        self._cacl = [complex(x) for x in c[ci] * a[ci]]
        self._b0cl = [complex(x) for x in b0[ci]]
        self._b1cl = [complex(x) for x in b1[ci]]
        B = np.zeros(m + ci.size + 1)
        B[:m] = b1.real / self.g
        B[m : m + ci.size] = b1.imag[ci] / self.g
        B[-1] = 1.0 / self.g
        rho = min((abs(z) for z in sysm.lam), default=math.inf)
        self.preview = math.ceil(math.log(1.0 / tol) / math.log(rho)) if sysm.lam.size else 0
        PB = B.copy()
        self._proj = []
        self._fir = []
        steps = np.arange(1, self.preview + 1, dtype=float)
        for k in range(sysm.lam.size):
            lv, rv, wt = sysm.left[k].copy(), sysm.right[k].copy(), float(sysm.weight[k])
            if wt == 1.0:  # real eigenvalue: make both eigenvectors real
                rv = rv * np.conj(rv[np.argmax(np.abs(rv))])
                lv = lv * np.conj(lv[np.argmax(np.abs(lv))])
                rv, lv = rv.real, lv.real
                lv = lv / (lv @ rv)
            beta = lv @ B
            PB = PB - wt * np.real(rv * beta)
            lim = np.zeros(m, dtype=lv.dtype)
            lim[ci] = lv[m : m + ci.size]
            rim = np.zeros(m, dtype=rv.dtype)
            rim[ci] = rv[m : m + ci.size]
            self._proj.append(
                (
                    np.ascontiguousarray(lv[ri]),
                    list(lv[ci]),
                    list(lim[ci]),
                    lv[-1],
                    np.ascontiguousarray(rv[ri]),
                    list(rv[ci]),
                    list(rim[ci]),
                    rv[-1],
                    wt,
                )
            )
            fir = -(sysm.lam[k] ** -steps) * beta
            self._fir.append((fir.real if wt == 1.0 else fir, rv[-1], wt))
        pbx = PB[:m]
        # stacked input vectors: x += [v_prev, w, y] @ rows
        self._inr = np.ascontiguousarray(np.stack([b0[ri].real, b1[ri].real, pbx[ri]]))
        self._pbcl = [complex(x) for x in pbx[ci] + 1j * PB[m : m + ci.size]]
        self._pbv = float(PB[-1])
        # start from rest: defect on the first q target samples (sum_m lam^-(m+1) y[m] = 0)
        lams = [*sysm.lam, *(np.conj(z) for z in sysm.lam if z.imag != 0)]
        self._q = len(lams)
        if self._q:
            jj = np.arange(self._q, dtype=float)
            allm = np.arange(self.preview + 1, dtype=float)
            self._defect_mat = np.array([lk ** -(jj + 1) for lk in lams])
            self._defect_rhs = np.array([-(lk ** -(allm + 1)) for lk in lams])
        self.reset()

    @property
    def n_modes(self) -> int:
        return self._ar.size + len(self._acl)

    def reset(self) -> None:
        self.xr = np.zeros(self._ar.size)
        self.xc = [0j] * len(self._acl)
        self.v = 0.0
        n = self.preview + 1
        self._ring = np.zeros(2 * n)  # each sample twice: the window is one contiguous slice
        self._pos = n - 1  # where the newest sample went
        self._count = 0
        self._started = False
        self._since = 0

    def _stable(self, y: float) -> float:
        """Stable part: ``z_s[n] = A z_s[n-1] + P B y[n]``; returns ``v_s[n]``."""
        v0 = self.v
        pred = float(np.dot(self._car, self.xr)) + self.cb0 * v0
        xc = self.xc
        for cac, x in zip(self._cacl, xc, strict=True):
            pred += (cac * x).real
        w = -pred / self.g
        xr = self._ar * self.xr
        xr += np.dot((v0, w, y), self._inr)
        if xc:
            xc = [
                a * x + b0 * v0 + b1 * w + pb * y
                for a, x, b0, b1, pb in zip(
                    self._acl, xc, self._b0cl, self._b1cl, self._pbcl, strict=True
                )
            ]
        v = w + self._pbv * y
        self._since += 1
        if self._proj and self._since >= REPROJECT:
            # remove the unstable components rounding has put into z_s (they grow like lam^n)
            self._since = 0
            for l_r, l_cre, l_cim, l_v, r_r, r_cre, r_cim, r_v, wt in self._proj:
                q = np.dot(l_r, xr) + l_v * v
                for lre, lim, x in zip(l_cre, l_cim, xc, strict=True):
                    q += lre * x.real + lim * x.imag
                if wt == 1.0:
                    xr -= r_r * q
                    xc = [
                        x - complex(rre * q, rim * q)
                        for x, rre, rim in zip(xc, r_cre, r_cim, strict=True)
                    ]
                    v -= r_v * q
                else:
                    xr -= wt * np.real(r_r * q)
                    xc = [
                        x - wt * complex((rre * q).real, (rim * q).real)
                        for x, rre, rim in zip(xc, r_cre, r_cim, strict=True)
                    ]
                    v -= wt * float(np.real(r_v * q))
        self.xr, self.xc, self.v = xr, xc, float(v)
        return self.v

    def push(self, y: float) -> float | None:
        n = self.preview + 1
        pos = self._pos + 1
        if pos == n:
            pos = 0
        self._pos = pos
        self._ring[pos] = self._ring[pos + n] = y
        self._count += 1
        if self._count < n:
            return None
        window = self._ring[pos + 1 : pos + 1 + n]  # y[k - P .. k], oldest first
        if self._q and not self._started:
            self._started = True
            d = np.linalg.solve(self._defect_mat, self._defect_rhs @ window).real
            for j in range(self._q):
                i = (pos + 1 + j) % n
                self._ring[i] += d[j]
                self._ring[i + n] = self._ring[i]
        v = self._stable(float(window[0]))
        if self._fir:
            ahead = window[1:]
            for fir, r_v, wt in self._fir:
                xi = np.dot(fir, ahead)
                v += float(r_v * xi) if wt == 1.0 else float(wt * np.real(r_v * xi))
        return float(v)
