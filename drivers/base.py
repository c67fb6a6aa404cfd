"""The hardware roles as Protocols, and the records they yield.

Two roles meet on a bench, each on its own clock:

* a :class:`CurrentSource` (a DAQ card) delivers phase currents in :class:`CurrentBlock` s, each
  stamped with its cumulative sample index (the card's own clock) and the host arrival time;
* a :class:`Drive` (servo drive) executes a motion profile and streams the encoder position in
  :class:`EncoderBlock` s, each sample carrying the drive's own cycle index (SYNC counter / frame
  sequence, unwrapped to a cumulative int64) and its host arrival time.

Host times are ``time.monotonic_ns()`` values (simulated benches running ``--fast`` use a virtual
host clock that starts at the real one). Nothing here resamples or corrects a timestamp: raw stream
indices go to disk, alignment is the analysis's job. Gaps are found by the recorder from the
indices, never from timing. Adapters raise :class:`acqcore.errors.DeviceError` on device failure.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal, Protocol, runtime_checkable

import numpy as np

from drivers.config import Profile

StreamName = Literal["current", "encoder", "drive", "recorder"]
EventKind = Literal["gap", "error", "warning", "info"]


@dataclass(frozen=True)
class CurrentBlock:
    """One read from a current source.

    Attributes
    ----------
    first_index : int
        Cumulative index of the first sample in the DAQ's own sample clock (0 at start).
    current_a : ndarray, shape (n_channels, n_samples), float64
        Phase currents, A, channels in the order of :attr:`CurrentSourceInfo.channels`.
    host_ns : int
        Host monotonic time when the read returned, ns.
    """

    first_index: int
    current_a: np.ndarray
    host_ns: int

    @property
    def count(self) -> int:
        """Samples per channel in this block."""
        return int(self.current_a.shape[1])


@dataclass(frozen=True)
class EncoderBlock:
    """Encoder samples from a drive, one entry per drive cycle received.

    Attributes
    ----------
    index : ndarray of int64
        Cumulative drive cycle index (SYNC counter or frame sequence, unwrapped by the driver).
    position_counts : ndarray of int64
        Position register, counts, unwrapped from its wire width by the driver.
    host_ns : ndarray of int64
        Host monotonic arrival time of each sample, ns.
    drive_time_s : ndarray of float64 or None
        The drive's own time stamp of each sample, s, where the transport carries one.
    velocity_counts_per_s : ndarray of float64 or None
        The drive's velocity actual value, counts/s, where mapped.
    velocity_demand_counts_per_s : ndarray of float64 or None
        The drive's velocity demand, counts/s (CiA 402 0x606B: the reference its speed loop acts on), where the
        drive gives it — with it a closed-loop (indirect) FRF is possible that load disturbances do not bias.
    """

    index: np.ndarray
    position_counts: np.ndarray
    host_ns: np.ndarray
    drive_time_s: np.ndarray | None = None
    velocity_counts_per_s: np.ndarray | None = None
    velocity_demand_counts_per_s: np.ndarray | None = None

    @property
    def count(self) -> int:
        """Samples in this block."""
        return int(self.index.shape[0])


@dataclass(frozen=True)
class StreamEvent:
    """Something worth keeping that is not a sample: a gap, a device error, a warning."""

    host_ns: int
    stream: StreamName
    kind: EventKind
    detail: str


#: The event a drive writes for a span in which it reported "internal limit active" (CiA 402 statusword 0x6041 bit 11:
#: a torque, speed or position limit held the motor), read back by :func:`limit_span_ns`.
LIMIT_EVENT = "internal limit active (0x6041 bit 11) from {start_s:.3f} s to {end_s:.3f} s after {origin}"
_LIMIT_EVENT = re.compile(r"^internal limit active \(0x6041 bit 11\) from (\S+) s to (\S+) s")


def limit_event(start_ns: int, end_ns: int, origin_ns: int, origin: str = "the motion started") -> StreamEvent:
    """The drive's event for a span of "internal limit active" seen from ``start_ns`` to ``end_ns`` (host monotonic
    ns), its times counted from ``origin_ns`` (what ``origin`` says happened then); stamped at its start."""
    detail = LIMIT_EVENT.format(start_s=(start_ns - origin_ns) * 1e-9, end_s=(end_ns - origin_ns) * 1e-9,
                                origin=origin)
    return StreamEvent(start_ns, "drive", "warning", detail + ": the drive held the motor at a torque, speed or "
                       "position limit (0x6072, 0x607F, 0x607D)")


#: CiA 402 statusword bit 11: internal limit active
SW_INTERNAL_LIMIT = 1 << 11


class LimitSpans:
    """The spans in which a drive's statusword had bit 11 "internal limit active" set, from statuswords seen one by one
    (polled by SDO, or in each TPDO): each from the first seen with it set to the first seen clear (host ns)."""

    def __init__(self) -> None:
        self._since_ns: int | None = None  # the first statusword with bit 11 set, None while clear
        self._seen_ns = 0  # the last with it set
        self._ended: list[tuple[int, int]] = []

    def see(self, active: bool, host_ns: int) -> None:
        """Bit 11 is ``active`` in the statusword seen at ``host_ns``."""
        if active:
            if self._since_ns is None:
                self._since_ns = host_ns
            self._seen_ns = host_ns
        elif self._since_ns is not None:
            self._ended.append((self._since_ns, host_ns))
            self._since_ns = None

    def take(self, final: bool = False) -> list[tuple[int, int]]:
        """The spans (start, end; host ns) that ended since the last call; with ``final`` also one still open, ended at
        the last statusword that had bit 11 set."""
        if final and self._since_ns is not None:
            self._ended.append((self._since_ns, self._seen_ns))
            self._since_ns = None
        out, self._ended = self._ended, []
        return out


def limit_span_ns(event: StreamEvent) -> tuple[int, int] | None:
    """The host span (start, end; monotonic ns) of a :func:`limit_event`, None for any other event."""
    match = _LIMIT_EVENT.match(event.detail) if event.stream == "drive" else None
    if match is None:
        return None
    length_ns = round((float(match[2]) - float(match[1])) * 1e9)
    return event.host_ns, event.host_ns + length_ns


@dataclass(frozen=True)
class CurrentSourceInfo:
    """What a started current source reports about itself.

    ``rate_hz`` is the rate the card actually runs at (coerced), not the one asked for.
    """

    rate_hz: float
    channels: tuple[str, ...]
    device: str
    units: str = "A"


@dataclass(frozen=True)
class DriveInfo:
    """What a started drive reports about itself.

    ``period_s`` is the drive cycle between encoder samples; ``transport`` is ``canopen``,
    ``serial`` or ``sim``; ``timestamp_kind`` says what ``index`` counts (e.g. ``sync_counter``).
    """

    period_s: float
    counts_per_rev: int
    transport: str
    timestamp_kind: str
    device: str


@runtime_checkable
class CurrentSource(Protocol):
    """A DAQ that samples phase currents on its own clock."""

    def start(self) -> CurrentSourceInfo:
        """Configure and start continuous acquisition; return the coerced settings."""
        ...

    def read(self, timeout_s: float) -> CurrentBlock | None:
        """Return the next block, or None if none arrived within ``timeout_s``."""
        ...

    def stop(self) -> None:
        """Stop acquisition and release the device. Idempotent."""
        ...

    def events(self) -> list[StreamEvent]:
        """Return and forget the events noticed since the last call."""
        ...


@runtime_checkable
class Drive(Protocol):
    """A servo drive: streams encoder position on its own cycle and executes a motion profile."""

    def start(self) -> DriveInfo:
        """Connect, configure the encoder stream and start it (the motor stays still)."""
        ...

    def start_motion(self, profile: Profile) -> None:
        """Enable the drive and start executing ``profile`` until :meth:`stop_motion`."""
        ...

    def read(self, timeout_s: float) -> EncoderBlock | None:
        """Return the samples received since the last read, or None after ``timeout_s``."""
        ...

    def stop_motion(self) -> None:
        """Bring the motor to rest and disable it. Idempotent; safe after a failure."""
        ...

    def stop(self) -> None:
        """Stop streaming and release the transport. Idempotent."""
        ...

    def events(self) -> list[StreamEvent]:
        """Return and forget the events noticed since the last call."""
        ...
