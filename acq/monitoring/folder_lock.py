"""One ``acq monitor`` per folder: an flock on ``<folder>/monitor.lock``, the file there only while a monitor runs."""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from acq.recording.storage import make_folders
from acqcore.errors import ConfigError

#: The file whose flock makes a folder one monitor's (:func:`folder_lock`).
LOCK_NAME = "monitor.lock"


@contextmanager
def folder_lock(folder: Path) -> Iterator[None]:
    """One monitor per folder: an flock on ``<folder>/monitor.lock``, which is removed when the monitor ends
    (normally, on Ctrl-C or an error; released by the kernel when the process dies, also on kill -9, which leaves
    the file: the next monitor takes it).

    The file is removed while its lock is still held, and a taker keeps its lock only if the file it locked is still
    the one at the path (same inode): a second monitor that opened the file just before the first removed it locks
    a file no longer in the folder, so it lets it go and takes the path's file anew — then two monitors can never
    each hold a lock on a different file of the same folder.
    """
    make_folders(folder)
    path = folder / LOCK_NAME
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise ConfigError(f"{folder}: another acq monitor is writing there") from None
        if _is_file_at(fd, path):
            break
        os.close(fd)  # its holder removed it as it ended: take the file at the path now
    try:
        yield
    finally:
        path.unlink(missing_ok=True)  # still locked here: see above
        os.close(fd)


def _is_file_at(fd: int, path: Path) -> bool:
    """The open file ``fd`` is the file at ``path`` (not one removed from it)."""
    try:
        at_path = os.stat(path)
    except FileNotFoundError:
        return False
    opened = os.fstat(fd)
    return (opened.st_dev, opened.st_ino) == (at_path.st_dev, at_path.st_ino)
