"""PI E-503 piezo amplifier with an E-517-style digital interface, over GCS 2.0 ASCII.

Our own small GCS client on pyserial (PI's PIPython is under a proprietary licence). The link is
any pyserial URL: a port name (``/dev/ttyUSB0``, ``COM3``), ``socket://host:port`` (a serial
server, or the simulator), ``rfc2217://...``. Commands are LF-terminated; answers are lines,
multi-line answers ending every line but the last with a space. After every command without an
answer the driver reads ``ERR?`` so a refused command is never silent.

Control modes (E-517): ONLINE (``ONL 1 1``) takes the output from the digital setpoint ``SVA``
and ignores the analog control input; OFFLINE (``ONL 1 0``) drives the output from the analog
input (the DAQ's AO) times the amplifier gain. So:

- :meth:`E503Amplifier.enable`: ``SVA A 0`` then ``ONL 1 0`` (the DAQ drives the stack);
- :meth:`E503Amplifier.disable` and :meth:`E503Amplifier.safe_zero`: ``ONL 1 1`` then
  ``SVA A 0`` (output held at 0 V whatever the DAQ does: a step, so the Rig calls them after
  it has ramped the output to 0 V);
- :meth:`E503Amplifier.take_digital_control` and :meth:`E503Amplifier.set_setpoint`: ``SVA A
  <V>`` then ``ONL 1 1``, then ``SVA A <V>`` steps: the Rig's ramp to 0 V when the DAQ fails.

Faults: a dropped link, a missing answer (timeout) or a damaged answer raise
:class:`~labrig.core.errors.DeviceError` naming the amplifier and the operation. The driver does not
move the output on a fault (the Rig ramps it to 0 V within the current limit); it closes a
link that is out of step, and the next call reconnects.
"""

from __future__ import annotations

import contextlib
import logging
import re
import socket
import time

import serial
from pydantic import BaseModel, ConfigDict, Field

from labrig.core.errors import DeviceError
from labrig.rig.instruments import AmplifierStatus, DriverContext, DriverInfo, Package

log = logging.getLogger("labrig.drivers.pi_e503")

GCS_ERRORS = {
    1: "parameter syntax error",
    2: "unknown command",
    15: "invalid axis or channel identifier",
    17: "parameter out of range",
}
_VALUE = re.compile(r"^(?P<id>[A-Za-z0-9_]+)=(?P<val>[-+0-9.eE]+|0x[0-9A-Fa-f]+)$")
_SRG = re.compile(r"^(?P<id>[A-Za-z0-9_]+) 1=(?P<val>0x[0-9A-Fa-f]+)$")


class E503Settings(BaseModel):
    """Rig-file section of the ``pi_e503`` driver."""

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)

    driver: str = "pi_e503"
    url: str = Field("sim", description="pyserial URL or port; 'sim' = the simulated bench")
    baudrate: int = Field(115200, gt=0)
    timeout_s: float = Field(0.5, gt=0, le=30, description="answer timeout")
    axis: str = Field("A", pattern=r"^[A-Za-z0-9_]+$", description="GCS axis (SVA, OVF?, SRG?)")
    channel: str = Field("1", pattern=r"^[0-9]+$", description="piezo channel (ONL, VOL?, VMA)")
    gain_V_per_V: float = Field(10.0, gt=0, description="calibrated amplifier gain")
    monitor_V_per_V: float = Field(0.05, gt=0, description="voltage monitor scale at the DAQ")
    apply_voltage_limits: bool = Field(
        True, description="set VMI/VMA to the rig limits' v_min_V/v_max_V when the rig opens"
    )


class GCSLink:
    """A GCS 2.0 ASCII link over pyserial (reconnects lazily after a failure)."""

    def __init__(
        self, url: str, baudrate: int = 115200, timeout_s: float = 0.5, device: str = "amplifier"
    ):
        self.url, self.baudrate, self.timeout_s, self.device = url, baudrate, timeout_s, device
        self._ser: serial.Serial | None = None

    def open(self) -> serial.Serial:
        """The link, opened now unless it is open."""
        if self._ser is not None:
            return self._ser
        try:
            self._ser = serial.serial_for_url(
                self.url,
                baudrate=self.baudrate,
                timeout=self.timeout_s,
                write_timeout=self.timeout_s,
            )
        except (serial.SerialException, OSError, ValueError) as e:
            raise DeviceError(self.device, f"open {self.url}", f"cannot open the link: {e}") from e
        sock = getattr(self._ser, "_socket", None)  # socket:// links: no Nagle delay
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return self._ser

    def close(self) -> None:
        if self._ser is None:
            return
        ser, self._ser = self._ser, None
        sock = getattr(ser, "_socket", None)
        if sock is not None:
            # pyserial's socket:// close() sleeps 0.3 s "for quick reconnects"; close it directly
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
            sock.close()
            ser._socket = None  # type: ignore[attr-defined]  # socket:// links' own attribute
            ser.is_open = False
            return
        with contextlib.suppress(Exception):
            ser.close()

    def _io_error(self, operation: str, e: Exception) -> DeviceError:
        self.close()
        return DeviceError(self.device, operation, f"link lost ({e}); will reconnect on next use")

    def send(self, command: str, operation: str) -> None:
        """Write one command line (no answer expected)."""
        ser = self.open()
        try:
            ser.reset_input_buffer()  # drop a late answer to an earlier command
            ser.write((command + "\n").encode("ascii"))
            ser.flush()
        except (serial.SerialException, OSError) as e:
            raise self._io_error(f"{operation} ({command})", e) from e

    def _readline(self, command: str, operation: str) -> str:
        ser = self._ser
        assert ser is not None, "send() opened the link"
        try:
            raw = ser.read_until(b"\n")
        except (serial.SerialException, OSError) as e:
            raise self._io_error(f"{operation} ({command})", e) from e
        if not raw.endswith(b"\n"):
            self.close()  # the stream may be out of step: start afresh next time
            got = f" (partial answer {raw!r})" if raw else ""
            raise DeviceError(
                self.device,
                f"{operation} ({command})",
                f"no answer within {self.timeout_s:g} s{got}",
            )
        try:
            return raw.decode("ascii")
        except UnicodeDecodeError as e:
            self.close()
            raise DeviceError(
                self.device, f"{operation} ({command})", f"garbled answer {raw!r}"
            ) from e

    def query(self, command: str, operation: str) -> list[str]:
        """Write a query and read its answer lines (without terminators)."""
        self.send(command, operation)
        lines = []
        while True:
            line = self._readline(command, operation)
            if line.endswith(" \n"):
                lines.append(line[:-2])
                if len(lines) > 64:
                    raise DeviceError(self.device, operation, "answer too long")
                continue
            lines.append(line[:-1])
            return lines


class E503Amplifier:
    """The :class:`~labrig.rig.instruments.Amplifier` role over GCS (see the module docstring)."""

    def __init__(self, settings: E503Settings, url: str | None = None):
        self.settings = settings
        self.url = url or settings.url
        self.gain = float(settings.gain_V_per_V)
        self.device = f"amplifier (PI E-503 at {self.url})"
        self.link = GCSLink(self.url, settings.baudrate, settings.timeout_s, self.device)
        self._idn: str | None = None

    # -- plumbing --------------------------------------------------------------------------------
    def _check_error(self, operation: str) -> None:
        lines = self.link.query("ERR?", operation)
        code = self._int(lines, "ERR?", operation)
        if code:
            raise DeviceError(
                self.device, operation, f"GCS error {code}: {GCS_ERRORS.get(code, 'unknown')}"
            )

    def _int(self, lines: list[str], command: str, operation: str) -> int:
        if len(lines) != 1 or not re.fullmatch(r"-?[0-9]+", lines[0]):
            raise DeviceError(self.device, f"{operation} ({command})", f"garbled answer {lines!r}")
        return int(lines[0])

    def _value(self, command: str, ident: str, operation: str) -> str:
        lines = self.link.query(f"{command} {ident}", operation)
        m = _VALUE.match(lines[0]) if len(lines) == 1 else None
        if not m or m["id"] != ident:
            self.link.close()
            raise DeviceError(
                self.device, f"{operation} ({command} {ident})", f"garbled answer {lines!r}"
            )
        return m["val"]

    def _float(self, command: str, ident: str, operation: str) -> float:
        val = self._value(command, ident, operation)
        try:
            return float(val)
        except ValueError as e:
            raise DeviceError(self.device, operation, f"garbled number {val!r}") from e

    def _set(self, command: str, operation: str) -> None:
        self.link.send(command, operation)
        self._check_error(f"{operation} ({command})")

    def _zero_commands(self, operation: str) -> None:
        s = self.settings
        self._set(f"ONL {s.channel} 1", operation)
        self._set(f"SVA {s.axis} 0", operation)

    # -- the Amplifier role ----------------------------------------------------------------------
    def identify(self) -> str:
        lines = self.link.query("*IDN?", "identify")
        if len(lines) != 1 or not lines[0].isprintable() or not lines[0]:
            raise DeviceError(self.device, "identify (*IDN?)", f"garbled answer {lines!r}")
        self._idn = lines[0]
        return self._idn

    def output_limits(self) -> tuple[float, float]:
        ch = self.settings.channel
        return (self._float("VMI?", ch, "output_limits"), self._float("VMA?", ch, "output_limits"))

    def set_output_limits(self, v_min: float, v_max: float) -> None:
        """Set the device's own output clamp (VMI/VMA), a hardware-side safety net."""
        ch = self.settings.channel
        _lo, hi = self.output_limits()
        # order the two writes so VMI < VMA holds at every step
        if v_min >= hi:
            self._set(f"VMA {ch} {v_max:.4f}", "set_output_limits")
            self._set(f"VMI {ch} {v_min:.4f}", "set_output_limits")
        else:
            self._set(f"VMI {ch} {v_min:.4f}", "set_output_limits")
            self._set(f"VMA {ch} {v_max:.4f}", "set_output_limits")

    def enable(self) -> None:
        s = self.settings
        self._set(f"SVA {s.axis} 0", "enable")
        self._set(f"ONL {s.channel} 0", "enable")
        online = self._value("ONL?", s.channel, "enable")
        if online != "0":
            raise DeviceError(self.device, "enable", "the channel did not go OFFLINE")

    def disable(self) -> None:
        self._zero_commands("disable")

    def take_digital_control(self, volts: float) -> None:
        """Hold ``volts`` from the digital setpoint (``SVA`` first, then ONLINE), so the output
        does not move when the analog input is dropped: the start of a setpoint ramp."""
        s = self.settings
        self._set(f"SVA {s.axis} {volts:.4f}", "take_digital_control")
        self._set(f"ONL {s.channel} 1", "take_digital_control")

    def set_setpoint(self, volts: float) -> None:
        """Set the digital setpoint (V): the output in ONLINE mode."""
        self._set(f"SVA {self.settings.axis} {volts:.4f}", "set_setpoint")

    def read_voltage(self) -> float:
        return self._float("VOL?", self.settings.channel, "read_voltage")

    def read_current(self) -> float | None:
        """The E-503 has no current read-back."""
        return None

    def status(self) -> AmplifierStatus:
        s = self.settings
        ovf = self._value("OVF?", s.axis, "status") == "1"
        lines = self.link.query(f"SRG? {s.axis} 1", "status")
        m = _SRG.match(lines[0]) if len(lines) == 1 else None
        if not m or m["id"] != s.axis:
            self.link.close()
            raise DeviceError(self.device, "status (SRG?)", f"garbled answer {lines!r}")
        bits = int(m["val"], 16)
        code = self._int(self.link.query("ERR?", "status"), "ERR?", "status")
        return AmplifierStatus(
            overflow=ovf or bool(bits & 1),
            over_temperature=bool(bits & 2),
            error_code=code,
            online=bool(bits & 4),
            detail=f"SRG=0x{bits:X}",
        )

    def check(self) -> None:
        """Raise DeviceError if the amplifier reports a fault (the output is left where it is:
        the Rig ramps it to 0 V)."""
        st = self.status()
        if not st.ok:
            raise DeviceError(self.device, "status check", "; ".join(st.problems()))

    def safe_zero(self) -> None:
        """ONLINE with SVA 0: output 0 V whatever the analog input does (a step: call it once
        the output is at 0 V). Never raises."""
        for attempt in range(2):
            try:
                self._zero_commands("safe_zero")
                return
            except Exception as e:
                log.error("%s: safe_zero attempt %d failed: %s", self.device, attempt + 1, e)
                self.link.close()
                time.sleep(0.05)

    def close(self) -> None:
        self.link.close()

    def describe(self) -> dict:
        d = {
            "driver": "pi_e503",
            "url": self.url,
            "gain_V_per_V": self.gain,
            "axis": self.settings.axis,
            "channel": self.settings.channel,
            "monitor_V_per_V": self.settings.monitor_V_per_V,
            "identity": self._idn,
        }
        try:
            d["output_limits_V"] = list(self.output_limits())
        except DeviceError as e:
            d["output_limits_V"] = str(e)
        return d


def create(settings: E503Settings, ctx: DriverContext) -> E503Amplifier:
    amp = E503Amplifier(settings, ctx.resolve("gcs", settings.url))
    amp.identify()
    if settings.apply_voltage_limits:
        amp.set_output_limits(ctx.limits.v_min_V, ctx.limits.v_max_V)
    amp.disable()
    return amp


DRIVER = DriverInfo(
    name="pi_e503",
    role="amplifier",
    settings=E503Settings,
    create=create,
    summary="PI E-503 amplifier, E-517-style GCS 2.0 interface over a pyserial URL",
    packages=(Package("serial", "pyserial", "pip install pyserial"),),
)
