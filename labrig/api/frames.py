"""Run-file entries as tables: pandas DataFrames and xarray Datasets (for
:class:`labrig.api.runs.Run`).

Column and variable names carry their units the way ``labrig export`` headers do
(``time_s``, ``command_voltage_V``, ``strain_ue``); the units and long names are also kept as
metadata (``DataFrame.attrs``, each xarray variable's ``attrs``).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr

    from labrig.store import RunEntry

XARRAY_MISSING = (
    "Run.to_xarray needs xarray, an optional package: pip install 'labrig[xarray]' "
    "(Run.to_pandas works without it)"
)


def column_name(channel: str, units: str) -> str:
    """``strain`` in ``ue`` -> ``strain_ue``; a channel without units keeps its name.

    Parameters
    ----------
    channel : str
        The channel's name.
    units : str
        Its unit (characters other than letters and digits dropped).

    Returns
    -------
    str
        The column's name.

    Examples
    --------
    >>> column_name("strain", "ue")
    'strain_ue'
    >>> column_name("command_voltage", "V")
    'command_voltage_V'
    >>> column_name("index", "")
    'index'
    """
    u = re.sub(r"[^A-Za-z0-9]+", "", units or "")
    return f"{channel}_{u}" if u else channel


def step_values(e: RunEntry) -> dict[str, Any]:
    """The scalar keys of an entry's step definition (``kind``, ``amplitude_V``,
    ``frequency_hz``, ``cycles``, ``rest_after_s``...; their units are in their names).

    Parameters
    ----------
    e : labrig.store.RunEntry
        An entry of a run file.

    Returns
    -------
    dict
        Key -> scalar value (str, int, float or bool).
    """
    return {
        k: v
        for k, v in e.step.items()
        if isinstance(v, str | int | float | bool) and not isinstance(v, np.ndarray)
    }


def entries_frame(entries: Sequence[RunEntry], attrs: Mapping[str, Any]) -> pd.DataFrame:
    """One row per sample of every entry, in run order: an ``entry`` column (categorical, in
    run order), one column per channel named with its unit (channels an entry lacks are NaN),
    then the entry's step definition, one column per scalar key (:func:`step_values`: ``kind``,
    ``amplitude_V``, ``frequency_hz``..., missing where an entry's step lacks the key; a key
    that is also a channel's column keeps the channel). ``attrs``: ``units`` and
    ``long_names`` by column, plus ``attrs`` given.

    Parameters
    ----------
    entries : sequence of labrig.store.RunEntry
        The entries, with their samples.
    attrs : mapping
        Copied into ``DataFrame.attrs``.

    Returns
    -------
    pandas.DataFrame
        The samples.
    """
    import pandas as pd

    frames, units, long_names = [], {"entry": ""}, {"entry": "entry name"}
    for e in entries:
        columns: dict[str, Any] = {"entry": np.full(e.n_samples, e.name, dtype=object)}
        for c in e.channels:
            name = column_name(c, e.units.get(c, ""))
            columns[name] = np.asarray(e.data[c][: e.n_samples], dtype=float)
            units[name] = e.units.get(c, "")
            long_names[name] = e.long_names.get(c, "")
        for key, value in step_values(e).items():
            if key not in columns:
                columns[key] = np.full(e.n_samples, value, dtype=object)
                long_names.setdefault(key, "step definition")
        frames.append(pd.DataFrame(columns))
    names = [e.name for e in entries]
    df = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame({"entry": []})
    df["entry"] = pd.Categorical(df["entry"], categories=names, ordered=True)
    channels = {n for n in units if n != "entry"}
    for col in df.columns:
        if col != "entry" and col not in channels:  # a step key: numbers as numbers
            df[col] = df[col].infer_objects()
    df.attrs.update(dict(attrs))
    df.attrs["units"] = units
    df.attrs["long_names"] = long_names
    return df


def _step_coordinate(entries: Sequence[RunEntry], key: str) -> np.ndarray | None:
    """A step key's value per entry (NaN where an entry lacks it); ``None`` when no entry has
    a number for it."""
    values = [e.step.get(key) for e in entries]
    if not any(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
        return None
    return np.array(
        [
            float(v) if isinstance(v, int | float) and not isinstance(v, bool) else np.nan
            for v in values
        ]
    )


def entries_dataset(entries: Sequence[RunEntry], attrs: Mapping[str, Any]) -> xr.Dataset:
    """The entries as one Dataset with dimensions ``entry`` and ``sample``: each channel a
    variable (NaN past an entry's last sample), ``time`` (s) a coordinate of both, and per
    entry ``n_samples``, ``rate_hz``, ``kind``, ``amplitude_V``, ``frequency_hz``.

    Parameters
    ----------
    entries : sequence of labrig.store.RunEntry
        The entries, with their samples.
    attrs : mapping
        The Dataset's attrs.

    Returns
    -------
    xarray.Dataset
        The samples.
    """
    try:
        import xarray as xr
    except ImportError:
        raise ImportError(XARRAY_MISSING) from None
    n = max((e.n_samples for e in entries), default=0)
    channels = list(dict.fromkeys(c for e in entries for c in e.channels))
    grids = {c: np.full((len(entries), n), np.nan) for c in channels}
    units: dict[str, str] = {}
    long_names: dict[str, str] = {}
    for i, e in enumerate(entries):
        for c in e.channels:
            grids[c][i, : e.n_samples] = e.data[c][: e.n_samples]
            units.setdefault(c, e.units.get(c, ""))
            long_names.setdefault(c, e.long_names.get(c, ""))
    coords: dict[str, Any] = {
        "entry": [e.name for e in entries],
        "n_samples": ("entry", [e.n_samples for e in entries]),
        "rate_hz": ("entry", [e.rate_hz for e in entries], {"units": "Hz"}),
        "kind": ("entry", [str(e.step.get("kind", "")) for e in entries]),
    }
    for key, unit in (("amplitude_V", "V"), ("frequency_hz", "Hz")):
        values = _step_coordinate(entries, key)
        if values is not None:
            coords[key] = ("entry", values, {"units": unit})
    if "time" in grids:
        t = grids.pop("time")
        coords["time"] = (("entry", "sample"), t, {"units": "s", "long_name": long_names["time"]})
    variables = {
        c: (("entry", "sample"), g, {"units": units[c], "long_name": long_names[c]})
        for c, g in grids.items()
    }
    return xr.Dataset(variables, coords=coords, attrs=dict(attrs))
