"""``labrig check PROTOCOL [--rig RIG] [--json] [--out FILE]``: validate a protocol, preflight it
against the rig's limits, and load the rig's drivers (their modules and the packages they need,
validated settings) without opening any device (:func:`labrig.runner.execute.preflight`,
:func:`labrig.rig.driver_check.load_rig_drivers`).

Exit codes: 0 OK; 2 a bad protocol or rig file (file, line, field); 3 a driver that cannot load
(a package missing: the role, the driver and how to install it); 64 a usage error.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from labrig.cli.common import (
    OVERWRITE_OPTION,
    RIG_OPTION_HELP,
    check_out,
    deliver_json,
    friendly,
    json_option,
    out_file_option,
    plural,
)

if TYPE_CHECKING:
    from labrig.rig.driver_check import DriverReport

__all__ = ["check", "driver_line"]


@friendly
def check(
    protocol: Path = typer.Argument(
        ..., help="Protocol file (YAML), or a shipped example's name (paper, sweep...)."
    ),
    rig: Path | None = typer.Option(None, "--rig", metavar="FILE", help=RIG_OPTION_HELP),
    as_json: bool = json_option("the plan, the rig and its drivers"),
    out: Path | None = out_file_option("the plan, the rig and its drivers as JSON"),
    overwrite: bool = OVERWRITE_OPTION,
) -> None:
    """Validate a protocol, preflight it against the rig's limits and load the rig's drivers;
    opens no device."""
    from labrig.rig.driver_check import load_rig_drivers
    from labrig.rig.rigspec import DEFAULT_RIG_NAME, load_rig
    from labrig.runner.execute import preflight

    plan, rig_path = preflight(protocol, rig)
    check_out(out, [protocol, rig, plan.path, rig_path], overwrite)
    spec = load_rig(rig_path)
    drivers = load_rig_drivers(spec)
    doc: dict[str, Any] = {
        **plan.to_dict(),
        "rig": str(rig_path) if rig_path is not None else DEFAULT_RIG_NAME,
        "rig_name": spec.name,
        "simulated": spec.simulated,
        "drivers": [d.to_json() for d in drivers],
    }
    if not deliver_json(doc, as_json=as_json, out=out, overwrite=overwrite):
        return
    from rich.console import Console

    from labrig.protocol.check import format_plan

    Console().print(format_plan(plan))
    where = "the built-in simulated rig" if rig_path is None else f"rig {rig_path}"
    typer.echo(f"drivers of {where} ({spec.name}; loaded, no device opened):")
    for d in drivers:
        typer.echo("  " + driver_line(d))
    typer.echo(f"{protocol}: OK, {plural(len(plan.steps), 'entry')}, {plan.total_duration_s:.1f} s")


def driver_line(d: DriverReport) -> str:
    """``daq: nidaqmx (labrig 0.1.0); needs nidaqmx 1.1 [...]; NI-DAQmx driver (ni.com) ...``."""
    text = f"{d.role}: {d.name} ({d.provided_by})"
    if d.error:
        return f"{text}: {d.error}"
    needs = [
        f"{p.distribution} {p.version}" if p.version else f"{p.distribution} missing ({p.install})"
        for p in d.packages
    ]
    if needs:
        text += "; needs " + ", ".join(needs)
    if d.runtime:
        text += f"; also needs {d.runtime}"
    return text
