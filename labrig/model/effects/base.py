"""The building blocks of an effect: its parameters, what it sees of a sequence, its interface.

See :mod:`labrig.model.effects` for where effects act and what a null value, a sign and a
signature mean.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["Context", "Effect", "Param", "fmt3", "plus_minus"]


@dataclass(frozen=True)
class Param:
    """One physical parameter of an effect (native units in ``unit``)."""

    name: str
    unit: str
    null: float  # the value where the effect vanishes
    lo: float
    hi: float
    init: float  # a start for the fit (near the null, on the physical side)
    sign: int = 0  # +1: only values above ``null`` are physical; 0: either sign
    log: bool = False  # fit in log coordinates (then ``null`` is never reached)
    expect: int = 0  # +1: values below ``null`` are possible but suspicious (reported)
    check_bounds: bool = True  # a fit ending on a bound makes the effect unphysical
    starts: tuple[float, ...] = ()  # further starts of a refit (other orders of magnitude)


@dataclass
class Context:
    """What an effect sees of one simulated sequence (a record or a chained run).

    ``entries`` maps each entry name to its ``slice`` in the sequence; samples outside every
    entry are rests at 0 V. ``amplifier_voltage`` and ``temperature`` span the whole sequence
    (``None`` when the run did not record them); ``temperature_ref`` is the campaign's
    reference temperature (default: the sequence's first temperature sample).
    """

    rate_hz: float
    v: NDArray[np.float64]
    entries: dict[str, slice]
    amplifier_voltage: NDArray[np.float64] | None = None
    temperature: NDArray[np.float64] | None = None
    #: the campaign's reference temperature (degC): the same for every sequence of a campaign,
    #: so a gain that follows the temperature compares a hot entry with a cool one
    temperature_ref: float | None = None
    cache: dict = field(default_factory=dict, repr=False)
    #: how the voltage behaves between samples: ``"zoh"`` (a DAQ holds each sample over the
    #: interval after it) or ``"linear"`` (a measured, smooth voltage)
    hold: str = "zoh"

    def acting_voltage(self) -> NDArray[np.float64]:
        """The voltage acting on the actuator at each sample time (V): with a zero-order hold the
        sample before (held over the interval that ends there; the first sample at rest), else
        the sample itself. The convention of the model's relaxors (their output at ``t_n`` sees
        the inputs before ``t_n``)."""
        if self.hold != "zoh" or self.n < 2:
            return self.v
        return self.cached(("acting_voltage",), lambda: np.r_[self.v[0], self.v[:-1]])

    @property
    def n(self) -> int:
        return int(self.v.size)

    @property
    def t(self) -> NDArray[np.float64]:
        return np.arange(self.n) / self.rate_hz

    def cached(self, key: tuple, make: Callable[[], Any]) -> Any:
        """``make()`` computed once per ``key``; keys that carry a fitted parameter come and go
        during a fit, so the cache is emptied when it holds more than 64 of them."""
        if key not in self.cache:
            if len(self.cache) > 64:
                self.cache.clear()
            self.cache[key] = make()
        return self.cache[key]


class Effect:
    """Base class; see the module docstring. Subclasses set the class attributes and implement
    :meth:`apply` (voltage/output effects) or :meth:`columns` (nuisance effects)."""

    name: str = ""
    where: str = ""  # "voltage" | "operator" | "output" | "nuisance"
    #: the cells of the table of effects in docs/diagnose.md (:mod:`labrig.model.effects.table`;
    #: Markdown): where it acts, in words; its parameters with their null values; its form as
    #: an equation. The table's signature is :attr:`signature`.
    acts_on: str = ""
    params_doc: str = ""
    form: str = ""
    physics: str = ""
    signature: str = ""
    confusable: tuple[str, ...] = ()
    tell_apart: str = ""
    params: tuple[Param, ...] = ()

    def apply(self, x: NDArray, ctx: Context, p: Mapping[str, float]) -> NDArray:
        """The voltage (``where == "voltage"``) or the strain (``"output"``) with the effect;
        for ``"operator"``, the strain term (ue) it adds, ``x`` being the operator's input."""
        raise NotImplementedError

    def tangent(self, x: NDArray, dx: NDArray, ctx: Context, p: Mapping[str, float]) -> NDArray:
        """For an output effect, the change of ``apply(x)`` along ``dx`` (the strain's
        derivative passed through the effect); the default is right for effects that are linear
        in the strain they receive."""
        return self.apply(dx, ctx, p)

    def tangent_columns(
        self, x: NDArray, dX: NDArray, ctx: Context, p: Mapping[str, float]
    ) -> NDArray:
        """:meth:`tangent` of every column of ``dX`` (N x k); effects whose tangent is cheaper
        for all columns at once (one batched FFT) override it."""
        out = np.empty_like(dX)
        for j in range(dX.shape[1]):
            out[:, j] = self.tangent(x, dX[:, j], ctx, p)
        return out

    def parameter_derivatives(
        self, x: NDArray, ctx: Context, p: Mapping[str, float]
    ) -> dict[str, NDArray] | None:
        """``d apply(x) / d q`` for each parameter ``q`` in closed form (native units), or
        ``None``: the engine then takes differences of :meth:`apply`."""
        return None

    def columns(self, t: NDArray, rate_hz: float) -> NDArray:
        """Nuisance regressors of one entry (``len(t) x k``), ``t`` the entry's time (s)."""
        raise NotImplementedError

    @property
    def null(self) -> dict[str, float]:
        return {q.name: q.null for q in self.params}

    @property
    def init(self) -> dict[str, float]:
        return {q.name: q.init for q in self.params}

    def refit_starts(self, start: Mapping[str, float]) -> list[dict[str, float]]:
        """Starts of a refit: ``start``, then ``start`` with one parameter moved to each of its
        :attr:`Param.starts` (orders of magnitude where a local optimum may hide)."""
        out = [dict(start)]
        for q in self.params:
            for v in q.starts:
                alt = {**start, q.name: min(max(v, q.lo), q.hi)}
                if alt not in out:
                    out.append(alt)
        return out

    def probes(self, contexts: list[Context]) -> list[dict[str, float]]:
        """Parameter values where the effect's direction is probed for ranking (the score
        test): by default its start, close to the null on the physical side."""
        return [self.init] if self.params else [{}]

    def caveats(self, p: Mapping[str, float], span_s: float) -> list[str]:
        """What makes fitted parameters ``p`` doubtful on data ``span_s`` long (the longest
        simulated sequence, s) although they passed: plain sentences; none by default."""
        return []

    def refusals(self, p: Mapping[str, float], sd: Mapping[str, float | None]) -> list[str]:
        """What makes fitted parameters ``p`` (1-sigma ``sd``) meaningless for this effect,
        beyond a parameter on a bound or of the wrong sign (which the acceptance rule checks for
        every effect): plain sentences, each a reason to refuse the candidate; none by default.
        An effect whose fit can drift into describing another mechanism (a filter's damping
        pushed to its resonant end) says so here."""
        return []

    def physical(self, p: Mapping[str, float]) -> dict[str, float]:
        """Reported parameters (derived units, e.g. a cutoff in Hz instead of a time constant)."""
        return {k: float(v) for k, v in p.items()}

    def describe(self, p: Mapping[str, float], sd: Mapping[str, float | None]) -> str:
        """``"fc = 118 +- 4 Hz"``-style text of the fitted parameters."""
        parts = []
        for q in self.params:
            v, s = p[q.name], sd.get(q.name)
            parts.append(plus_minus(q.name, v, s, q.unit))
        return ", ".join(parts)


def fmt3(x: float) -> str:
    """``x`` with three significant digits."""
    return f"{x:.3g}"


def plus_minus(name: str, v: float, s: float | None, unit: str) -> str:
    """``name = v +- s unit`` (without ``+- s`` when ``s`` is unknown)."""
    u = f" {unit}" if unit else ""
    if s is None or not np.isfinite(s):
        return f"{name} = {fmt3(v)}{u}"
    return f"{name} = {fmt3(v)} +- {fmt3(s)}{u}"
