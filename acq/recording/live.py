"""A running recorder's mark on its session file, so nothing rewrites a file that is still being written.

The writer creates its session file and holds a Linux open-file-description lock (``F_OFD_SETLK``, write lock over
the whole file) on it until it has finished the file; :func:`being_recorded` asks for it without taking anything.
The kernel drops the lock when the recorder's process ends in any way (also kill -9), so a killed recorder's file
is repairable at once.

Why not ``flock``: HDF5 itself takes ``flock`` locks on the file — a reader holds a shared one for as long as it has
the file open (an analysis, the monitor's window worker), and the SWMR writer drops its own once it switches to SWMR
mode — so an ``flock`` could not tell a recorder from a reader. OFD locks are independent of ``flock`` on local file
systems (on NFS the kernel emulates ``flock`` with the same byte-range locks: keep sessions on a local disk).
"""

from __future__ import annotations

import fcntl
import os
import struct
from pathlib import Path
from typing import BinaryIO

from acqcore.errors import ConfigError

#: Linux ``struct flock`` with a 64-bit ``off_t`` (l_type, l_whence, l_start, l_len, l_pid, padded to 32 bytes), as
#: ``F_OFD_SETLK``/``F_OFD_GETLK`` take it: Python's fcntl has no binding that builds it. l_len 0: to the end of the
#: file, however long it grows; l_pid must be 0 for OFD locks.
_FLOCK = struct.Struct("hhqqi4x")


class SessionBeingRecorded(ConfigError):
    """A session file a running recorder still writes: not to be rewritten."""


def create_marked(path: Path) -> BinaryIO:
    """Create ``path`` (``FileExistsError`` if it exists) and mark it as being recorded until the returned file is
    closed or the process ends. A file system that has no such locks gets the file unmarked (the recording matters
    more than the mark)."""
    marker = open(path, "xb")  # noqa: SIM115 - held open for the whole recording: closing it ends the mark
    try:
        fcntl.fcntl(marker.fileno(), fcntl.F_OFD_SETLK, _FLOCK.pack(fcntl.F_WRLCK, os.SEEK_SET, 0, 0, 0))
    except OSError:
        pass
    return marker


def being_recorded(path: Path) -> bool:
    """Whether a running recorder holds ``path`` (see :func:`create_marked`); False when it cannot be asked."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        held = fcntl.fcntl(fd, fcntl.F_OFD_GETLK, _FLOCK.pack(fcntl.F_RDLCK, os.SEEK_SET, 0, 0, 0))
    except OSError:
        return False
    finally:
        os.close(fd)
    return _FLOCK.unpack(held)[0] != fcntl.F_UNLCK


def refuse_if_recorded(path: Path) -> None:
    """Raise :class:`SessionBeingRecorded` when a running recorder holds ``path``."""
    if being_recorded(path):
        raise SessionBeingRecorded(f"{path}: being recorded by a running recorder — not modified (wait until it "
                                   "finishes)")
