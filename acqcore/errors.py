"""The one error type people see, and its kinds.

Exception tree (each kind maps to a process exit code in ``acq.ui.cli``)::

    AcqError                      one line for people; ``kind`` selects the exit code
     ├── ConfigError              bad input: config file, option, session file  -> exit 2
     ├── DeviceError              a device failed, is missing or timed out      -> exit 1
     └── StorageError             a file could not be written (disk full, I/O)  -> exit 1

Drivers raise these with a message that names the device, channel, file, key or value.
"""

from __future__ import annotations

from typing import Literal

ErrorKind = Literal["input", "device", "storage"]

#: Exit code of a command stopped by Ctrl-C or SIGTERM (128 + SIGINT, as a shell reports a process it interrupted).
EXIT_INTERRUPTED = 130


class AcqError(Exception):
    """An error with a one-line message meant for the person at the bench."""

    kind: ErrorKind = "input"

    @property
    def exit_code(self) -> int:
        """Process exit code: 2 for bad input, 1 for a failed device or write."""
        return 2 if self.kind == "input" else 1


class ConfigError(AcqError):
    """Bad input: a config file, a command-line value or a session file."""

    kind: ErrorKind = "input"


class DeviceError(AcqError):
    """A device is missing, refused a setting, stopped answering or reported an error."""

    kind: ErrorKind = "device"


class StorageError(AcqError):
    """A write failed (disk full, I/O error, the folder vanished); the message names the file."""

    kind: ErrorKind = "storage"
