"""Scoring a batch's flags against a simulated fleet's ``truth.json`` (for the benchmark and the
tests; no analysis reads the truth).

A defective actuator is **found** when its run is flagged (:mod:`labrig.fleet.outliers`), and
its defect is **named** when what the analysis reports matches the physics
(:data:`RIGHT_EFFECT`):

- depolarised: ``alpha0_ue_per_V`` is an outlier on the low side;
- cracked (extra creep): diagnose added ``creep`` or ``viscoelastic_creep``, or the creep the
  fitted model describes (``creep_pct_per_decade``) is an outlier on the high side;
- loose gauge (an undeclared low-pass): diagnose added ``sensor_lowpass``.

A healthy actuator whose run is flagged is a false alarm.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from labrig.core.jsonsafe import MAX_JSON_BYTES, loads_bounded
from labrig.core.textfile import read_text_bounded
from labrig.fleet.outliers import Z_LIMIT


def _effects(row: dict[str, Any]) -> set[str]:
    return {e for e in str(row.get("effects") or "").split(",") if e}


def _z(row: dict[str, Any], q: str) -> float:
    z = row.get(f"z_{q}")
    return float(z) if isinstance(z, int | float) else 0.0


RIGHT_EFFECT: dict[str, Callable[[dict[str, Any]], bool]] = {
    "depolarised": lambda r: _z(r, "alpha0_ue_per_V") < -Z_LIMIT,
    "cracked": lambda r: (
        bool(_effects(r) & {"creep", "viscoelastic_creep"})
        or _z(r, "creep_pct_per_decade") > Z_LIMIT
    ),
    "loose_gauge": lambda r: "sensor_lowpass" in _effects(r),
}


def read_truth(path: Path) -> dict[str, Any]:
    return loads_bounded(read_text_bounded(path, MAX_JSON_BYTES))


def score(rows: list[dict[str, Any]], truth: dict[str, Any]) -> dict[str, Any]:
    """Found, named and false alarms: counts, fractions, and the runs behind each."""
    by_file = {Path(str(r["run_file"])).name: r for r in rows}
    defective: list[tuple[dict[str, Any], dict[str, Any]]] = []
    healthy: list[tuple[dict[str, Any], dict[str, Any]]] = []
    for a in truth["actuators"]:
        row = by_file.get(a["run_file"])
        if row is None or row.get("status") != "ok":
            continue
        (defective if a["defect"] else healthy).append((a, row))
    found = [(a, r) for a, r in defective if r.get("flagged")]
    named = [(a, r) for a, r in defective if RIGHT_EFFECT[a["defect"]](r)]
    false_alarms = [(a, r) for a, r in healthy if r.get("flagged")]
    per_defect: dict[str, dict[str, int]] = {}
    for a, r in defective:
        d = per_defect.setdefault(a["defect"], {"n": 0, "found": 0, "named": 0})
        d["n"] += 1
        d["found"] += bool(r.get("flagged"))
        d["named"] += RIGHT_EFFECT[a["defect"]](r)
    missing = [a["run_file"] for a in truth["actuators"] if a["run_file"] not in by_file]
    failed = [n for n, r in by_file.items() if r.get("status") != "ok"]
    return {
        "defective": len(defective),
        "found": len(found),
        "named": len(named),
        "named_fraction": len(named) / len(defective) if defective else None,
        "healthy": len(healthy),
        "false_alarms": len(false_alarms),
        "false_alarm_fraction": len(false_alarms) / len(healthy) if healthy else None,
        "per_defect": per_defect,
        "not_found": [a["run_file"] for a, r in defective if not r.get("flagged")],
        "not_named": [
            f"{a['run_file']} ({a['defect']}: {r.get('named_effect') or 'nothing'})"
            for a, r in defective
            if not RIGHT_EFFECT[a["defect"]](r)
        ],
        "false_alarm_runs": [f"{a['run_file']} ({r.get('flags')})" for a, r in false_alarms],
        "missing": missing,
        "failed": failed,
    }
