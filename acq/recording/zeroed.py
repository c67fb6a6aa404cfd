"""Chunks that storage replaced by zeros: their stored bytes, samples and checksum, all 0, which Fletcher32 passes.

HDF5's Fletcher32 of all-zero bytes is 0 (``H5_checksum_fletcher32``: both running sums start at 0), so a chunk
whose bytes the storage zeroed reads back without error as rows of zeros. Zeros are what storage produces when it
loses data: a downloader or copier that pre-allocates the whole file and is cut, blocks a file system leaves
zero-filled after a crash (XFS and others after power loss, ext4 with some mount options), a sparse copy. A chunk
that really holds zeros is stored byte for byte the same (its checksum is 0 too), so the bytes alone cannot tell
the two apart; the rows can, by what the column holds:

* **Stamps and indices** (:data:`STAMPS`: the block table, the encoder's ``index`` and ``host_ns``, the events and
  the flushes) are never zero in two rows: the DAQ sample index and the drive cycle increase strictly (the
  recorder drops rows out of order, :mod:`acq.recording.stream_check`), a read holds at least one sample, host
  stamps are nanoseconds of the host's monotonic clock (an import's may start at 0 once), every event and flush row
  has its stamp. A zeroed chunk of them (more than one row, or not the stream's first row) is invented.
* **Values** (the phase currents, the position, the drive's time and speeds) can be 0, but a run of exact zeros is
  bounded by its cause: a channel reading exactly 0.0 (a real card's reading carries noise and its calibration
  offset, so that is a noise-free simulation or a disconnected simulated channel) or a joint resting exactly at
  count 0 reads 0 also next to the chunk, unless the zeros began exactly at the chunk's first row and ended exactly
  at its last (about 1 in 500² for the encoder's chunk of 500 rows, 1 in 2 560² for the current's; 1 in 500 for a
  joint resting at count 0 from the start of the recording, whose first chunk has no row before it: the simulated
  joint rests there 0.2 s, 201 rows). So a run of zeroed chunks of a value column is invented when the nearest
  readable row before it and the one after it (where there is one) are both not 0, and real when either is 0 or
  there is none (the whole column zero: nothing in the file says otherwise).

Finding a zeroed chunk costs an intact file nearly nothing: only a chunk whose first row is 0 in every byte is
looked at whole, and only a chunk whose rows are all 0 has its stored bytes read (``read_direct_chunk``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from acq.recording.holes import Span

#: Datasets (paths without the leading /) whose rows are never zero twice; every other one holds values.
STAMPS = frozenset({"current/blocks/count", "current/blocks/first_index", "current/blocks/host_ns", "encoder/index",
                    "encoder/host_ns", "events", "flushes"})


def _words(values: np.ndarray) -> np.ndarray:
    """The rows as integers covering their every byte (−0.0 is not 0 here: its sign bit is stored)."""
    if values.dtype.itemsize % 8 == 0:
        return values.view(np.int64).reshape(values.size, -1)
    return values.view(np.uint8).reshape(values.size, -1)


def zero_chunks(ds: Any, step: int, values: np.ndarray, holes: tuple[Span, ...]) -> list[Span]:
    """The chunks (``step`` rows each) of dataset ``ds`` (h5py) whose rows in ``values`` (its first rows as read) are
    all 0 and whose stored bytes, checksum included, are all 0: ``[start, stop)`` clipped to ``values``, in order.
    Chunks in ``holes`` (their rows were not read) are left out."""
    if values.size == 0:
        return []
    words = _words(values)
    starts = np.arange(0, values.size, step)
    candidates = starts[~words[starts].any(axis=1)]
    found: list[Span] = []
    for start in candidates.tolist():
        stop = min(start + step, values.size)
        if any(a < stop and start < b for a, b in holes) or words[start:stop].any():
            continue
        try:
            _, stored = ds.id.read_direct_chunk((start,))
        except (OSError, RuntimeError, ValueError):
            continue
        if not any(stored):
            found.append((start, stop))
    return found


def _runs(chunks: list[Span]) -> list[Span]:
    """Adjacent spans joined."""
    runs: list[Span] = []
    for a, b in chunks:
        if runs and runs[-1][1] == a:
            runs[-1] = (runs[-1][0], b)
        else:
            runs.append((a, b))
    return runs


def invented(name: str, values: np.ndarray, chunks: list[Span], holes: tuple[Span, ...]) -> tuple[Span, ...]:
    """The zeroed ``chunks`` of dataset ``name`` whose rows were invented by the storage, joined into runs (the
    rule: module doc). ``values`` are the rows read, ``holes`` the spans of them not readable."""
    if name in STAMPS:
        return tuple(run for run in _runs(chunks) if run[1] - run[0] > 1 or run[0] > 0)
    unreadable = np.zeros(values.size, dtype=bool)
    for a, b in (*holes, *chunks):
        unreadable[a:b] = True
    readable_rows = np.flatnonzero(~unreadable)
    lost: list[Span] = []
    for a, b in _runs(chunks):
        at = np.searchsorted(readable_rows, a)
        near = readable_rows[at - 1:at + 1] if at else readable_rows[:1]
        if near.size and bool(np.all(values[near] != 0)):  # NaN, a value never stored as zeros, is not 0
            lost.append((a, b))
    return tuple(lost)
