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
* **Values** (the phase currents, the position, the drive's time and speeds) can be 0 for any number of rows: a
  channel reading exactly 0.0 (a noise-free simulation, a disconnected simulated channel), a joint resting at count
  0 (drives zero their position at enable or homing, so a record that starts at rest at 0 is common), a speed of 0
  at rest. Zeros alone are no evidence; the rows around them are. A run of zeroed chunks of a value column is
  invented when the column reads NaN next to it (a value never stored as zeros: an optional column the drive does
  not give) or when its value next to it is farther from 0 than the column moves in as many rows at its pace beside
  the run: ``|value| > largest step × rows apart``, the largest step being the largest absolute difference between
  two adjacent readable rows within :data:`EDGE_ROWS` of that row on its side (derived from the record; the record's
  largest step let one fast move hide a joint at rest near 0). A moving joint's
  position lands tens of thousands of counts from 0 next to a zeroed chunk; a joint resting at 0 that starts to
  move takes a step no larger than its others: at count 0 for the whole first encoder chunk, moving at row 500 (a
  new user reported about 1 monitor window in 250 of the simulated robot), it reads 0 → 9 counts there, its
  largest step 1 793. A run with no readable neighbour, or a column with no step to compare with, is kept (nothing
  in the file says otherwise).
  A phase current is a DAQ's analog reading: its noise never lets it hold one value for long, so a run of zeroed
  chunks of a phase is also invented when it is longer than the longest run of one repeated value among the phase's
  readable rows, with no exact 0 next to it (a channel reading exactly 0.0 throughout has no readable row besides its
  zero chunks, a disabled drive logged as 0.000 has zeros on past the chunks: both kept). The
  largest step alone would miss a zeroed chunk of a phase whose both ends lie within it of 0 (the simulated phases
  step up to 1.1 A at 3 A amplitude: 150 of the 894 inner chunks of a 30 s three-phase session). The encoder's
  values are a drive's digital readings, which hold still at rest as long as the joint rests: for them only the
  step counts. A run that joins a real zero chunk to a zeroed one is lost whole (its rows cannot be told apart).

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


def _longest_still(values: np.ndarray, unreadable: np.ndarray) -> int:
    """The most rows of ``values`` in a row, none ``unreadable``, holding one value (0 when every row is)."""
    if unreadable.all():
        return 0
    same = (values[1:] == values[:-1]) & ~unreadable[:-1] & ~unreadable[1:]
    edges = np.flatnonzero(np.diff(np.concatenate(([0], same.astype(np.int8), [0]))))
    return int((edges[1::2] - edges[::2]).max()) + 1 if edges.size else 1


def _is_phase(name: str) -> bool:
    """Dataset ``name`` is a phase current (``current/<channel>_A``), an analog reading."""
    return name.startswith("current/") and name.endswith("_A")


#: Rows on each side of a zeroed run whose steps set the pace the value next to it is judged by: a few steps of the
#: motion at the run's edge, few against a move (a robot's moves last hundreds of rows at 1 kHz). The record's largest
#: step instead let one fast move anywhere hide a run next to a joint resting near 0 (session 13's reviewer: largest
#: step 1 762 counts, a joint at rest at 362 counts zeroed for 500 rows passed as intact).
EDGE_ROWS = 50


def _jumps_at(values: np.ndarray, readable_rows: np.ndarray, row: int, run: Span) -> bool:
    """Whether the readable ``row`` next to ``run`` lies farther from 0 than the column moves, at its pace beside the
    run (the largest step between adjacent readable rows within :data:`EDGE_ROWS` of ``row`` on its side), in the rows
    between them; a NaN there (never stored as zeros) counts as a jump, a side with no step to compare with does not."""
    at = int(np.searchsorted(readable_rows, row))
    side = readable_rows[max(at - EDGE_ROWS, 0):at + 1] if row < run[0] else readable_rows[at:at + EDGE_ROWS + 1]
    adjacent = np.diff(side) == 1
    steps = np.abs(np.diff(values[side].astype(np.float64)))[adjacent]
    steps = steps[np.isfinite(steps)]
    value = abs(float(values[row]))
    if np.isnan(value):
        return True
    apart = run[0] - row if row < run[0] else row - (run[1] - 1)  # rows from the run's zero at that end
    return bool(steps.size) and value > float(steps.max()) * apart


def invented(name: str, values: np.ndarray, chunks: list[Span], holes: tuple[Span, ...]) -> tuple[Span, ...]:
    """The zeroed ``chunks`` of dataset ``name`` whose rows were invented by the storage, joined into runs (the
    rule: module doc). ``values`` are the rows read, ``holes`` the spans of them not readable."""
    if name in STAMPS:
        return tuple(run for run in _runs(chunks) if run[1] - run[0] > 1 or run[0] > 0)
    unreadable = np.zeros(values.size, dtype=bool)
    for a, b in (*holes, *chunks):
        unreadable[a:b] = True
    readable_rows = np.flatnonzero(~unreadable)
    still = _longest_still(values, unreadable) if _is_phase(name) else values.size
    lost: list[Span] = []
    for a, b in _runs(chunks):
        at = np.searchsorted(readable_rows, a)
        near = readable_rows[max(at - 1, 0):at + 1]  # the nearest readable row before the run and the one after
        jumps = any(_jumps_at(values, readable_rows, int(row), (a, b)) for row in near)
        # held still too long for an analog reading — unless an exact 0 is next to it: then the zeros go on outside
        # the chunks (a disabled drive logged as 0.000), which storage does not do (reviewer: a 2.2 s idle import)
        held = bool(near.size) and bool(np.all(values[near] != 0)) and still and b - a > still
        if jumps or held:
            lost.append((a, b))
    return tuple(lost)
