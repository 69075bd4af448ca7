"""Simulated DAQ: hardware-timed AO playback with synchronised AI, on the virtual bench.

Shaped like a real multifunction DAQ task pair (one AO channel driving the amplifier's analog
input; AI channels sampled on the same clock, one AI sample per AO sample): a real backend
(NI-DAQmx, a dSPACE bridge) is a module with the same methods. Blocks are computed on demand,
faster than real time, unless ``realtime`` is set (then each block is released when its last
sample's time has passed on the wall clock).

After a playback ends the AO keeps its last value (as a DAQ's DAC does); :meth:`SimDAQ.stop`
aborts a playback and writes 0 V, :meth:`SimDAQ.abort_playback` aborts it holding the value.

A static write (:meth:`SimDAQ.write_static`, no playback) advances the bench by ``settle_s`` of
simulated time, or with ``realtime`` by the wall-clock time since the bench last advanced (at
least one sample, at most ``MAX_STATIC_ADVANCE_S``): the bench then follows the wall clock, so
a ramp written by static writes has, on the bench, the slope it has in real time.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from labrig.core.errors import DeviceError
from labrig.rig.instruments import AcquiredBlock, DriverContext, DriverInfo, converter_step_V

#: realtime static writes advance the bench by at most this much simulated time (s)
MAX_STATIC_ADVANCE_S = 1.0


class SimDAQSettings(BaseModel):
    """Rig-file section of the ``sim_daq`` driver."""

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)

    driver: str = "sim_daq"
    realtime: bool = Field(False, description="pace playback to the wall clock")


class SimDAQ:
    """The :class:`~labrig.rig.instruments.DAQ` role on a :class:`VirtualBench`."""

    device = "daq (simulated)"

    def __init__(self, bench, realtime: bool = False, rate_limits: tuple[float, float] = (10, 1e5)):
        self.bench = bench
        self.realtime = realtime
        self.rate_limits = rate_limits
        self.rate_hz = bench.rate_hz
        self.channels = list(bench.ai_channels()[:2])
        self._abort = False
        self._closed = False
        self._active: Iterator[AcquiredBlock] | None = None
        self._wall: float | None = None  # realtime: wall-clock time the bench has reached

    def _check_open(self, operation: str) -> None:
        if self._closed:
            raise DeviceError(self.device, operation, "the DAQ is closed")

    def identify(self) -> str:
        return "labrig simulated DAQ (virtual bench), 1 AO, AI on the AO clock"

    def ao_range_V(self) -> tuple[float, float]:
        r = self.bench.config.daq.ao_range_V
        return (-r, r)

    def ao_step_V(self) -> float | None:
        """Volts of one code of the AO converter (``None``: the bench's AO is not quantised)."""
        d = self.bench.config.daq
        return converter_step_V(d.ao_range_V, d.ao_bits) if d.ao_bits else None

    def ai_range_V(self) -> tuple[float, float]:
        r = self.bench.config.daq.ai_range_V
        return (-r, r)

    def ai_channel_names(self) -> list[str]:
        """Every AI channel this DAQ can acquire (``configure`` selects among them)."""
        return list(self.bench.ai_channels())

    def configure(
        self, rate_hz: float, ai_channels: list[str], realtime: bool | None = None
    ) -> None:
        self._check_open("configure")
        lo, hi = self.rate_limits
        if not lo <= rate_hz <= hi:
            raise DeviceError(self.device, "configure", f"rate {rate_hz} Hz outside {lo}..{hi} Hz")
        unknown = [c for c in ai_channels if c not in self.bench.ai_channels()]
        if unknown or not ai_channels:
            raise DeviceError(
                self.device,
                "configure",
                f"unknown AI channel(s) {unknown}; available: {self.bench.ai_channels()}",
            )
        self.bench.set_rate(float(rate_hz))
        self.rate_hz = float(rate_hz)
        self.channels = list(ai_channels)
        if realtime is not None:
            self.realtime = realtime

    def play(self, ao_volts: NDArray, block_size: int) -> Iterator[AcquiredBlock]:
        """Play ``ao_volts`` at the configured rate; yield the synchronised AI block by block."""
        self._check_open("play")
        ao = np.asarray(ao_volts, dtype=float).ravel()
        lo, hi = self.ao_range_V()
        if ao.size and (not np.all(np.isfinite(ao)) or ao.min() < lo or ao.max() > hi):
            raise DeviceError(
                self.device, "play", f"AO waveform outside the output range {lo:g}..{hi:g} V"
            )
        if block_size < 1:
            raise ValueError("block_size must be at least 1")
        self._close_active()
        self._active = self._play(ao, int(block_size))
        return self._active

    def _close_active(self) -> None:
        gen, self._active = self._active, None
        if gen is not None:
            # leaves the bench's playback state; ValueError: the generator is executing in
            # another thread, and the abort flag stops it at the next block
            with contextlib.suppress(ValueError):
                gen.close()

    def _play(self, ao: NDArray, block_size: int) -> Iterator[AcquiredBlock]:
        self._abort = False
        b = self.bench
        with b.playback():
            t0 = time.monotonic()
            for start in range(0, ao.size, block_size):
                if self._abort:
                    return
                blk = ao[start : start + block_size]
                with b.lock:
                    b.ao_level = float(blk[-1])
                    out = b.step(blk)
                if self.realtime:
                    due = t0 + (start + blk.size) / self.rate_hz
                    delay = due - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                    self._wall = due
                yield AcquiredBlock(start, {c: out[c] for c in self.channels})

    def write_static(self, volts: float) -> None:
        self._check_open("write_static")
        lo, hi = self.ao_range_V()
        if not lo <= volts <= hi:
            raise DeviceError(self.device, "write_static", f"{volts} V outside {lo:g}..{hi:g} V")
        with self.bench.lock:
            self.bench.ao_level = float(volts)
        self._advance_static()

    def _advance_static(self) -> None:
        """Let the bench settle after a static change: ``settle_s``, or the wall-clock time
        since it last advanced when ``realtime``."""
        if not self.realtime:
            self.bench.settle()
            return
        now = time.monotonic()
        elapsed = now - self._wall if self._wall is not None else 0.0
        self.bench.settle(min(max(elapsed, 1.0 / self.rate_hz), MAX_STATIC_ADVANCE_S))
        self._wall = now

    def ao_level(self) -> float:
        """The AO volts output now (the last sample played or written)."""
        return float(self.bench.ao_level)

    def abort_playback(self) -> None:
        """End a playback; the AO holds the last value it played."""
        self._abort = True
        self._close_active()

    def stop(self) -> None:
        self.abort_playback()
        with self.bench.lock:
            self.bench.ao_level = 0.0
        self._advance_static()

    def close(self) -> None:
        if not self._closed:
            self.stop()
            self._closed = True

    def describe(self) -> dict:
        return {
            "driver": "sim_daq",
            "identity": self.identify(),
            "rate_hz": self.rate_hz,
            "ai_channels": self.channels,
            "ao_range_V": list(self.ao_range_V()),
            "ai_range_V": list(self.ai_range_V()),
            "ai_bits": self.bench.config.daq.ai_bits,
            "ao_bits": self.bench.config.daq.ao_bits,
            "realtime": self.realtime,
        }


def create(settings: SimDAQSettings, ctx: DriverContext) -> SimDAQ:
    if ctx.bench is None:
        raise DeviceError("daq (simulated)", "open", "the sim_daq driver needs a simulated bench")
    lim = ctx.limits
    return SimDAQ(ctx.bench, settings.realtime, (lim.rate_min_hz, lim.rate_max_hz))


DRIVER = DriverInfo(
    name="sim_daq",
    role="daq",
    settings=SimDAQSettings,
    create=create,
    summary="simulated DAQ on the virtual bench (AO playback with synchronised AI)",
)
