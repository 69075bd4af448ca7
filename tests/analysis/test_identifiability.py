"""Identifiability flags of ``labrig fit`` and ``labrig report``
(:mod:`labrig.analysis.identifiability`): a parameter whose relative standard uncertainty is
over 100 %, or whose |correlation| with another free parameter is over 0.99, is flagged;
the thresholds are tested just inside and just outside. The operator's loop width and curvature
uncertainties are checked against a propagation by central differences of the map itself (not
its analytic Jacobian)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from rich.console import Console

from labrig.analysis.engine import LoopScale
from labrig.analysis.fit import FitResult
from labrig.analysis.identifiability import loop_coordinates, unidentifiable
from labrig.cli.fit import summary_tables
from labrig.model import PAPER_TABLE1, ModelParams
from labrig.report.data import Fitted
from labrig.report.html import params_context

FREE = ("alpha0_ue_per_V", "gamma_ue_per_V", "vc_V")


def corr(r_gv: float) -> dict[str, dict[str, float]]:
    """A correlation matrix of the free operator parameters with ``r(gamma, vc) = r_gv``."""
    c = {a: {b: (1.0 if a == b else 0.1) for b in FREE} for a in FREE}
    c["gamma_ue_per_V"]["vc_V"] = c["vc_V"]["gamma_ue_per_V"] = r_gv
    return c


def sds(rel_alpha0: float) -> dict[str, float | None]:
    p = PAPER_TABLE1.model_dump()
    out: dict[str, float | None] = dict.fromkeys(p)
    out.update({k: 0.01 * p[k] for k in FREE})
    out["alpha0_ue_per_V"] = rel_alpha0 * p["alpha0_ue_per_V"]
    return out


@pytest.mark.parametrize(
    ("rel", "r_gv", "flagged"),
    [
        (0.99, 0.5, set()),  # 99 %: inside
        (1.01, 0.5, {"alpha0_ue_per_V"}),  # 101 %: outside
        (0.5, 0.989, set()),
        (0.5, 0.991, {"gamma_ue_per_V", "vc_V"}),
        (0.5, -0.991, {"gamma_ue_per_V", "vc_V"}),  # the sign does not matter
        (1.01, 0.991, {"alpha0_ue_per_V", "gamma_ue_per_V", "vc_V"}),
    ],
)
def test_thresholds_just_inside_and_outside(rel: float, r_gv: float, flagged: set) -> None:
    got = unidentifiable(PAPER_TABLE1.model_dump(), sds(rel), corr(r_gv))
    assert set(got) == flagged
    if "alpha0_ue_per_V" in flagged:
        assert got["alpha0_ue_per_V"] == "relative uncertainty 101 %"
    if "vc_V" in flagged:
        assert got["vc_V"] == f"|correlation| {abs(r_gv):.4g} with gamma_ue_per_V"


def test_fixed_parameters_are_not_judged_and_zero_is() -> None:
    p = PAPER_TABLE1.model_dump()
    u = sds(0.5)
    assert u["lam_d"] is None  # fixed
    assert "lam_d" not in unidentifiable(p, u, corr(0.5))
    p["alpha0_ue_per_V"] = 0.0  # any uncertainty around zero is over 100 %
    assert set(unidentifiable(p, u, corr(0.5))) == {"alpha0_ue_per_V"}


def test_loop_coordinates_against_central_differences() -> None:
    p = PAPER_TABLE1.model_dump()
    span = 100.0
    sg, sv, r = 0.02 * p["gamma_ue_per_V"], 0.05 * p["vc_V"], 0.97
    u = {"gamma_ue_per_V": sg, "vc_V": sv}
    c = {"gamma_ue_per_V": {"vc_V": r}, "vc_V": {"gamma_ue_per_V": r}}
    got = loop_coordinates(p, u, c, span)
    assert got is not None
    scale = LoopScale(span, p["shape"])
    g0, v0 = p["gamma_ue_per_V"], p["vc_V"]
    w, _ = scale.to_loop(g0, v0)
    assert got["loop_width_ue"] == pytest.approx(w) and got["loop_curvature"] == span / v0
    G = np.zeros((2, 2))
    for j, (dg, dv) in enumerate(((1e-4 * g0, 0.0), (0.0, 1e-4 * v0))):
        hi = np.array(scale.to_loop(g0 + dg, v0 + dv))
        lo = np.array(scale.to_loop(g0 - dg, v0 - dv))
        G[:, j] = (hi - lo) / (2 * (dg + dv))
    cov = np.array([[sg * sg, r * sg * sv], [r * sg * sv, sv * sv]])
    ref = np.sqrt(np.diag(G @ cov @ G.T))
    assert got["loop_width_ue_sd"] == pytest.approx(ref[0], rel=1e-6)
    assert got["loop_curvature_sd"] == pytest.approx(ref[1], rel=1e-6)
    # the width is far better determined than gamma and vc when they are correlated
    assert got["loop_width_ue_sd"] / w < min(sg / g0, sv / v0)
    assert loop_coordinates({**p, "shape": "linear"}, u, c, span) is None
    assert (
        loop_coordinates(p, {"gamma_ue_per_V": None, "vc_V": sv}, c, span)["loop_width_ue_sd"]
        is None
    )


def fit_result(r_gv: float) -> FitResult:
    u = sds(0.5)
    return FitResult(
        params=ModelParams(**PAPER_TABLE1.model_dump()),
        uncertainty=u,
        correlation=corr(r_gv),
        nrmse_pct=0.3,
        per_entry={"e": 0.3},
        heldout_nrmse_pct=None,
        method="global",
        entries=["e"],
        loop_span_V=100.0,
    )


def test_fit_json_table_and_report_flag_and_give_the_loop() -> None:
    j = fit_result(0.995).to_json()
    ident = j["identifiability"]
    assert set(ident["unidentifiable"]) == {"gamma_ue_per_V", "vc_V"}
    assert ident["loop"]["span_V"] == 100.0 and ident["loop"]["loop_width_ue_sd"] > 0
    assert fit_result(0.98).to_json()["identifiability"]["unidentifiable"] == {}
    con = Console(width=300, record=True)
    for t in summary_tables(fit_result(0.995), "dynamic"):
        con.print(t)
    text = con.export_text()
    line = next(x for x in text.splitlines() if "vc_V  " in x or "│ vc_V" in x)
    assert "unidentifiable (fitted 65" in line and "0.995 with gamma_ue_per_V" in line
    assert "loop_width_ue" in text and "loop_curvature" in text
    fm = Fitted("dynamic", {}, None, None, j["params"], j["uncertainty"], j["correlation"])
    fm.loop_span_V = 100.0
    ctx = params_context(SimpleNamespace(models={"dynamic": fm}))
    rows = {r["field"]: r for r in ctx["rows"]}
    assert rows["vc_V"]["value"].startswith("unidentifiable (fitted 65")
    assert rows["alpha0_ue_per_V"]["value"] == "8.9"
    assert [r["field"] for r in ctx["loop_rows"]] == ["loop_width_ue", "loop_curvature"]
