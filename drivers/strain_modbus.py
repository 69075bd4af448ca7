"""Strain-gauge conditioner (DH3840-class) over Modbus TCP or Modbus RTU, with pymodbus 3.x.

The register map is :mod:`labrig.drivers.strain_registers` (designed for labrig: the DH3840's own
map is not public). ``transport: tcp`` takes ``address: host:port``; ``transport: rtu`` takes a
serial port or any pyserial URL (``/dev/ttyUSB0``, ``COM4``, ``socket://host:port``).

Every Modbus failure becomes a :class:`~labrig.core.errors.DeviceError` naming the conditioner and
the operation (with the register): no answer within ``timeout_s``, an exception response (its code
and meaning), a damaged frame, or a lost connection. The link is closed after a failure and
reopened by the next call (every operation here is safe to repeat).
"""

from __future__ import annotations

import contextlib
import logging

from labrig.drivers import strain_registers as R
from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator
from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ModbusException

from labrig.core.errors import DeviceError
from labrig.rig.instruments import ConditionerStatus, DriverContext, DriverInfo, Package

log = logging.getLogger("labrig.drivers.strain_modbus")
# pymodbus logs frame dumps on every failure; ours are reported as DeviceError instead
logging.getLogger("pymodbus.logging").setLevel(logging.CRITICAL)

EXCEPTION_CODES = {
    1: "illegal function",
    2: "illegal data address",
    3: "illegal data value",
    4: "device failure",
    5: "acknowledge",
    6: "device busy",
}


class StrainModbusSettings(BaseModel):
    """Rig-file section of the ``strain_modbus`` driver."""

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)

    driver: str = "strain_modbus"
    transport: str = Field("tcp", pattern="^(tcp|rtu)$", description="tcp or rtu")
    address: str = Field("sim", description="tcp: host:port; rtu: port or pyserial URL; 'sim'")
    unit: int = Field(1, ge=1, le=247, description="Modbus unit (device) id")
    baudrate: int = Field(19200, gt=0, description="rtu only")
    timeout_s: float = Field(0.5, gt=0, le=30)
    excitation_V: float = Field(2.0, ge=0.5, le=10.0)
    gain: int = Field(1, description=f"one of {R.GAIN_STEPS}")
    filter_hz: int = Field(0, ge=0, le=R.FILTER_MAX_HZ, description="0 = off")
    sensitivity_mV_per_ue: float | None = Field(
        1.085, gt=0, description="calibration at gain 1 and this excitation; null: ask the device"
    )
    zero_on_open: bool = Field(True, description="auto-balance when the rig opens")

    @field_validator("address")
    @classmethod
    def _tcp_address(cls, v: str, info: ValidationInfo) -> str:
        if info.data.get("transport", "tcp") == "tcp" and v != "sim":
            host, sep, port = v.rpartition(":")
            if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
                raise ValueError(f"a tcp address is host:port with a port 1-65535, got {v!r}")
        return v

    @field_validator("gain")
    @classmethod
    def _gain(cls, v: int) -> int:
        if v not in R.GAIN_STEPS:
            raise ValueError(f"gain must be one of {list(R.GAIN_STEPS)}")
        return v


class ModbusConditioner:
    """The :class:`~labrig.rig.instruments.Conditioner` role over Modbus."""

    def __init__(self, settings: StrainModbusSettings, address: str | None = None):
        self.settings = settings
        self.address = address or settings.address
        self.device = (
            f"conditioner (Modbus {settings.transport} {self.address} unit {settings.unit})"
        )
        self._client: ModbusTcpClient | ModbusSerialClient | None = None
        self._gain = float(settings.gain)
        self._idn: str | None = None

    # -- link --------------------------------------------------------------------------------
    def _connect(self, operation: str):
        if self._client is not None:
            return self._client
        s = self.settings
        try:
            if s.transport == "tcp":
                host, _, port = self.address.rpartition(":")
                if not host or not port.isdigit():
                    raise DeviceError(self.device, operation, "address must be host:port")
                client: ModbusTcpClient | ModbusSerialClient = ModbusTcpClient(
                    host, port=int(port), timeout=s.timeout_s, retries=0
                )
            else:
                client = ModbusSerialClient(
                    self.address,
                    framer=FramerType.RTU,
                    baudrate=s.baudrate,
                    timeout=s.timeout_s,
                    retries=0,
                )
            ok = client.connect()
        except DeviceError:
            raise
        except Exception as e:
            raise DeviceError(self.device, operation, f"cannot connect: {e}") from e
        if not ok:
            client.close()
            raise DeviceError(self.device, operation, "cannot connect (no answer at the address)")
        self._client = client
        return client

    def _drop(self) -> None:
        if self._client is not None:
            with contextlib.suppress(Exception):
                self._client.close()
            self._client = None

    def _call(self, operation: str, reg: R.Register, fn_name: str, *args, **kw):
        where = f"{operation} ({reg.table} register {reg.address} {reg.name})"
        client = self._connect(where)
        try:
            resp = getattr(client, fn_name)(*args, device_id=self.settings.unit, **kw)
        except ModbusException as e:
            self._drop()
            text = str(e)
            if "No response" in text:
                t = self.settings.timeout_s
                text = f"no valid answer within {t:g} s (no reply or a damaged frame)"
            raise DeviceError(self.device, where, text) from e
        except (OSError, ValueError, AttributeError) as e:
            self._drop()
            raise DeviceError(self.device, where, f"link failure: {e}") from e
        if resp.isError():
            code = getattr(resp, "exception_code", None)
            meaning = EXCEPTION_CODES.get(code, "unknown") if code is not None else "unknown"
            raise DeviceError(self.device, where, f"Modbus exception {code} ({meaning})")
        return resp

    def read(self, reg: R.Register, operation: str = "read") -> int | str:
        fn = "read_input_registers" if reg.table == "input" else "read_holding_registers"
        resp = self._call(operation, reg, fn, reg.address, count=reg.count)
        words = list(resp.registers)
        if len(words) != reg.count:
            self._drop()
            raise DeviceError(
                self.device, f"{operation} ({reg.name})", f"expected {reg.count} words, got {words}"
            )
        return R.from_registers(reg, words)

    def write(self, reg: R.Register, raw: int, operation: str = "write") -> None:
        if reg.table != "holding":
            raise ValueError(f"{reg.name} is read-only")
        self._call(operation, reg, "write_register", reg.address, int(raw))

    # -- the Conditioner role ------------------------------------------------------------------
    def identify(self) -> str:
        dev = self.read(R.DEVICE_ID, "identify")
        model = str(self.read(R.MODEL, "identify")).strip()
        serial_no = self.read(R.SERIAL, "identify")
        fw = int(self.read(R.FIRMWARE, "identify"))
        if dev != R.DEVICE_ID_VALUE:
            raise DeviceError(self.device, "identify", f"unexpected device id 0x{dev:04X}")
        self._idn = f"{model}, SN {serial_no}, firmware {fw >> 8}.{fw & 0xFF:02d}"
        return self._idn

    def configure(self, excitation_V: float, gain: float, filter_hz: float) -> None:
        if int(gain) != gain or int(gain) not in R.GAIN_STEPS:
            raise DeviceError(self.device, "configure", f"gain must be one of {R.GAIN_STEPS}")
        self.write(R.EXCITATION, round(excitation_V / R.EXCITATION.scale), "configure")
        self.write(R.GAIN, int(gain), "configure")
        self.write(R.FILTER, round(filter_hz), "configure")
        self._gain = float(self.read(R.GAIN, "configure"))

    def zero(self) -> None:
        self.write(R.COMMAND, R.CMD_BALANCE, "zero")
        st = self.status()
        if st.balance_failed:
            raise DeviceError(self.device, "zero", "balance failed: " + "; ".join(st.problems()))

    def status(self) -> ConditionerStatus:
        bits = int(self.read(R.STATUS, "status"))
        code = int(self.read(R.ERROR, "status"))
        return ConditionerStatus(
            over_range=bool(bits & 1),
            excitation_fault=bool(bits & 2),
            balance_failed=bool(bits & 4),
            error_code=code,
            filter_on=bool(bits & 8),
            detail=f"STATUS=0x{bits:04X} ({R.ERROR_CODES.get(code, 'unknown error')})",
        )

    def check(self) -> None:
        st = self.status()
        if not st.ok:
            raise DeviceError(self.device, "status check", "; ".join(st.problems()))

    def sensitivity_mV_per_ue(self) -> float:
        if self.settings.sensitivity_mV_per_ue is not None:
            return float(self.settings.sensitivity_mV_per_ue)
        return int(self.read(R.SENSITIVITY, "sensitivity")) * R.SENSITIVITY.scale

    def device_sensitivity_mV_per_ue(self) -> float:
        return int(self.read(R.SENSITIVITY, "sensitivity")) * R.SENSITIVITY.scale

    def gain(self) -> float:
        return self._gain

    def read_output_V(self) -> float:
        return int(self.read(R.OUTPUT, "read_output")) * R.OUTPUT.scale

    def close(self) -> None:
        self._drop()

    def describe(self) -> dict:
        d = {
            "driver": "strain_modbus",
            "transport": self.settings.transport,
            "address": self.address,
            "unit": self.settings.unit,
            "identity": self._idn,
            "gain": self._gain,
            "calibration_sensitivity_mV_per_ue": self.settings.sensitivity_mV_per_ue,
        }
        try:
            d["excitation_V"] = int(self.read(R.EXCITATION, "describe")) * R.EXCITATION.scale
            d["filter_hz"] = int(self.read(R.FILTER, "describe"))
            d["device_sensitivity_mV_per_ue"] = self.device_sensitivity_mV_per_ue()
        except DeviceError as e:
            d["error"] = str(e)
        return d


def create(settings: StrainModbusSettings, ctx: DriverContext) -> ModbusConditioner:
    kind = "modbus_tcp" if settings.transport == "tcp" else "modbus_rtu"
    cond = ModbusConditioner(settings, ctx.resolve(kind, settings.address))
    try:
        cond.identify()
        cond.configure(settings.excitation_V, settings.gain, settings.filter_hz)
        if settings.zero_on_open:
            cond.zero()
    except Exception:
        cond.close()
        raise
    return cond


DRIVER = DriverInfo(
    name="strain_modbus",
    role="conditioner",
    settings=StrainModbusSettings,
    create=create,
    summary="strain-gauge conditioner (DH3840-class), labrig register map, Modbus TCP or RTU",
    packages=(Package("pymodbus", "pymodbus", "pip install 'pymodbus>=3.16,<3.17'"),),
)
