"""Bounds on what ``labrig import`` reads, so that no input can exhaust memory or hang it.

Each bound is refused with exit code 2 naming the file and the bound (docs/import.md).
"""

from __future__ import annotations

#: largest input file read (bytes): text or MATLAB
MAX_FILE_BYTES = 2 * 1024**3
#: largest number of data rows in a text file
MAX_ROWS = 50_000_000
#: largest number of columns in a text file, or of signals in a MATLAB file
MAX_COLUMNS = 1000
#: largest number of numeric values in one MATLAB file (all variables together)
MAX_MAT_VALUES = 200_000_000
#: deepest nesting of MATLAB structs and cells read
MAX_STRUCT_DEPTH = 12
#: most struct or cell elements read from one MATLAB file (all levels together)
MAX_MAT_ELEMENTS = 100_000
#: time a MATLAB file may take to read before it is given up as malformed (s)
MAT_READ_TIMEOUT_S = 120.0
#: sample rates accepted (Hz), from ``--rate-hz`` or a time column
RATE_RANGE_HZ = (1e-3, 1e8)
#: how far a time step may depart from the median step (fraction) and still count as uniform
TIME_JITTER = 0.01
#: bytes of a text file looked at to find its layout (encoding, separator, header, units row)
SNIFF_BYTES = 256 * 1024
#: rows parsed per block while reading a text file (bounds the parser's working memory)
CHUNK_ROWS = 262_144
