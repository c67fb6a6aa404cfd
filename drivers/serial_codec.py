"""Frame codecs for the serial drive link, and the resynchronising stream parser.

A codec is one class that both encodes and decodes every frame of one wire protocol; the host
(:mod:`drivers.serial_drive`) and the simulated device (:mod:`drivers.sim.serial_device`) use the
same class, so a vendor's protocol is one more class in :data:`CODECS`.

Codec ``acq1`` (the default)
----------------------------
Every frame, in both directions::

    offset  size  field
    0       2     start bytes 0xA5 0x5A
    2       1     length L: bytes from ``type`` to the end of the payload (1 + payload size)
    3       1     type
    4       L-1   payload, little-endian
    3+L     2     CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final XOR;
                  ``binascii.crc_hqx(data, 0xFFFF)``) over bytes 2 … 2+L (length, type, payload),
                  sent most significant byte first

Frame types and payloads:

* ``0x01`` telemetry (device → host), 16 bytes in all: sequence ``u16`` (cycle counter, wraps at
  65536), drive time ``u32`` µs (wraps after 4295 s), position ``i32`` counts (the encoder
  register, wraps at ±2³¹);
* ``0x10`` stream on, ``0x11`` stream off, ``0x21`` stop motion (host → device): no payload;
* ``0x20`` start triangle (host → device): top speed ``i32`` milli-rpm, accel, decel and dwell
  ``u32`` µs, duration ``u32`` ms (20 bytes); a speed-dithered profile adds speed dither d ``u32`` in
  millionths and the dither seed ``u64`` (32 bytes, a 38-byte frame): the device runs full cycle c at
  s_c times the top speed and swing, s_c the c-th draw of ``numpy.random.default_rng(seed).uniform(1 − d,
  1 + d)`` (PCG64 seeded by NumPy's SeedSequence; s = 1 − d + 2d·(u64 >> 11)·2⁻⁵³ per draw), see
  :func:`drivers.motion.speed_factors`;
* ``0x80`` acknowledge (device → host): the command's type ``u8``, status ``u8`` (0 = done).

Frames are at most :data:`MAX_FRAME_BYTES` long. The parser finds a start, checks the length bound
and the CRC, and on any failure drops **one** byte and searches again, so a good frame that follows
(or hides inside) garbage or a corrupted frame is never lost.
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass, field
from typing import ClassVar, Protocol

from drivers.profile import Profile


@dataclass(frozen=True)
class Telemetry:
    """One encoder sample as sent on the wire (raw register widths)."""

    sequence: int
    drive_time_us: int
    position: int


@dataclass(frozen=True)
class Command:
    """A host → device command; ``profile`` is set for ``start_triangle`` only."""

    kind: str  # "stream_on" | "stream_off" | "start_triangle" | "stop_motion"
    profile: Profile | None = None


@dataclass(frozen=True)
class Ack:
    """The device's answer to a :class:`Command` of kind ``command`` (status 0 = done)."""

    command: str
    status: int = 0


Frame = Telemetry | Command | Ack


class Codec(Protocol):
    """A wire protocol: frame ⇄ bytes. Implementations are stateless."""

    name: str
    #: the bytes every frame starts with
    start: bytes
    #: bytes of one telemetry frame (sets the baud rate a frame rate needs)
    telemetry_bytes: int

    def encode(self, frame: Frame) -> bytes:
        """The bytes of ``frame`` on the wire."""
        ...

    def find_start(self, buf: bytearray, pos: int) -> int:
        """Index ≥ ``pos`` where a frame may start (a partial start at the end counts), or ``len(buf)``."""
        ...

    def decode(self, buf: bytearray, pos: int) -> tuple[str, Frame | None, int]:
        """Examine a frame candidate at ``pos``.

        Returns ``("ok", frame, n_bytes)``, ``("more", None, 0)`` if more bytes are needed,
        ``("bad", None, 0)`` for an impossible header or ``("crc", None, 0)`` for a checksum error.
        """
        ...


MAX_FRAME_BYTES = 64


class Acq1Codec:
    """The ``acq1`` protocol (see the module docstring)."""

    name: ClassVar[str] = "acq1"
    start: ClassVar[bytes] = b"\xa5\x5a"
    TELEMETRY: ClassVar[int] = 0x01
    ACK: ClassVar[int] = 0x80
    COMMANDS: ClassVar[dict[str, int]] = {"stream_on": 0x10, "stream_off": 0x11, "start_triangle": 0x20,
                                          "stop_motion": 0x21}
    _CMD_NAMES: ClassVar[dict[int, str]] = {v: k for k, v in COMMANDS.items()}
    _TEL = struct.Struct("<HIi")
    _TRI = struct.Struct("<iIIII")
    _DITHER = struct.Struct("<IQ")  # appended to _TRI for a speed-dithered profile
    _ACK = struct.Struct("<BB")
    telemetry_bytes: ClassVar[int] = 2 + 1 + 1 + _TEL.size + 2

    def encode(self, frame: Frame) -> bytes:
        """The bytes of ``frame`` on the wire (values are wrapped to their register widths)."""
        if isinstance(frame, Telemetry):
            kind, payload = self.TELEMETRY, self._TEL.pack(
                frame.sequence & 0xFFFF, frame.drive_time_us & 0xFFFFFFFF,
                (frame.position + 2**31) % 2**32 - 2**31)
        elif isinstance(frame, Ack):
            kind, payload = self.ACK, self._ACK.pack(self.COMMANDS[frame.command], frame.status)
        else:
            kind, payload = self.COMMANDS[frame.kind], b""
            if frame.kind == "start_triangle":
                p = frame.profile
                if p is None:
                    raise ValueError("start_triangle needs a profile")
                payload = self._TRI.pack(round(p.top_speed_rpm * 1e3), round(p.accel_time_s * 1e6),
                                         round(p.decel_time_s * 1e6), round(p.dwell_s * 1e6),
                                         round(p.duration_s * 1e3))
                if p.speed_dither:
                    if p.dither_seed is None:
                        raise ValueError("start_triangle of a dithered profile needs its dither_seed")
                    payload += self._DITHER.pack(round(p.speed_dither * 1e6), p.dither_seed)
        body = bytes((1 + len(payload), kind)) + payload
        return self.start + body + binascii.crc_hqx(body, 0xFFFF).to_bytes(2, "big")

    def find_start(self, buf: bytearray, pos: int) -> int:
        """Index ≥ ``pos`` of the next ``A5 5A`` (or a trailing ``A5``), else ``len(buf)``."""
        i = buf.find(self.start, pos)
        if i >= 0:
            return i
        n = len(buf)
        return n - 1 if n > pos and buf[-1] == self.start[0] else n

    def decode(self, buf: bytearray, pos: int) -> tuple[str, Frame | None, int]:
        """Examine a candidate frame at ``pos`` (see :class:`Codec`)."""
        if len(buf) - pos < 3:
            return "more", None, 0
        length = buf[pos + 2]
        total = 3 + length + 2
        if length < 1 or total > MAX_FRAME_BYTES:
            return "bad", None, 0
        if len(buf) - pos < total:
            return "more", None, 0
        body = bytes(buf[pos + 2:pos + 3 + length])
        if binascii.crc_hqx(body, 0xFFFF) != int.from_bytes(buf[pos + 3 + length:pos + total], "big"):
            return "crc", None, 0
        frame = self._frame(body[1], body[2:])
        return ("ok", frame, total) if frame is not None else ("bad", None, 0)

    def _frame(self, kind: int, payload: bytes) -> Frame | None:
        """Decode a checked payload; None for an unknown type or a payload of the wrong size."""
        try:
            if kind == self.TELEMETRY:
                return Telemetry(*self._TEL.unpack(payload))
            if kind == self.ACK:
                cmd, status = self._ACK.unpack(payload)
                return Ack(self._CMD_NAMES[cmd], status)
            name = self._CMD_NAMES[kind]
            if name != "start_triangle":
                return Command(name) if not payload else None
            mrpm, acc, dec, dwell, dur = self._TRI.unpack(payload[:self._TRI.size])
            dither = {}
            if len(payload) > self._TRI.size:
                ppm, seed = self._DITHER.unpack(payload[self._TRI.size:])
                dither = {"speed_dither": ppm / 1e6, "dither_seed": seed}
            return Command(name, Profile(kind="triangle", top_speed_rpm=mrpm / 1e3, accel_time_s=acc / 1e6,
                                         decel_time_s=dec / 1e6, dwell_s=dwell / 1e6, duration_s=dur / 1e3, **dither))
        except (struct.error, KeyError, ValueError):
            return None


#: codec name in ``[drive] codec`` → class
CODECS: dict[str, type[Codec]] = {"acq1": Acq1Codec}


def bits_per_byte(parity: str) -> int:
    """Bits on the line per byte: start + 8 data + parity (if any) + 1 stop."""
    return 10 if parity == "N" else 11


def required_baud(codec: Codec, period_s: float, parity: str) -> float:
    """Lowest baud rate (bit/s) that carries one telemetry frame every ``period_s`` (s)."""
    return codec.telemetry_bytes * bits_per_byte(parity) / period_s


@dataclass
class ParserStats:
    """What the parser has seen, cumulative.

    ``crc_errors``: candidates with a good header whose checksum failed; ``bad_headers``: starts with
    an impossible length or type; ``resyncs``: times sync was regained after skipping bytes;
    ``bytes_skipped``: bytes that belonged to no good frame.
    """

    frames: int = 0
    crc_errors: int = 0
    bad_headers: int = 0
    resyncs: int = 0
    bytes_skipped: int = 0


@dataclass
class StreamParser:
    """Cuts a byte stream into frames; resynchronises by dropping one byte after any failure.

    Holds at most one incomplete frame (≤ :data:`MAX_FRAME_BYTES`) between calls.
    """

    codec: Codec
    stats: ParserStats = field(default_factory=ParserStats)
    _buf: bytearray = field(default_factory=bytearray)
    _lost: bool = False

    def feed(self, data: bytes) -> list[Frame]:
        """Add received bytes; return the complete good frames they finish, in order."""
        buf = self._buf
        buf += data
        frames: list[Frame] = []
        pos = 0
        while pos < len(buf):
            start = self.codec.find_start(buf, pos)
            self._skip(start - pos)
            pos = start
            if pos >= len(buf):
                break
            status, frame, n = self.codec.decode(buf, pos)
            if status == "more":
                break
            if status == "ok":
                assert frame is not None
                if self._lost:
                    self.stats.resyncs += 1
                    self._lost = False
                self.stats.frames += 1
                frames.append(frame)
                pos += n
                continue
            if status == "crc":
                self.stats.crc_errors += 1
            else:
                self.stats.bad_headers += 1
            self._skip(1)
            pos += 1
        del buf[:pos]
        return frames

    def _skip(self, n: int) -> None:
        if n > 0:
            self.stats.bytes_skipped += n
            self._lost = True
