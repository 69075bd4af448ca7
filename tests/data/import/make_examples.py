"""Make the tiny example files of docs/import.md, one per format, and a broken variant of each.

Run from the repository root: ``.venv/bin/python tests/data/import/make_examples.py``. The
signals come from :func:`signals` (tests import it to check what labrig reads); every file is
written with scipy, h5py or pandas, as a lab's software would write it. The broken variants
each carry one fault that ``labrig import`` must name (tests/importers/test_import_examples.py).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

import h5py
import numpy as np
from scipy.io import savemat

if TYPE_CHECKING:
    import pandas as pd

HERE = Path(__file__).resolve().parent
N = 64  # samples per record
RATE_HZ = 200.0
STACK_MM = 18.0  # the stack length of the examples whose strain sensor reads um


def signals(n: int = N, rate_hz: float = RATE_HZ) -> dict[str, np.ndarray]:
    """time (s), voltage (V), strain (ue), displacement (um over an 18 mm stack), temperature
    (degC): a 2 Hz drive around 50 V, a lagging strain, a slowly warming stack."""
    t = np.arange(n) / rate_hz
    v = 50.0 + 40.0 * np.sin(2 * np.pi * 2.0 * t)
    s = 9.0 * v + 40.0 * np.sin(2 * np.pi * 2.0 * t - 0.3)
    return {
        "time": t,
        "voltage": np.round(v, 4),
        "strain": np.round(s, 3),
        "displacement_um": np.round(s * STACK_MM * 1e-3, 5),
        "temperature": np.round(25.0 + 2.0 * t, 3),
    }


def _frame(cols: dict[str, np.ndarray]) -> pd.DataFrame:
    import pandas as pd  # on use: the import tests load this module, most never need pandas

    return pd.DataFrame(cols)


def text_examples() -> None:
    import pandas as pd

    sig = signals()
    t, v, s, d, temp = (sig[k] for k in ("time", "voltage", "strain", "displacement_um",
                                         "temperature"))  # fmt: skip
    full = {"time_s": t, "voltage_V": v, "strain_ue": s, "temperature_C": temp}
    _frame(full).to_csv(HERE / "header.csv", index=False)
    bad = _frame(full).astype(object)
    bad.iloc[20, 2] = "12.5.1"
    bad.to_csv(HERE / "header_bad.csv", index=False)

    index = pd.DataFrame({"": [""] * N, "t": t, "v": v, "s": s})
    index.to_csv(HERE / "headerless_index.csv", index=False, header=False)
    lines = (HERE / "headerless_index.csv").read_text().splitlines()
    lines[30] += ",7.5"  # one field too many
    (HERE / "headerless_index_bad.csv").write_text("\n".join(lines) + "\n")

    units = pd.DataFrame({"time": t, "voltage": v, "strain": d})
    text = "time,voltage,strain\ns,V,um\n" + units.to_csv(index=False, header=False)
    (HERE / "units_row.csv").write_text(text)
    lines = text.splitlines()
    lines[2 + 10] = "nan," + lines[2 + 10].split(",", 1)[1]  # NaN in the time column
    (HERE / "units_row_bad.csv").write_text("\n".join(lines) + "\n")

    semi = _frame({"time [s]": t, "voltage [V]": v, "strain [ue]": s})
    semi.to_csv(HERE / "semicolon_decimal_comma.csv", sep=";", decimal=",", index=False)
    lines = (HERE / "semicolon_decimal_comma.csv").read_text().splitlines()
    lines[40] = lines[40].rsplit(";", 1)[0] + ";1.234,5"  # thousands mark: not a number
    (HERE / "semicolon_decimal_comma_bad.csv").write_text("\n".join(lines) + "\n")

    german = _frame({"Zeit [s]": t, "Spannung [V]": v, "Dehnung [µm/m]": s,
                     "Temperatur [°C]": temp})  # fmt: skip
    german.to_csv(HERE / "cp1252.csv", sep=";", decimal=",", index=False, encoding="cp1252")
    german.iloc[25, 0] = german.iloc[24, 0]  # time stands still
    german.to_csv(HERE / "cp1252_bad.csv", sep=";", decimal=",", index=False, encoding="cp1252")

    frame = _frame({"time_s": t, "voltage_V": v, "strain_ue": s})
    frame.to_csv(HERE / "utf16.csv", sep="\t", index=False, encoding="utf-16")
    text = frame.to_csv(sep="\t", index=False, lineterminator="\n")
    (HERE / "utf16_bad.csv").write_bytes(text.rsplit("\t", 1)[0].encode("utf-16") + b"\n\x00")

    frame.to_csv(HERE / "bom.csv", index=False, encoding="utf-8-sig")
    (HERE / "bom_bad.csv").write_bytes("time_s,voltage_V,strain_ue\n".encode("utf-8-sig"))

    tab = pd.DataFrame({"": [""] * N, "t": t, "v": v, "s": s})
    tab.to_csv(HERE / "tab_empty_first.tsv", sep="\t", index=False, header=False)
    tab.loc[33, "t"] = t[33] + 0.4 / RATE_HZ  # a time step 40 % off
    tab.to_csv(HERE / "tab_empty_first_bad.tsv", sep="\t", index=False, header=False)


def _v73_header() -> bytes:
    text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 "
    text += b"HDF5 schema 1.00 ."
    return text.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM"


def write_v73(path: Path, variables: dict[str, np.ndarray]) -> None:
    """A MATLAB v7.3 file as MATLAB writes one: HDF5 after a 512-byte header, each array
    transposed (MATLAB is column-major) with its ``MATLAB_class``."""
    with h5py.File(path, "w", userblock_size=512, libver="earliest") as f:
        for name, a in variables.items():
            ds = f.create_dataset(name, data=np.atleast_2d(a), track_times=False)
            ds.attrs["MATLAB_class"] = np.bytes_("double")
    with path.open("r+b") as f:
        f.write(_v73_header().ljust(512, b"\x00"))


def _v73_text(group: h5py.Group, name: str, text: str) -> h5py.Dataset:
    ds = group.create_dataset(name, data=np.array([[ord(c)] for c in text], dtype=np.uint16))
    ds.attrs["MATLAB_class"] = np.bytes_("char")
    return ds


def _v73_value(f: h5py.File, group: h5py.Group, name: str, value: object) -> h5py.Dataset:
    if isinstance(value, str):
        return _v73_text(group, name, value)
    ds = group.create_dataset(name, data=np.atleast_2d(np.asarray(value, dtype=float)))
    ds.attrs["MATLAB_class"] = np.bytes_("double")
    return ds


def write_v73_capture(path: Path, name: str, x: dict, channels: list[dict]) -> None:
    """A ControlDesk capture saved as MATLAB v7.3: the struct ``name`` with ``X`` (a struct)
    and ``Y`` (a 1 x n struct array: each field a column of references into ``#refs#``)."""
    with h5py.File(path, "w", userblock_size=512, libver="earliest") as f:
        refs = f.create_group("#refs#")
        cap = f.create_group(name)
        cap.attrs["MATLAB_class"] = np.bytes_("struct")
        xg = cap.create_group("X")
        xg.attrs["MATLAB_class"] = np.bytes_("struct")
        for key, value in x.items():
            _v73_value(f, xg, key, value)
        yg = cap.create_group("Y")
        yg.attrs["MATLAB_class"] = np.bytes_("struct")
        for key in channels[0]:
            targets = [
                _v73_value(f, refs, f"{key}{i}", ch[key]).ref for i, ch in enumerate(channels)
            ]
            yg.create_dataset(key, data=np.array(targets, dtype=h5py.ref_dtype)[:, None])
    with path.open("r+b") as fh:
        fh.write(_v73_header().ljust(512, b"\x00"))


def _capture(n: int, rate_hz: float, shift: float, short_sensor: bool = False) -> dict:
    sig = signals(n, rate_hz)
    names = ("Model Root/Amplifier/Out1", "Model Root/Sensor/Out1", "Model Root/Thermo/Out1")
    units = ("V", "um", "degC")
    data = (sig["voltage"] + shift, sig["displacement_um"], sig["temperature"])
    y = np.zeros((1, 3), dtype=[("Name", "O"), ("Type", "O"), ("Data", "O"), ("Unit", "O"),
                                ("XIndex", "O")])  # fmt: skip
    for i, (name, unit, d) in enumerate(zip(names, units, data, strict=True)):
        d = d[: n - 14] if short_sensor and i == 1 else d
        y[0, i] = (name, "Data", d[None, :], unit, 1.0)
    x = np.zeros((1, 1), dtype=[("Name", "O"), ("Type", "O"), ("Data", "O"), ("Unit", "O")])
    x[0, 0] = ("Time", "Reference", sig["time"][None, :], "s")
    return {
        "X": x,
        "Y": y,
        "Description": {"General": {"Description": "ControlDesk MATLAB File Format Revision 2.0"}},
        "RTProgram": {"Name": "piezo_rig.sdf"},
        "Capture": {"SamplingPeriod": 1.0 / rate_hz},
    }


def mat_examples() -> None:
    sig = signals()
    t, v, s, temp = sig["time"], sig["voltage"], sig["strain"], sig["temperature"]
    col = {"time_s": t[:, None], "voltage_V": v[:, None], "strain_ue": s[:, None],
           "temperature_C": temp[:, None], "fs": RATE_HZ}  # fmt: skip
    savemat(HERE / "plain_v5.mat", col)
    savemat(HERE / "plain_v5_bad.mat", col | {"voltage_V": v[:-5, None]})

    rows = np.vstack([t, v, s])  # one signal per ROW, as a 3 x N matrix
    savemat(HERE / "rows_v5.mat", {"data": rows})
    rows_bad = rows.copy()
    rows_bad[1, 16] = np.nan
    savemat(HERE / "rows_v5_bad.mat", {"data": rows_bad})

    write_v73(HERE / "plain_v73.mat", {"t": t, "voltage": v, "strain": s})
    t_bad = t.copy()
    t_bad[5] = t_bad[4]
    write_v73(HERE / "plain_v73_bad.mat", {"t": t_bad, "voltage": v, "strain": s})

    two = {"capture_1": _capture(N, RATE_HZ, 0.0), "capture_2": _capture(N, RATE_HZ, 10.0)}
    savemat(HERE / "controldesk.mat", two)
    bad = {"capture_1": _capture(N, RATE_HZ, 0.0, short_sensor=True)}
    savemat(HERE / "controldesk_bad.mat", bad)

    x = {"Name": "Time", "Unit": "s", "Data": t}
    amp = {"Name": "Model Root/Amplifier/Out1", "Unit": "mV", "Data": 1000.0 * v, "XIndex": 1.0}
    gauge = {"Name": "Model Root/Gauge/Out1", "Unit": "ue", "Data": s, "XIndex": 1.0}
    write_v73_capture(HERE / "controldesk_v73.mat", "capture_1", x, [amp, gauge])
    gauge_bad = gauge | {"Data": np.where(np.arange(N) == 40, np.inf, s)}
    write_v73_capture(HERE / "controldesk_v73_bad.mat", "capture_1", x, [amp, gauge_bad])


def logical_example() -> None:
    """A v5 file with a logical variable whose name gives a unit (``enabled_V``, a relay's state
    sampled with the signals): MATLAB logical values are flags, not measurements, and are left
    out (scipy stores them as uint8 with a logical flag)."""
    sig = signals()
    enabled = (np.arange(N) % 16) < 12
    savemat(
        HERE / "logical_v5.mat",
        {"time_s": sig["time"][:, None], "voltage_V": sig["voltage"][:, None],
         "strain_ue": sig["strain"][:, None], "enabled_V": enabled[:, None]},
    )  # fmt: skip


if __name__ == "__main__":
    text_examples()
    mat_examples()
    logical_example()
    sys.stdout.write(f"wrote the examples to {HERE}\n")
