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
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import can
import numpy as np

from drivers.base import SW_INTERNAL_LIMIT, EncoderBlock, LimitSpans

log = logging.getLogger(__name__)

SYNC_COB_ID = 0x80
SYNC_COUNTER_OVERFLOW = 240
RAW_PRE_LOG_MAX = 100_000  # frames kept while no raw log file is open yet
POSITION_ACTUAL, VELOCITY_ACTUAL, VELOCITY_DEMAND, HIGH_RES_TIMESTAMP = 0x6064, 0x606C, 0x606B, 0x1013
STATUSWORD = 0x6041


@dataclass(frozen=True)
class TpdoLayout:
    """Where the recorded objects sit in a TPDO's payload (byte offsets; None: not mapped).

    ``position`` is 0x6064 (int32), ``velocity`` 0x606C (int32), ``timestamp`` 0x1013 (uint32 µs),
    ``velocity_demand`` 0x606B (int32, the speed loop's reference, in the velocity's units), ``statusword`` 0x6041
    (uint16, watched for bit 11 "internal limit active"); any other mapped object is skipped. ``size`` is the
    payload's length, bytes.
    """

    size: int
    position: int
    velocity: int | None = None
    timestamp: int | None = None
    velocity_demand: int | None = None
    statusword: int | None = None

    @classmethod
    def from_entries(cls, entries: Sequence[int]) -> TpdoLayout:
        """The layout of CiA 301 mapping ``entries`` (index << 16 | subindex << 8 | bits), in mapping order."""
        offsets: dict[int, int] = {}
        at = 0
        for e in entries:
            if (e & 0xFF == 32 or e >> 16 == STATUSWORD and e & 0xFF == 16) and (e >> 8) & 0xFF == 0:
                offsets.setdefault(e >> 16, at // 8)
            at += e & 0xFF
        if POSITION_ACTUAL not in offsets:
            raise ValueError("the TPDO does not map 0x6064 position actual value (32 bit)")
        return cls(at // 8, offsets[POSITION_ACTUAL], offsets.get(VELOCITY_ACTUAL), offsets.get(HIGH_RES_TIMESTAMP),
                   offsets.get(VELOCITY_DEMAND), offsets.get(STATUSWORD))

    def dtype(self) -> np.dtype:
        """A numpy structured dtype reading the mapped fields of one payload (little endian, CiA 301)."""
        fields = {"position": (self.position, "<i4"), "velocity": (self.velocity, "<i4"),
                  "timestamp": (self.timestamp, "<u4"), "velocity_demand": (self.velocity_demand, "<i4"),
                  "statusword": (self.statusword, "<u2")}
        used = {k: v for k, v in fields.items() if v[0] is not None}
        return np.dtype({"names": list(used), "formats": [f for _, f in used.values()],
                         "offsets": [o for o, _ in used.values()], "itemsize": self.size})


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
    """Notifier-side callbacks: remember the SYNC counter, queue each TPDO as (counter, bytes, host_ns, syncs) —
    ``syncs`` the SYNC frames seen so far.

    ``counter`` is the SYNC's data byte, or the running count of SYNC frames when they carry none;
    0 means "before the first SYNC". A full queue drops the frame and counts an overrun.
    """

    def __init__(self, with_counter: bool, max_frames: int) -> None:
        self.frames: queue.Queue[tuple[int, bytes, int, int]] = queue.Queue(max_frames)
        self._with_counter = with_counter
        self.syncs = 0
        self.first_sync_ns = 0  # host arrival of the first SYNC seen, ns
        self.first_sync_bytes = 0  # its data length: 1 if the SYNC carries a counter
        self._counter = 0
        self.overruns = 0
        self.errors = 0

    def on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        try:
            if self.syncs == 0:
                self.first_sync_ns, self.first_sync_bytes = time.monotonic_ns(), len(data)
            self.syncs += 1
            self._counter = data[0] if self._with_counter else self.syncs
        except Exception:  # noqa: BLE001 - canopen would only log it; count it too
            self._failed()

    def on_tpdo(self, can_id: int, data: bytearray, timestamp: float) -> None:
        try:
            self.frames.put_nowait((self._counter, bytes(data), time.monotonic_ns(), self.syncs))
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
    recorder drops repeats); a silence longer than one wrap is resolved with the number of SYNC frames the host
    saw in between — not with the host stamps where that count is known: a host that stalls (a loaded machine)
    reads frames that came in order with bunched stamps after a gap in time, and the stamps alone would then
    invent a wrap of lost cycles. SYNC frames lost below the host (a driver's receive buffer overflowing)
    and a silence of the master are told apart by neither.
    """

    def __init__(self, modulus: int | None, period_s: float, first_sync_ns: int) -> None:
        self._modulus = modulus
        self._period_ns = period_s * 1e9
        self._counter = 0
        self._index = -1
        self._ns = first_sync_ns - int(self._period_ns)
        self._syncs = 0

    def push(self, counter: int, host_ns: int, syncs_seen: int | None = None) -> int:
        """Index of a frame that answered SYNC ``counter`` and arrived at ``host_ns`` (monotonic ns), the host
        having seen ``syncs_seen`` SYNC frames by then (None: unknown; then the host time tells the wraps)."""
        if self._modulus is None:
            self._index = counter - 1
        else:
            step = (counter - self._counter) % self._modulus
            elapsed = (host_ns - self._ns) / self._period_ns
            if syncs_seen is not None:  # the SYNC frames the host saw in between: exact, however late it read them
                elapsed = syncs_seen - self._syncs
            step += self._modulus * max(0, round((elapsed - step) / self._modulus))
            self._index += step
        self._counter, self._ns = counter, host_ns
        if syncs_seen is not None:
            self._syncs = syncs_seen
        return self._index


class TpdoDecoder:
    """Raw TPDO payloads (int32 position [, int32 velocity] [, uint32 0x1013 time stamp µs], little endian, or
    any ``layout``) → an :class:`EncoderBlock`.

    The int32 position register is unwrapped to int64; velocity and velocity demand (drive units) are scaled to
    counts/s by ``counts_per_s_per_unit``; the time stamp (wrapping every 2³² µs ≈ 71.6 min) is unwrapped into
    ``drive_time_s`` (s of the drive's clock, its origin the drive's). Frames of the wrong length are
    counted and skipped. A mapped statusword is watched for bit 11 "internal limit active": each span it stays set,
    from the host stamp of the first frame with it set to that of the first with it clear, is kept for
    :meth:`take_limit_spans` (a span still open at the end: :meth:`take_limit_spans` with ``final``).
    """

    def __init__(self, unwrapper: SyncUnwrapper, with_velocity: bool, counts_per_s_per_unit: float,
                 with_timestamp: bool = False, layout: TpdoLayout | None = None) -> None:
        self._unwrapper = unwrapper
        if layout is None:
            layout = TpdoLayout(4 * (1 + with_velocity + with_timestamp), 0, 4 if with_velocity else None,
                                4 * (1 + with_velocity) if with_timestamp else None)
        self._layout, self._dtype = layout, layout.dtype()
        self._with_velocity, self._with_timestamp = layout.velocity is not None, layout.timestamp is not None
        self._scale = counts_per_s_per_unit
        self._last_raw: int | None = None
        self._last_counts = 0
        self._last_stamp_raw: int | None = None
        self._last_stamp_us = 0
        self.bad_length = 0
        self.before_first_sync = 0
        self._limit_spans = LimitSpans()

    def decode(self, frames: list[tuple[int, bytes, int]] | list[tuple[int, bytes, int, int]]) -> EncoderBlock | None:
        """Decode frames (counter, payload, host_ns[, SYNC frames seen]) in arrival order; None if none is usable."""
        size = self._layout.size
        good = [f for f in frames if len(f[1]) == size and f[0] != 0]
        self.bad_length += sum(len(f[1]) != size for f in frames)
        self.before_first_sync += sum(len(f[1]) == size and f[0] == 0 for f in frames)
        if not good:
            return None
        index = np.array([self._unwrapper.push(f[0], f[2], f[3] if len(f) > 3 else None) for f in good],
                         dtype=np.int64)
        host_ns = np.array([f[2] for f in good], dtype=np.int64)
        values = np.frombuffer(b"".join(f[1] for f in good), dtype=self._dtype)
        raw = values["position"].astype(np.int64)
        prev = raw[0] if self._last_raw is None else self._last_raw
        steps = (np.diff(np.r_[prev, raw]) + 2**31) % 2**32 - 2**31
        counts = self._last_counts + np.cumsum(steps) + (raw[0] if self._last_raw is None else 0)
        self._last_raw, self._last_counts = int(raw[-1]), int(counts[-1])
        velocity = values["velocity"] * self._scale if self._with_velocity else None
        demand = values["velocity_demand"] * self._scale if self._layout.velocity_demand is not None else None
        drive_time_s = self._unwrap_stamps(values["timestamp"]) if self._with_timestamp else None
        if self._layout.statusword is not None:
            self._watch_limit((values["statusword"] & SW_INTERNAL_LIMIT) != 0, host_ns)
        return EncoderBlock(index=index, position_counts=counts, host_ns=host_ns, drive_time_s=drive_time_s,
                            velocity_counts_per_s=velocity, velocity_demand_counts_per_s=demand)

    def _watch_limit(self, active: np.ndarray, host_ns: np.ndarray) -> None:
        """Follow bit 11 over frames stamped ``host_ns``: the first frame, those where it changes, and the last are
        enough (:meth:`drivers.base.LimitSpans.see` keeps a span's start and its last frame)."""
        changes = np.flatnonzero(np.diff(active.astype(np.int8))) + 1
        for i in np.r_[0, changes, active.size - 1].tolist():
            self._limit_spans.see(bool(active[i]), int(host_ns[i]))

    def take_limit_spans(self, final: bool = False) -> list[tuple[int, int]]:
        """The "internal limit active" spans (host ns: start, end) that ended since the last call; with ``final`` also
        one still open, ended at the last frame that had bit 11 set (:class:`drivers.base.LimitSpans`)."""
        return self._limit_spans.take(final)

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
