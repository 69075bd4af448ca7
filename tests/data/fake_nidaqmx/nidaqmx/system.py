"""``nidaqmx.system``: the local system and its devices."""

from nidaqmx.errors import DaqError, driver_call, mode

#: the device the stand-in has (``no_device``: another one)
PRESENT = "Dev1"


class Device:
    def __init__(self, name: str):
        self.name = name

    @property
    def product_type(self) -> str:
        driver_call()
        if self.name != PRESENT or mode() == "no_device":
            raise DaqError(f"Device identifier is invalid.\nDevice Specified: {self.name}", -200220)
        return "USB-6361 (BNC)"

    @property
    def dev_serial_num(self) -> int:
        return 0x1234ABCD


class System:
    @staticmethod
    def local() -> "System":
        return System()

    @property
    def devices(self) -> list[Device]:
        driver_call()
        return [Device("Dev7" if mode() == "no_device" else PRESENT)]
