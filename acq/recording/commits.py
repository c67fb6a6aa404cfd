"""What the writer committed to a session file, and what is read when that is unknown.

A finished file's footer holds its sample counts; a file its recorder did not finish (killed) has the ``/flushes``
rows, each written after the samples it counts. When neither can be read (no footer, the last ``/flushes`` row in a
chunk that fails its checksum) the commits are unknown: the reader (:mod:`acq.recording.reader`) then reads what the
datasets store, and their checksums, extents, block table and host stamps decide which rows are samples. Only
arrays: the reader reads the datasets.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from acq.recording.holes import Column, lost_spans, readable
from acq.recording.layout import FLUSH_DTYPE, NO_COUNT

#: The commit table's dataset: its damage is named in rows ("flushes: rows 0–5 unreadable").
FLUSHES = "flushes"
#: Added to the damage of ``/flushes`` when its last row is lost with it: the commits are unknown, so what the
#: datasets store is read instead (their checksums, extents and block table decide what is kept).
COMMITS_UNKNOWN = "unreadable (the last commit lost with them: the samples stored are read)"


def committed_counts(attrs: dict[str, Any], flushes: Column | None) -> dict[str, int] | None:
    """What the writer committed: the footer's counts (``attrs``, the root attributes read), else the last row of
    ``flushes`` (``/flushes`` as read); None if neither is known (no ``/flushes``, or its last row unreadable: then
    every sample stored is read, and the holes, tails and block table decide which are kept).

    The counts are numbers overwritten in place, and :func:`~acq.recording.layout.write_footer` writes them before
    the status: a count other than :data:`NO_COUNT` is a footer's whatever the status says, or if a cut lost the
    status string."""
    counts = [int(attrs.get(name, NO_COUNT)) for name in ("current_samples", "encoder_samples")]
    if min(counts) > NO_COUNT:
        return {"current_samples": counts[0], "encoder_samples": counts[1]}
    if flushes is None or not last_commit_readable(flushes):
        return None
    if flushes.values.size == 0:
        return {"current_samples": 0, "current_blocks": 0, "encoder_samples": 0, "events": 0}
    return {name: int(flushes.values[-1][name]) for name in FLUSH_DTYPE.names if name != "host_ns"}


def last_commit_readable(flushes: Column) -> bool:
    """Whether the last row ``/flushes`` stores was read (none stored: nothing committed, known)."""
    rows = flushes.values.size
    return flushes.lost_from is None and (rows == 0 or bool(readable((flushes,), rows)[-1]))


def flushes_damage(flushes: Column, stored: int, committed: dict[str, int] | None) -> list[tuple[str, int, int, str]]:
    """The spans of ``/flushes`` (``stored`` rows) not read, in rows; the last one says when the commits are unknown
    for it (``committed`` None: no footer's counts either)."""
    keep = readable((flushes,), flushes.values.size)
    spans = [(FLUSHES, a, b, "unreadable") for a, b in lost_spans(keep, stored)]
    if spans and committed is None:
        spans[-1] = (*spans[-1][:3], COMMITS_UNKNOWN)
    return spans


def commit_stamps(flushes: Column | None, blocks: int) -> np.ndarray | None:
    """For each of the first ``blocks`` rows of the current's block table, the host time, ns, of the first readable
    ``/flushes`` row that commits it (its ``current_blocks`` total beyond the row), -1 for a row none commits; None
    without a ``/flushes``. Each is true as "this read had arrived by then": a commit is written after the samples it
    counts (a row lost in a hole is committed again by the next, later). What places the current's reads in host time
    when every stamp of its own is lost."""
    if flushes is None:
        return None
    rows = flushes.values[readable((flushes,), flushes.values.size)]
    first = np.searchsorted(rows["current_blocks"], np.arange(blocks), side="right")
    stamps = np.full(blocks, -1, dtype=np.int64)
    stamps[first < rows.size] = rows["host_ns"][first[first < rows.size]]
    return stamps


def stamped(columns: list[Column], stamps: Column) -> list[Column]:
    """``columns`` (of one stream) cut after the last row whose host stamp in ``stamps`` (ns) is not 0 or not read.

    For a file whose commits are unknown (:func:`committed_counts` None): a kill can leave a dataset extended over rows
    of a chunk already on disk that were never written there; they read as zeros that pass the checksum, and no host
    arrival stamp is 0 (a monotonic clock's ns since boot)."""
    zero = stamps.values == 0
    for a, b in stamps.lost:  # a row not read says nothing
        zero[a:b] = False
    rows = int(np.flatnonzero(~zero)[-1]) + 1 if (~zero).any() else 0
    return [replace(c, values=c.values[:rows]) if len(c.values) > rows else c for c in columns]
