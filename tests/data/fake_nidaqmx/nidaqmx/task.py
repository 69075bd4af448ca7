"""``nidaqmx.Task``: every channel or write fails like the real driver's."""

from nidaqmx.errors import DaqError, driver_call, mode

GONE = (
    "Device cannot be accessed.\nPossible causes:\nDevice is no longer present in the system.\n"
    "Device is not powered."
)


class _Channels:
    def add_ao_voltage_chan(self, *args, **kwargs) -> None:
        _fail()

    def add_ai_voltage_chan(self, *args, **kwargs) -> None:
        _fail()


class _Timing:
    def cfg_samp_clk_timing(self, *args, **kwargs) -> None:
        _fail()


def _fail() -> None:
    driver_call()
    if mode() == "unplugged":
        raise DaqError(GONE, -201003)


class Task:
    def __init__(self, name: str = ""):
        driver_call()
        self.ao_channels = _Channels()
        self.ai_channels = _Channels()
        self.timing = _Timing()

    def __enter__(self) -> "Task":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def write(self, data, auto_start=False, timeout=10.0) -> int:
        _fail()
        return 0

    def read(self, number_of_samples_per_channel=1, timeout=10.0):
        _fail()
        return []

    def start(self) -> None:
        _fail()

    def stop(self) -> None:
        _fail()

    def close(self) -> None:
        pass
