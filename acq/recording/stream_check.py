"""Order and gaps of the streams as the recorder stores them: every block is checked against the stream's own
index (DAQ sample index, drive cycle), never against timing.

A jump forward is a gap event; samples repeated or out of order are dropped with a warning event, so the
stored streams increase strictly. Encoder blocks queued one after another are joined into one before the
check (:func:`join_encoder_blocks`).
"""

from __future__ import annotations

import numpy as np

from drivers.base import CurrentBlock, EncoderBlock, StreamEvent


class StreamChecker:
    """Keeps the stored streams strictly ordered and turns index jumps into gap events."""

    def __init__(self) -> None:
        self.next_current: int | None = None
        self.last_cycle: int | None = None
        self.current_gaps = 0
        self.encoder_gaps = 0

    def current(self, block: CurrentBlock) -> tuple[CurrentBlock | None, list[StreamEvent]]:
        """The part of ``block`` to store (None: nothing new in it) and the events it raises."""
        events: list[StreamEvent] = []
        if self.next_current is not None and block.first_index != self.next_current:
            missing = block.first_index - self.next_current
            if missing > 0:
                self.current_gaps += 1
                events.append(StreamEvent(block.host_ns, "current", "gap",
                                          f"{missing} samples missing before index {block.first_index}"))
            else:
                overlap = min(-missing, block.count)
                events.append(StreamEvent(block.host_ns, "current", "warning",
                                          f"{overlap} samples repeated at index {block.first_index} dropped"))
                if overlap == block.count:
                    return None, events
                block = CurrentBlock(block.first_index + overlap, block.current_a[:, overlap:], block.host_ns)
        self.next_current = block.first_index + block.count
        return block, events

    def encoder(self, block: EncoderBlock) -> tuple[EncoderBlock | None, list[StreamEvent]]:
        """The samples of ``block`` to store (None: nothing new in it) and the events it raises."""
        events: list[StreamEvent] = []
        idx = np.asarray(block.index, dtype=np.int64)
        last = self.last_cycle if self.last_cycle is not None else int(idx[0]) - 1
        # a --fast bench delivers 100 small blocks a second: the usual block (in order, after the last one, no gap)
        # is recognised in two comparisons, the rest of the checks run only on a block that is not
        in_order = bool(idx[0] > last) and bool((idx[1:] > idx[:-1]).all())
        if in_order and int(idx[-1]) - last == idx.size:
            self.last_cycle = int(idx[-1])
            return block, events
        if not in_order:
            keep = idx > np.maximum.accumulate(np.concatenate(([last], idx[:-1])))
            events.append(StreamEvent(int(block.host_ns[0]), "encoder", "warning",
                                      f"{int((~keep).sum())} samples out of order or repeated dropped"))
            block = _select(block, keep)
            idx = idx[keep]
            if idx.size == 0:
                return None, events
        steps = np.diff(idx, prepend=last)
        for pos in np.flatnonzero(steps > 1):
            self.encoder_gaps += 1
            events.append(StreamEvent(int(block.host_ns[pos]), "encoder", "gap",
                                      f"{int(steps[pos] - 1)} frames missing before cycle {int(idx[pos])}"))
        self.last_cycle = int(idx[-1])
        return block, events


def _select(block: EncoderBlock, keep: np.ndarray) -> EncoderBlock:
    def pick(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.asarray(a)[keep]

    return EncoderBlock(
        index=np.asarray(block.index)[keep],
        position_counts=np.asarray(block.position_counts)[keep],
        host_ns=np.asarray(block.host_ns)[keep],
        drive_time_s=pick(block.drive_time_s),
        velocity_counts_per_s=pick(block.velocity_counts_per_s),
        velocity_demand_counts_per_s=pick(block.velocity_demand_counts_per_s),
    )


def join_encoder_blocks(blocks: list[EncoderBlock]) -> EncoderBlock:
    """Consecutive encoder blocks as one; an optional column missing from some block is NaN there."""
    def column(name: str) -> np.ndarray | None:
        parts = [getattr(b, name) for b in blocks]
        missing = [p is None for p in parts]
        if all(missing):
            return None
        if not any(missing):  # the usual case: every block has it
            return np.concatenate(parts)
        return np.concatenate([np.full(b.count, np.nan) if p is None else p for b, p in zip(blocks, parts)])

    return EncoderBlock(
        index=np.concatenate([b.index for b in blocks]),
        position_counts=np.concatenate([b.position_counts for b in blocks]),
        host_ns=np.concatenate([b.host_ns for b in blocks]),
        drive_time_s=column("drive_time_s"),
        velocity_counts_per_s=column("velocity_counts_per_s"),
        velocity_demand_counts_per_s=column("velocity_demand_counts_per_s"),
    )
