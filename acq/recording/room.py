"""How many bytes a recording needs on its disk, known before it starts (rates × channels × duration), and the
refusal to start one that cannot fit: on the disk, or under the process's file size limit (``ulimit -f``)."""

from __future__ import annotations

import resource
from pathlib import Path

from acq.recording.storage import free_bytes, refused_write
from acq.recording.writer import RESERVE_BYTES
from drivers.config import Bench
from acqcore.errors import StorageError

#: Also flush once this much is pending (a --fast simulated bench delivers seconds of data per 0.5 s): bounds
#: the memory held and what a failed write can lose. 2 MiB ≈ 1.7 s of 3 × 51.2 kS/s float64, so in real time the
#: 0.5 s interval commits first for any card below 4 MB/s. Each commit costs its two H5Fflush and the partial chunks
#: it rewrites: a 10 s --fast session at those rates commits 7 times instead of 13 and the recording thread's CPU
#: falls from 38.4 to 29.5 ms (4 MiB: 27.0; medians of 10, bench/record_throughput.py rates, load 2–3). Not more:
#: a commit needs twice its size free (SessionWriter's room check), 4 MiB kept nothing on an 8 MB disk.
FLUSH_BYTES = 2 << 20
#: Expected session size = this × the data's raw size (HDF5 chunks, block tables, events): measured 1.1…1.2.
SIZE_MARGIN = 1.5


def expected_session_bytes(bench: Bench, duration_s: float) -> int:
    """Bytes a session file of ``duration_s`` needs at most: current (f8 per channel) and encoder (5 columns of 8
    bytes), times :data:`SIZE_MARGIN`, plus 200 kB of layout."""
    current = bench.daq.rate_hz * len(bench.daq.channels) * 8
    encoder = 5 * 8 / bench.drive.period_s
    return int(SIZE_MARGIN * duration_s * (current + encoder)) + 200_000


def bytes_to_record(session_bytes: int) -> int:
    """Free bytes a recording of ``session_bytes`` needs as the writer judges room: its last flush — up to
    :data:`FLUSH_BYTES`, the whole session of a --fast bench — needs twice its size free beyond
    :data:`~acq.recording.writer.RESERVE_BYTES` once the rest is written (session + reserve alone passed with 3.0 MB
    free, and a monitor window failed at 0 s)."""
    return session_bytes + min(session_bytes, FLUSH_BYTES) + RESERVE_BYTES


def file_size_limit() -> int | None:
    """The largest file this process may write (its soft RLIMIT_FSIZE, ``ulimit -f``), bytes; None when unlimited."""
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    return None if soft == resource.RLIM_INFINITY else soft


def require_file_size_limit(session_bytes: int, what: str, shorter: str) -> None:
    """Raise :class:`StorageError` naming the limit and ``session_bytes`` when a session file of that size cannot be
    written under :func:`file_size_limit`: ``what`` is the file ("a 30 s recording"), ``shorter`` how to make it
    smaller ("record shorter"). Before, the write that met the limit failed the recording part way (EFBIG, "file size
    limit reached": a progress bar for nothing, a failed file left)."""
    limit = file_size_limit()
    if limit is not None and limit < session_bytes:
        raise StorageError(f"file size limit: files may grow to {limit / 1e6:.1f} MB (ulimit -f {limit // 1024}), "
                           f"{what} needs {session_bytes / 1e6:.1f} MB ({shorter}, or raise ulimit -f)")


def require_room(folder: Path, bench: Bench, duration_s: float) -> None:
    """Raise :class:`StorageError` naming ``folder`` and why when this process may not write there ("read-only file
    system"), naming its free and the needed bytes when a recording of ``duration_s`` on ``bench`` cannot fit there,
    or naming the file size limit (:func:`require_file_size_limit`) when its file may not grow that large (checked
    before any device starts; a folder still to be made: the free space where it will be)."""
    session = expected_session_bytes(bench, duration_s)
    require_file_size_limit(session, f"a {duration_s:g} s recording", "record shorter")
    existing = next((p for p in (folder, *folder.parents) if p.is_dir()), None)
    if existing is None:
        return  # nothing to measure: making the folder says what is wrong
    refused = refused_write(existing)  # first: a small read-only mount has few free bytes too, and is not full
    if refused is not None:
        raise StorageError(f"{refused}: {folder}")
    need, free = bytes_to_record(session), free_bytes(existing)
    if free < need:
        raise StorageError(f"disk full: {folder} has {free / 1e6:.1f} MB free, a {duration_s:g} s recording needs "
                           f"{need / 1e6:.1f} MB (record shorter, or make room)")
