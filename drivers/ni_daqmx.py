"""NI-DAQmx backend for the DAQ role (optional: needs ``pip install nidaqmx`` and NI's driver).

One AO channel drives the amplifier's analog input; the AI channels are sampled on the AO
sample clock (``/<dev>/ao/SampleClock``), so AI sample ``n`` is taken with AO sample ``n``. The
whole waveform is written to the device buffer (finite generation) and the AI is read back block
by block. ``stop()`` aborts both tasks and writes 0 V with an on-demand AO task.

Not exercised in CI (no hardware); the simulated DAQ (:mod:`labrig.drivers.sim.daq`) has the same
methods. Channel names map to physical channels in the rig file (``ai: {gauge: Dev1/ai0, ...}``).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from labrig.errors import DeviceError
from labrig.instruments import AcquiredBlock, DriverContext, DriverInfo


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
    ai_range_V: float = Field(10.0, gt=0)
    terminal_config: str = Field("DIFF", pattern="^(DIFF|RSE|NRSE|PSEUDO_DIFF|DEFAULT)$")
    timeout_margin_s: float = Field(2.0, gt=0)


class NIDAQmx:
    """The :class:`~labrig.instruments.DAQ` role on an NI multifunction device."""

    def __init__(self, settings: NIDAQmxSettings):
        try:
            import nidaqmx  # noqa: F401
        except ImportError as e:
            raise DeviceError(
                "daq (NI-DAQmx)",
                "open",
                "the nidaqmx package is not installed (pip install nidaqmx)",
            ) from e
        self.s = settings
        self.device = f"daq (NI-DAQmx {settings.device})"
        self.rate_hz = 1000.0
        self.channels = list(settings.ai)
        self._tasks: list = []
        self._ao_last = 0.0  # AO volts last output (sample of the latest block read, or static)

    def _phys(self, ch: str) -> str:
        return f"{self.s.device}/{ch}"

    def identify(self) -> str:
        import nidaqmx.system

        dev = nidaqmx.system.Device(self.s.device)
        return f"NI {dev.product_type}, SN {dev.dev_serial_num:X}"

    def ai_channel_names(self) -> list[str]:
        return list(self.s.ai)

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
        import nidaqmx
        from nidaqmx.constants import AcquisitionType, TerminalConfiguration

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
        except nidaqmx.DaqError as e:
            raise DeviceError(self.device, "play", str(e)) from e
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
        import nidaqmx

        if abs(volts) > self.s.ao_range_V:
            raise DeviceError(self.device, "write_static", f"{volts} V outside the output range")
        try:
            with nidaqmx.Task() as t:
                r = self.s.ao_range_V
                t.ao_channels.add_ao_voltage_chan(self._phys(self.s.ao), min_val=-r, max_val=r)
                t.write(float(volts), auto_start=True)
        except nidaqmx.DaqError as e:
            raise DeviceError(self.device, "write_static", str(e)) from e
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
    summary="NI-DAQmx multifunction device (optional extra: nidaqmx); AI on the AO clock",
)
