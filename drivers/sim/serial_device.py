"""A simulated serial drive behind a real pseudo-terminal, with switchable link faults.

:class:`SimSerialDevice` opens a pty (``os.openpty``, raw mode) and serves the host end's path
(``port_name``, e.g. ``/dev/pts/7``) to :mod:`drivers.serial_drive`, which opens it like any port.
Its thread answers the host's command frames (stream on/off, start triangle — with its speed dither and
seed, executed by the source's motion, :func:`drivers.motion.speed_factors` —, stop) and, while
streaming, sends one telemetry frame per drive cycle k, encoded by the same codec class the host
decodes with: sequence k, the drive's time stamp of cycle k (µs: k·period, or the instant the position was
latched when the source's SYNC latch jitters), the source's int32 position register at cycle k.

Pacing: frame k is ready at the source's ``host_ns_at(k·period)`` and the bytes leave at the
configured baud rate — a pty ignores baud, so the device models the UART itself: each byte occupies
the line for ``bits_per_byte / baud`` s after the previous one or after it became ready, on the ideal
schedule (a late wake-up sends the backlog at once, it never stretches the line).

Faults are scheduled by drive cycle from tests (deterministic whatever the timing):
:meth:`~SimSerialDevice.inject_garbage` (random bytes, never 0xA5, before a frame),
:meth:`~SimSerialDevice.inject_bytes` (exact bytes, e.g. a false header),
:meth:`~SimSerialDevice.flip_bit` (one bit of a frame's type, payload or CRC → one CRC error),
:meth:`~SimSerialDevice.drop_frames` (never sent → a sequence gap) and
:meth:`~SimSerialDevice.pause` (the line goes silent; held frames follow late, none lost).
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from drivers.config import Bench, DriveSerial, Profile, SimSettings
from drivers.serial_codec import CODECS, Ack, Codec, Command, StreamParser, Telemetry, bits_per_byte

MAX_WAIT_S = 0.02
MAX_BATCH_FRAMES = 1000
LOOKAHEAD_NS = 10_000_000  # frames are computed in batches up to 10 ms ahead, each still sent when due
_FLIP_FROM_BYTE = 3  # type, payload and CRC: every single-bit error there is a CRC error


class FrameSource(Protocol):
    """What the device needs from a simulated bench (:class:`drivers.sim.bench.SimBench` is one)."""

    drive_period_s: float

    def host_ns_at(self, t_s: np.ndarray | float) -> np.ndarray:
        """Host monotonic ns at which a frame of drive time ``t_s`` (s) is ready to send."""
        ...

    def encoder_register(self, first_cycle: int, count: int) -> np.ndarray:
        """int32 position register, counts, at drive cycles ``first_cycle …``."""
        ...

    def stamp_times_s(self, first_cycle: int, count: int) -> np.ndarray:
        """The drive's time stamp, s, of drive cycles ``first_cycle …``."""
        ...

    def start_motion(self, profile: Profile, t_start_s: float) -> float:
        """Start ``profile`` at drive time ``t_start_s`` (s)."""
        ...

    def stop_motion(self, t_s: float) -> float | None:
        """Ramp to rest from drive time ``t_s`` (s)."""
        ...

    def hold_history(self, consumer: str, from_t_s: float) -> None:
        """The device will still read cycles at drive times ≥ ``from_t_s`` (s)."""
        ...

    def release_history(self, consumer: str) -> None:
        """The device reads no more."""
        ...


@dataclass(frozen=True)
class _Pause:
    duration_ns: int


@dataclass
class FaultLog:
    """Faults actually applied (counted when the affected frame was due)."""

    garbage_bytes: int = 0
    garbage_bursts: int = 0
    flipped_frames: int = 0
    dropped_frames: int = 0
    pauses: int = 0


class SimSerialDevice:
    """A drive on a pseudo-terminal streaming a :class:`FrameSource` (see the module docstring).

    Parameters
    ----------
    source : the simulated bench (or any :class:`FrameSource`).
    codec : the wire protocol (the host must use the same class).
    baud : line rate to pace at, bit/s; parity : ``N``, ``E`` or ``O`` (11 bits per byte with parity).
    pre_roll_s : delay between a start command and the triangle's start, s.
    seed : seed of the garbage and bit-flip choices.
    dropped : drive cycles whose frames are never sent.
    """

    _CONSUMER = "serial-device"

    def __init__(self, source: FrameSource, codec: Codec, *, baud: int, parity: str = "N",
                 pre_roll_s: float = 0.2, seed: int = 0, dropped: Iterable[int] = ()) -> None:
        self.source, self.codec = source, codec
        self.period_s = float(source.drive_period_s)
        self.byte_ns = bits_per_byte(parity) * 1e9 / baud
        self.pre_roll_s = pre_roll_s
        self.log = FaultLog()
        self.commands: list[str] = []  # the kinds of the host's commands, in order received
        self._rng = np.random.default_rng(seed)
        self._master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(self._master, False)
        self._slave = slave  # kept open so the pty survives the host closing and reopening it
        self.port_name = os.ttyname(slave)
        self._parser = StreamParser(codec)
        self._lock = threading.Lock()
        self._garbage: dict[int, list[bytes]] = {}
        self._flips: dict[int, int | None] = {}
        self._drops: set[int] = set(dropped)
        self._pauses: dict[int, float] = {}
        self._tx: deque[tuple[int, bytes | _Pause]] = deque()  # (ready host ns, item)
        self._line_free_ns = 0
        self._streaming = False
        self._next_cycle = 0
        self._t0_ns = int(source.host_ns_at(0.0))
        self._closed = threading.Event()
        self._thread = threading.Thread(target=self._run, name="acq-sim-serial-device", daemon=True)
        self._thread.start()

    # ---- fault switches (call from tests; cycles are drive cycles not yet sent) --------------------
    def next_cycle(self) -> int:
        """The first cycle not yet produced: faults must be scheduled at or after it."""
        with self._lock:
            return max(self._next_cycle, self._cycle_at(time.monotonic_ns()) + 1)

    def inject_garbage(self, before_cycle: int, n_bytes: int) -> None:
        """Send ``n_bytes`` random bytes (never 0xA5, so never a false start) before frame ``before_cycle``."""
        choices = np.array([b for b in range(256) if b != self.codec.start[0]], dtype=np.uint8)
        self.inject_bytes(before_cycle, bytes(self._rng.choice(choices, n_bytes)))

    def inject_bytes(self, before_cycle: int, data: bytes) -> None:
        """Send exactly ``data`` before frame ``before_cycle`` (e.g. a false header)."""
        with self._lock:
            self._check_future(before_cycle)
            self._garbage.setdefault(before_cycle, []).append(bytes(data))

    def flip_bit(self, cycle: int, bit: int | None = None) -> None:
        """Corrupt frame ``cycle`` by one bit of its type, payload or CRC (``bit`` counted from the type
        byte's LSB; random if None, chosen so that the damaged frame holds no false start)."""
        with self._lock:
            self._check_future(cycle)
            self._flips[cycle] = bit

    def drop_frames(self, cycles: list[int] | range) -> None:
        """Never send the frames of ``cycles``."""
        with self._lock:
            for c in cycles:
                self._check_future(c)
            self._drops.update(int(c) for c in cycles)

    def pause(self, before_cycle: int, duration_s: float) -> None:
        """Hold the line silent for ``duration_s`` (s) before frame ``before_cycle``; held frames follow."""
        with self._lock:
            self._check_future(before_cycle)
            self._pauses[before_cycle] = self._pauses.get(before_cycle, 0.0) + duration_s

    def _check_future(self, cycle: int) -> None:
        if cycle < max(self._next_cycle, self._cycle_at(time.monotonic_ns()) + 1):
            raise ValueError(f"cycle {cycle} is already sent or due; schedule faults ahead of next_cycle()")

    # ---- life cycle --------------------------------------------------------------------------------
    def close(self) -> None:
        """Stop the device thread and close the pty. Idempotent."""
        if self._closed.is_set():
            return
        self._closed.set()
        self._thread.join(timeout=1.0)
        self.source.release_history(self._CONSUMER)
        os.close(self._master)
        os.close(self._slave)

    def _cycle_at(self, host_ns: int) -> int:
        return int((host_ns - self._t0_ns) // round(self.period_s * 1e9))

    def _run(self) -> None:
        readable: list[int] = []
        while not self._closed.is_set():
            if readable:
                self._receive()
            with self._lock:
                now = time.monotonic_ns()
                if self._streaming:
                    self._produce(now)
                wake_ns = self._transmit(now)
            wait_s = min(max((wake_ns - time.monotonic_ns()) * 1e-9, 0.0), MAX_WAIT_S)
            readable, _, _ = select.select([self._master], [], [], wait_s)

    # ---- host → device -----------------------------------------------------------------------------
    def _receive(self) -> None:
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, OSError):
            return
        for frame in self._parser.feed(data):
            if isinstance(frame, Command):
                with self._lock:
                    self._obey(frame)

    def _obey(self, command: Command) -> None:
        """Execute a command (under the lock) and queue its acknowledgement."""
        now = time.monotonic_ns()
        self.commands.append(command.kind)
        if command.kind == "stream_on" and not self._streaming:
            self._streaming = True
            self._next_cycle = max(self._next_cycle, self._cycle_at(now) + 1)
            self.source.hold_history(self._CONSUMER, self._next_cycle * self.period_s)
        elif command.kind == "stream_off":
            self._streaming = False
        elif command.kind == "start_triangle" and command.profile is not None:
            self.source.start_motion(command.profile, self._present_s(now) + self.pre_roll_s)
        elif command.kind == "stop_motion":
            self.source.stop_motion(self._present_s(now))
        self._tx.append((now, self.codec.encode(Ack(command.kind))))

    def _present_s(self, now_ns: int) -> float:
        """The drive's present time, s: the later of the host clock's cycle and the last frame produced."""
        return max(self._cycle_at(now_ns), self._next_cycle - 1) * self.period_s

    # ---- device → host -----------------------------------------------------------------------------
    def _produce(self, now_ns: int) -> None:
        """Queue the frames due by ``now_ns`` with their scheduled faults (under the lock)."""
        count = min(self._cycle_at(now_ns + LOOKAHEAD_NS) + 1 - self._next_cycle, MAX_BATCH_FRAMES)
        if count <= 0:
            return
        first = self._next_cycle
        positions = self.source.encoder_register(first, count)
        stamps_us = np.round(self.source.stamp_times_s(first, count) * 1e6).astype(np.int64)
        ready = self.source.host_ns_at(np.arange(first, first + count) * self.period_s)
        for i in range(count):
            k, t_ns = first + i, int(ready[i])
            if k in self._pauses:
                self._tx.append((t_ns, _Pause(round(self._pauses.pop(k) * 1e9))))
                self.log.pauses += 1
            for data in self._garbage.pop(k, []):
                self._tx.append((t_ns, data))
                self.log.garbage_bursts += 1
                self.log.garbage_bytes += len(data)
            if k in self._drops:
                self._drops.discard(k)
                self.log.dropped_frames += 1
                continue
            frame = self.codec.encode(Telemetry(k & 0xFFFF, int(stamps_us[i]) & 0xFFFFFFFF, int(positions[i])))
            if k in self._flips:
                frame = self._flipped(frame, self._flips.pop(k))
                self.log.flipped_frames += 1
            self._tx.append((t_ns, frame))
        self._next_cycle = first + count
        self.source.hold_history(self._CONSUMER, self._next_cycle * self.period_s)

    def _flipped(self, frame: bytes, bit: int | None) -> bytes:
        n_bits = (len(frame) - _FLIP_FROM_BYTE) * 8
        candidates = [bit] if bit is not None else list(self._rng.permutation(n_bits))
        for b in candidates:
            out = bytearray(frame)
            out[_FLIP_FROM_BYTE + b // 8] ^= 1 << (b % 8)
            if bit is not None or out.find(self.codec.start, 1) < 0:
                return bytes(out)
        raise ValueError("no bit flip of this frame avoids a false start")

    def _transmit(self, now_ns: int) -> int:
        """Write what the line has carried by ``now_ns`` (under the lock); return when to wake next, ns."""
        while self._tx:
            ready_ns, item = self._tx[0]
            start_ns = max(self._line_free_ns, ready_ns)
            if start_ns > now_ns:
                return start_ns
            if isinstance(item, _Pause):
                self._tx.popleft()
                self._line_free_ns = start_ns + item.duration_ns
                continue
            try:
                n = os.write(self._master, item)
            except BlockingIOError:
                return now_ns + round(MAX_WAIT_S * 1e9)  # the host is not reading: its buffer is full
            self._line_free_ns = start_ns + round(n * self.byte_ns)
            if n < len(item):
                self._tx[0] = (ready_ns, item[n:])
            else:
                self._tx.popleft()
        return now_ns + round(MAX_WAIT_S * 1e9)


def open_simulated_device(bench: Bench, sim_bench: FrameSource | None) -> SimSerialDevice:
    """The pty device for a bench with ``[drive] simulated_device = true``, streaming ``sim_bench``.

    Frames listed in ``[sim] drop_encoder_frames`` as (first_cycle, count) are never sent.
    """
    settings = bench.drive
    assert isinstance(settings, DriveSerial) and sim_bench is not None
    sim = bench.sim if bench.sim is not None else SimSettings()
    return SimSerialDevice(sim_bench, CODECS[settings.codec](), baud=settings.baud,
                           parity=settings.parity, pre_roll_s=sim.pre_roll_s, seed=sim.seed,
                           dropped=(c for first, n in sim.drop_encoder_frames for c in range(first, first + n)))
