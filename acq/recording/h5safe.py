"""HDF5 with bounds: open damaged files without hanging, drop a writer after a failed write without crashing.

Nothing here knows the session layout (that is :mod:`acq.recording.layout`); these are the library-level
guards it needs, each written by hand because h5py has no binding for it:

* **Truncation before opening.** The superblock records the file's end-of-file address; a file
  shorter than that was cut. :func:`superblock_eof` reads it (HDF5 file format spec, "Superblock").
* **A tail of zeros.** :func:`zero_tail_start` finds where the zero bytes that end a file begin (a cut copy that
  was pre-allocated to its full size).
* **Bounded metadata reads.** A reader opened with ``swmr=True`` retries every metadata block whose
  checksum fails up to 100 times with growing sleeps (HDF5 ``H5Pset_metadata_read_attempts``,
  default 100 for SWMR) — on a file cut to 10 % that is minutes inside one h5py call, which Ctrl-C
  cannot interrupt. :func:`open_read` sets the attempts to :data:`READ_ATTEMPTS` through ctypes on
  the libhdf5 h5py loaded (h5py does not wrap that call).
* **Abandoning a writer.** After a write error (ENOSPC, EIO) HDF5's state for that file is
  unreliable: closing it rewrites the failed blocks and can crash the process (seen: SIGSEGV,
  ``free(): invalid pointer``). :func:`abandon` points the file descriptor at ``/dev/null`` first,
  so the close completes and nothing after the failure reaches the disk.
* **Reopening an abandoned file.** Its superblock still says it is open for SWMR writing, and HDF5 refuses to open it
  for writing again ("file is already open for write"). :func:`open_abandoned` clears those flags as ``h5clear -s``
  does (the file-access property ``clear_status_flags``, set through ``H5Pset``), so the writer can finish the file:
  what its flushes committed was synced before the failed write began.
"""

from __future__ import annotations

import ctypes
import functools
import os
import struct
from pathlib import Path

import h5py

_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: Metadata read attempts for readers: a few (a live writer may be caught mid-update), not 100.
READ_ATTEMPTS = 4


def superblock_eof(path: Path) -> int | None:
    """The end-of-file address the superblock records (base address included), or None if unknown.

    The superblock sits at byte 0, 512, 1024, 2048, … (after a user block). Versions 0/1 keep the
    EOF address after 16 (v0) or 20 (v1) bytes of small fields and two addresses; versions 2/3 after
    4 bytes and two addresses (base, superblock extension).
    """
    size = path.stat().st_size
    with path.open("rb") as f:
        offset = 0
        while offset + 64 <= size:
            f.seek(offset)
            head = f.read(64)
            if head[:8] == _SIGNATURE:
                break
            offset = 512 if offset == 0 else offset * 2
        else:
            return None
    version = head[8]
    if version in (0, 1):
        o = head[13]
        fields = 24 if version == 0 else 28
    elif version in (2, 3):
        o = head[9]
        fields = 12
    else:
        return None
    if o not in (4, 8) or fields + 3 * o > len(head):
        return None
    fmt = "<I" if o == 4 else "<Q"
    base = struct.unpack_from(fmt, head, fields)[0]
    eof = struct.unpack_from(fmt, head, fields + 2 * o)[0]
    return base + eof


def zero_tail_start(path: Path, block: int = 1 << 20) -> int:
    """Where the run of zero bytes that ends the file begins (its size when the last byte is not 0): a copier or
    downloader that pre-allocates the whole file and is cut leaves the rest zero; read backwards ``block`` bytes at a
    time, so a file that does not end in zeros costs one read."""
    with path.open("rb") as f:
        end = f.seek(0, os.SEEK_END)
        while end > 0:
            start = max(0, end - block)
            f.seek(start)
            data = f.read(end - start)
            last = len(data.rstrip(b"\0"))
            if last:
                return start + last
            end = start
    return 0


@functools.cache
def _libhdf5() -> ctypes.CDLL | None:
    """The libhdf5 h5py runs on (found among the process's mapped files), or None."""
    try:
        with open("/proc/self/maps", "rb") as maps:  # bytes: a mapped file's path need not be UTF-8 (a Latin-1 folder)
            names = {os.fsdecode(line.split()[-1]) for line in maps if b"libhdf5" in line and b"libhdf5_hl" not in line}
    except OSError:
        return None
    for name in sorted(names):
        try:
            lib = ctypes.CDLL(name)
        except OSError:
            continue
        if hasattr(lib, "H5Pset_metadata_read_attempts"):
            lib.H5Pset_metadata_read_attempts.argtypes = [ctypes.c_int64, ctypes.c_uint]
            return lib
    return None


def open_read(path: Path) -> h5py.File:
    """Open ``path`` read-only as an SWMR reader with bounded metadata read attempts.

    HDF5's file lock is taken where the file system has locks and skipped where it has none (``best-effort``: a
    network share mounted without them answers ENOSYS, which would otherwise refuse every read); a lock another
    process holds still refuses the open (errno 11, :mod:`acq.recording.reader` says so).
    """
    lib = _libhdf5()
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_fclose_degree(h5py.h5f.CLOSE_STRONG)
    fapl.set_file_locking(True, ignore_when_disabled=True)
    if lib is None or lib.H5Pset_metadata_read_attempts(fapl.id, READ_ATTEMPTS) < 0:
        return h5py.File(path, "r", swmr=True, locking="best-effort")  # HDF5's default attempts
    fid = h5py.h5f.open(os.fsencode(path), h5py.h5f.ACC_RDONLY | h5py.h5f.ACC_SWMR_READ, fapl=fapl)
    return h5py.File(fid)


def abandon(f: h5py.File) -> None:
    """Close a file whose last write failed without writing anything more to it (see module doc)."""
    try:
        fd = f.id.get_vfd_handle()
        null = os.open(os.devnull, os.O_RDWR)
        try:
            os.dup2(null, fd)
        finally:
            os.close(null)
    except Exception:  # noqa: BLE001 - no descriptor to redirect: close as it is
        pass
    try:
        f.close()
    except Exception:  # noqa: BLE001 - the close of a dropped file may report the old error again
        pass


def open_abandoned(path: Path, libver: tuple[str, str]) -> h5py.File:
    """Open for writing the file an abandoned writer left (see module doc): its status flags cleared. Raises
    :class:`OSError` when this libhdf5 offers no way to clear them, or HDF5 refuses the file."""
    lib = _libhdf5()
    if lib is None:
        raise OSError("libhdf5 not found to clear the file's status flags")
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_libver_bounds(*(getattr(h5py.h5f, f"LIBVER_{v.upper()}") for v in libver))
    clear = ctypes.c_bool(True)
    lib.H5Pset.argtypes = [ctypes.c_int64, ctypes.c_char_p, ctypes.c_void_p]
    if lib.H5Pset(fapl.id, b"clear_status_flags", ctypes.byref(clear)) < 0:
        raise OSError("this libhdf5 cannot clear a file's status flags")
    return h5py.File(h5py.h5f.open(os.fsencode(path), h5py.h5f.ACC_RDWR, fapl=fapl))
