"""The Python API at the package top (docs/python-api.md): ``labrig.open``, ``labrig.run``,
``labrig.runs`` and :class:`Run`.

Every function calls the library the command line calls (the runner, the store, the analysis,
the report, the catalogue), so a result here is the result of the matching command:
:func:`as_json` of ``Run.fit()``, ``Run.report()`` and ``Run.diagnose()`` is what
``labrig fit --json``, ``labrig report --json`` and ``labrig diagnose --json`` print. Imports of
the numerical stack happen on first use, so ``import labrig`` stays light.
"""

from __future__ import annotations

import html
import os
import sys
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from labrig.core.words import plural

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr

    from labrig.analysis.baselines import BaselineResult
    from labrig.analysis.diagnose import Diagnosis
    from labrig.analysis.fit import FitResult
    from labrig.analysis.fit_effects import EffectsFit
    from labrig.analysis.records import Record
    from labrig.commands.fit import CommandUI
    from labrig.commands.report import BuiltReport
    from labrig.runner.execute import ProgressFn
    from labrig.store import RunEntry, RunFile

PathLike = str | os.PathLike[str]
#: the most entries ``repr`` and ``_repr_html_`` list one by one
REPR_ENTRIES = 8
HTML_ENTRIES = 20
#: the longest line ``repr`` writes (characters)
REPR_WIDTH = 100

__all__ = ["EntryInfo", "Run", "as_json", "open", "run", "runs"]


@dataclass(frozen=True)
class EntryInfo:
    """One entry of a run without its samples: name, position, step kind and definition,
    status, sample rate (Hz), number of samples, duration (s, ``(samples - 1) / rate``).

    Parameters
    ----------
    name : str
        The entry's name (``sine_100V_1Hz``).
    index : int
        Its position in the run, from 0.
    title : str
        Its title (the step's description).
    kind : str
        The step kind (``sine``, ``offset_sine``, ``ramp``...).
    status : str
        ``complete``, ``aborted``, ``failed`` or ``running``.
    reason : str
        Why it ended early (``""`` when complete).
    rate_hz : float
        Sample rate (Hz).
    samples : int
        Number of samples recorded.
    duration_s : float
        ``(samples - 1) / rate_hz`` (s), 0 for fewer than two samples.
    start_time : str
        When it began (ISO 8601, ``""`` when unknown).
    step : dict
        The step definition, keys with their units in their names.
    units : dict
        Each channel's unit.
    """

    name: str
    index: int
    title: str
    kind: str
    status: str
    reason: str
    rate_hz: float
    samples: int
    duration_s: float
    start_time: str
    step: dict[str, Any] = field(repr=False)
    units: dict[str, str] = field(repr=False)


def _when(text: str) -> datetime | None:
    try:
        return datetime.fromisoformat(text) if text else None
    except ValueError:
        return None


def _entry_info(e: RunEntry) -> EntryInfo:
    n = next(iter(e.data.values())).shape[0] if e.data else 0
    rate = e.rate_hz
    return EntryInfo(
        name=e.name,
        index=e.index,
        title=e.title,
        kind=str(e.step.get("kind", "")),
        status=e.status,
        reason=e.reason,
        rate_hz=rate,
        samples=int(n),
        duration_s=(n - 1) / rate if n > 1 and rate > 0 else 0.0,
        start_time=e.start_time,
        step=dict(e.step),
        units=dict(e.units),
    )


class Run:
    """A run file opened by :func:`open` (or written by :func:`run`).

    The metadata is read at once; the samples on first use (``run["sine_100V_1Hz"]``,
    :meth:`to_pandas`, :meth:`to_xarray`) and kept. ``metadata`` holds whatever the file
    records beyond the fixed fields, keyed by path below ``/run`` or below the entries
    (``instrument/amplifier/identity``, ``sample/name``), as ``labrig runs`` indexes it.

    Parameters
    ----------
    path : pathlib.Path
        The run file.
    header : labrig.store.RunFile
        The file's metadata as the store read it (entries without their samples).
    metadata : dict
        The recorded metadata beyond the fixed fields, by path.
    units : dict
        The units of those metadata values that have one.

    See Also
    --------
    open : Open a run file.
    run : Run a protocol and open its file.
    """

    def __init__(
        self, path: Path, header: RunFile, metadata: dict[str, Any], units: dict[str, str]
    ):
        self.path = path
        self._header = header
        self._full: RunFile | None = None
        self.metadata = metadata
        #: units of the metadata values that have one
        self.metadata_units = units
        self.entries: dict[str, EntryInfo] = {e.name: _entry_info(e) for e in header}

    # -- what the run is ------------------------------------------------------------------
    @property
    def status(self) -> str:
        """``complete``, ``aborted``, ``failed`` or ``running`` (the writer never finished)."""
        return self._header.status

    @property
    def reason(self) -> str:
        return self._header.reason

    @property
    def incomplete(self) -> bool:
        return self._header.incomplete

    @property
    def protocol(self) -> str:
        """The protocol's name (its text: :attr:`protocol_text`)."""
        return self._header.protocol_name

    @property
    def protocol_text(self) -> str:
        return self._header.protocol_text

    @property
    def rig(self) -> str:
        """The rig file run on (``""``: the built-in simulated rig; its text: :attr:`rig_text`)."""
        return self._header.rig_file

    @property
    def rig_text(self) -> str:
        return self._header.rig_text

    @property
    def seed(self) -> int | None:
        return self._header.seed

    @property
    def instrument(self) -> dict[str, Any]:
        """The rig's description: every device's identity and settings."""
        return self._header.instrument

    @property
    def start_time(self) -> datetime | None:
        return _when(self._header.start_time)

    @property
    def end_time(self) -> datetime | None:
        return _when(self._header.end_time)

    # -- samples --------------------------------------------------------------------------
    @property
    def file(self) -> RunFile:
        """The whole file as the store reads it (every entry's arrays), read once."""
        if self._full is None:
            from labrig.store import read_run

            self._full = read_run(self.path)
        return self._full

    def __getitem__(self, name: str) -> RunEntry:
        """An entry with its arrays (``run[name]["strain"]``, ``.time``, ``.units``)."""
        if name not in self.entries:
            raise KeyError(f"{name!r}: not an entry of {self.path} (entries: {list(self.entries)})")
        return self.file[name]

    def __len__(self) -> int:
        return len(self.entries)

    def __enter__(self) -> Run:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Let go of the samples read (the file itself is never held open: every read is made
        and closed in a child process). ``with labrig.open(path) as run:`` calls it at the
        end; the run's metadata stays usable, the samples are read again if asked for."""
        self._full = None

    def records(self, entries: Sequence[str] | str | None = None) -> list[Record]:
        """The entries as the analysis sees them (:class:`~labrig.analysis.records.Record`:
        voltage, strain, auxiliary channels, step definition): the complete ones with voltage
        and strain, or ``entries`` by name. What ``fit(...).predict(run)`` simulates.

        Parameters
        ----------
        entries : str or sequence of str, optional
            Entry names (default: every complete entry with voltage and strain).

        Returns
        -------
        list of labrig.analysis.records.Record
            One record per entry, in run order.
        """
        from labrig.analysis.load import records_of

        names = [entries] if isinstance(entries, str) else (list(entries) if entries else None)
        return records_of(self.file, self.path, names)

    def __contains__(self, name: object) -> bool:
        return name in self.entries

    def _chosen(self, entries: Sequence[str] | str | None) -> list[RunEntry]:
        names = [entries] if isinstance(entries, str) else list(entries or self.entries)
        return [self[n] for n in names]

    def _attrs(self) -> dict[str, Any]:
        return {
            "path": str(self.path),
            "status": self.status,
            "protocol": self.protocol,
            "start_time": self._header.start_time,
        }

    def to_pandas(self, entries: Sequence[str] | str | None = None) -> pd.DataFrame:
        """The samples of ``entries`` (default: all, in run order) as one DataFrame: an
        ``entry`` column, one column per channel named with its unit (``time_s``,
        ``command_voltage_V``, ``strain_ue``), then the entry's step definition (``kind``,
        ``amplitude_V``, ``frequency_hz``...; :func:`labrig.api.frames.step_values`);
        ``df.attrs["units"]`` and ``df.attrs["long_names"]`` by column. One entry:
        ``df[df.entry == name]``.

        Parameters
        ----------
        entries : str or sequence of str, optional
            Entry names (default: all, in run order).

        Returns
        -------
        pandas.DataFrame
            One row per sample of every entry chosen.
        """
        from labrig.api.frames import entries_frame

        return entries_frame(self._chosen(entries), self._attrs())

    def to_xarray(self, entries: Sequence[str] | str | None = None) -> xr.Dataset:
        """The samples as an xarray Dataset with dimensions ``entry`` and ``sample`` (shorter
        entries padded with NaN), units in each variable's attrs. Needs xarray
        (``pip install 'labrig[xarray]'``): without it, an ImportError that says so.

        Parameters
        ----------
        entries : str or sequence of str, optional
            Entry names (default: all, in run order).

        Returns
        -------
        xarray.Dataset
            Dimensions ``entry`` and ``sample``.
        """
        from labrig.api.frames import entries_dataset

        return entries_dataset(self._chosen(entries), self._attrs())

    # -- analysis -------------------------------------------------------------------------
    def fit(
        self,
        entries: Sequence[str] | None = None,
        *,
        method: str = "global",
        model: str = "dynamic",
        memory: str = "return_point",
        effects: Sequence[str] = (),
        warmup_s: float | None = None,
        heldout: bool = True,
        offset: bool | None = None,
        progress: bool = False,
    ) -> FitResult | BaselineResult | EffectsFit:
        """``labrig fit``: identify the model (or the baseline ``model``) from the run; the
        options are the command's. ``as_json(result)`` is what ``labrig fit --json`` prints;
        ``result.params`` the parameters (our model).

        Parameters
        ----------
        entries : sequence of str, optional
            The entries fitted and scored (default: the command's choice).
        method : str
            ``global`` or ``staged`` (``labrig fit --method``).
        model : str
            ``dynamic`` (our model) or a baseline (``prandtl_ishlinskii``, ``bouc_wen``, ``sindy``).
        memory : str
            The operator's memory rule (``return_point``, ``return_point_open``,
            ``last_reversal``).
        effects : sequence of str
            Library effects added to our model (``labrig fit --effect``).
        warmup_s : float, optional
            Start of each entry left out of the score (s).
        heldout : bool
            Also score each entry by leave-one-entry-out refits.
        offset : bool, optional
            Fit one strain offset per entry (default: the command's choice).
        progress : bool
            Show progress bars on stderr.

        Returns
        -------
        FitResult or BaselineResult or EffectsFit
            The fit, as ``labrig fit`` makes it.
        """
        from labrig.commands.fit import fit_run_file

        outcome = fit_run_file(
            self.path,
            entries=list(entries) if entries else None,
            method=method,
            model=model,
            memory=memory,
            effects=list(effects),
            warmup_s=warmup_s,
            heldout=heldout,
            offset=offset,
            ui=command_ui(progress),
        )
        return outcome.result

    def report(
        self,
        out: PathLike | None = None,
        *,
        params: PathLike | None = None,
        entries: Sequence[str] | None = None,
        method: str = "global",
        warmup_s: float | None = None,
        heldout: bool = True,
        offset: bool | None = None,
        overwrite: bool = False,
        progress: bool = False,
        peers: Sequence[str] | None = None,
    ) -> BuiltReport:
        """``labrig report``: model versus measurement. Returns the report (``.page``, the
        HTML; ``.metrics``, what ``labrig report --json`` prints) and writes the page to
        ``out`` when given (an existing file only with ``overwrite``).

        Parameters
        ----------
        out : str or os.PathLike, optional
            Where to write the page (nothing written without it).
        params : str or os.PathLike, optional
            A ``labrig fit --out`` file whose parameters are reported (default: fitted now).
        entries : sequence of str, optional
            The entries fitted and shown.
        method : str
            ``global`` or ``staged``.
        warmup_s : float, optional
            Start of each entry left out of the metrics (s).
        heldout : bool
            Also score each entry by leave-one-entry-out refits.
        offset : bool, optional
            Fit one strain offset per entry.
        overwrite : bool
            Replace an existing ``out``.
        progress : bool
            Show progress bars on stderr.
        peers : sequence of str
            The baselines fitted beside our model (``labrig report --peers``; default: all,
            empty: none).

        Returns
        -------
        labrig.commands.report.BuiltReport
            The page and its metrics.
        """
        from labrig.commands.report import build_run_report

        target = Path(out) if out is not None else None
        params_path = Path(params) if params is not None else None
        if target is not None:
            _check_targets([target], [self.path, params_path], overwrite)
        built = build_run_report(
            self.path,
            params_path,
            entries=list(entries) if entries else None,
            warmup_s=warmup_s,
            offset=offset,
            method=method,
            heldout=heldout,
            ui=command_ui(progress),
            peers=peers,
        )
        if target is not None:
            from labrig.core.outputs import write_text_output
            from labrig.store.reader import being_written

            write_text_output(target, built.page, overwrite=overwrite, being_written=being_written)
        return built

    def diagnose(
        self,
        *,
        params: PathLike | None = None,
        also: Sequence[str] = (),
        max_effects: int = 2,
        mains_hz: float | None = None,
        out: PathLike | None = None,
        overwrite: bool = False,
        progress: bool = False,
    ) -> Diagnosis:
        """``labrig diagnose``: what the model misses. ``as_json(result)`` is what
        ``labrig diagnose --json`` prints; ``result.verdict`` the verdict in words.
        ``mains_hz``: the mains frequency (Hz; default: detected at 50 or 60 Hz). ``out``: a
        folder for ``diagnosis.json`` and ``diagnosis.html`` (existing ones replaced only with
        ``overwrite``; checked before the work, written beside and renamed into place).

        Parameters
        ----------
        params : str or os.PathLike, optional
            A ``labrig fit --out`` file to start from (default: fitted now).
        also : sequence of str
            Effects tried beside the default candidates.
        max_effects : int
            The most effects the verdict adds.
        mains_hz : float, optional
            The mains frequency (Hz).
        out : str or os.PathLike, optional
            A folder for ``diagnosis.json`` and ``diagnosis.html``.
        overwrite : bool
            Replace existing outputs in ``out``.
        progress : bool
            Show progress on stderr.

        Returns
        -------
        labrig.analysis.diagnose.Diagnosis
            The evidence, the candidates tried and the verdict.
        """
        from labrig.commands.diagnose import OUTPUT_NAMES, diagnose_run_file

        folder = Path(out) if out is not None else None
        params_path = Path(params) if params else None
        if folder is not None:
            targets = [folder / n for n in OUTPUT_NAMES]
            _check_targets(targets, [self.path, params_path], overwrite)
        say = _stderr if progress else _silent
        result = diagnose_run_file(
            self.path,
            params_path,
            also=also,
            max_effects=max_effects,
            mains_hz=mains_hz,
            out=folder,
            overwrite=overwrite,
            say=say,
            progress=say,
        )
        return result.diagnosis

    # -- display --------------------------------------------------------------------------
    def _head(self) -> list[str]:
        start = self._header.start_time[:19].replace("T", " ") or "-"
        status = self.status + (f" ({self.reason})" if self.reason else "")
        seed = f"; seed {self.seed}" if self.seed is not None else ""
        from labrig.catalogue.read import shown_metadata

        shown = shown_metadata(self.metadata)
        lines = [
            f"<labrig.Run {self.path}>",
            f"status {status}; protocol {self.protocol!r}; started {start}{seed}",
        ]
        if shown:
            lines.append("metadata: " + ", ".join(f"{k}={v}" for k, v in shown.items()))
        return lines

    def __repr__(self) -> str:
        infos = list(self.entries.values())
        samples = sum(e.samples for e in infos)
        total = sum(e.duration_s for e in infos)
        lines = self._head()
        lines.append(f"{plural(len(infos), 'entry')}, {plural(samples, 'sample')}, {total:.3g} s:")
        width = min(max((len(e.name) for e in infos), default=0), 40)

        def line(e: EntryInfo) -> str:
            return (
                f"  {e.name:<{width}}  {e.status}  {plural(e.samples, 'sample')}  "
                f"{e.duration_s:.3g} s"
            )

        shown = infos if len(infos) <= REPR_ENTRIES else infos[: REPR_ENTRIES - 2]
        lines += [line(e) for e in shown]
        if len(infos) > len(shown):
            lines += [f"  ... {len(infos) - len(shown) - 1} more ...", line(infos[-1])]
        return "\n".join(_cut(text, REPR_WIDTH) for text in lines)

    def _repr_html_(self) -> str:
        infos = list(self.entries.values())
        head = "<br>".join(html.escape(_cut(line, 300)) for line in self._head())
        rows = "".join(
            f"<tr><td>{html.escape(e.name)}</td><td>{html.escape(e.kind)}</td>"
            f"<td>{html.escape(e.status)}</td><td>{e.samples}</td><td>{e.duration_s:.3g}</td>"
            f"<td>{e.rate_hz:g}</td></tr>"
            for e in infos[:HTML_ENTRIES]
        )
        more = (
            f"<tr><td colspan=6>... {len(infos) - HTML_ENTRIES} more</td></tr>"
            if len(infos) > HTML_ENTRIES
            else ""
        )
        return (
            f"<div><p>{head}</p><table><thead><tr><th>entry</th><th>kind</th><th>status</th>"
            f"<th>samples</th><th>s</th><th>Hz</th></tr></thead><tbody>{rows}{more}</tbody>"
            "</table></div>"
        )


def _cut(line: str, width: int) -> str:
    return line if len(line) <= width else line[: width - 3] + "..."


def _stderr(message: str) -> None:
    print(message, file=sys.stderr)


def _silent(message: str) -> None:
    pass


def command_ui(progress: bool) -> CommandUI:
    """The analysis' :class:`~labrig.commands.fit.CommandUI`: bars on stderr or nothing.

    Parameters
    ----------
    progress : bool
        Draw progress bars on stderr (:class:`~labrig.commands.progress.RichUI`); otherwise say
        nothing.

    Returns
    -------
    CommandUI
        What the fits and reports call as they work.
    """
    if progress:
        from labrig.commands.progress import RichUI

        return RichUI()
    from labrig.commands.fit import QuietUI

    return QuietUI()


def _check_targets(targets: list[Path], inputs: list[Path | None], overwrite: bool) -> None:
    """Before the work, the one output check (:func:`labrig.core.outputs.check_writable`):
    an existing file without ``overwrite`` is a :class:`FileExistsError`, a folder where a file
    goes an :class:`IsADirectoryError` (both also
    :class:`~labrig.core.errors.InputFileError`), an input as output or a run file being
    written an :class:`~labrig.core.errors.InputFileError`."""
    from labrig.core.outputs import check_writable
    from labrig.store.reader import being_written

    check_writable(
        targets,
        inputs=inputs,
        overwrite=overwrite,
        option="out",
        being_written=being_written,
    )


def as_json(result: Any) -> dict[str, Any]:
    """What the command line prints with ``--json`` for a result of :meth:`Run.fit`,
    :meth:`Run.diagnose` (``to_json()``, undefined numbers as ``None``) or :meth:`Run.report`
    (its metrics).

    Parameters
    ----------
    result : object
        What :meth:`Run.fit`, :meth:`Run.diagnose` or :meth:`Run.report` returned.

    Returns
    -------
    dict
        JSON-ready values (undefined numbers as ``None``).
    """
    from labrig.commands.report import BuiltReport
    from labrig.core.jsonsafe import json_safe

    if isinstance(result, BuiltReport):
        return result.metrics
    return json_safe(result.to_json())


def open(path: PathLike) -> Run:  # labrig.open (the builtin stays open inside labrig.api.runs)
    """Open a run file: metadata now, samples on first use. A missing, damaged or foreign file
    raises :class:`~labrig.core.errors.InputFileError` naming it.

    Parameters
    ----------
    path : str or os.PathLike
        The run file.

    Returns
    -------
    Run
        The run, its metadata read.
    """
    from labrig.catalogue.read import read_metadata
    from labrig.store import read_run

    p = Path(path)
    header = read_run(p, load_data=False)
    metadata, units = read_metadata(p)
    return Run(p, header, metadata, units)


@contextmanager
def _bar(total_s: float, show: bool) -> Iterator[ProgressFn | None]:
    """A progress bar on stderr over the protocol's time (``None`` when not shown)."""
    if not show:
        yield None
        return
    from rich.console import Console
    from rich.markup import escape
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    with Progress(
        TextColumn("[bold]{task.fields[step]}[/] {task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>5.1f} %"),
        TimeRemainingColumn(),
        console=Console(stderr=True),
    ) as bar:
        task = bar.add_task("", total=total_s, step="")

        def progress(k: int, n: int, name: str, frac: float, left: float) -> None:
            bar.update(
                task, completed=total_s - left, step=f"step {k + 1}/{n}", description=escape(name)
            )

        yield progress


def run(
    protocol: PathLike,
    rig: PathLike | None = None,
    out: PathLike | None = None,
    seed: int | None = None,
    progress: bool = True,
    *,
    realtime: bool = False,
    overwrite: bool = False,
) -> Run:
    """``labrig run``: preflight ``protocol`` against the rig's limits (``rig``, else the
    protocol's, else the built-in simulated rig), run it, log it to ``out`` (default
    ``runs/NAME-DATE-TIME.h5``) and open the file.

    Safety is the runner's: every ending ramps the amplifier to 0 V within its current limit.
    Ctrl-C (SIGINT) stops the run that way and then raises ``KeyboardInterrupt``; another stop
    signal raises ``SystemExit`` with the command's exit code (128 + the signal number). A run
    that ended on a device fault or a full disk is returned (``status`` says ``failed``, with
    a warning). Bad input raises :class:`~labrig.core.errors.InputFileError` before anything is
    energised.

    Parameters
    ----------
    protocol : str or os.PathLike
        A protocol file or the name of a shipped one (``paper``).
    rig : str or os.PathLike, optional
        A rig file or the name of a shipped one (default: the protocol's, else the simulated
        rig).
    out : str or os.PathLike, optional
        The run file to write.
    seed : int, optional
        Seed of the simulated rig's noise.
    progress : bool
        Show a progress bar on stderr.
    realtime : bool
        Pace a simulated rig at the protocol's own speed.
    overwrite : bool
        Replace an existing ``out``.

    Returns
    -------
    Run
        The run file written, opened.
    """
    from labrig.runner.execute import check_run_output, default_out_path, execute, preflight

    rig_path = Path(rig) if rig is not None else None
    plan, rig_path = preflight(protocol if isinstance(protocol, str) else Path(protocol), rig_path)
    target = Path(out) if out is not None else default_out_path(plan)
    check_run_output(plan, rig_path, target, overwrite)  # before anything is energised
    with _bar(plan.total_duration_s, progress) as callback:
        outcome = execute(plan, rig_path, target, seed, realtime, callback, overwrite)
    if outcome.exit_code == 130:
        raise KeyboardInterrupt(f"run aborted ({outcome.reason}); output at 0 V; {outcome.path}")
    if outcome.exit_code > 128:
        raise SystemExit(outcome.exit_code)
    if outcome.status != "complete":
        warnings.warn(f"run {outcome.status}: {outcome.reason} ({outcome.path})", stacklevel=2)
    return open(outcome.path)


def runs(*paths: PathLike, where: Sequence[str] = (), reindex: bool = False) -> pd.DataFrame:
    """``labrig runs``: the runs under ``paths`` (folders, searched recursively, or run
    files; default ``runs/``) that satisfy every ``where`` expression (docs/catalogue.md), one
    row per run, oldest first: path, status, protocol, start (a Timestamp), entries, kinds,
    amplitudes_V, frequencies_hz, duration_s, matching_entries, error, then one column per
    metadata key (the instrument's in ``--json`` only).

    Parameters
    ----------
    *paths : str or os.PathLike
        Folders (searched recursively) or run files; default ``runs/``.
    where : sequence of str
        Filter expressions, all to hold (``"amplitude_V >= 100"``).
    reindex : bool
        Rebuild each folder's index first.

    Returns
    -------
    pandas.DataFrame
        One row per matching run, oldest first.
    """
    import pandas as pd

    from labrig.catalogue import entry_summary, list_runs

    listing = list_runs([Path(p) for p in paths] or [Path("runs")], where, reindex=reindex)
    rows = []
    for r in listing.runs:
        rec = r.record
        summary = entry_summary(rec)
        rows.append(
            {
                "path": str(r.path),
                "status": rec.get("status"),
                "protocol": rec.get("protocol"),
                "start": pd.to_datetime(rec.get("start_time") or None, utc=True),
                "entries": summary["entries"],
                "kinds": summary["kinds"],
                "amplitudes_V": summary["amplitudes_V"],
                "frequencies_hz": summary["frequencies_hz"],
                "duration_s": summary["duration_s"],
                "matching_entries": r.entries,
                "error": rec.get("error", ""),
                **rec.get("metadata", {}),
            }
        )
    frame = pd.DataFrame(rows)
    # a whole number above 2**53 in a column with gaps stays an int (pandas would make it float)
    for key in {k for r in rows for k, v in r.items() if type(v) is int and abs(v) > 2**53}:
        frame[key] = pd.Series([r.get(key) for r in rows], dtype=object, index=frame.index)
    return frame
