"""Reading a run file back: metadata and arrays, summaries, CSV export (layout:
:mod:`labrig.store`). Files from older labrig versions (without checksums or the records of how
a run ended) read the same; a chunk whose checksum fails is an input error naming the entry and
channel."""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from labrig.errors import InputFileError, InputIssue


@dataclass
class RunEntry:
    """One entry read back: arrays by channel name plus the entry's metadata."""

    name: str
    index: int
    title: str
    status: str
    reason: str
    start_time: str
    end_time: str
    rate_hz: float
    step: dict
    data: dict[str, np.ndarray]
    units: dict[str, str]
    long_names: dict[str, str]
    signal: str = "strain"
    #: True when the channels had different lengths (writer killed mid-block) and were trimmed
    trimmed: bool = False

    def __getitem__(self, channel_name: str) -> np.ndarray:
        return self.data[channel_name]

    @property
    def channels(self) -> list[str]:
        return list(self.data)

    @property
    def time(self) -> np.ndarray:
        return self.data["time"]

    @property
    def n_samples(self) -> int:
        return len(self.data["time"]) if "time" in self.data else 0

    @property
    def duration_s(self) -> float:
        t = self.data.get("time")
        return float(t[-1] - t[0]) if t is not None and len(t) > 1 else 0.0

    @property
    def complete(self) -> bool:
        return self.status == "complete"


@dataclass
class RunFile:
    """A run file read back (see :func:`read_run`)."""

    path: Path
    format_version: int
    creator_version: str
    file_time: str
    status: str
    reason: str
    start_time: str
    end_time: str
    seed: int | None
    software_version: str
    protocol_name: str
    protocol_text: str
    rig_text: str
    protocol_file: str
    rig_file: str
    instrument: dict
    planned_entries: list[str]
    entries: dict[str, RunEntry] = field(default_factory=dict)
    #: the exit code ``labrig run`` ended with (None: not recorded, an older or unfinished file)
    exit_code: int | None = None

    def __getitem__(self, name: str) -> RunEntry:
        return self.entries[name]

    def __iter__(self):
        return iter(self.entries.values())

    def __len__(self) -> int:
        return len(self.entries)

    @property
    def incomplete(self) -> bool:
        """True when the writer never finished the run (crash, kill, still running)."""
        return self.status == "running"


def _s(group: h5py.Group, name: str, default: str = "") -> str:
    if name not in group:
        return default
    v = group[name][()]
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


def _attr(obj, name: str, default=""):
    v = obj.attrs.get(name, default)
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.ndarray) and v.dtype.kind in "OSU":
        return [x.decode() if isinstance(x, bytes) else str(x) for x in v]
    return v


def _int_or_none(group: h5py.Group, name: str) -> int | None:
    try:
        return int(group[name][()]) if name in group else None
    except (TypeError, ValueError, OSError):
        return None


def _open(path: Path | str) -> h5py.File:
    p = Path(path)
    if not p.is_file():
        raise InputFileError([InputIssue(str(path), None, "", "run file not found")])
    try:
        return h5py.File(p, "r", locking=False)
    except OSError as e:
        raise InputFileError(
            [InputIssue(str(path), None, "", f"not a readable HDF5 run file ({e})")]
        ) from None


def _read_samples(path: Path | str, entry: str, name: str, ds: h5py.Dataset) -> np.ndarray:
    """A channel's samples; a chunk that fails its Fletcher32 checksum (or cannot be read) is
    an :class:`InputFileError` naming the entry and the channel."""
    try:
        return ds[()]
    except (OSError, RuntimeError) as e:
        text = str(e)
        if ds.fletcher32 and ("Fletcher32" in text or "filter" in text):
            why = "checksum mismatch: the stored samples are damaged"
        else:
            why = "unreadable: " + ((text.strip().splitlines() or [""])[0][:160])
        raise InputFileError([InputIssue(str(path), None, f"{entry}/data/{name}", why)]) from None


def _read_entry(path: Path | str, name: str, g: h5py.Group, load_data: bool) -> RunEntry:
    data_g = g.get("data")
    data: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    long_names: dict[str, str] = {}
    trimmed = False
    if isinstance(data_g, h5py.Group):
        for cname, ds in data_g.items():
            if not isinstance(ds, h5py.Dataset):
                continue
            units[cname] = str(_attr(ds, "units"))
            long_names[cname] = str(_attr(ds, "long_name"))
            data[cname] = _read_samples(path, name, cname, ds) if load_data else np.empty(ds.shape)
        if data:
            n = min(len(v) for v in data.values())
            if any(len(v) != n for v in data.values()):
                trimmed = True
                data = {k: v[:n] for k, v in data.items()}
    try:
        step = json.loads(_s(g, "step_definition", "{}"))
    except json.JSONDecodeError:
        step = {}
    rate = float(g["sample_rate"][()]) if "sample_rate" in g else float("nan")
    return RunEntry(
        name=name,
        index=int(g["entry_index"][()]) if "entry_index" in g else -1,
        title=_s(g, "title", name),
        status=_s(g, "status", "unknown"),
        reason=_s(g, "status_reason"),
        start_time=_s(g, "start_time"),
        end_time=_s(g, "end_time"),
        rate_hz=rate,
        step=step,
        data=data,
        units=units,
        long_names=long_names,
        signal=str(_attr(data_g, "signal", "strain")) if data_g is not None else "strain",
        trimmed=trimmed,
    )


def read_run(path: Path | str, load_data: bool = True) -> RunFile:
    """Read a run file: metadata, and every entry's arrays (in run order).

    ``load_data=False`` reads metadata only (arrays are left empty of the right shape).
    A file that is not a labrig run file raises :class:`InputFileError`.
    """
    with _open(path) as f:
        if _attr(f, "creator") != "labrig" or "run" not in f:
            raise InputFileError(
                [InputIssue(str(path), None, "", "not a labrig run file (no /run group)")]
            )
        run = f["run"]
        try:
            instrument = json.loads(_s(run["instrument"], "description_json", "{}"))
        except (KeyError, json.JSONDecodeError):
            instrument = {}
        try:
            planned = json.loads(_s(run, "planned_entries", "[]"))
        except json.JSONDecodeError:
            planned = []
        seed = int(run["seed"][()]) if "seed" in run else -1
        out = RunFile(
            path=Path(path),
            format_version=int(_attr(f, "labrig_format", 0)),
            creator_version=str(_attr(f, "creator_version")),
            file_time=str(_attr(f, "file_time")),
            status=_s(run, "status", "unknown"),
            reason=_s(run, "status_reason"),
            start_time=_s(run, "start_time"),
            end_time=_s(run, "end_time"),
            seed=None if seed < 0 else seed,
            software_version=_s(run, "software_version"),
            protocol_name=_s(run, "protocol_name"),
            protocol_text=_s(run["protocol"], "data") if "protocol" in run else "",
            rig_text=_s(run["rig"], "data") if "rig" in run else "",
            protocol_file=_s(run["protocol"], "file_name") if "protocol" in run else "",
            rig_file=_s(run["rig"], "file_name") if "rig" in run else "",
            instrument=instrument,
            planned_entries=list(planned),
            exit_code=_int_or_none(run, "exit_code"),
        )
        entries = []
        for name, g in f.items():
            if name == "run" or not isinstance(g, h5py.Group):
                continue
            if _attr(g, "NX_class") != "NXentry":
                continue
            entries.append(_read_entry(path, name, g, load_data))
        entries.sort(key=lambda e: e.index)
        out.entries = {e.name: e for e in entries}
    return out


def run_summary(path: Path | str) -> dict:
    """JSON-able summary of a run: status, seed, and per entry status, samples, duration,
    rate and the largest command voltage, amplifier voltage and strain."""
    run = read_run(path)

    def mx(e: RunEntry, k: str) -> float | None:
        v = e.data.get(k)
        return float(np.max(v)) if v is not None and len(v) else None

    return {
        "path": str(run.path),
        "protocol": run.protocol_name,
        "status": run.status,
        "reason": run.reason,
        "incomplete": run.incomplete,
        "start_time": run.start_time,
        "end_time": run.end_time,
        "seed": run.seed,
        "software_version": run.software_version,
        "planned_entries": len(run.planned_entries),
        "entries": [
            {
                "name": e.name,
                "status": e.status,
                "reason": e.reason,
                "samples": e.n_samples,
                "duration_s": e.duration_s,
                "rate_hz": e.rate_hz,
                "max_command_voltage_V": mx(e, "command_voltage"),
                "max_amplifier_voltage_V": mx(e, "amplifier_voltage"),
                "max_strain_ue": mx(e, "strain"),
                "channels": e.channels,
            }
            for e in run
        ],
    }


def run_info(path: Path | str):
    """A rich renderable summarising a run file (for ``labrig info RUN``)."""
    from rich.console import Group
    from rich.table import Table
    from rich.text import Text

    s = run_summary(path)
    status = s["status"]
    if s["incomplete"]:
        status += " (incomplete: the writer stopped without finishing the run)"
    elif s["reason"]:
        status += f" ({s['reason']})"
    planned = s["planned_entries"]
    n = len(s["entries"])
    head = Text.assemble(
        ("run file ", "bold"),
        s["path"],
        "\nprotocol: ",
        s["protocol"] or "-",
        "\nstatus: ",
        (status, "green" if s["status"] == "complete" else "red"),
        f"\nentries: {n}" + (f" of {planned} planned" if planned else ""),
        f"\nstarted {s['start_time'] or '-'}, ended {s['end_time'] or '-'}",
        f"\nseed {s['seed'] if s['seed'] is not None else '-'}, "
        f"labrig {s['software_version'] or '-'}",
    )
    t = Table(
        caption="s: duration; Hz: sample rate; max V: largest command voltage; "
        "max ue: largest strain"
    )
    t.add_column("entry", no_wrap=True)
    t.add_column("status")
    for col in ("samples", "s", "Hz", "max V", "max ue"):
        t.add_column(col, justify="right")

    def g(x, spec=".1f"):
        return "-" if x is None else format(x, spec)

    for e in s["entries"]:
        st = e["status"] + (f": {e['reason']}" if e["reason"] else "")
        t.add_row(
            e["name"],
            st,
            str(e["samples"]),
            g(e["duration_s"], ".3f"),
            g(e["rate_hz"], "g"),
            g(e["max_command_voltage_V"]),
            g(e["max_strain_ue"]),
        )
    return Group(head, t)


def _col_header(name: str, units: str) -> str:
    u = re.sub(r"[^A-Za-z0-9]+", "", units or "")
    return f"{name}_{u}" if u else name


def export_csv(path: Path | str, out_dir: Path | str) -> list[Path]:
    """Write one CSV per entry (``<out_dir>/<entry>.csv``); returns the paths written.

    The header line names the columns with their units, e.g. ``time_s,command_voltage_V,
    amplifier_voltage_V,gauge_raw_V,strain_ue``; values use up to 10 significant digits.
    """
    run = read_run(path)
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputFileError(
            [InputIssue(str(out), None, "--csv", f"cannot create directory: {e.strerror}")]
        ) from None
    written = []
    for e in run:
        p = out / f"{e.name}.csv"
        cols = e.channels
        header = [_col_header(c, e.units.get(c, "")) for c in cols]
        table = np.column_stack([e.data[c] for c in cols]) if cols else np.empty((0, 0))
        np.savetxt(p, table, fmt="%.10g", delimiter=",", header=",".join(header), comments="")
        written.append(p)
    return written
