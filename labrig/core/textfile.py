"""Reading a small input file (a protocol, a rig, a parameter or diagnosis file) within a size
limit, whatever the path names.

``Path.read_bytes`` reads until the end of the file: given ``/dev/zero`` (or another device, a
pipe that never closes) it reads until memory runs out (24 GB on the shared host before the
kernel stopped it). Only regular files are read here, and never more than the limit plus one
byte.
"""

from __future__ import annotations

import errno
import stat
from pathlib import Path

__all__ = ["read_bytes_bounded", "read_text_bounded"]


def read_bytes_bounded(path: Path | str, max_bytes: int) -> bytes:
    """The bytes of the regular file ``path``.

    Raises
    ------
    OSError
        As :func:`open` does (not found, permission, a directory), and with ``strerror``
        "not a regular file" for a device, a pipe or a socket.
    ValueError
        For a file of more than ``max_bytes`` bytes ("larger than ... MB").
    """
    p = Path(path)
    try:
        mode = p.stat().st_mode
    except FileNotFoundError:
        mode = None  # open() says so
    # checked before opening: opening a pipe waits for a writer
    if mode is not None and not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        raise OSError(errno.EINVAL, "not a regular file (a device, a pipe or a socket)", str(p))
    with p.open("rb") as fh:
        data = fh.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise ValueError(f"larger than {max_bytes / 1e6:g} MB")
    return data


def read_text_bounded(path: Path | str, max_bytes: int) -> str:
    """:func:`read_bytes_bounded` decoded as UTF-8 (:class:`UnicodeDecodeError` otherwise)."""
    return read_bytes_bounded(path, max_bytes).decode("utf-8")
