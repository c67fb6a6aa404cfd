"""Rows lost inside a stream of a damaged session file (a chunk whose checksum fails, or that the storage zeroed,
with intact chunks after it).

The reader (:mod:`acq.recording.reader`) reads each dataset chunk by chunk into a :class:`Column`: the rows read, the
spans whose chunk failed its checksum (holes), and where the readable rows end (the tail: a chunk never written or
beyond the file's end). This module decides which rows of a stream survive, the same rows in every column of the
stream, and turns the lost ones into what the rest of the code already understands as a gap: a jump in the DAQ
sample index of the current's block table, a jump in the drive cycle index of the encoder. Only arrays: no HDF5.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

#: A span of rows ``[start, stop)``.
Span = tuple[int, int]


@dataclass(frozen=True)
class Column:
    """One dataset as read.

    Attributes
    ----------
    values : ndarray
        Its rows up to the first one not readable at the tail; the rows inside ``holes`` hold nothing meaningful.
    lost_from : int or None
        The first row wanted but not read (a tail: not written, beyond the file's end, not stored); None when every
        wanted row was read (holes aside).
    holes : tuple of (int, int)
        Spans ``[start, stop)`` of rows inside ``values`` whose chunk failed its checksum, in order.
    zeroed : tuple of (int, int)
        Spans of rows inside ``values`` whose chunks the storage replaced by zeros (:mod:`acq.recording.zeroed`):
        holes too, named apart.
    """

    values: np.ndarray
    lost_from: int | None
    holes: tuple[Span, ...] = ()
    zeroed: tuple[Span, ...] = ()

    @property
    def damaged(self) -> bool:
        return self.lost_from is not None or bool(self.holes) or bool(self.zeroed)

    @property
    def lost(self) -> tuple[Span, ...]:
        """Every span of rows inside ``values`` not to use: the checksum failures and the zeroed chunks."""
        return (*self.holes, *self.zeroed)

    def trusting_zeros(self) -> Column:
        """The column with its zeroed chunks taken as read (to tell the rows lost to them from the others)."""
        return replace(self, zeroed=())


def readable(columns: Sequence[Column], rows: int) -> np.ndarray:
    """Mask of the first ``rows`` rows that no column holds in a hole (a row lost in one column is lost in all)."""
    keep = np.ones(rows, dtype=bool)
    for column in columns:
        for start, stop in column.lost:
            keep[start:min(stop, rows)] = False
    return keep


def only_zeroed(columns: Sequence[Column], rows: int) -> np.ndarray:
    """Mask of the first ``rows`` rows lost to a zeroed chunk of some column and to no checksum failure."""
    return ~readable([replace(c, holes=()) for c in columns], rows) & readable([c.trusting_zeros() for c in columns],
                                                                               rows)


def lost_spans(keep: np.ndarray, total: int) -> list[Span]:
    """The spans of rows ``[0, total)`` not kept: the runs of False in ``keep``, and ``[len(keep), total)``."""
    flags = np.concatenate(([True], keep[:total], [True]))
    edges = np.flatnonzero(np.diff(flags.astype(np.int8)))
    spans = [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]
    if keep.size < total:
        if spans and spans[-1][1] == keep.size:
            spans[-1] = (spans[-1][0], total)
        else:
            spans.append((keep.size, total))
    return spans


@dataclass(frozen=True)
class CurrentRows:
    """The current's samples kept and its block table made true for them (see :func:`current_rows`)."""

    sample_keep: np.ndarray
    zeroed: np.ndarray
    first_index: np.ndarray
    count: np.ndarray
    host_ns: np.ndarray
    stamps_from_commits: bool = False  # every host stamp lost: each read stamped by the commit that stored it


def current_rows(count: Column, first_index: Column, host_ns: Column, phases: Sequence[Column],
                 samples_committed: int | None, commit_ns: np.ndarray | None = None) -> CurrentRows:
    """Which current samples survive holes in the phases or in the block table, and the block table for them.

    Parameters
    ----------
    count, first_index, host_ns : Column
        The block table: samples per DAQ read, the DAQ sample index of its first sample, its host arrival, ns.
    phases : sequence of Column
        The phase currents: a sample in a hole of one is lost in all.
    samples_committed : int or None
        Samples the writer committed, the sum of every committed block's count: where the samples of blocks after a
        hole in ``count`` start is counted back from it. None: unknown (those blocks are lost).
    commit_ns : ndarray of int64 or None
        Per block row, the host time, ns, of the commit that stored it (-1: none;
        :func:`acq.recording.commits.commit_stamps`): when no host stamp of ``host_ns`` is readable, the reads are
        stamped with these (``stamps_from_commits``) rather than lost — their samples are on the DAQ's own clock, and
        a host stamp only relates it to the encoder's. None: not known (the reads are then lost).

    Returns
    -------
    CurrentRows
        ``sample_keep`` (mask over the samples stored in every phase), ``zeroed`` (the samples lost to zeroed chunks
        only: of the phases, or of the block table rows that place them) and the block table of the kept samples.

    Notes
    -----
    A block (one DAQ read) whose row is in a hole of any block-table column is lost whole: its DAQ index, its
    length or its arrival is unknown. A block partly in a hole of the phases is split around it: each piece's
    ``first_index`` and ``count`` are exact, and each keeps the block's ``host_ns``. ``host_ns`` is when the read
    that returned the samples came back, and the analysis and the exporter pair it with the block's last sample
    (:func:`analysis.clock_host.host_relation`, :func:`acq.offline.exporters.current_t0_s`): for the piece before the
    hole this is later than its own last sample by the samples cut off, i.e. an arrival delay overstated by at most
    one chunk (0.1 s). Both use only the least-delayed arrivals (a lower envelope, a minimum), on which a late
    stamp has no effect; the stamp stays true as "these samples had arrived by then". Dropping the piece whole
    instead would lose intact samples, which the file still holds.
    """
    samples_stored = min(len(phase.values) for phase in phases)
    rows = min(len(count.values), len(first_index.values), len(host_ns.values))
    block_ok = readable((count, first_index), rows)
    n = count.values.astype(np.int64)
    n_known = n.copy()
    for start, stop in count.lost:
        n_known[start:stop] = 0
    unknown = ~readable((count,), len(n))
    offset = np.concatenate(([0], np.cumsum(n_known)[:-1])) if len(n) else np.zeros(0, dtype=np.int64)
    known = np.cumsum(unknown) == 0  # before the first hole in count: counted from sample 0
    if unknown.any() and samples_committed is not None and count.lost_from is None:
        after_last = np.arange(len(n)) > np.flatnonzero(unknown)[-1]  # after the last: counted back from the end
        from_end = samples_committed - np.cumsum(n_known[::-1])[::-1]
        offset = np.where(after_last, from_end, offset)
        known |= after_last
    block_ok &= known[:rows]
    offset, n = offset[:rows], n[:rows]
    block_ok &= offset + n <= samples_stored  # samples of a read not all stored (a kill between the two writes)
    first = first_index.values[:rows].astype(np.int64)
    stamp_ok, stamps = readable((host_ns,), rows), host_ns.values[:rows]
    from_commits = rows > 0 and not stamp_ok.any() and commit_ns is not None
    if from_commits:
        stamps = commit_ns[:rows]
        stamp_ok = stamps >= 0
    borrowed = _borrowing_stamps(block_ok, stamp_ok, offset, n, first)
    block_ok &= stamp_ok | borrowed
    placed = np.zeros(samples_stored, dtype=bool)
    for a, b in zip(offset[block_ok], offset[block_ok] + n[block_ok]):
        placed[a:b] = True
    sample_keep = placed & readable(phases, samples_stored)
    zeroed = _zeroed_samples(placed, offset, block_ok, only_zeroed((count, first_index, host_ns), rows), phases)
    ok = np.flatnonzero(block_ok)
    heads = np.flatnonzero(~np.concatenate(([False], borrowed[ok[:-1]])) | (np.diff(ok, prepend=-1) != 1))
    last = np.append(heads[1:], ok.size)[:heads.size] - 1  # each group's last row: the read whose stamp it takes
    grouped = np.add.reduceat(n[ok], heads) if ok.size else n[ok]
    rows_kept = _split_blocks(sample_keep, zeroed & ~sample_keep, offset[ok][heads], grouped, first[ok][heads],
                              stamps[ok][last])
    return replace(rows_kept, stamps_from_commits=bool(from_commits and ok.size))


def _borrowing_stamps(placeable: np.ndarray, stamped: np.ndarray, offset: np.ndarray, n: np.ndarray,
                      first_index: np.ndarray) -> np.ndarray:
    """Block rows placed (``placeable``: count and DAQ index read) whose host stamp is lost (not ``stamped``) that
    join the next read with a stamp: a run of them followed by such a read, every sample of the run and of that read
    contiguous in the file and in the DAQ's index. The joined reads are one block stamped when its last read
    returned: its samples had all arrived then, and the stamp is paired with its last sample, as a read's is."""
    borrowed = np.zeros(placeable.size, dtype=bool)
    for a, b in lost_spans(stamped, placeable.size):
        if b < placeable.size and placeable[a:b + 1].all() \
                and np.array_equal(offset[a:b] + n[a:b], offset[a + 1:b + 1]) \
                and np.array_equal(first_index[a:b] + n[a:b], first_index[a + 1:b + 1]):
            borrowed[a:b] = True
    return borrowed


def _zeroed_samples(placed: np.ndarray, offset: np.ndarray, block_ok: np.ndarray, table_zeroed: np.ndarray,
                    phases: Sequence[Column]) -> np.ndarray:
    """Samples lost to zeroed chunks only: those of a phase's zeroed chunk that a block places, and those no block
    places where every block-table row between the placed blocks around them was zeroed (a checksum failure or a
    tail among them: unreadable)."""
    size = placed.size
    zeroed = only_zeroed(phases, size) & placed
    if table_zeroed.any():
        phases_ok = readable([c.trusting_zeros() for c in phases], size)
        ok = np.flatnonzero(block_ok)
        for a, b in lost_spans(placed, size):
            before = int(np.searchsorted(offset[ok], a)) - 1  # the last placed block before the span
            first = int(ok[before]) + 1 if before >= 0 else 0
            stop = int(ok[before + 1]) if before + 1 < ok.size else table_zeroed.size
            if first < stop and table_zeroed[first:stop].all():
                zeroed[a:b] |= phases_ok[a:b]
    return zeroed


def _split_blocks(sample_keep: np.ndarray, zeroed: np.ndarray, offset: np.ndarray, count: np.ndarray,
                  first_index: np.ndarray, host_ns: np.ndarray) -> CurrentRows:
    """The block table of the kept samples: each block cut into its runs of kept samples (``zeroed`` passed on)."""
    size = sample_keep.size
    block_start = np.zeros(size + 1, dtype=bool)
    block_start[offset[offset < size]] = True
    before = np.concatenate(([False], sample_keep))  # before[s]: sample s − 1 kept
    after = np.concatenate((sample_keep[1:], [False]))  # after[s]: sample s + 1 kept
    starts = np.flatnonzero(sample_keep & (block_start[:-1] | ~before[:-1]))
    stops = np.flatnonzero(sample_keep & (block_start[1:] | ~after)) + 1
    block = np.searchsorted(offset, starts, side="right") - 1
    return CurrentRows(sample_keep=sample_keep, zeroed=zeroed,
                       first_index=first_index[block] + (starts - offset[block]),
                       count=(stops - starts).astype(np.int64), host_ns=host_ns[block])
