"""A stand-in for NI's ``nidaqmx`` package (tests only): it imports like the real one, and its
calls fail the way the real package's do on a machine without NI's driver (``DaqNotFoundError``)
or, with ``LABRIG_FAKE_NIDAQMX=no_device`` / ``unplugged``, without the device named in the rig
file / with a device that stops answering once a task touches it (``DaqError``).

Put ``tests/data/fake_nidaqmx`` first on ``sys.path`` (``PYTHONPATH``) to use it.
"""

from nidaqmx import constants, errors, system
from nidaqmx.errors import DaqError
from nidaqmx.task import Task

__version__ = "0.0.0+labrig.stand-in"
__all__ = ["DaqError", "Task", "constants", "errors", "system"]
