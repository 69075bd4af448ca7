"""Compile labrig's numba kernels into their on-disk cache before a parallel test session.

In a new checkout numba's cache (``__pycache__`` beside each kernel's module) is empty, and
every process that first needs a kernel compiles it: the test workers and the ``labrig``
commands the tests start did so at the same time, compiling the same kernels several times
over. ``tests/conftest.py`` runs this file twice at once before the workers start (one process
per group below, each a small workload that reaches its group's kernels), so that the workers
load machine code instead. It is only a warm-up: a kernel it misses is compiled where it is
first used, as before.

Usage: ``python tests/compile_kernels.py stream_and_peers|operator_and_fit``.
"""

from __future__ import annotations

import sys

import numpy as np

RATE = 500.0


def _records(strain_of):
    """Two short unipolar sines (100 V 1 Hz, 50 V 5 Hz; 1 s at 500 Hz) as fit records."""
    from labrig.analysis.records import Record

    rng = np.random.default_rng(1)
    out = []
    for a, f in [(100, 1), (50, 5)]:
        t = np.arange(round(RATE)) / RATE
        v = a / 2 * (1 - np.cos(2 * np.pi * f * t))
        s = strain_of(v) + rng.normal(0, 1.0, v.size)
        out.append(Record(f"s{a}_{f}", RATE, t, v, s, {}, "zoh", {"frequency_hz": f}))
    return out


def stream_and_peers() -> None:
    """The bank kernel first (the other group's fit loads it), the simulator's streaming
    kernel, and the Bouc-Wen and SINDy peers' kernels."""
    from labrig.analysis.baselines import fit_baseline
    from labrig.model import PAPER_TABLE1, DynamicHysteresisModel
    from labrig.model.modal import DiscreteBank, run_bank

    run_bank(DiscreteBank.from_arrays([0.5], [0.0], [0.5], [1.0]), np.zeros(8))
    DynamicHysteresisModel(PAPER_TABLE1).stream(1000.0).process(np.zeros(8))
    records = _records(lambda v: 0.9 * v + 0.002 * v * v)
    for kind in ("bouc_wen", "sindy"):
        fit_baseline(records, kind, heldout=False)


def operator_and_fit() -> None:
    """The exact prediction (the operator and its interpolant), the Prandtl-Ishlinskii peer,
    then our model's fit with its sensitivities and the compiled effects: by then the other
    group has written the bank kernel, which the fit loads instead of compiling it again."""
    from labrig.analysis.baselines import fit_baseline
    from labrig.analysis.fit import fit_model
    from labrig.model import PAPER_TABLE1, DynamicHysteresisModel
    from labrig.model.effects.amplifier_bandwidth import charging_lowpass
    from labrig.model.effects.rate_hysteresis import rate_hysteresis_state
    from labrig.model.sections import foh_section, run_section

    records = _records(lambda v: 0.9 * v + 0.002 * v * v)
    v = np.tile(records[0].voltage_V, 6)  # past 2048 samples: the exact kernel's branch cut
    DynamicHysteresisModel(PAPER_TABLE1).predict(v, RATE, method="exact")
    fit_baseline(records, "prandtl_ishlinskii", heldout=False)
    fit_model(records, heldout=False)
    v = records[0].voltage_V
    charging_lowpass(v, 1e-3, 0.1, 100.0, RATE)
    rate_hysteresis_state(v, 0.1, 0.01, 0.1, RATE)
    run_section(foh_section([1.0], [1e-6, 1e-3, 1.0], RATE), v)


#: each kernel is compiled by one group only (both at once would each compile the operator and
#: the bank, about 7 s of CPU twice)
GROUPS = {"stream_and_peers": stream_and_peers, "operator_and_fit": operator_and_fit}

if __name__ == "__main__":
    GROUPS[sys.argv[1]]()
