"""The error classes of nidaqmx (same names and bases as the real package's)."""

import os


class Error(Exception):
    """Base error class of the module."""


class DaqNotFoundError(Error):
    """Raised when the NI-DAQmx driver is not installed."""


class DaqNotSupportedError(Error):
    """Raised when NI-DAQmx is not supported on this platform."""


class DaqError(Error):
    """An error the NI-DAQmx driver reports, with its status code."""

    def __init__(self, message: str, error_code: int, task_name: str = ""):
        text = message
        if task_name:
            text += f"\nTask Name: {task_name}"
        text += f"\n\nStatus Code: {error_code}"
        super().__init__(text)
        self.error_code = error_code


NOT_FOUND = (
    "Could not find an installation of NI-DAQmx. Please ensure that NI-DAQmx is installed on "
    "this machine or contact National Instruments for support."
)


def mode() -> str:
    """``no_runtime`` (default), ``no_device`` or ``unplugged``."""
    return os.environ.get("LABRIG_FAKE_NIDAQMX", "no_runtime")


def driver_call() -> None:
    """What every call into NI's driver does first: fail when there is no driver."""
    if mode() == "no_runtime":
        raise DaqNotFoundError(NOT_FOUND)
