"""The recorder's reader threads: one per device, reading it and queueing what it got, nothing else."""

from __future__ import annotations

import queue
import threading
from typing import Any

from drivers.base import CurrentBlock, CurrentSource, Drive, EncoderBlock

#: Longest wait for one device read, s: a reader sees a stop request within this time.
READ_TIMEOUT_S = 0.2


class DeviceReader(threading.Thread):
    """Reads one device until it has ``target`` samples or is told to stop; queues everything."""

    def __init__(self, name: str, device: CurrentSource | Drive, target: int, out: queue.SimpleQueue[tuple[str, Any]]):
        super().__init__(name=f"acq-{name}-reader", daemon=True)
        self.stream = name
        self.device = device
        self.target = target
        self.out = out
        self.stop_requested = threading.Event()
        self.first_index: int | None = None
        self.covered = 0

    def _advance(self, block: CurrentBlock | EncoderBlock) -> None:
        """Stream position covered so far, by the stream's own index (drops do not delay the end)."""
        if isinstance(block, CurrentBlock):
            first, end = block.first_index, block.first_index + block.count
        else:
            first, end = int(block.index[0]), int(block.index[-1]) + 1
        if self.first_index is None:
            self.first_index = first
        self.covered = end - self.first_index

    def run(self) -> None:
        try:
            while not self.stop_requested.is_set() and self.covered < self.target:
                block = self.device.read(READ_TIMEOUT_S)
                for event in self.device.events():
                    self.out.put(("event", event))
                if block is not None and block.count:
                    self._advance(block)
                    self.out.put((self.stream, block))
        except Exception as e:  # noqa: BLE001 - every device failure ends the recording cleanly
            self.out.put(("error", e))
        finally:
            self.out.put(("done", self.stream))
