"""A simulated stand-in for the whole SmartHysteresis file: 10 s at 5 kHz, idle, then the drive.

The file it stands in for (which labrig does not have: only two of its periods, every fifth row,
are kept in ``tests/data/real/chandratue-SmartHysteresis/``): another lab's piezo stack, bipolar
+-150 V at 1 Hz, about 50 000 rows at 5 kHz over 10 s, idle at 0 V for the first 7.36 s, then
the drive ``150 sin(2 pi t - 46.2178545458)`` V for the remaining 2.64 periods, written as
headerless CSV whose rows are ``,time s,displacement um,voltage V``.

**What it is.** A simulation, not a measurement: the same time base and drive, and a
displacement computed by a model identified on the two kept periods, plus white noise.

- The model (:data:`TRUTH_XI`, over the library of :mod:`labrig.analysis.sindy`): the
  six-term sparse ODE of Duhem form that ``labrig diagnose`` identifies on the kept 2 periods at
  1 kHz (2026-11-27, :func:`labrig.analysis.diagnose.sparse_ode.identify` in its first form,
  coefficients rounded to four significant digits; today's ``diagnose`` adopts the same terms
  with coefficients within 0.3 % of these)

      dS/dt = -0.2088 S + 0.07620 V + 0.1302 V' - 6.968e-4 V' S + 9.024e-5 V' V
              + 1.196e-3 |V'| S

  (S in um, V in V, t in s, ``V' = dV/dt``), run free from rest at 0 V
  (:func:`labrig.analysis.sindy.free_run`: exact for this equation with the voltage linear
  between samples), plus :data:`OFFSET_UM` (the kept record's mean offset from it). Started
  from rest at the kept window's first sample it follows the kept record within 0.066 um RMS;
  started, as here, where the file's drive starts (0.41 s earlier) it is off by about 10 um and
  its two periods differ by 4.1 um RMS (the real ones by 0.071 um): this ODE **grows under its
  own drive** (a disturbance as ``exp(0.53 t)``), which is why ``diagnose`` refuses it on the
  real record since 2026-11-27. Being in the sparse ODE's own library, the stand-in tests the
  identification's handling of the rate, the noise and the idle stretch, not whether the
  library suffices, nor what the real file would give.
- Noise: white, Gaussian, :data:`NOISE_UM` RMS per sample (the kept record's two periods differ
  by 0.0714 um RMS: ``sqrt 2`` times this), independent per row at 5 kHz (the real sensor's
  noise between its 1 kHz rows is not known).
- Time stamps ``k / 5000`` s printed with eight decimals, the displacement and the voltage with
  six (the authors' format; their stamps carry a jitter of 1e-8 s, these do not).

``python -m labrig.studies.smart_standin OUT.csv [--seed N] [--rate-hz R] [--overwrite]``
writes it and prints the commands that import and diagnose it.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from labrig.analysis.sindy import free_run

__all__ = [
    "DRIVE_PHASE_RAD",
    "DURATION_S",
    "NOISE_UM",
    "OFFSET_UM",
    "RATE_HZ",
    "TRUTH_XI",
    "drive_on_s",
    "standin_rows",
    "write_standin",
]

#: the file's sample rate (Hz) and length (s)
RATE_HZ = 5000.0
DURATION_S = 10.0
#: the drive ``150 sin(2 pi t - DRIVE_PHASE_RAD)`` V (1 Hz), from the time its phase is 0
DRIVE_PHASE_RAD = 46.2178545458
AMPLITUDE_V = 150.0
#: the truth's coefficients per :data:`~labrig.analysis.sindy.LIBRARY` term (module docstring)
TRUTH_XI: tuple[float, ...] = (
    0.0,
    -0.2088,
    0.07620,
    0.1302,
    0.0,
    -6.968e-4,
    9.024e-5,
    1.196e-3,
    0.0,
    0.0,
)
#: the kept record's mean displacement less the truth's free run (um)
OFFSET_UM = 1.550
#: white sensor noise per sample (um RMS)
NOISE_UM = 0.0505


def drive_on_s() -> float:
    """When the drive starts (s): the first time its phase ``2 pi t - DRIVE_PHASE_RAD`` is a
    whole number of periods at or after 0, 7.3558 s."""
    return DRIVE_PHASE_RAD / (2.0 * math.pi)


def standin_rows(
    seed: int = 1, rate_hz: float = RATE_HZ, duration_s: float = DURATION_S
) -> NDArray[np.float64]:
    """The stand-in's rows ``(time s, displacement um, voltage V)`` at ``rate_hz`` over
    ``duration_s`` (module docstring), noise drawn with ``seed``."""
    t = np.arange(round(duration_s * rate_hz)) / float(rate_hz)
    v = np.where(t >= drive_on_s(), AMPLITUDE_V * np.sin(2.0 * math.pi * t - DRIVE_PHASE_RAD), 0.0)
    s = free_run(TRUTH_XI, v, rate_hz, 0.0) + OFFSET_UM
    s = s + np.random.default_rng(seed).normal(0.0, NOISE_UM, t.size)
    return np.column_stack([t, s, v])


def write_standin(
    path: Path | str,
    seed: int = 1,
    *,
    rate_hz: float = RATE_HZ,
    overwrite: bool = False,
) -> Path:
    """Write :func:`standin_rows` to ``path`` as the authors' headerless CSV (each row: an
    empty field, time, displacement, voltage). An existing file is replaced only with
    ``overwrite`` (written beside, then renamed)."""
    from labrig.core.outputs import check_writable, write_text_output

    out = Path(path)
    check_writable([out], inputs=[], overwrite=overwrite)
    rows = standin_rows(seed, rate_hz)
    text = "".join(f",{t:.8f},{s:.6f},{v:.6f}\n" for t, s, v in rows.tolist())
    write_text_output(out, text, overwrite=overwrite)
    return out


def _commands(path: Path) -> list[str]:
    """The commands that import the stand-in as PROVENANCE.md says and diagnose it."""
    h5 = path.with_suffix(".h5")
    return [
        f"labrig import {path} --time 2 --voltage 4 --strain 3 --strain-units raw --out {h5}",
        f"labrig diagnose {h5} --out {path.with_suffix('')}_diagnosis",
    ]


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m labrig.studies.smart_standin OUT.csv [--seed N] [--rate-hz R]
    [--overwrite]``."""
    ap = argparse.ArgumentParser(prog="python -m labrig.studies.smart_standin", description=__doc__)
    ap.add_argument("out", type=Path)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--rate-hz", type=float, default=RATE_HZ)
    ap.add_argument("--overwrite", action="store_true")
    a = ap.parse_args(argv)
    if not 10.0 <= a.rate_hz <= 1e6:  # below 10 Hz the 1 Hz drive is not sampled
        ap.error(f"--rate-hz must be in [10, 1e6] Hz (the drive is 1 Hz), got {a.rate_hz}")
    from labrig.core.errors import LabrigError

    try:
        path = write_standin(a.out, a.seed, rate_hz=a.rate_hz, overwrite=a.overwrite)
    except LabrigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(path)
    print("\n".join(_commands(path)))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
