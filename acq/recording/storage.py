"""Writing files so that a failed write is a failure: named, one line, no temp file left behind, and durable.

Every output of acq (result JSON, report PNG, CSV export, imported session) is written to a temp
file in the destination folder and renamed over the destination only when complete, so a reader
never sees half a file; on any error the temp file is removed and a :class:`StorageError` names
the destination and the cause ("disk full: /data/x.result.json").

Durable means on the disk, not only in the kernel's page cache: a power cut or a kernel crash loses what a closed
file or a rename left there, in any order. So the temp file's data is synced before the rename and its folder after
it (a new name is durable only once the folder holding it is synced), and a folder acq makes has its parent synced
(:func:`make_folders`). A failed sync is a failed write ("I/O error: <file>"): on Linux the pages it could not write
may already be dropped from the cache, so retrying it proves nothing. A failed sync of the folder after the rename is
one too (exit 1), but the file is complete under its name and the message says so (:func:`replace_durably`).
"""

from __future__ import annotations

import errno
import glob
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from acq.process_signals import signals_deferred
from acqcore.errors import StorageError

_CAUSES = {
    errno.ENOSPC: "disk full",
    errno.EDQUOT: "disk quota exceeded",
    errno.EFBIG: "file size limit reached",  # RLIMIT_FSIZE (ulimit -f) or the file system's largest file
    errno.EIO: "I/O error",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
    errno.ENOENT: "folder vanished",
}


#: errnos of a write the storage refused (read-only, full, I/O, no permission): a failed write (exit 1), not bad input.
WRITE_FAILURES = frozenset(_CAUSES) - {errno.ENOENT}


def cause_of(e: BaseException) -> str:
    """A short cause for an OS error ("disk full", "I/O error", …), else its first line."""
    code = getattr(e, "errno", None)
    if code in _CAUSES:
        return _CAUSES[code]
    full = str(e)
    if "No space left" in full or "errno = 28" in full:  # HDF5 reports the errno inside its (multi-line) message
        return "disk full"
    if "errno = 27," in full or "File too large" in full:
        return _CAUSES[errno.EFBIG]
    if "errno = 5," in full or "Input/output error" in full:
        return "I/O error"
    if isinstance(e, OSError) and e.strerror and e.filename is not None:  # the caller names the path (not a temp one)
        return e.strerror[0].lower() + e.strerror[1:]
    return full.splitlines()[0] if full else type(e).__name__


def out_of_room(e: BaseException) -> bool:
    """Whether the write failed only for room (disk full, quota exceeded, the file at its size limit): the storage
    itself is sound, and what is on it may be overwritten in place (unlike after an I/O error, when nothing more
    should be written)."""
    return cause_of(e) in (_CAUSES[errno.ENOSPC], _CAUSES[errno.EDQUOT], _CAUSES[errno.EFBIG])


def storage_error(e: BaseException, path: Path | str) -> StorageError:
    """The one-line error for a failed write of ``path``: ``<cause>: <path>``."""
    return StorageError(f"{cause_of(e)}: {path}")


def refused_write(folder: Path | str) -> str | None:
    """Why this process may not write into the existing ``folder`` ("read-only file system", "permission denied"),
    or None when it may (or the folder does not exist): for a library that says only that it failed (SQLite's
    "unable to open database file")."""
    if not Path(folder).is_dir() or os.access(folder, os.W_OK):
        return None
    try:
        return _CAUSES[errno.EROFS] if os.statvfs(folder).f_flag & os.ST_RDONLY else _CAUSES[errno.EACCES]
    except OSError:
        return _CAUSES[errno.EACCES]


def free_bytes(folder: Path | str) -> int:
    """Bytes an unprivileged writer can still put into the file system holding ``folder``."""
    st = os.statvfs(folder)
    return st.f_bavail * st.f_frsize


def _nearly_full(folder: Path) -> bool:
    try:
        return free_bytes(folder) < 1 << 16
    except OSError:
        return False


def sync_file(path: Path | str) -> None:
    """Make the data and size of the file at ``path`` durable (fsync through a descriptor of its own: Linux syncs
    the inode's pages whichever descriptor wrote them)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


#: What a folder's sync may answer where the file system or the folder's permissions do not let a folder be synced
#: (SMB/CIFS and some FUSE file systems refuse fsync of a directory with EINVAL; a folder writable but not readable
#: cannot be opened for it): its names are then as durable as that file system makes them, as SQLite treats the same
#: answers (os_unix.c ignores a directory it cannot open or sync). An I/O error (EIO, ENOSPC) is never among them.
FOLDER_SYNC_UNSUPPORTED = frozenset({errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EACCES, errno.EPERM})


def sync_folder(folder: Path | str) -> None:
    """Make the names created, renamed or removed in ``folder`` durable (fsync of the folder); a file system or
    folder that does not allow it (:data:`FOLDER_SYNC_UNSUPPORTED`) is left as it is, any other error raised."""
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError as e:
        if e.errno in FOLDER_SYNC_UNSUPPORTED:
            return
        raise
    try:
        os.fsync(fd)
    except OSError as e:
        if e.errno not in FOLDER_SYNC_UNSUPPORTED:
            raise
    finally:
        os.close(fd)


def make_folders(folder: Path | str) -> None:
    """``mkdir -p folder`` whose new folders are durable: each one made has the folder holding it synced.
    Raises the :class:`OSError` of ``mkdir`` or of a sync as it is (callers name the folder)."""
    target = Path(folder)
    missing = [p for p in (target, *target.parents) if not p.exists()][::-1]  # outermost first
    target.mkdir(parents=True, exist_ok=True)
    for made in missing:
        sync_folder(made.parent)


def replace_durably(tmp: Path | str, target: Path | str, *, exclusive: bool = False) -> None:
    """Rename the complete file ``tmp`` over ``target`` so that a power cut leaves either the old ``target`` or the
    whole new one: ``tmp``'s data synced before the rename, the folder after it. Raises the :class:`OSError` of the
    file's sync or the rename as is; a failed sync of the folder, after the rename, raises a :class:`StorageError`
    that says what is true: "<target>: written, but its name may not survive a power cut (I/O error when syncing its
    folder)" — still a failed write (exit 1): what acq reports as written survives a power cut, and this may not.

    With ``exclusive`` an existing ``target`` is never replaced (:class:`FileExistsError`, ``tmp`` kept), also one
    another process makes meanwhile: a check before writing leaves a window in which two writers both find the name
    free and the second rename silently replaces the first's file."""
    sync_file(tmp)
    if exclusive:
        _rename_no_replace(tmp, target)
    else:
        os.replace(tmp, target)
    try:
        sync_folder(Path(target).parent)
    except OSError as e:
        raise StorageError(f"{target}: written, but its name may not survive a power cut ({cause_of(e)} when syncing "
                           "its folder)") from None


def _rename_no_replace(tmp: Path | str, target: Path | str) -> None:
    """Give ``tmp`` the name ``target`` unless that exists (:class:`FileExistsError`): a hard link, made only when the
    name is free, then the temp name removed. A file system without hard links (FAT, exFAT on a USB stick: EPERM)
    takes the name by creating ``target`` with ``O_EXCL`` and renaming over that placeholder."""
    try:
        os.link(tmp, target)
    except FileExistsError:
        raise
    except OSError as e:
        if e.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.EMLINK, errno.ENOSYS):
            raise
        # Ctrl-C / SIGTERM held back over the placeholder and the rename: raised as os.open returned it left the
        # placeholder; as os.replace returned, the handler below removed the complete file (the review)
        with signals_deferred():
            os.close(os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
            try:
                os.replace(tmp, target)
            except OSError:
                with suppress(OSError):  # the empty placeholder would make every later try "exists"
                    os.unlink(target)
                raise
        return
    with suppress(OSError):  # the target is complete under its name; a temp name left over is only clutter
        os.unlink(tmp)


@contextmanager
def atomic_path(path: Path | str, *, exclusive: bool = False) -> Iterator[Path]:
    """Yield a temp path beside ``path``; rename it to ``path`` when the block succeeds (:func:`replace_durably`:
    what the block wrote is on the disk before the rename, the rename is on it when this returns). With
    ``exclusive`` an existing ``path`` is kept: :class:`FileExistsError` (``filename2`` is ``path``), the temp removed.

    On any exception the temp file is removed; an :class:`OSError` becomes a :class:`StorageError`
    naming ``path``. The temp name is unique per writer (two writers never share one). A folder that exists but
    takes no new file (``/proc``: ENOENT, which elsewhere means the folder vanished) is "cannot write a file there".
    """
    target = Path(path)
    try:
        fd, name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.",
                                   suffix=f".tmp{target.suffix}")  # the suffix kept: writers infer the format
    except OSError as e:
        if isinstance(e, FileNotFoundError) and target.parent.is_dir():
            raise StorageError(f"cannot write a file there: {target}") from None
        raise storage_error(e, target) from None
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.chmod(tmp, 0o644)
        replace_durably(tmp, target, exclusive=exclusive)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        if exclusive and isinstance(e, FileExistsError):  # this one's or a nested exclusive one's: not a failed write
            raise
        if e.errno is None:  # a library's own "could not write" (e.g. Qt's image writer): say why — a folder that
            # turned read-only (a file system remounted ro on an error) before a full one: a tiny read-only mount has
            # next to no free bytes too, and was called "disk full"
            refused = refused_write(target.parent)
            if refused is not None:
                raise StorageError(f"{refused}: {target}") from None
            e = OSError(errno.ENOSPC, "") if _nearly_full(target.parent) else OSError(errno.EIO, "write failed")
        raise storage_error(e, target) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def remove_temp_files(path: Path | str) -> None:
    """Remove temp files :func:`atomic_path` left for ``path`` (its writer was killed before it could)."""
    target = Path(path)
    for tmp in target.parent.glob(f".{glob.escape(target.name)}.*.tmp{target.suffix}"):
        tmp.unlink(missing_ok=True)


def write_text_atomically(path: Path | str, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a temp file; see :func:`atomic_path`."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
