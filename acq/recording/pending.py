"""The writer's appends held in memory until the next flush, and the extendable datasets a flush grows."""

from __future__ import annotations

from typing import Any

import h5py
import numpy as np


class Column:
    """An extendable 1-D dataset and its length, kept here rather than asked of HDF5 (a dataspace query) per append.

    The writer is the file's only writer, so the length cannot change behind it.
    """

    def __init__(self, ds: h5py.Dataset) -> None:
        self.ds, self.id, self.dtype = ds, ds.id, ds.dtype
        # the memory type h5py would derive from the array at each write, made once (a /flushes row: 80 -> 39 µs)
        self.mtype = h5py.h5t.py_create(self.dtype)
        self.length = ds.shape[0]

    def append(self, values: np.ndarray) -> None:
        """Grow the dataset by ``values`` (its dtype) in one HDF5 write."""
        start, count = self.length, values.shape[0]
        if not count:
            return
        self.id.set_extent((start + count,))
        file_space = self.id.get_space()
        file_space.select_hyperslab((start,), (count,))
        self.id.write(h5py.h5s.create_simple((count,)), file_space, np.ascontiguousarray(values, self.dtype),
                      self.mtype)
        self.length = start + count


class PendingColumns:
    """Appends held in memory until the next flush, so each dataset grows once per flush.

    Small appends (a DAQ block, an encoder batch, an event) are copied into one buffer per dataset that is kept from
    flush to flush: the block handed in is released at once, its memory reused for the next one, and the flush writes
    the buffer as it is (no concatenation, no fresh memory each flush). Fresh memory costs a page fault per 4 KiB: with
    the blocks held until the flush and a new array per flush, a --fast 10 s session of bench/record_throughput.py
    took 1 959 minor faults in the DAQ reader and 778 in the recording thread; with the buffers 931 and 84 (medians
    of 6). A large append (an import hands over a whole session at once) is copied into a part of its own instead
    of into the growing buffer. Every append is a copy, so a caller may reuse its arrays at once: holding large ones
    by reference let a reused array change the stored samples, and the copy costs nothing measurable (``acq import``
    of a 60 s CSV pair: peak RSS 402 MB either way, the parsed CSV dominates).
    """

    #: Appends of at least this many bytes are copied into a part of their own, not into the dataset's buffer.
    OWN_PART_BYTES = 1 << 20

    def __init__(self) -> None:
        self._buffers: dict[str, np.ndarray] = {}  # per dataset, reused; the first ``_used[name]`` rows are pending
        self._used: dict[str, int] = {}
        self._parts: dict[str, list[np.ndarray]] = {}  # large appends' copies, and buffered rows before them, in order
        self.nbytes = 0  # bytes held, as they will be written

    def add(self, name: str, values: np.ndarray, dtype: np.dtype) -> None:
        """Hold ``values`` (1-D, cast to ``dtype``) for dataset ``name``."""
        count = values.shape[0]
        if count * dtype.itemsize >= self.OWN_PART_BYTES:
            self._seal(name)
            self._parts.setdefault(name, []).append(np.array(values, dtype=dtype))
        else:
            used = self._used.get(name, 0)
            self._room(name, used + count, dtype)[used:used + count] = values
            self._used[name] = used + count
        self.nbytes += count * dtype.itemsize

    def add_value(self, name: str, value: Any, dtype: np.dtype) -> None:
        """Hold one row ``value`` for dataset ``name`` (as :meth:`add` of a 1-row array, without making one)."""
        used = self._used.get(name, 0)
        self._room(name, used + 1, dtype)[used] = value
        self._used[name] = used + 1
        self.nbytes += dtype.itemsize

    def _room(self, name: str, rows: int, dtype: np.dtype) -> np.ndarray:
        """The buffer of dataset ``name``, grown (its pending rows kept) to hold at least ``rows``."""
        buffer = self._buffers.get(name)
        if buffer is None or buffer.shape[0] < rows:
            grown = np.empty(max(rows, 2 * (0 if buffer is None else buffer.shape[0])), dtype=dtype)
            used = self._used.get(name, 0)
            if used:
                grown[:used] = buffer[:used]
            self._buffers[name] = buffer = grown
        return buffer

    def _seal(self, name: str) -> None:
        """Move the rows buffered for ``name`` into its parts (a part held by reference follows them)."""
        used = self._used.get(name, 0)
        if used:
            self._parts.setdefault(name, []).append(self._buffers[name][:used].copy())
            self._used[name] = 0

    def count(self, name: str) -> int:
        """Rows held for dataset ``name``."""
        return self._used.get(name, 0) + sum(part.shape[0] for part in self._parts.get(name, []))

    def clear(self) -> None:
        self._parts.clear()
        self._used.clear()
        self.nbytes = 0

    def _bytes_of(self, name: str) -> int:
        """Bytes held for dataset ``name``."""
        parts = self._parts.get(name, [])
        used = self._used.get(name, 0)
        return sum(part.nbytes for part in parts) + (used * self._buffers[name].itemsize if used else 0)

    def write_to(self, columns: dict[str, Column]) -> None:
        """Append every held row to its dataset, the smallest first: a copy of the file cut short (a partial copy)
        then still holds the block table and the encoder of the last commit before the cut, and its phase currents up
        to the cut, where the order of the appends put the phases first and lost those with them."""
        self.nbytes = 0
        names = [*self._used, *(n for n in self._parts if n not in self._used)]
        for name in sorted(names, key=self._bytes_of):
            parts = self._parts.pop(name, [])
            used = self._used.pop(name, 0)  # taken before writing: an interrupted flush never repeats a part
            if used:
                parts.append(self._buffers[name][:used])
            if parts:
                columns[name].append(parts[0] if len(parts) == 1 else np.concatenate(parts))
