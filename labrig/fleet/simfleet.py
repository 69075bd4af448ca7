"""A simulated fleet (``labrig sim fleet N --out DIR``): N actuators, each with its own
parameters drawn from a manufacturing spread, a fraction of them defective, each run through a
protocol on the simulated rig, and the truth in ``DIR/truth.json`` (which no analysis reads).

**Manufacturing spread**: each parameter of the paper's Table 1 (:data:`BASE`) is multiplied by
``1 + s * g`` with ``g`` a standard normal draw redrawn beyond +-3 (a part outside 3 sigma
fails incoming inspection) and ``s`` the relative standard deviation of :data:`SPREAD`
(alpha0 3 %, gamma and Vc 5 %, the relaxors' orders and time constants 10 %).

**Defects** (:data:`DEFECTS`), switched on for ``round(N * fraction)`` actuators chosen at
random, in turn: a **depolarised** stack (alpha0 20 % lower), a **cracked** one (extra creep: the
bench effect ``log_creep``, 5 %/decade) and a **loose gauge** (an undeclared 2nd-order 150 Hz
low-pass in the conditioner: the bench effect ``conditioner_lowpass``).

Each actuator gets a rig file (the built-in simulated rig,
:data:`labrig.rig.rigspec.DEFAULT_RIG_YAML`, with its truth in ``bench.truth.paper_overrides`` and
its defect in ``bench.effects``, named after one of :data:`STATIONS`) and a protocol file (the given
protocol with ``description`` starting ``actuator A0007``) in ``DIR/setup/``; the run file
``DIR/A0007.h5`` is written by :func:`labrig.runner.execute`, as ``labrig run`` would, with the
actuator's own random seed. The run file records the protocol and rig texts, so it names its
actuator and its station.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from labrig.core.errors import InputFileError, InputIssue, LabrigError
from labrig.core.seeds import check_seed
from labrig.core.textfile import read_text_bounded
from labrig.core.yamlio import MAX_BYTES as YAML_MAX_BYTES
from labrig.fleet.cache import write_atomic
from labrig.model import PAPER_TABLE1

BASE = PAPER_TABLE1
SPREAD: dict[str, float] = {
    "alpha0_ue_per_V": 0.03,
    "gamma_ue_per_V": 0.05,
    "vc_V": 0.05,
    "lam_t": 0.10,
    "tau_t_s": 0.10,
    "lam_d": 0.10,
    "tau_d_s": 0.10,
}
TRUNCATE_SIGMA = 3.0
DEFECTS: dict[str, dict[str, Any]] = {
    "depolarised": {"alpha0_factor": 0.8},
    "cracked": {"bench_effect": {"name": "log_creep", "per_decade": 0.05}},
    "loose_gauge": {
        "bench_effect": {"name": "conditioner_lowpass", "cutoff_hz": 150.0, "order": 2}
    },
}
DEFECT_ORDER = ("depolarised", "cracked", "loose_gauge")
STATIONS = ("sim-station-1", "sim-station-2")
#: the largest fleet `labrig sim fleet` makes (its actuators are drawn one by one)
MAX_FLEET = 100_000


@dataclass
class Actuator:
    """One simulated actuator: its identity, station, seed, parameters and defect."""

    id: str
    rig: str
    seed: int
    params: dict[str, float]
    defect: str | None = None
    bench_effects: list[dict[str, Any]] = field(default_factory=list)

    @property
    def run_file(self) -> str:
        return f"{self.id}.h5"


def _spread_factor(rng: np.random.Generator, s: float) -> float:
    while True:
        g = rng.standard_normal()
        if abs(g) <= TRUNCATE_SIGMA:
            return 1.0 + s * float(g)


def draw_fleet(n: int, seed: int, defect_fraction: float) -> list[Actuator]:
    """The fleet's actuators (module docstring), reproducible from ``seed`` (0 to 2^63-1)."""
    if not 1 <= n <= MAX_FLEET:
        raise ValueError(f"a fleet has 1 to {MAX_FLEET} actuators, not {n}")
    check_seed(seed, "--seed")
    if not 0 <= defect_fraction <= 1:
        raise ValueError("the defect fraction must be between 0 and 1")
    rng = np.random.default_rng(seed)
    fleet = []
    for k in range(n):
        params = {p: float(getattr(BASE, p)) * _spread_factor(rng, s) for p, s in SPREAD.items()}
        rig = STATIONS[int(rng.integers(len(STATIONS)))]
        fleet.append(Actuator(f"A{k + 1:04d}", rig, int(rng.integers(2**31 - 1)), params))
    n_def = round(n * defect_fraction)
    chosen = sorted(int(i) for i in rng.choice(n, size=n_def, replace=False))
    for j, i in enumerate(chosen):
        a = fleet[i]
        a.defect = DEFECT_ORDER[j % len(DEFECT_ORDER)]
        spec = DEFECTS[a.defect]
        if "alpha0_factor" in spec:
            a.params["alpha0_ue_per_V"] *= spec["alpha0_factor"]
        if "bench_effect" in spec:
            a.bench_effects.append(dict(spec["bench_effect"]))
    return fleet


def rig_text(a: Actuator) -> str:
    """The actuator's rig file: the built-in simulated rig with its truth and defect."""
    from labrig.rig.rigspec import DEFAULT_RIG_YAML

    doc = yaml.safe_load(DEFAULT_RIG_YAML)
    doc["name"] = a.rig
    doc["description"] = f"{a.rig} of the simulated fleet, testing actuator {a.id}"
    doc["bench"]["truth"]["paper_overrides"] = dict(a.params)
    doc["bench"]["effects"] = [dict(e) for e in a.bench_effects]
    return yaml.safe_dump(doc, sort_keys=False)


def protocol_text(a: Actuator, base_text: str, source: str) -> str:
    """The protocol ``base_text`` (from ``source``) with a description naming the actuator."""
    doc = yaml.safe_load(base_text)
    if not isinstance(doc, dict):
        raise InputFileError([InputIssue(source, None, "", "not a protocol (a YAML mapping)")])
    doc.pop("rig", None)
    was = str(doc.get("description") or "")
    doc["description"] = f"actuator {a.id} (simulated fleet)" + (f"; {was}" if was else "")
    return yaml.safe_dump(doc, sort_keys=False)


def truth_doc(fleet: list[Actuator], seed: int, defect_fraction: float, protocol: Path) -> dict:
    """``truth.json``: how the fleet was drawn and each actuator's truth."""
    return {
        "about": "the truth of a simulated fleet (labrig sim fleet); no analysis reads this file",
        "seed": seed,
        "n": len(fleet),
        "defect_fraction": defect_fraction,
        "protocol": str(protocol),
        "base_params": {p: float(getattr(BASE, p)) for p in SPREAD},
        "spread_rel_sd": SPREAD,
        "truncated_at_sigma": TRUNCATE_SIGMA,
        "defects": DEFECTS,
        "actuators": [{**asdict(a), "run_file": a.run_file} for a in fleet],
    }


def check_free(out: Path, fleet: list[Actuator], protocol: Path, overwrite: bool) -> None:
    """The one output check (:func:`labrig.core.outputs.check_outputs`) for the fleet's folder
    and files: ``out`` is a folder (or new), no file of the fleet is the protocol or a run file
    being written, and files of an earlier fleet are replaced only with ``overwrite``."""
    from labrig.core.outputs import check_outputs
    from labrig.store.reader import being_written

    check_outputs([out], inputs=[protocol], folder=True)
    check_outputs(
        [out / "truth.json", *(out / a.run_file for a in fleet)],
        inputs=[protocol],
        overwrite=overwrite,
        being_written=being_written,
    )


def write_fleet(
    n: int,
    out: Path,
    protocol: Path,
    *,
    seed: int = 0,
    defect_fraction: float = 0.05,
    overwrite: bool = False,
    progress: Callable[[Actuator], None] | None = None,
    checked: Callable[[], None] | None = None,
) -> list[Path]:
    """Draw the fleet, run each actuator on its simulated rig, write ``truth.json``; returns
    the run files. ``protocol``: a file or a shipped example's name. ``checked()`` is called
    once the inputs and outputs are checked (:func:`check_free`), before the first run;
    ``progress(actuator)`` after each run. A run that does not complete is a
    :class:`LabrigError` naming it."""
    from labrig.runner.examples import resolve_existing
    from labrig.runner.execute import execute, preflight

    protocol = resolve_existing(protocol, "protocol")
    try:
        base = read_text_bounded(protocol, YAML_MAX_BYTES)
    except (OSError, ValueError, UnicodeDecodeError) as e:
        why = (e.strerror if isinstance(e, OSError) else None) or str(e)
        raise InputFileError([InputIssue(str(protocol), None, "--protocol", why)]) from None
    fleet = draw_fleet(n, seed, defect_fraction)
    check_free(out, fleet, protocol, overwrite)
    if checked is not None:
        checked()
    setup = out / "setup"
    setup.mkdir(parents=True, exist_ok=True)
    if n > 1:
        # many campaigns in one process: numba's start repays itself, and the simulated rig
        # runs the compiled model once it is loaded (accel.stream_engine)
        from labrig.model.accel import kernels

        kernels()
    paths = []
    for a in fleet:
        rig = setup / f"{a.id}.rig.yaml"
        proto = setup / f"{a.id}.protocol.yaml"
        rig.write_text(rig_text(a), encoding="utf-8")
        proto.write_text(protocol_text(a, base, str(protocol)), encoding="utf-8")
        plan, rig_path = preflight(proto, rig)
        outcome = execute(plan, rig_path, out / a.run_file, a.seed, overwrite=overwrite)
        if outcome.exit_code != 0:
            raise LabrigError(f"actuator {a.id}: the run ended {outcome.status}: {outcome.reason}")
        paths.append(outcome.path)
        if progress is not None:
            progress(a)
    text = json.dumps(truth_doc(fleet, seed, defect_fraction, protocol), indent=2) + "\n"
    write_atomic(out / "truth.json", text)
    return paths
