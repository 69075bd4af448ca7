"""NI-DAQmx backend for the DAQ role (optional: ``pip install 'labrig[nidaq]'`` for the
``nidaqmx`` package, and NI's NI-DAQmx driver from ni.com, the runtime the package calls).

One AO channel drives the amplifier's analog input; the AI channels are sampled on the AO
sample clock (``/<dev>/ao/SampleClock``), so AI sample ``n`` is taken with AO sample ``n``. The
whole waveform is written to the device buffer (finite generation) and the AI is read back block
by block. ``stop()`` aborts both tasks and writes 0 V with an on-demand AO task.

Opening the driver checks what the rig needs before anything is energised: the package (its
absence: exit 3, "pip install 'labrig[nidaq]'"), NI's runtime (the package installed without
it raises ``DaqNotFoundError`` on its first call) and the device named in the rig file (among
the devices the runtime lists). Every failure of the package, whatever its class, becomes a
:class:`~labrig.core.errors.DeviceError` naming the device and the operation, in words
(:func:`failure_text`).

Not exercised on hardware in CI; tests/data/fake_nidaqmx stands in for the package (its calls
fail as without NI's runtime or without the device). The simulated DAQ
(:mod:`labrig.drivers.sim.daq`) has the same methods. Channel names map to physical channels in
the rig file (``ai: {gauge: ai0, ...}`` on ``device: Dev1``).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from types import ModuleType

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from labrig.core.errors import DeviceError
from labrig.rig.instruments import (
    AcquiredBlock,
    DriverContext,
    DriverInfo,
    Package,
    converter_step_V,
)

#: the package the driver needs and how to install it
PACKAGE = Package("nidaqmx", "nidaqmx", "pip install 'labrig[nidaq]'")
#: what the package itself needs
RUNTIME = "NI's NI-DAQmx driver from ni.com (checked when the device is opened)"


def import_nidaqmx(device: str, operation: str) -> ModuleType:
    """The ``nidaqmx`` package, or a :class:`DeviceError` saying how to install it."""
    try:
        import nidaqmx
        import nidaqmx.constants
        import nidaqmx.errors
        import nidaqmx.system
    except ImportError as e:
        raise DeviceError(
            device, operation, f"the nidaqmx package is not installed ({PACKAGE.install})"
        ) from e
    return nidaqmx


def failure_text(e: Exception, nidaqmx: ModuleType) -> str:
    """What went wrong, in words (no exception class names): NI's runtime missing, else the
    driver's message (its first line) with its DAQmx status code."""
    errors = getattr(nidaqmx, "errors", None)
    not_found = getattr(errors, "DaqNotFoundError", ())
    if not_found and isinstance(e, not_found):
        return (
            "NI's NI-DAQmx runtime is not installed (the nidaqmx package is, but it needs NI's "
            "driver: install NI-DAQmx from ni.com)"
        )
    lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
    head = lines[0] if lines else "the NI-DAQmx driver failed without a message"
    code = getattr(e, "error_code", None)
    return f"{head} (DAQmx status {code})" if code is not None else head


class NIDAQmxSettings(BaseModel):
    """Rig-file section of the ``nidaqmx`` driver."""

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)

    driver: str = "nidaqmx"
    device: str = Field("Dev1", description="NI device name")
    ao: str = Field("ao0", description="AO channel driving the amplifier input")
    ai: dict[str, str] = Field(
        default_factory=lambda: {"gauge": "ai0", "amp_monitor": "ai1"},
        description="AI channel name -> physical channel",
    )
    ao_range_V: float = Field(10.0, gt=0)
    ao_bits: int = Field(
        16, ge=8, le=32, description="AO converter resolution (a sample at a limit stays in)"
    )
    ai_range_V: float = Field(10.0, gt=0)
    terminal_config: str = Field("DIFF", pattern="^(DIFF|RSE|NRSE|PSEUDO_DIFF|DEFAULT)$")
    timeout_margin_s: float = Field(2.0, gt=0)


class NIDAQmx:
    """The :class:`~labrig.rig.instruments.DAQ` role on an NI multifunction device."""

    def __init__(self, settings: NIDAQmxSettings):
        self.s = settings
        self.device = f"daq (NI-DAQmx {settings.device})"
        self.nidaqmx = import_nidaqmx(self.device, "open")
        self.rate_hz = 1000.0
        self.channels = list(settings.ai)
        self._tasks: list = []
        self._ao_last = 0.0  # AO volts last output (sample of the latest block read, or static)
        self.check_device()

    def _error(self, operation: str, e: Exception) -> DeviceError:
        return DeviceError(self.device, operation, failure_text(e, self.nidaqmx))

    def check_device(self) -> None:
        """The runtime answers and lists the rig file's device (else a DeviceError)."""
        try:
            names = [d.name for d in self.nidaqmx.system.System.local().devices]
        except Exception as e:  # any failure of the package is the device's
            raise self._error("open", e) from None
        if self.s.device not in names:
            found = ", ".join(names) or "none"
            raise DeviceError(
                self.device, "open", f"device {self.s.device!r} not found (devices: {found})"
            )

    def _phys(self, ch: str) -> str:
        return f"{self.s.device}/{ch}"

    def identify(self) -> str:
        try:
            dev = self.nidaqmx.system.Device(self.s.device)
            return f"NI {dev.product_type}, SN {dev.dev_serial_num:X}"
        except Exception as e:
            raise self._error("identify", e) from None

    def ai_channel_names(self) -> list[str]:
        return list(self.s.ai)

    def ai_range_V(self) -> tuple[float, float]:
        return (-self.s.ai_range_V, self.s.ai_range_V)

    def ao_step_V(self) -> float:
        """Volts of one code of the AO converter over its range (``ao_range_V``, ``ao_bits``)."""
        return converter_step_V(self.s.ao_range_V, self.s.ao_bits)

    def configure(self, rate_hz: float, ai_channels: list[str]) -> None:
        unknown = [c for c in ai_channels if c not in self.s.ai]
        if unknown:
            raise DeviceError(self.device, "configure", f"unknown AI channel(s) {unknown}")
        self.rate_hz, self.channels = float(rate_hz), list(ai_channels)

    def play(self, ao_volts: NDArray, block_size: int) -> Iterator[AcquiredBlock]:
        ao = np.ascontiguousarray(ao_volts, dtype=float)
        if ao.size and np.max(np.abs(ao)) > self.s.ao_range_V:
            raise DeviceError(self.device, "play", "AO waveform outside the output range")
        return self._play(ao, int(block_size))

    def _play(self, ao: NDArray, block_size: int) -> Iterator[AcquiredBlock]:
        nidaqmx = self.nidaqmx
        AcquisitionType = nidaqmx.constants.AcquisitionType
        TerminalConfiguration = nidaqmx.constants.TerminalConfiguration

        n = ao.size
        try:
            ao_task, ai_task = nidaqmx.Task(), nidaqmx.Task()
            self._tasks = [ai_task, ao_task]
            r = self.s.ao_range_V
            ao_task.ao_channels.add_ao_voltage_chan(self._phys(self.s.ao), min_val=-r, max_val=r)
            ao_task.timing.cfg_samp_clk_timing(
                self.rate_hz, sample_mode=AcquisitionType.FINITE, samps_per_chan=n
            )
            term = getattr(TerminalConfiguration, self.s.terminal_config)
            for ch in self.channels:
                ai_task.ai_channels.add_ai_voltage_chan(
                    self._phys(self.s.ai[ch]),
                    terminal_config=term,
                    min_val=-self.s.ai_range_V,
                    max_val=self.s.ai_range_V,
                )
            ai_task.timing.cfg_samp_clk_timing(
                self.rate_hz,
                source=f"/{self.s.device}/ao/SampleClock",
                sample_mode=AcquisitionType.FINITE,
                samps_per_chan=n,
            )
            ao_task.write(ao, auto_start=False)
            ai_task.start()  # armed: waits for the AO sample clock
            ao_task.start()
            timeout = block_size / self.rate_hz + self.s.timeout_margin_s
            for start in range(0, n, block_size):
                m = min(block_size, n - start)
                data = np.asarray(
                    ai_task.read(number_of_samples_per_channel=m, timeout=timeout), dtype=float
                ).reshape(len(self.channels), m)
                self._ao_last = float(ao[start + m - 1])
                yield AcquiredBlock(start, dict(zip(self.channels, data, strict=True)))
        except Exception as e:  # any failure of the package is the device's
            raise self._error("play", e) from None
        finally:
            self._close_tasks()

    def _close_tasks(self) -> None:
        for t in self._tasks:
            with contextlib.suppress(Exception):
                t.stop()
            with contextlib.suppress(Exception):
                t.close()
        self._tasks = []

    def write_static(self, volts: float) -> None:
        if abs(volts) > self.s.ao_range_V:
            raise DeviceError(self.device, "write_static", f"{volts} V outside the output range")
        try:
            with self.nidaqmx.Task() as t:
                r = self.s.ao_range_V
                t.ao_channels.add_ao_voltage_chan(self._phys(self.s.ao), min_val=-r, max_val=r)
                t.write(float(volts), auto_start=True)
        except Exception as e:  # any failure of the package is the device's
            raise self._error(f"write {volts:g} V", e) from None
        self._ao_last = float(volts)

    def ao_level(self) -> float:
        """The AO volts last output (for a playback: the sample of the latest block read)."""
        return self._ao_last

    def abort_playback(self) -> None:
        """Stop a playback's tasks; the AO holds the value it reached."""
        self._close_tasks()

    def stop(self) -> None:
        self._close_tasks()
        self.write_static(0.0)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.stop()

    def describe(self) -> dict:
        return {"driver": "nidaqmx", **self.s.model_dump(), "rate_hz": self.rate_hz}


def create(settings: NIDAQmxSettings, ctx: DriverContext) -> NIDAQmx:
    return NIDAQmx(settings)


DRIVER = DriverInfo(
    name="nidaqmx",
    role="daq",
    settings=NIDAQmxSettings,
    create=create,
    summary="NI-DAQmx multifunction device; AI on the AO clock",
    packages=(PACKAGE,),
    runtime=RUNTIME,
)
