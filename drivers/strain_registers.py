"""Modbus register map of the strain-gauge conditioner: the ONE place it is defined.

The Donghua DH3840's own Modbus map is not public; this is a map designed for labrig (a
DH3840-class bridge conditioner: excitation, gain, low-pass filter, auto-balance, calibration).
Both the driver (:mod:`labrig.drivers.strain_modbus`) and the simulator
(:mod:`labrig.drivers.sim.modbus_server`) read it from here, so a real map replaces this file.

Addresses are 0-based PDU addresses (add 30001 / 40001 for the classic 3xxxx / 4xxxx numbers).
32-bit values take two registers, high word first. Input registers (function 04) are read-only;
holding registers are read with 03 and written with 06 or 16. Out-of-range writes answer
exception 03 (illegal data value), unmapped addresses exception 02 (illegal data address).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class Register:
    name: str
    table: Literal["input", "holding"]
    address: int
    kind: Literal["uint16", "uint32", "int32", "ascii16"]
    unit: str
    description: str
    scale: float = 1.0  # physical value = raw * scale

    @property
    def count(self) -> int:
        return {"uint16": 1, "uint32": 2, "int32": 2, "ascii16": 8}[self.kind]


# input registers (function 04, read-only)
DEVICE_ID = Register("DEVICE_ID", "input", 0, "uint16", "", "device type code, 0x3840")
FIRMWARE = Register("FIRMWARE", "input", 1, "uint16", "", "firmware version, 0x0100 = 1.00")
SERIAL = Register("SERIAL", "input", 2, "uint32", "", "serial number")
MODEL = Register("MODEL", "input", 4, "ascii16", "", "model name, 16 ASCII chars, 2 per reg")
STATUS = Register("STATUS", "input", 16, "uint16", "", "status bits, see STATUS_BITS")
ERROR = Register("ERROR", "input", 17, "uint16", "", "last error code, see ERROR_CODES")
SENSITIVITY = Register(
    "SENSITIVITY",
    "input",
    18,
    "uint32",
    "mV/ue",
    "calibrated sensitivity at gain 1 and the present excitation",
    scale=1e-6,
)
BALANCE = Register(
    "BALANCE", "input", 20, "int32", "ue", "imbalance nulled by the last auto-balance", 1e-3
)
OUTPUT = Register("OUTPUT", "input", 22, "int32", "V", "present output voltage", scale=1e-6)

# holding registers (functions 03 / 06 / 16)
EXCITATION = Register(
    "EXCITATION", "holding", 256, "uint16", "V", "bridge excitation, 500..10000 mV", 1e-3
)
GAIN = Register("GAIN", "holding", 257, "uint16", "V/V", "output gain, one of GAIN_STEPS")
FILTER = Register("FILTER", "holding", 258, "uint16", "Hz", "low-pass -3 dB, 0 = off, <= 20000")
COMMAND = Register(
    "COMMAND", "holding", 259, "uint16", "", "write a COMMANDS code (runs at once); reads the last"
)

REGISTERS = (
    DEVICE_ID,
    FIRMWARE,
    SERIAL,
    MODEL,
    STATUS,
    ERROR,
    SENSITIVITY,
    BALANCE,
    OUTPUT,
    EXCITATION,
    GAIN,
    FILTER,
    COMMAND,
)

DEVICE_ID_VALUE = 0x3840
EXCITATION_RANGE_mV = (500, 10000)
GAIN_STEPS = (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000)
FILTER_MAX_HZ = 20000

STATUS_BITS = {
    0: "input over range",
    1: "excitation fault (open or shorted bridge)",
    2: "balance failed (imbalance beyond the balance range)",
    3: "low-pass filter on",
    15: "fault (any error code set)",
}
ERROR_CODES = {
    0: "no error",
    1: "excitation fault",
    2: "balance out of range",
    3: "invalid setting",
}
COMMANDS = {1: "auto-balance (zero)", 2: "clear error"}
CMD_BALANCE = 1
CMD_CLEAR_ERROR = 2


def to_registers(reg: Register, value: int | str) -> list[int]:
    """Raw value (integer, or text for ascii16) to register words, high word first."""
    if reg.kind == "ascii16":
        b = str(value).encode("ascii")[:16].ljust(16, b" ")
        return [b[i] << 8 | b[i + 1] for i in range(0, 16, 2)]
    v = int(value)
    if reg.kind == "uint16":
        return [v & 0xFFFF]
    v &= 0xFFFFFFFF
    return [v >> 16, v & 0xFFFF]


def from_registers(reg: Register, words: list[int]) -> int | str:
    """Register words (high word first) to the raw value (integer, or text for ascii16)."""
    if reg.kind == "ascii16":
        return bytes(b for w in words for b in (w >> 8, w & 0xFF)).decode("ascii", "replace")
    if reg.kind == "uint16":
        return words[0]
    v = words[0] << 16 | words[1]
    if reg.kind == "int32" and v >= 1 << 31:
        v -= 1 << 32
    return v
