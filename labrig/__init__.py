"""labrig: piezo-actuator experiments on real or simulated rigs, logged to HDF5, compared with a
fractional-order dynamic hysteresis model."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("labrig")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"
