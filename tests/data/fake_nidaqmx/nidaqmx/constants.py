"""The enumerations labrig uses."""

import enum


class AcquisitionType(enum.Enum):
    FINITE = 10178
    CONTINUOUS = 10123


class TerminalConfiguration(enum.Enum):
    DEFAULT = -1
    RSE = 10083
    NRSE = 10078
    DIFF = 10106
    PSEUDO_DIFF = 12529
