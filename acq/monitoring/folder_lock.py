"""One ``acq monitor`` per folder: an flock on ``<folder>/monitor.lock``, the file there only while a monitor runs; and
a run that filed nothing leaves nothing of its own behind (:func:`removed_unless_used`)."""

from __future__ import annotations

import fcntl
import os
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager, suppress
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


@contextmanager
def removed_unless_used(files: Iterable[Path], folder: Path, used: Callable[[], bool]) -> Iterator[None]:
    """Of ``files`` (a catalogue file with its SQLite companions, an identity) and ``folder`` with its parents, those
    that do not exist before the block are removed after it unless ``used()`` (a monitor whose devices failed to open
    left an empty catalogue and its folders behind); a folder only when empty."""
    made = [p for p in files if not p.exists()]
    folders = [f for f in (folder, *folder.parents) if not f.exists()]  # the deepest first
    try:
        yield
    finally:
        if not used():
            for path in made:
                for left in (path, *(path.with_name(path.name + end) for end in ("-wal", "-shm", "-journal"))):
                    left.unlink(missing_ok=True)
            with suppress(OSError):
                for f in folders:
                    f.rmdir()
