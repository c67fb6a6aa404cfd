"""The CANopen encoder stream: SYNC with counter, the notifier-side capture, decoding, raw frames.

Threads: python-can's notifier thread calls :class:`FrameCapture` for every SYNC and TPDO frame; it
only records the SYNC counter and queues ``(counter, raw bytes, host_ns)`` — no decoding, no I/O, so
the notifier never stalls (canopen logs and swallows callback exceptions, so the capture counts and
logs its own). The consumer (:meth:`drivers.canopen_drive.CanopenDrive.read`) drains the queue and
turns it into :class:`~drivers.base.EncoderBlock` s with :class:`TpdoDecoder`.

Which SYNC a TPDO answers is known from bus order: a synchronous TPDO (transmission type 1) is sent by
the drive after SYNC k and before SYNC k+1 (CiA 301 synchronous window), and the host sees its own SYNC
frames in that order because the bus is opened with ``receive_own_messages``. The counter (1…overflow,
0x1019) is unwrapped into the cumulative ``index`` by :class:`SyncUnwrapper`; host time decides how
many wraps a long silence hid. A drive without 0x1019 gets SYNC without data and the capture counts
the SYNC frames itself.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import deque
from pathlib import Path

import can
import numpy as np

from drivers.base import EncoderBlock

log = logging.getLogger(__name__)

SYNC_COB_ID = 0x80
SYNC_COUNTER_OVERFLOW = 240
RAW_PRE_LOG_MAX = 100_000  # frames kept while no raw log file is open yet


class SyncProducer:
    """SYNC every ``period_s`` (s) with the counter 1…``overflow`` in its data byte (none if 0).

    canopen's own :class:`canopen.sync.SyncProducer` sends one fixed message. The counter is a cyclic
    *sequence* of ``overflow`` messages, so python-can schedules it where the interface can — the
    kernel's broadcast manager on SocketCAN (µs timing, no Python thread), a software thread elsewhere.
    """

    def __init__(self, bus: can.BusABC, period_s: float, overflow: int) -> None:
        self._bus, self._period_s = bus, period_s
        self._messages = [can.Message(arbitration_id=SYNC_COB_ID, is_extended_id=False, data=[c] if c else [])
                          for c in (range(1, overflow + 1) if overflow else [0])]
        self._task: can.broadcastmanager.CyclicSendTaskABC | None = None

    def start(self) -> None:
        """Start sending (the first SYNC carries counter 1)."""
        self._task = self._bus.send_periodic(self._messages, self._period_s)

    def stop(self) -> None:
        """Stop sending. Idempotent."""
        if self._task is not None:
            self._task.stop()
            self._task = None


class FrameCapture:
    """Notifier-side callbacks: remember the SYNC counter, queue each TPDO as (counter, bytes, host_ns).

    ``counter`` is the SYNC's data byte, or the running count of SYNC frames when they carry none;
    0 means "before the first SYNC". A full queue drops the frame and counts an overrun.
    """

    def __init__(self, with_counter: bool, max_frames: int) -> None:
        self.frames: queue.Queue[tuple[int, bytes, int]] = queue.Queue(max_frames)
        self._with_counter = with_counter
        self.syncs = 0
        self._counter = 0
        self.overruns = 0
        self.errors = 0

    def on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        try:
            self.syncs += 1
            self._counter = data[0] if self._with_counter else self.syncs
        except Exception:  # noqa: BLE001 - canopen would only log it; count it too
            self._failed()

    def on_tpdo(self, can_id: int, data: bytearray, timestamp: float) -> None:
        try:
            self.frames.put_nowait((self._counter, bytes(data), time.monotonic_ns()))
        except queue.Full:
            self.overruns += 1
        except Exception:  # noqa: BLE001
            self._failed()

    def _failed(self) -> None:
        self.errors += 1
        log.exception("CANopen frame capture callback failed")


class SyncUnwrapper:
    """SYNC counter (1…``modulus``, or a running count if ``modulus`` is None) → cumulative index.

    Index 0 is the first SYNC sent (counter 1). A step of 0 is the same SYNC again (kept as is, the
    recorder drops repeats); a silence longer than one wrap is resolved with the host stamps.
    """

    def __init__(self, modulus: int | None, period_s: float, first_sync_ns: int) -> None:
        self._modulus = modulus
        self._period_ns = period_s * 1e9
        self._counter = 0
        self._index = -1
        self._ns = first_sync_ns - int(self._period_ns)

    def push(self, counter: int, host_ns: int) -> int:
        """Index of a frame that answered SYNC ``counter`` and arrived at ``host_ns`` (monotonic ns)."""
        if self._modulus is None:
            self._index = counter - 1
        else:
            step = (counter - self._counter) % self._modulus
            elapsed = (host_ns - self._ns) / self._period_ns
            step += self._modulus * max(0, round((elapsed - step) / self._modulus))
            self._index += step
        self._counter, self._ns = counter, host_ns
        return self._index


class TpdoDecoder:
    """Raw TPDO payloads (int32 position [, int32 velocity] [, uint32 0x1013 time stamp µs], little endian)
    → an :class:`EncoderBlock`.

    The int32 position register is unwrapped to int64; velocity (drive units) is scaled to counts/s
    by ``counts_per_s_per_unit``; the time stamp (wrapping every 2³² µs ≈ 71.6 min) is unwrapped into
    ``drive_time_s`` (s of the drive's clock, its origin the drive's). Frames of the wrong length are
    counted and skipped.
    """

    def __init__(self, unwrapper: SyncUnwrapper, with_velocity: bool, counts_per_s_per_unit: float,
                 with_timestamp: bool = False) -> None:
        self._unwrapper = unwrapper
        self._fields = 1 + with_velocity + with_timestamp
        self._with_velocity, self._with_timestamp = with_velocity, with_timestamp
        self._scale = counts_per_s_per_unit
        self._last_raw: int | None = None
        self._last_counts = 0
        self._last_stamp_raw: int | None = None
        self._last_stamp_us = 0
        self.bad_length = 0
        self.before_first_sync = 0

    def decode(self, frames: list[tuple[int, bytes, int]]) -> EncoderBlock | None:
        """Decode frames in arrival order; None if none is usable."""
        size = 4 * self._fields
        good = [f for f in frames if len(f[1]) == size and f[0] != 0]
        self.bad_length += sum(len(f[1]) != size for f in frames)
        self.before_first_sync += sum(len(f[1]) == size and f[0] == 0 for f in frames)
        if not good:
            return None
        index = np.array([self._unwrapper.push(c, ns) for c, _, ns in good], dtype=np.int64)
        host_ns = np.array([ns for _, _, ns in good], dtype=np.int64)
        values = np.frombuffer(b"".join(d for _, d, _ in good), dtype="<i4").reshape(-1, self._fields)
        raw = values[:, 0].astype(np.int64)
        prev = raw[0] if self._last_raw is None else self._last_raw
        steps = (np.diff(np.r_[prev, raw]) + 2**31) % 2**32 - 2**31
        counts = self._last_counts + np.cumsum(steps) + (raw[0] if self._last_raw is None else 0)
        self._last_raw, self._last_counts = int(raw[-1]), int(counts[-1])
        velocity = values[:, 1] * self._scale if self._with_velocity else None
        drive_time_s = self._unwrap_stamps(values[:, -1].view("<u4")) if self._with_timestamp else None
        return EncoderBlock(index=index, position_counts=counts, host_ns=host_ns, drive_time_s=drive_time_s,
                            velocity_counts_per_s=velocity)

    def _unwrap_stamps(self, raw_us: np.ndarray) -> np.ndarray:
        """uint32 µs stamps → cumulative drive time, s (a step is taken modulo 2³²: frames come in order)."""
        raw = raw_us.astype(np.int64)
        prev = raw[0] if self._last_stamp_raw is None else self._last_stamp_raw
        start = raw[0] if self._last_stamp_raw is None else self._last_stamp_us
        us = start + np.cumsum(np.diff(np.r_[prev, raw]) % 2**32)
        self._last_stamp_raw, self._last_stamp_us = int(raw[-1]), int(us[-1])
        return us * 1e-6


class RawFrameLog(can.Listener):
    """Keeps every frame on the bus: the notifier thread appends, the consumer writes a ``.blf``.

    Until :meth:`open` names the file, frames are held in memory (the last ``RAW_PRE_LOG_MAX``).
    """

    def __init__(self) -> None:
        self._pending: deque[can.Message] = deque()
        self._lock = threading.Lock()  # the consumer drains, the recorder's thread may open or stop
        self._writer: can.BLFWriter | None = None
        self.path: Path | None = None
        self.frames_written = 0

    def on_message_received(self, msg: can.Message) -> None:
        self._pending.append(msg)

    def open(self, path: Path) -> None:
        """Start writing to ``path`` (BLF, python-can's :class:`can.BLFWriter`), held frames first."""
        with self._lock:
            self.path = path
            self._writer = can.BLFWriter(path)
        self.drain()

    def drain(self) -> None:
        """Write what arrived since the last call (or trim the in-memory hold)."""
        with self._lock:
            if self._writer is None:
                while len(self._pending) > RAW_PRE_LOG_MAX:
                    self._pending.popleft()
                return
            while self._pending:
                self._writer.on_message_received(self._pending.popleft())
                self.frames_written += 1

    def stop(self) -> None:
        """Write the rest and close the file. Idempotent."""
        self.drain()
        with self._lock:
            if self._writer is not None:
                self._writer.stop()
                self._writer = None
