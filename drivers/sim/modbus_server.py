"""Modbus server: the simulated strain-gauge conditioner (pymodbus 3.x, on 127.0.0.1).

Serves the register map of :mod:`labrig.drivers.strain_registers` from the state of a
:class:`~labrig.drivers.sim.bench.VirtualBench`, with TCP framing (``framer="tcp"``) or RTU
framing over a TCP socket (``framer="rtu"``: pymodbus listens on ``socket://127.0.0.1:PORT`` and
a serial client reaches it through pyserial's ``socket://`` URL, exactly as through a cable).

The server runs its own asyncio loop in a daemon thread. Registers are refreshed from the bench
on every read and writes are applied to the bench (a pymodbus ``SimDevice`` action).

Faults for tests (:meth:`ModbusConditionerServer.inject`), for the next ``count`` requests:
``exception`` (answer Modbus exception ``code``, default 4 = device failure), ``timeout`` (never
answer), ``garble`` (answer with damaged bytes).
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading

from labrig.drivers import strain_registers as R
from pymodbus import FramerType
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

log = logging.getLogger("labrig.sim.modbus")

MODEL_NAME = "DH3840-SIM"
SERIAL_NUMBER = 3840001
FIRMWARE = 0x0100


class ModbusConditionerServer:
    """The conditioner simulator; ``start()`` binds a free port on 127.0.0.1 unless given."""

    def __init__(
        self, bench, framer: str = "tcp", host: str = "127.0.0.1", port: int = 0, unit: int = 1
    ):
        if framer not in ("tcp", "rtu"):
            raise ValueError("framer must be 'tcp' or 'rtu'")
        self.bench, self.framer, self.host, self.port, self.unit = bench, framer, host, port, unit
        self._faults: list[list] = []  # [kind, count, code]
        self._flock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._server = None
        self._error: BaseException | None = None
        self.requests = 0
        self._last_command = 0

    # -- lifecycle -------------------------------------------------------------------------------
    @property
    def address(self) -> str:
        """``host:port`` for TCP framing, ``socket://host:port`` for RTU framing."""
        if self.framer == "tcp":
            return f"{self.host}:{self.port}"
        return f"socket://{self.host}:{self.port}"

    def start(self) -> ModbusConditionerServer:
        ready = threading.Event()
        self._loop = asyncio.new_event_loop()

        def run():
            asyncio.set_event_loop(self._loop)
            try:
                self._loop.run_until_complete(self._start())
            except BaseException as e:  # reported to start()
                self._error = e
                ready.set()
                return
            ready.set()
            self._loop.run_forever()
            self._loop.close()

        self._thread = threading.Thread(target=run, name=f"modbus-{self.framer}", daemon=True)
        self._thread.start()
        if not ready.wait(5.0):
            raise RuntimeError("the Modbus simulator did not start within 5 s")
        if isinstance(self._error, OSError):  # e.g. the port is in use
            raise self._error
        if self._error is not None:
            # pymodbus reports a failed bind in its own words: find out whether it is the port
            refused = _bind_error(self.host, self.port)
            if refused is not None:
                raise refused
            raise RuntimeError(f"the Modbus simulator could not start: {self._error}")
        return self

    async def _start(self) -> None:
        dev = SimDevice(id=self.unit, simdata=self._simdata(), action=self._action)
        if self.framer == "tcp":
            self._server = ModbusTcpServer(
                dev, address=(self.host, self.port), trace_packet=self._trace
            )
        else:
            self._server = ModbusSerialServer(
                dev,
                framer=FramerType.RTU,
                port=f"socket://{self.host}:{self.port}",
                trace_packet=self._trace,
            )
        await self._server.serve_forever(background=True)
        self.port = self._server.transport.sockets[0].getsockname()[1]

    def stop(self) -> None:
        if self._loop is None or self._thread is None:
            return
        loop = self._loop
        if self._server is not None and loop.is_running():
            fut = asyncio.run_coroutine_threadsafe(self._server.shutdown(), loop)
            try:
                fut.result(2.0)
            except Exception as e:
                log.warning("Modbus simulator shutdown: %s", e)
        if loop.is_running():
            loop.call_soon_threadsafe(loop.stop)
        self._thread.join(2.0)
        self._thread = None

    def inject(self, kind: str, count: int = 1, code: int = 4) -> None:
        if kind not in ("exception", "timeout", "garble"):
            raise ValueError(f"unknown Modbus fault {kind!r}")
        with self._flock:
            self._faults.append([kind, count, code])

    def _take(self, kinds: tuple[str, ...]) -> list | None:
        with self._flock:
            for f in self._faults:
                if f[0] in kinds:
                    f[1] -= 1
                    if f[1] <= 0:
                        self._faults.remove(f)
                    return f
        return None

    # -- register image --------------------------------------------------------------------------
    @staticmethod
    def _simdata():
        hr = [SimData(R.EXCITATION.address, count=4, values=0, datatype=DataType.REGISTERS)]
        n_in = max(r.address + r.count for r in R.REGISTERS if r.table == "input")
        ir = [SimData(0, count=n_in, values=0, datatype=DataType.REGISTERS)]
        bits = [SimData(0, values=False, datatype=DataType.BITS)]
        return (bits, list(bits), hr, ir)

    def input_image(self) -> dict[int, int]:
        """Input-register words from the bench state (address -> word)."""
        b = self.bench
        with b.lock:
            c = b.cond
            status = (
                int(c.over_range)
                | int(c.excitation_fault) << 1
                | int(c.balance_failed) << 2
                | int(c.filter_hz > 0) << 3
                | int(c.error_code != 0) << 15
            )
            values = {
                R.DEVICE_ID: R.DEVICE_ID_VALUE,
                R.FIRMWARE: FIRMWARE,
                R.SERIAL: SERIAL_NUMBER,
                R.MODEL: MODEL_NAME,
                R.STATUS: status,
                R.ERROR: c.error_code,
                R.SENSITIVITY: round(b.sensitivity_V_per_ue() * 1e3 / R.SENSITIVITY.scale),
                R.BALANCE: round(c.balance_ue / R.BALANCE.scale),
                R.OUTPUT: round(c.output_V / R.OUTPUT.scale),
            }
        image = {}
        for reg, val in values.items():
            for k, w in enumerate(R.to_registers(reg, val)):
                image[reg.address + k] = w
        return image

    def holding_image(self) -> dict[int, int]:
        c = self.bench.cond
        return {
            R.EXCITATION.address: round(c.excitation_V / R.EXCITATION.scale),
            R.GAIN.address: int(c.gain),
            R.FILTER.address: int(c.filter_hz),
            R.COMMAND.address: self._last_command,
        }

    async def _action(self, fc, start, address, count, registers, values):
        self.requests += 1
        f = self._take(("exception",))
        if f is not None:
            return ExcCodes(f[2])
        if fc == 4:
            image = self.input_image()
        elif values is None:
            image = self.holding_image()
        else:
            err = self._write(address, list(values))
            if err is not None:
                return err
            image = self.holding_image()
        for k in range(len(registers)):
            registers[k] = image.get(start + k, 0)
        return None

    def _write(self, address: int, values: list[int]) -> ExcCodes | None:
        b = self.bench
        new = dict(zip(range(address, address + len(values)), values, strict=True))
        exc = new.get(R.EXCITATION.address)
        gain = new.get(R.GAIN.address)
        filt = new.get(R.FILTER.address)
        cmd = new.get(R.COMMAND.address)
        lo, hi = R.EXCITATION_RANGE_mV
        bad = (
            (exc is not None and not lo <= exc <= hi)
            or (gain is not None and gain not in R.GAIN_STEPS)
            or (filt is not None and filt > R.FILTER_MAX_HZ)
            or (cmd is not None and cmd not in (0, *R.COMMANDS))
        )
        if bad:
            with b.lock:
                b.cond.error_code = 3
            return ExcCodes.ILLEGAL_VALUE
        with b.lock:
            if exc is not None:
                b.cond.excitation_V = exc * R.EXCITATION.scale
            if gain is not None:
                b.cond.gain = int(gain)
            if filt is not None and filt != b.cond.filter_hz:
                b.set_filter(filt)
            if cmd is not None:
                self._last_command = cmd
            if cmd == R.CMD_CLEAR_ERROR:
                b.cond.error_code = 1 if b.cond.excitation_fault else 0
                b.cond.balance_failed = False
            elif cmd == R.CMD_BALANCE:
                b.balance()
        return None

    def _trace(self, sending: bool, data: bytes) -> bytes:
        if not sending:
            return data
        f = self._take(("timeout", "garble"))
        if f is None:
            return data
        if f[0] == "timeout":
            log.info("fault: not answering a Modbus request")
            return b""
        damaged = bytearray(data)
        for i in range(len(damaged) // 2, len(damaged)):
            damaged[i] ^= 0x5A
        return bytes(damaged)


def _bind_error(host: str, port: int) -> OSError | None:
    """The OSError binding ``host:port`` gives now (None if it binds, or for port 0)."""
    if not port:
        return None
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as e:
            return e
    return None
