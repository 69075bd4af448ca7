"""The drivers installed, and whether a rig's drivers load, without opening any device.

:func:`installed_drivers` (``labrig drivers``) lists every driver of the ``labrig.drivers``
entry-point group: role, summary, the distribution that registers it, the
Python packages it needs (installed or not, with their versions) and what else it needs that
only opening the device can check (a vendor's runtime). :func:`load_rig_drivers` (``labrig
check``) imports the drivers of a validated rig file and the packages they need and reports
them; a missing package is a :class:`~labrig.core.errors.DeviceError` naming the role, the driver
and the package (exit code 3), as a run would fail. Neither opens a port, a socket or a device.
"""

from __future__ import annotations

import importlib
import importlib.util
from dataclasses import asdict, dataclass, field
from importlib import metadata
from typing import Any

from labrig.core.errors import DeviceError
from labrig.rig.instruments import DriverInfo, Package
from labrig.rig.rigspec import (
    ROLES,
    RigSpec,
    driver_entries,
    driver_names,
    get_driver,
    missing_package,
)

__all__ = ["DriverReport", "PackageState", "installed_drivers", "load_rig_drivers"]


@dataclass(frozen=True)
class PackageState:
    """A package a driver needs: its names, how to install it, and its installed version
    (``None``: not installed); ``error`` when importing it failed."""

    module: str
    distribution: str
    install: str
    version: str | None
    error: str = ""

    @property
    def ok(self) -> bool:
        return self.version is not None and not self.error


@dataclass
class DriverReport:
    """A driver as ``labrig drivers`` and ``labrig check`` show it; ``error`` when it does not
    load (its module, or a package it imports, is missing or broken)."""

    name: str
    role: str
    reference: str
    provided_by: str
    summary: str = ""
    packages: list[PackageState] = field(default_factory=list)
    runtime: str = ""
    error: str = ""

    @property
    def ok(self) -> bool:
        return not self.error and all(p.ok for p in self.packages)

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["ok"] = self.ok
        return d


def _version(distribution: str) -> str | None:
    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return None


def package_state(pkg: Package, import_it: bool) -> PackageState:
    """Whether ``pkg`` is installed (its distribution's version, else the module's
    ``__version__``, else ``"unknown"``) and, with ``import_it``, whether it imports (else it
    is only looked for on the path)."""
    version, error = _version(pkg.distribution), ""
    if not import_it:
        if importlib.util.find_spec(pkg.module) is None:
            return PackageState(pkg.module, pkg.distribution, pkg.install, None)
        return PackageState(pkg.module, pkg.distribution, pkg.install, version or "unknown")
    try:
        module = importlib.import_module(pkg.module)
        version = version or str(getattr(module, "__version__", "unknown"))
    except ImportError:
        version = None
    except Exception as e:  # a broken installation: say what it said
        error = f"does not import: {e}"
    return PackageState(pkg.module, pkg.distribution, pkg.install, version, error)


def _providers() -> dict[str, str]:
    """Driver name -> ``distribution version`` of the entry point that registers it."""
    try:
        return {e.name: e.provided_by for e in driver_entries()}
    except Exception:  # a broken installation must not hide the built-in drivers
        return {}


def _report(
    name: str, ref: str, provided_by: str, info: DriverInfo, import_it: bool
) -> DriverReport:
    return DriverReport(
        name,
        info.role,
        ref,
        provided_by,
        info.summary,
        [package_state(p, import_it) for p in info.packages],
        info.runtime,
    )


def installed_drivers() -> list[DriverReport]:
    """Every driver labrig can find (module docstring), by role then name; a driver that does
    not load is listed with its error."""
    providers = _providers()
    out = []
    for name, ref in driver_names().items():
        provided_by = providers.get(name, "?")
        try:
            info = get_driver(name)
        except ModuleNotFoundError as e:
            err = missing_package("?", name, e)
            out.append(DriverReport(name, "?", ref, provided_by, error=err.detail))
            continue
        except Exception as e:
            out.append(DriverReport(name, "?", ref, provided_by, error=f"does not load: {e}"))
            continue
        out.append(_report(name, ref, provided_by, info, import_it=False))
    order = {r: i for i, r in enumerate(ROLES)}
    return sorted(out, key=lambda r: (order.get(r.role, len(ROLES)), r.name))


def load_rig_drivers(spec: RigSpec) -> list[DriverReport]:
    """The drivers of the validated rig ``spec`` (its roles' order), each with the packages it
    needs imported; a package that is missing is a :class:`DeviceError` (exit code 3) naming
    the role, the driver and how to install it. Opens nothing."""
    providers = _providers()
    names = driver_names()
    out = []
    for role in ROLES:
        info = spec.drivers[role]
        provided_by = providers.get(info.name, "?")
        report = _report(info.name, names.get(info.name, "?"), provided_by, info, import_it=True)
        for p in report.packages:
            if not p.ok:
                why = "is not installed" if p.version is None else p.error
                raise DeviceError(
                    f"{role} ({info.name} driver)",
                    "load driver",
                    f"the Python package {p.module!r} {why} ({p.install})",
                )
        out.append(report)
    return out
