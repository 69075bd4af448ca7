"""Errors meant for people: what went wrong, where (file, line, field), and what would be valid.

The CLI prints these without a traceback and exits with :attr:`LabrigError.exit_code`.
"""

from __future__ import annotations

from dataclasses import dataclass


class LabrigError(Exception):
    """An expected failure with a message for the user."""

    exit_code = 1


@dataclass
class InputIssue:
    """One problem in an input file."""

    file: str
    line: int | None
    field: str
    message: str

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}" if self.line else self.file
        fld = f" [{self.field}]" if self.field else ""
        return f"{where}:{fld} {self.message}"


class InputFileError(LabrigError):
    """A protocol, rig or data file that cannot be used as it is (exit code 2)."""

    exit_code = 2

    def __init__(self, issues: list[InputIssue]):
        self.issues = issues
        super().__init__("\n".join(str(i) for i in issues))

    def __reduce__(self) -> tuple:
        # pickled with its issues (a run file is read in a child process: labrig.store.isolated)
        return (type(self), (self.issues,))


class OptionValueError(InputFileError):
    """A command-line option's value that cannot be used, known before any file is read
    (``--rate-hz 0``, ``--window 5:1``): a usage error, exit code 64 like the values the
    parser itself refuses. An :class:`InputFileError` to Python callers."""

    exit_code = 64


def option_error(option: str, message: str) -> OptionValueError:
    """The error for a bad option value: ``--OPTION: MESSAGE`` (exit 64)."""
    return OptionValueError([InputIssue(option, None, "", message)])


class DeviceError(LabrigError):
    """An instrument failed or refused: names the device and the operation (exit code 3)."""

    exit_code = 3

    def __init__(self, device: str, operation: str, detail: str):
        self.device, self.operation, self.detail = device, operation, detail
        super().__init__(f"{device}: {operation} failed: {detail}")


class StorageError(LabrigError):
    """The run file could not be written (disk full, quota, I/O error) (exit code 3, like a
    device fault: the run stops, ramps to 0 V, and keeps what was written readable)."""

    exit_code = 3

    def __init__(self, path: str, operation: str, detail: str):
        self.path, self.operation, self.detail = path, operation, detail
        super().__init__(f"run file {path}: {operation} failed: {detail}")
