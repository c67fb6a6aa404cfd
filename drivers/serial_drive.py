"""A servo drive streaming framed encoder telemetry over a serial link (pyserial, imported lazily).

The port is opened with ``serial.serial_for_url`` from ``[drive]`` (``port``, ``baud``, ``parity``,
``codec``, ``period_s``, ``read_timeout_s``), so ``/dev/ttyUSB0``, ``socket://host:port``, ``loop://``
and a pseudo-terminal all work. Frames are cut by a codec (:mod:`drivers.serial_codec`; the default
``acq1`` frame is start bytes, length, type, sequence u16, drive time µs u32, position i32 and a
CRC-16/CCITT-FALSE, 16 bytes, byte table there and in README). Motion commands (stream on/off, start
triangle, stop) travel over the same link as frames of the same codec and are acknowledged.

A reader thread owned by the drive drains the port from :meth:`SerialDrive.start` to
:meth:`SerialDrive.stop`, not the recorder's read loop, because (1) the port must be read whether or
not a consumer is calling :meth:`~SerialDrive.read` — a UART/pty buffer holds only a fraction of a
second at 1 kHz; (2) acknowledgements to motion commands must be received while the consumer thread
is busy or not yet started; (3) each frame's ``host_ns`` must be the arrival time. Every port read
has a timeout (``read_timeout_s``), so the thread never blocks forever and stops promptly.

With ``[drive] motion = "external"`` (``acq monitor``: the machine's own controller moves the joint) acq only
switches the telemetry stream on and off; it never sends ``start_triangle`` or ``stop_motion``.

Raw wire values are unwrapped, never corrected: the u16 sequence becomes the cumulative int64
``index`` (the u32 drive time disambiguates a silence longer than 65536 frames), the u32 µs drive time
becomes ``drive_time_s``, the i32 position register becomes int64 ``position_counts``. A sequence
jump is counted and reported as a ``gap`` event; CRC errors, resynchronisations and skipped bytes
are counted (:class:`LinkStats`) and summarised in ``warning`` events at most once a second.
"""

from __future__ import annotations

import os
import queue
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.base import DriveInfo, EncoderBlock, EventKind, StreamEvent
from drivers.config import Bench, DriveSerial, Profile
from drivers.motion import with_dither_seed
from acqcore.errors import ConfigError, DeviceError
from drivers.serial_codec import CODECS, Ack, Codec, Command, ParserStats, StreamParser, Telemetry

WARNING_INTERVAL_S = 1.0
READ_CHUNK_BYTES = 4096


def codec_for(settings: DriveSerial) -> Codec:
    """The codec ``[drive] codec`` names (its name and the baud rate it needs are validators of
    :class:`DriveSerial`)."""
    return CODECS[settings.codec]()


@dataclass(frozen=True)
class LinkStats:
    """Counters of the serial link since :meth:`SerialDrive.start` (all cumulative).

    ``frames``: good telemetry frames (acknowledgements not counted); ``crc_errors``, ``bad_headers``, ``resyncs``,
    ``bytes_skipped``: see :class:`drivers.serial_codec.ParserStats`; ``gaps``: sequence jumps;
    ``frames_missing``: frames those jumps skipped; ``bytes_received``: all bytes read.
    """

    frames: int
    crc_errors: int
    bad_headers: int
    resyncs: int
    bytes_skipped: int
    gaps: int
    frames_missing: int
    bytes_received: int

    def describe(self) -> str:
        """One line for an event or a log."""
        return (f"{self.frames} frames, {self.gaps} gaps ({self.frames_missing} frames missing), "
                f"{self.crc_errors} CRC errors, {self.bad_headers} bad headers, {self.resyncs} resyncs "
                f"({self.bytes_skipped} bytes skipped), {self.bytes_received} bytes received")


class FrameUnwrapper:
    """Turns wrapping wire registers into cumulative values (sequence, drive time, position)."""

    def __init__(self, period_us: float) -> None:
        self.period_us = period_us
        self.index: int | None = None
        self._seq = self._time_raw = self._pos_raw = 0
        self.time_us = self.position = 0

    def push(self, t: Telemetry) -> int:
        """Advance to frame ``t``; return the frames skipped before it (0 when contiguous)."""
        if self.index is None:
            self.index, self.time_us, self.position = t.sequence, t.drive_time_us, t.position
            skipped = 0
        else:
            d_time = (t.drive_time_us - self._time_raw) % 2**32
            d_seq = (t.sequence - self._seq) % 2**16
            # a silence longer than 65536 frames: the drive time tells how many wraps were missed
            d_seq += round((d_time / self.period_us - d_seq) / 2**16) * 2**16
            skipped = d_seq - 1
            self.index += d_seq
            self.time_us += d_time
            self.position += (t.position - self._pos_raw + 2**31) % 2**32 - 2**31
        self._seq, self._time_raw, self._pos_raw = t.sequence, t.drive_time_us, t.position
        return skipped


class SerialDrive:
    """Encoder stream and motion of a drive on a serial link (implements :class:`drivers.base.Drive`).

    Parameters
    ----------
    settings : the ``[drive]`` section (``driver = "serial"``).
    counts_per_rev : encoder resolution, counts per motor revolution.
    """

    def __init__(self, settings: DriveSerial, counts_per_rev: int) -> None:
        self.settings = settings
        self.codec = codec_for(settings)
        self.port_name = settings.port
        self.counts_per_rev = counts_per_rev
        self._port: Any = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.Condition()
        self._pending: list[tuple[int, int, int, int]] = []  # (index, time_us, position, host_ns)
        self._events: list[StreamEvent] = []
        self._acks: queue.Queue[Ack] = queue.Queue()
        self._failure: DeviceError | None = None
        self._parser = StreamParser(self.codec)
        self._unwrap = FrameUnwrapper(settings.period_s * 1e6)
        self._frames = self._gaps = self._missing = self._bytes = 0
        self._command_lock = threading.Lock()
        self._reported_errors = (0, 0, 0)
        self._last_warning_s = time.monotonic()

    # ---- Drive protocol ----------------------------------------------------------------------------
    def start(self) -> DriveInfo:
        """Open the port, start the reader thread and switch the telemetry stream on."""
        import serial

        try:
            self._port = serial.serial_for_url(self.port_name, baudrate=self.settings.baud,
                                               parity=self.settings.parity, timeout=self.settings.read_timeout_s,
                                               write_timeout=self.settings.read_timeout_s)
        except (serial.SerialException, OSError, ValueError) as e:
            raise DeviceError(f"serial port {self.port_name}: cannot open: {e}") from None
        self._stop.clear()
        self._thread = threading.Thread(target=self._read_loop, name=f"acq-serial-{self.port_name}", daemon=True)
        self._thread.start()
        self._command(Command("stream_on"))
        return DriveInfo(period_s=self.settings.period_s, counts_per_rev=self.counts_per_rev, transport="serial",
                         timestamp_kind="frame_sequence", device=f"{self.port_name} ({self.codec.name})")

    def start_motion(self, profile: Profile) -> None:
        """Send the triangle's parameters (with a speed dither, its d and seed — one drawn here if the profile has
        none; the recorder draws it before); the drive starts it and acknowledges."""
        if self.settings.motion == "external":
            raise ConfigError("[drive] motion = \"external\": the machine's controller moves the drive, acq never "
                              "commands motion")
        if profile.cruise_s or profile.jerk_time_s:
            raise ConfigError(f"profile: cruise_s = {profile.cruise_s:g} s, jerk_time_s = {profile.jerk_time_s:g} s "
                              "cannot be sent in the serial protocol's start_triangle; set both to 0")
        self._command(Command("start_triangle", with_dither_seed(profile)))

    def stop_motion(self) -> None:
        """Tell the drive to ramp to rest. Idempotent; does nothing if the port is not open."""
        if self._port is not None and self._failure is None:
            self._command(Command("stop_motion"))

    def read(self, timeout_s: float) -> EncoderBlock | None:
        """Frames received since the last read, or None if none arrived within ``timeout_s`` (s).

        Raises :class:`DeviceError` once the link has failed (after the frames received before).
        """
        with self._lock:
            self._lock.wait_for(lambda: self._pending or self._failure is not None, timeout_s)
            rows, self._pending = self._pending, []
            if not rows and self._failure is not None:
                raise self._failure
        if not rows:
            return None
        a = np.array(rows, dtype=np.int64)
        return EncoderBlock(index=a[:, 0], position_counts=a[:, 2], host_ns=a[:, 3], drive_time_s=a[:, 1] * 1e-6)

    def stop(self) -> None:
        """Switch the stream off, stop the reader, close the port. Idempotent."""
        if self._port is not None:
            if self._failure is None:
                try:
                    self._command(Command("stream_off"))
                except DeviceError as e:
                    self._event("warning", f"stream off: {e}")
            self._stop.set()
            if hasattr(self._port, "cancel_read"):
                self._port.cancel_read()
            if self._thread is not None:
                self._thread.join(timeout=2 * self.settings.read_timeout_s)
            self._port.close()
            self._port = None
            self._event("info", f"serial link {self.port_name}: {self.stats().describe()}")

    def events(self) -> list[StreamEvent]:
        """Return and forget the gap, warning and error events noticed since the last call."""
        with self._lock:
            events, self._events = self._events, []
        return events

    # ---- link --------------------------------------------------------------------------------------
    def stats(self) -> LinkStats:
        """A snapshot of the link counters."""
        with self._lock:
            p: ParserStats = self._parser.stats
            return LinkStats(self._frames, p.crc_errors, p.bad_headers, p.resyncs, p.bytes_skipped, self._gaps,
                             self._missing, self._bytes)

    def _event(self, kind: EventKind, detail: str) -> None:
        with self._lock:
            self._events.append(StreamEvent(time.monotonic_ns(), "drive", kind, detail))

    def _command(self, command: Command) -> None:
        """Send ``command`` and wait ``read_timeout_s`` for its acknowledgement."""
        with self._command_lock:
            while not self._acks.empty():
                self._acks.get_nowait()
            try:
                self._port.write(self.codec.encode(command))
            except Exception as e:  # noqa: BLE001 - pyserial raises SerialException, OSError or its timeout
                raise DeviceError(f"serial port {self.port_name}: sending {command.kind} failed: {e}") from None
            deadline = time.monotonic() + self.settings.read_timeout_s
            while (left := deadline - time.monotonic()) > 0:
                try:
                    ack = self._acks.get(timeout=left)
                except queue.Empty:
                    break
                if ack.command == command.kind:
                    if ack.status != 0:
                        raise DeviceError(f"serial port {self.port_name}: drive refused {command.kind} "
                                          f"(status {ack.status}){_dither_hint(command)}")
                    return
            raise DeviceError(f"serial port {self.port_name}: no acknowledgement of {command.kind} within "
                              f"{self.settings.read_timeout_s:g} s{_dither_hint(command)}")

    def _read_loop(self) -> None:
        """Reader thread: drain the port, cut frames, unwrap, queue; never blocks longer than a timeout."""
        try:
            while not self._stop.is_set():
                data = self._port.read(max(1, min(self._port.in_waiting, READ_CHUNK_BYTES)))
                if not data:
                    continue
                host_ns = time.monotonic_ns()
                with self._lock:
                    self._bytes += len(data)
                    telemetry = [self._accept(frame, host_ns) for frame in self._parser.feed(data)]
                    if any(telemetry):
                        self._lock.notify_all()
                    self._warn_if_errors(host_ns)
        except Exception as e:  # noqa: BLE001 - a vanished port ends the stream with one clear error
            if not self._stop.is_set():
                with self._lock:
                    self._failure = DeviceError(f"serial port {self.port_name}: link lost: {e}")
                    self._events.append(StreamEvent(time.monotonic_ns(), "drive", "error", str(self._failure)))
                    self._lock.notify_all()

    def _warn_if_errors(self, host_ns: int) -> None:
        """Summarise new link errors in one ``warning`` event, at most every WARNING_INTERVAL_S (under the lock)."""
        p = self._parser.stats
        errors = (p.crc_errors, p.bad_headers, p.resyncs)
        now = time.monotonic()
        if errors != self._reported_errors and now - self._last_warning_s >= WARNING_INTERVAL_S:
            self._reported_errors, self._last_warning_s = errors, now
            self._events.append(StreamEvent(host_ns, "drive", "warning",
                                            f"serial link {self.port_name}: {self.stats().describe()}"))

    def _accept(self, frame: object, host_ns: int) -> bool:
        """Handle one good frame (under the lock); True if it was telemetry."""
        if isinstance(frame, Ack):
            self._acks.put(frame)
            return False
        if not isinstance(frame, Telemetry):
            return False  # a command echoed back: nothing for the host
        self._frames += 1
        skipped = self._unwrap.push(frame)
        index = self._unwrap.index
        assert index is not None
        if skipped > 0:
            self._gaps += 1
            self._missing += skipped
            self._events.append(StreamEvent(host_ns, "drive", "gap",
                                            f"serial sequence gap: {skipped} frame(s) missing before index {index}"))
        self._pending.append((index, self._unwrap.time_us, self._unwrap.position, host_ns))
        return True


def _dither_hint(command: Command) -> str:
    """What to try when a drive neither takes nor acknowledges a dithered start: its firmware may predate the longer
    start_triangle frame that carries speed_dither and dither_seed."""
    if command.kind != "start_triangle" or command.profile is None or not command.profile.speed_dither:
        return ""
    return (f" — the profile dithers (speed_dither = {command.profile.speed_dither:g}): a drive firmware that predates "
            "the dithered start_triangle frame refuses it; set speed_dither = 0 in the profile or update the firmware")


def open_drive(bench: Bench, sim_bench: object, fast: bool) -> SerialDrive:
    """Registry factory: a serial drive on ``[drive] port`` (``sim_bench`` and ``fast`` unused: a
    simulated device is put behind the port by :mod:`drivers.sim.peers`, chosen by the registry).

    A missing port path is refused here, before anything starts (:class:`DeviceError`, exit code 1).
    """
    settings = bench.drive
    assert isinstance(settings, DriveSerial)
    if settings.port.startswith("/") and not os.path.exists(settings.port):  # a device path (not a URL, not COM3)
        raise DeviceError(f"serial port {settings.port}: no such device (is the drive connected and powered?)")
    return SerialDrive(settings, bench.encoder.counts_per_rev)
