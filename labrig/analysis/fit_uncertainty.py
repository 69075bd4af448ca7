"""What a least-squares fit's Jacobian says about its parameters: their covariance (1-sigma and
correlations) and the bounds they ended on. One code path under ``labrig fit`` (with or
without ``--effect``) and ``labrig diagnose``'s refits.

**Covariance.** With ``J`` (n x p) the Jacobian of the weighted residual ``r`` with respect to
the native parameters, ``c_j = ||J[:, j]||`` its column norms, ``D = diag(c)`` and
``J D^-1 = U S V^T`` the thin SVD of the column-scaled Jacobian, the rows fall in groups ``g``
(a fit's scored entries, weighted differently) of ``m_g`` rows and ``k_g`` nuisance parameters
eliminated from them (an entry's offset); ``p`` is the number of directions the data determine
(the singular values kept, below). The covariance is the sandwich estimate

    ``C = A^+ (sum_g s_g^2 J_g^T J_g) A^+``, ``A = J^T J``,
    ``s_g^2 = r_g^T r_g / (m_g - p m_g / n - k_g)``

(one group: the pooled ``s^2 A^+``). In the SVD, ``A^+ = D^-1 V S^-2 V^T D^-1`` and, with
``R`` the triangular factor of ``W^1/2 U`` (``W`` the rows' ``s_g^2``),

    ``C = F^T F,  F = R S^-1 V^T D^-1``

symmetric positive semi-definite by construction; the correlation ``F_i . F_j / (|F_i| |F_j|)``
is within [-1, 1] (clipped against rounding in the last digit). Singular values up to
:data:`RCOND` times the largest are dropped (the pseudo-inverse).

**Not determined.** A parameter the dropped directions move (the norm of its row of their
``V`` over :data:`NULL_TOL`; a parameter the residual does not depend on is the extreme case)
has no uncertainty and no correlation: its 1-sigma is ``NaN`` here (``None`` in the JSON, and
``labrig fit`` says "not determined by these data"), never 0.

**Bounds.** A parameter whose coordinate ends within ``1e-6`` of a bound
(:meth:`~labrig.analysis.engine.Coordinates.at_bound`) ended at it: the data do not determine
it within the bounds, and its 1-sigma (a local, unconstrained estimate) is not meaningful.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.engine import Coordinates, Problem

__all__ = [
    "NULL_TOL",
    "RCOND",
    "Covariance",
    "bound_notes",
    "bounds_reached",
    "fit_covariance",
    "native_names",
]

#: singular values of the column-scaled Jacobian up to this fraction of the largest are
#: dropped (numpy's ``pinv`` default of 1e-15 on ``J^T J``, which ``labrig diagnose``'s
#: uncertainties always used, is this on ``J``)
RCOND = float(np.sqrt(1e-15))
#: a parameter whose row of the dropped directions has a norm over this is not determined
NULL_TOL = 1e-6


def native_names(coords: Coordinates) -> list[str]:
    """The free parameters in the order of
    :meth:`~labrig.analysis.engine.Coordinates.native_jacobian`.

    Parameters
    ----------
    coords : Coordinates
        A problem's free coordinates.

    Returns
    -------
    list of str
        The base's free parameters (``ModelParams`` fields), then each effect's as
        ``"effect.param"``.
    """
    effects = [f"{c.who}.{c.name}" for c in coords.items if c.who != "base"]
    return [*coords.base_free, *effects]


@dataclass(frozen=True)
class Covariance:
    """The 1-sigma and correlations of a fit's free parameters (module docstring).

    ``sd[i]`` is in the unit of parameter ``names[i]``, ``NaN`` when it is not determined;
    ``correlation`` (p x p) is ``NaN`` in the rows and columns of those.
    """

    names: tuple[str, ...]
    sd: NDArray[np.float64]
    correlation: NDArray[np.float64]

    @classmethod
    def of(
        cls,
        names: Sequence[str],
        jacobian: NDArray,
        residual: NDArray,
        groups: Sequence[int],
        nuisance: Sequence[int],
    ) -> Covariance:
        """The sandwich covariance (module docstring) of a weighted least-squares fit.

        Parameters
        ----------
        names : sequence of str
            The free parameters, one per column of ``jacobian``.
        jacobian : ndarray
            ``d(weighted residual) / d(native parameters)``, n x p (residual units per unit
            of each parameter).
        residual : ndarray
            The weighted residual at the optimum, n.
        groups : sequence of int
            The rows of each group, in order (they add up to n): one per scored entry, or
            ``[n]`` for the pooled estimate.
        nuisance : sequence of int
            The nuisance parameters eliminated from each group's rows (its dof).

        Returns
        -------
        Covariance
            The 1-sigma (native units) and correlations of the parameters.
        """
        J = np.asarray(jacobian, dtype=float)
        r = np.asarray(residual, dtype=float)
        n, p = J.shape
        none = cls(tuple(names), np.full(p, np.nan), np.full((p, p), np.nan))
        if p == 0 or n == 0 or not (np.all(np.isfinite(J)) and np.all(np.isfinite(r))):
            return none
        scale = np.linalg.norm(J, axis=0)
        scale[scale == 0] = 1.0
        u, s, vt = np.linalg.svd(J / scale, full_matrices=False)
        keep = s > RCOND * s[0]
        if not s[0] > 0 or not np.any(keep):
            return none
        weights = _row_variances(r, groups, nuisance, int(np.count_nonzero(keep)))
        R = np.linalg.qr(np.sqrt(weights)[:, None] * u[:, keep], mode="r")
        F = (R / s[keep]) @ vt[keep]  # C (column-scaled) = F^T F
        return cls._from_factor(tuple(names), F, scale, vt[~keep])

    @classmethod
    def _from_factor(
        cls, names: tuple[str, ...], F: NDArray, scale: NDArray, dropped: NDArray
    ) -> Covariance:
        """From ``C = F^T F`` in column-scaled units (``scale`` the column norms) and the
        dropped directions' rows of ``V^T``."""
        p = F.shape[1]
        undetermined = np.linalg.norm(dropped, axis=0) > NULL_TOL
        norm = np.linalg.norm(F, axis=0)
        unit = F / np.where(norm > 0, norm, 1.0)
        corr = unit.T @ unit
        corr = np.clip(0.5 * (corr + corr.T), -1.0, 1.0)
        flat = norm == 0  # no residual at all: no variance to correlate
        corr[flat, :] = np.nan
        corr[:, flat] = np.nan
        corr[np.diag_indices(p)] = 1.0
        sd = norm / scale
        sd[undetermined] = np.nan
        corr[undetermined, :] = np.nan
        corr[:, undetermined] = np.nan
        return cls(names, sd, corr)

    def uncertainty(self) -> dict[str, float | None]:
        """The 1-sigma of each parameter.

        Returns
        -------
        dict
            Parameter to its 1-sigma (its unit), ``None`` when it is not determined.
        """
        return {
            n: float(x) if np.isfinite(x) else None
            for n, x in zip(self.names, self.sd, strict=True)
        }

    def correlations(self) -> dict[str, dict[str, float]]:
        """The correlations between the determined parameters (a parameter that is not
        determined has none: it is left out, not given a number).

        Returns
        -------
        dict
            Parameter to parameter to the correlation of their estimates (-1 to 1).
        """
        ok = [i for i, x in enumerate(self.sd) if np.isfinite(x)]
        c = self.correlation
        return {
            self.names[i]: {self.names[j]: float(c[i, j]) for j in ok if np.isfinite(c[i, j])}
            for i in ok
        }


def _row_variances(
    r: NDArray, groups: Sequence[int], nuisance: Sequence[int], p: int
) -> NDArray[np.float64]:
    """Each row's residual variance ``s_g^2`` (module docstring): its group's mean square
    corrected for the group's share of the ``p`` parameters the fit determines (the rank kept)
    and its nuisance parameters."""
    n = r.size
    out = np.empty(n)
    pos = 0
    for m, k in zip(groups, nuisance, strict=True):
        rg = r[pos : pos + m]
        dof = max(m - p * m / n - k, 1.0)
        out[pos : pos + m] = float(rg @ rg) / dof
        pos += m
    return out


def fit_covariance(
    problem: Problem,
    z: NDArray,
    base0: Mapping[str, float],
    jacobian: NDArray | None = None,
    residual: NDArray | None = None,
    pooled: bool = False,
) -> Covariance:
    """The covariance of a fitted ``problem``'s free parameters in native units.

    The native Jacobian is ``J T^-1`` with ``T = d(native) / dz``
    (:meth:`~labrig.analysis.engine.Coordinates.native_jacobian`); the groups are the scored
    entries with their nuisance parameters (an offset, a nuisance effect's columns), or one
    group (``pooled``).

    Parameters
    ----------
    problem : Problem
        The fitted problem (a base fit's, or a base + effects fit's).
    z : ndarray
        The optimum in the problem's coordinates.
    base0 : mapping
        The base parameters held fixed (and the rest, overridden by ``z``).
    jacobian, residual : ndarray, optional
        ``d(weighted residual) / dz`` and the weighted residual at ``z``, when already
        computed.
    pooled : bool
        One residual variance over every row (``labrig diagnose``'s refits) instead of one
        per entry.

    Returns
    -------
    Covariance
        The free parameters' 1-sigma and correlations (:func:`native_names`).
    """
    J = problem.jacobian(z, base0) if jacobian is None else jacobian
    r = problem.residual(z, base0) if residual is None else residual
    T = problem.coords.native_jacobian(z, base0)
    Jn = np.linalg.solve(T.T, J.T).T if J.size else J
    segments = [g for segs in problem.segments for g in segs]
    if pooled:
        groups, nuisance = [r.size], [0]
    else:
        groups = [g.measured_ue.size for g in segments]
        nuisance = [_nuisance_count(problem, g.name) for g in segments]
    return Covariance.of(native_names(problem.coords), Jn, r, groups, nuisance)


def _nuisance_count(problem: Problem, entry: str) -> int:
    Q = problem.nuisance.get(entry)
    return 0 if Q is None else int(Q.shape[1])


def bounds_reached(
    coords: Coordinates,
    z: NDArray,
    base: Mapping[str, float],
    effects: Mapping[str, Mapping[str, float]] | None = None,
) -> dict[str, float]:
    """The free parameters that ended on a bound of the fit.

    Parameters
    ----------
    coords : Coordinates
        The fit's coordinates.
    z : ndarray
        The optimum in them.
    base, effects : mapping
        The base parameters and each effect's parameters at ``z`` (native units).

    Returns
    -------
    dict
        Parameter (as :func:`native_names` names it) to its value there (its unit).
    """
    out: dict[str, float] = {}
    names = native_names(coords)  # one per coordinate, in order (a loop coordinate's native)
    for name, c, on in zip(names, coords.items, coords.at_bound(z), strict=True):
        if on:
            out[name] = float(base[name] if c.who == "base" else (effects or {})[c.who][c.name])
    return out


def bound_notes(at_bound: Mapping[str, float]) -> list[str]:
    """The notes ``labrig fit`` prints for the parameters that ended on a bound.

    Parameters
    ----------
    at_bound : mapping
        Parameter to its value (:func:`bounds_reached`).

    Returns
    -------
    list of str
        One sentence per parameter.
    """
    return [
        f"{name} ended at a bound ({value:.4g}): the data do not determine it within the "
        "bounds, and its uncertainty is not meaningful"
        for name, value in at_bound.items()
    ]
