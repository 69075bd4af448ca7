"""``labrig drivers [--json] [--out FILE]``: the drivers labrig can find (the ``labrig.drivers``
entry-point group and the built-in ones), each with its role, the distribution that registers
it and the packages it needs (:func:`labrig.rig.driver_check.installed_drivers`). Opens no device.

Exit codes: 0 listed (a driver that does not load is listed with its error); 64 a usage error.
"""

from __future__ import annotations

from pathlib import Path

import typer

from labrig.cli.common import (
    OVERWRITE_OPTION,
    check_out,
    deliver_json,
    friendly,
    json_option,
    out_file_option,
    plural,
)

__all__ = ["drivers"]


@friendly
def drivers(
    as_json: bool = json_option("the drivers"),
    out: Path | None = out_file_option("the drivers as JSON (what --json prints)"),
    overwrite: bool = OVERWRITE_OPTION,
) -> None:
    """List the installed drivers: role, who provides them, the packages they need."""
    from labrig.cli.check import driver_line
    from labrig.rig.driver_check import installed_drivers
    from labrig.rig.rigspec import ENTRY_POINT_GROUP

    check_out(out, [], overwrite)
    found = installed_drivers()
    doc = {"entry_point_group": ENTRY_POINT_GROUP, "drivers": [d.to_json() for d in found]}
    if not deliver_json(doc, as_json=as_json, out=out, overwrite=overwrite):
        return
    for d in found:
        mark = "ok " if d.ok else "-- "
        typer.echo(mark + driver_line(d))
        if d.summary:
            typer.echo(f"     {d.summary}")
    usable = sum(d.ok for d in found)
    typer.echo(
        f"{plural(len(found), 'driver')} ({usable} usable; '--' marks a missing package or "
        f"runtime), entry-point group {ENTRY_POINT_GROUP}",
        err=True,
    )
