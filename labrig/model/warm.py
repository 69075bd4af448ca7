"""Load the compiled kernels of a streaming simulation before it is needed."""

from __future__ import annotations

import functools

from labrig.model.accel import kernels


@functools.cache
def warm() -> bool:
    """Load the compiled kernels a streaming simulation uses (numba's import and each kernel's
    cached machine code, once per process) now, not on the
    first block: a simulator that answers its instruments' queries within a timeout must not
    pause for it mid-dialogue. Returns whether the kernels are compiled.

    Returns
    -------
    bool
        Whether the kernels are compiled (``False``: numba is missing, the numpy code runs).
    """
    import numpy as np

    from labrig.model.dynamic import DynamicHysteresisModel
    from labrig.model.modal import DiscreteBank, run_bank
    from labrig.model.params import PAPER_TABLE1

    if kernels() is None:
        return False
    model = DynamicHysteresisModel(PAPER_TABLE1)
    model.stream(1000.0).process(np.zeros(8))
    model.operator.apply(np.zeros(8))
    # a bank run on its own: the simulated amplifier's average current is one such mode
    run_bank(DiscreteBank.from_arrays([0.5], [0.0], [0.5], [1.0]), np.zeros(8))
    return True
