"""``labrig fit`` on the inputs of an adversarial trial: the covariance is symmetric and its
correlations within [-1, 1] (checked against a linear least-squares problem whose sandwich
covariance is known in closed form), a parameter the data do not determine has no uncertainty
(never ``± 0``), a parameter that ended at a bound is flagged, ``fit --effect`` judges its
parameters by the same rule and keeps ``G_d`` fixed where the plain fit does, and a warm-up
that leaves an entry fewer than the documented 20 samples is refused.

The imported records are a lagged linear response (5 ms) with a small square term and 2 ue of
noise to an 80 V, 5 Hz unipolar sine of five periods at 1 kHz (1001 samples): one entry at one
frequency, so ``G_d`` stays fixed and the slow relaxor's order ends on its bound (0.9);
negated, no positive gain fits it and every free parameter ends on a bound.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import Result

from helpers import FIT_JSON_KEYS, ROOT, invoke

RATE_HZ = 1000.0
#: the documented minimum of scored samples per entry (docs/analysis.md)
MIN_SCORED = 20
#: the keys ``fit --effect`` adds to a plain fit's (docs/analysis.md)
EFFECT_KEYS = ("effects", "without_effects", "heldout_scoring", "effects_context")


def lagged_sine(sign: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time (s), voltage (V) and strain (ue) of the record described in the module doc."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(5 * RATE_HZ / 5) + 1) / RATE_HZ
    v = 40.0 * (1 - np.cos(2 * np.pi * 5 * t))
    a = np.exp(-1 / (RATE_HZ * 0.005))
    y = np.zeros_like(v)
    for i in range(1, v.size):
        y[i] = a * y[i - 1] + (1 - a) * v[i]
    return t, v, sign * (8.9 * y + 0.01 * v**2 + rng.normal(0, 2, v.size))


@pytest.fixture(scope="module")
def imported(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``good1.h5`` (the record) and ``neg.h5`` (negated), imported by ``labrig import``."""
    tmp = tmp_path_factory.mktemp("trials")
    out = {}
    for name, sign in (("good1", 1.0), ("neg", -1.0)):
        csv = tmp / f"{name}.csv"
        rows = np.column_stack(lagged_sine(sign))
        np.savetxt(csv, rows, delimiter=",", header="time_s,voltage_V,strain_ue", comments="")
        out[name] = tmp / f"{name}.h5"
        res = invoke("import", csv, "--out", out[name])
        assert res.exit_code == 0, res.output
    return out


def fit_json(*args: object) -> tuple[dict, Result]:
    """``labrig fit ARGS --no-heldout --json``: the document and the result (stderr apart)."""
    res = invoke("fit", *args, "--no-heldout", "--json")
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout), res


def sandwich(X: np.ndarray, r: np.ndarray, groups: list[int], nuisance: list[int]) -> np.ndarray:
    """The closed-form sandwich covariance of linear least squares ``y = X b``:
    ``(X^T X)^-1 (sum_g s_g^2 X_g^T X_g) (X^T X)^-1``, ``s_g^2 = r_g^T r_g / dof_g``."""
    n, p = X.shape
    inv = np.linalg.inv(X.T @ X)
    B = np.zeros((p, p))
    pos = 0
    for m, k in zip(groups, nuisance, strict=True):
        Xg, rg = X[pos : pos + m], r[pos : pos + m]
        B += float(rg @ rg) / (m - p * m / n - k) * (Xg.T @ Xg)
        pos += m
    return inv @ B @ inv


def linear_problem(scales: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """A design matrix with correlated columns, each multiplied by its ``scales``, the residual
    of its least-squares fit to noisy data (three groups of different noise) and the groups'
    sizes."""
    rng = np.random.default_rng(4)
    groups = [200, 300, 250]
    n = sum(groups)
    t = np.linspace(0, 1, n)
    X0 = np.column_stack([np.ones(n), t, t**2 + 0.01 * rng.normal(size=n), np.sin(7 * t)])
    sigma = np.repeat([0.1, 1.0, 3.0], groups)
    y = X0 @ np.array([1.0, -2.0, 0.5, 3.0]) + sigma * rng.normal(size=n)
    X = X0 * scales
    b, *_ = np.linalg.lstsq(X, y, rcond=None)
    return X, X @ b - y, groups


@pytest.mark.parametrize("spread", [0.0, 20.0])
def test_covariance_is_the_closed_form_sandwich_symmetric_and_bounded(spread: float) -> None:
    """Against the closed form, with columns of like scale and spread over 40 decades (the
    neg.h5 trial: 1e-22 next to 1e5), where a product of the unscaled matrices loses the
    symmetry and the bound |r| <= 1."""
    from labrig.analysis.fit_uncertainty import Covariance

    scales = 10.0 ** (spread * np.array([-1.0, 0.3, 1.0, -0.5]))
    X, r, groups = linear_problem(scales)
    names = ["a", "b", "c", "d"]
    for nuisance in ([0, 0, 0], [1, 0, 2]):
        cov = Covariance.of(names, X, r, groups, nuisance)
        ref = sandwich(X / scales, r, groups, nuisance) / np.outer(scales, scales)
        sd = np.sqrt(np.diag(ref))
        np.testing.assert_allclose(cov.sd, sd, rtol=1e-9)
        np.testing.assert_allclose(cov.correlation, ref / np.outer(sd, sd), atol=1e-9)
        c = cov.correlations()
        assert all(c[a][b] == c[b][a] and -1.0 <= c[a][b] <= 1.0 for a in c for b in c)
    # one group: the pooled s^2 (X^T X)^-1
    pooled = Covariance.of(names, X, r, [r.size], [0])
    s2 = float(r @ r) / (r.size - 4)
    np.testing.assert_allclose(pooled.sd, np.sqrt(s2 * np.diag(np.linalg.inv(X.T @ X))), rtol=1e-9)


def test_a_parameter_without_information_has_no_uncertainty_nor_correlation() -> None:
    """A column of zeros (the residual does not depend on the parameter): its uncertainty is
    undefined, never 0, it has no correlation, and the others are those of the problem
    without it."""
    from labrig.analysis.fit_uncertainty import Covariance

    X, r, groups = linear_problem(np.ones(4))
    with_zero = np.column_stack([X[:, :2], np.zeros(r.size), X[:, 2:]])
    cov = Covariance.of(["a", "b", "z", "c", "d"], with_zero, r, groups, [0, 0, 0])
    assert cov.uncertainty()["z"] is None
    assert "z" not in cov.correlations() and all(
        "z" not in row for row in cov.correlations().values()
    )
    ref = Covariance.of(["a", "b", "c", "d"], X, r, groups, [0, 0, 0])
    got = cov.uncertainty()
    for k, v in ref.uncertainty().items():
        assert got[k] == pytest.approx(v, rel=1e-9)


def test_neg_correlations_are_symmetric_bounded_and_undetermined_ones_are_said(
    imported: dict[str, Path],
) -> None:
    """The negated record (every parameter on a bound): the correlation matrix printed is
    symmetric, within [-1, 1], and a free parameter without an uncertainty is named as not
    determined by the data (never ``± 0``)."""
    j, _ = fit_json(imported["neg"])
    c = j["correlation"]
    assert c, "no correlation at all"
    for a, row in c.items():
        for b, r in row.items():
            assert r == c[b][a] and -1.0 <= r <= 1.0, (a, b, r, c[b][a])
    ident = j["identifiability"]["unidentifiable"]
    free = [n for n, u in j["uncertainty"].items() if n not in ("lam_d", "tau_d_s")]
    for name in free:
        sd = j["uncertainty"][name]
        assert sd is None or sd > 0, name
        if sd is None:
            assert "not determined by these data" in ident[name] and name not in c


def test_a_parameter_at_its_bound_is_flagged_in_the_table_and_json(
    imported: dict[str, Path],
) -> None:
    """lam_t ends at its bound 0.9 on the 5 Hz record: the note, the JSON's identifiability
    and the printed table all say so, and the table gives it no 1-sigma."""
    j, res = fit_json(imported["good1"])
    ident = j["identifiability"]
    assert ident["at_bound"]["lam_t"] == pytest.approx(0.9)
    assert "ended at a bound" in ident["unidentifiable"]["lam_t"]
    assert "lam_t ended at a bound (0.9)" in " ".join(res.stderr.split())
    table = invoke("fit", imported["good1"], "--no-heldout", columns=300)
    assert table.exit_code == 0, table.output
    row = next(x for x in table.stdout.splitlines() if "│ lam_t" in x)
    cells = [x.strip() for x in row.split("│")]
    assert cells[2].startswith("unidentifiable (fitted 0.9; ended at a bound"), row
    assert cells[3] == "—" and cells[4] == "—", row


def test_fit_effect_judges_as_a_plain_fit_and_keeps_g_d_fixed(tiny_run: Path) -> None:
    """``negative_field_asymmetry`` on a 0-100 V run (the data never touch it): no ``± 0`` but
    "not determined by these data"; the JSON has a plain fit's keys plus the documented ones
    of ``--effect``, each documented; every entry at 2 Hz: ``G_d`` stays fixed as in the plain
    fit."""
    j, res = fit_json(tiny_run, "--effect", "negative_field_asymmetry")
    assert set(j) == {*FIT_JSON_KEYS, *EFFECT_KEYS}
    doc = (ROOT / "docs" / "analysis.md").read_text()
    assert all(f"`{k}`" in doc for k in j)
    (e,) = j["effects"]
    assert e["uncertainty"]["a"] is None and "+- 0" not in e["description"]
    ident = j["identifiability"]
    assert ident["unidentifiable"]["negative_field_asymmetry.a"] == "not determined by these data"
    assert j["uncertainty"]["lam_d"] is None and j["uncertainty"]["tau_d_s"] is None
    assert j["params"]["lam_d"] == 1.2 and j["params"]["tau_d_s"] == 1e-5
    assert "G_d is not identifiable and stays fixed" in " ".join(res.stderr.split())
    for a, row in j["correlation"].items():
        assert all(row[b] == j["correlation"][b][a] for b in row)
    table = invoke("fit", tiny_run, "--effect", "negative_field_asymmetry", "--no-heldout")
    assert "a: unidentifiable (not determined by these data)" in " ".join(table.stdout.split())


def test_fit_effect_notes_the_bounds_of_its_parameters(tiny_run: Path) -> None:
    """``sensor_lowpass`` on the simulated rig (no low-pass in its truth) ends on its damping's
    lower bound: noted on stderr and flagged in the JSON and the table, as a plain fit's base
    parameters are."""
    j, res = fit_json(tiny_run, "--effect", "sensor_lowpass")
    ident = j["identifiability"]
    assert "sensor_lowpass.zeta" in ident["at_bound"], ident
    notes = " ".join(res.stderr.split())
    for name, value in ident["at_bound"].items():
        assert "ended at a bound" in ident["unidentifiable"][name]
        assert f"{name} ended at a bound ({value:.4g})" in notes
    table = invoke("fit", tiny_run, "--effect", "sensor_lowpass", "--no-heldout", columns=300)
    assert "zeta: unidentifiable (ended at a bound" in table.stdout


def test_a_warmup_leaving_too_few_samples_is_refused(imported: dict[str, Path]) -> None:
    """1001 samples at 1 kHz: a warm-up of 0.981 s leaves 20 to score (just inside: fitted),
    0.982 s leaves 19 (just outside: refused, exit 2, naming the entry, the samples left and
    the minimum)."""
    inside = invoke("fit", imported["good1"], "--warmup-s", 0.981, "--no-heldout", "--json")
    assert inside.exit_code == 0, inside.output
    res = invoke("fit", imported["good1"], "--warmup-s", 0.982, "--no-heldout", "--json")
    assert res.exit_code == 2, res.output
    msg = " ".join(res.output.split())
    assert "[good1/data]" in msg and f"leaves {MIN_SCORED - 1} of its 1001 samples" in msg
    assert f"at least {MIN_SCORED}" in msg and "Traceback" not in msg


def test_an_entry_named_twice_is_named(imported: dict[str, Path]) -> None:
    res = invoke("fit", imported["good1"], "--entries", "good1,good1", "--no-heldout")
    assert res.exit_code == 2 and "'good1' named twice" in " ".join(res.output.split())


def test_the_report_page_flags_what_the_fit_judged(
    imported: dict[str, Path], tmp_path: Path
) -> None:
    """The report's parameter table takes the fit's own judgement (which knows the free
    parameters and the bounds): lam_t at its bound is unidentifiable on the page, fitted now
    and from the fit's parameter file alike; before, the page judged from the numbers alone
    and printed lam_t 0.9 with a 1.9 % uncertainty."""
    params = tmp_path / "p.json"
    fitted = invoke("fit", imported["good1"], "--no-heldout", "--out", params)
    assert fitted.exit_code == 0, fitted.output
    for extra in ((), ("--params", params)):
        page = tmp_path / f"page{len(extra)}.html"
        res = invoke(
            "report", imported["good1"], "--peers", "none", "--no-heldout", "--out", page, *extra
        )
        assert res.exit_code == 0, res.output
        text = " ".join(page.read_text().split())
        assert "unidentifiable (fitted 0.9; ended at a bound" in text, extra
