"""A session file read back (:func:`acq.recording.reader.load`): both streams, the events, the configs as used and
the root attributes, typed."""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from acq.recording.live import being_recorded
from drivers.base import StreamEvent
from drivers.config import Bench, Profile
from acqcore.errors import ConfigError


@dataclass(frozen=True)
class CurrentData:
    """The current stream as stored: phases in A, per-read block table, coerced rate in Hz."""

    rate_hz: float
    device: str
    phases_a: dict[str, np.ndarray]
    block_first_index: np.ndarray
    block_count: np.ndarray
    block_host_ns: np.ndarray

    @property
    def sample_count(self) -> int:
        """Samples per channel stored."""
        return int(self.block_count.sum())

    def sample_index(self) -> np.ndarray:
        """The DAQ's cumulative sample index of every stored sample (int64)."""
        if self.block_count.size == 0:
            return np.zeros(0, dtype=np.int64)
        starts = np.repeat(self.block_first_index - np.cumsum(np.r_[0, self.block_count[:-1]]), self.block_count)
        return starts + np.arange(self.sample_count, dtype=np.int64)


@dataclass(frozen=True)
class EncoderData:
    """The encoder stream as stored (counts, drive cycle index, host arrival ns; the optional columns None where the
    drive did not give them)."""

    period_s: float
    counts_per_rev: int
    transport: str
    timestamp_kind: str
    device: str
    position_counts: np.ndarray
    index: np.ndarray
    host_ns: np.ndarray
    drive_time_s: np.ndarray | None
    velocity_counts_per_s: np.ndarray | None
    velocity_demand_counts_per_s: np.ndarray | None = None


@dataclass(frozen=True)
class SessionHistory:
    """What a session carries through ``acq export`` and ``acq import`` (:mod:`acq.offline.export_metadata`).

    ``session_id``, ``joint``, ``created_utc`` (ISO 8601 UTC of the start) are None only in a file that lacks
    them; ``operator`` is ``""`` when absent; ``origin`` is where the data came from (``{"kind": "recorded"}``,
    or the imported files; ``{}`` when absent); ``tags`` the free-form tags; ``host_clock_shared`` whether both
    streams' host stamps are arrival times on one host clock.
    """

    session_id: str | None
    joint: str | None
    created_utc: str | None
    operator: str
    origin: dict[str, Any]
    tags: dict[str, Any]
    host_clock_shared: bool


@dataclass(frozen=True)
class SessionMeta(SessionHistory):
    """What a session file says about itself (its root attributes), typed: the one way other modules read them.

    Its :class:`SessionHistory`, and ``host_ns_at_start`` (host monotonic clock at the start, ns; None only in a
    file that lacks it); ``stopped_utc``, ``status`` and ``stop_reason`` are ``""`` when absent.
    """

    host_ns_at_start: int | None
    stopped_utc: str
    status: str
    stop_reason: str

    @classmethod
    def from_attrs(cls, attrs: dict[str, Any]) -> SessionMeta:
        """From the root attributes as read (``load`` has checked them: :mod:`acq.recording.root_attrs`)."""
        origin = json.loads(attrs.get("origin_json", "{}"))
        if "host_clock_shared" in attrs:
            shared = bool(attrs["host_clock_shared"])
        else:  # older files: recordings are, imports are not
            shared = origin.get("kind", "recorded") != "imported"
        start = attrs.get("host_monotonic_ns_at_start")

        def text(name: str) -> str | None:
            value = attrs.get(name)
            return None if value is None else str(value)

        return cls(session_id=text("session_id"), joint=text("joint"), created_utc=text("created_utc"),
                   host_ns_at_start=None if start is None else int(start),
                   stopped_utc=str(attrs.get("stopped_utc", "")), status=str(attrs.get("status", "")),
                   stop_reason=str(attrs.get("stop_reason", "")), operator=str(attrs.get("operator", "")),
                   origin=origin, tags=json.loads(attrs.get("tags_json", "{}")), host_clock_shared=shared)


@dataclass(frozen=True)
class Session:
    """A session file read back: root attributes, configs as used, both streams and the events."""

    path: Path
    attrs: dict[str, Any]
    bench: Bench
    profile: Profile | None  # None: recorded passively, the machine's own controller moved the joint
    current: CurrentData
    encoder: EncoderData
    events: list[StreamEvent] = field(default_factory=list)
    #: What could not be read, one line per span ("current: samples 62 550–65 109 unreadable"); the streams above
    #: hold every readable sample: a span inside a stream is left out as a gap (a jump in the DAQ sample index or the
    #: drive cycle index), a damaged or missing tail is cut.
    damage: tuple[str, ...] = ()
    #: The span of each line of :attr:`damage` that names one: (stream, first row lost, end row), in its order.
    damage_spans: tuple[tuple[str, int, int], ...] = ()

    @functools.cached_property
    def meta(self) -> SessionMeta:
        """The root attributes, typed (the way to read them outside the session file's modules)."""
        return SessionMeta.from_attrs(self.attrs)

    @property
    def status(self) -> str:
        return self.meta.status

    def require_usable(self, *, partial: bool = False, action: str = "analyse") -> None:
        """Raise :class:`ConfigError` for a session still ``recording`` or damaged, unless ``partial``.

        ``partial`` accepts them: the intact part is used (the caller marks its result partial). ``action`` is what
        ``--partial`` would do with it, in the message ("analyse", "export").
        """
        if partial:
            return
        if self.damage:
            raise ConfigError(f"{self.path}: damaged ({'; '.join(self.damage)}) — run acq check, or use --partial "
                              f"to {action} the intact part")
        if self.status == "recording":
            raise ConfigError(f"{self.path}: {self.unfinished_note()}, or use --partial to {action} what is stored")

    def unfinished_note(self) -> str:
        """What a session with status ``recording`` is and what to do about it: a running recorder still holds it
        (wait), or none does any more (acq check repairs it)."""
        if being_recorded(self.path):
            return "still being recorded by a running recorder — wait until it finishes"
        return ("status recording, but no recorder holds it (killed, or stopped without finishing the file) — "
                f"run acq check {self.path} to repair it")

    def kept_after_first_damage(self, stream: str) -> int:
        """Samples of ``stream`` (``"current"``, ``"encoder"``) kept after its first damaged span (every sample before
        it is kept); all it holds when it has none."""
        held = self.current.sample_count if stream == "current" else self.encoder.index.size
        first = [start for name, start, _ in self.damage_spans if name == stream]
        return held - first[0] if first else held

    @property
    def tags(self) -> dict[str, Any]:
        return self.meta.tags

    @property
    def host_clock_shared(self) -> bool:
        """Whether both streams' host stamps are arrival times on one host clock (older files: recordings are)."""
        return self.meta.host_clock_shared

    def require_samples(self) -> None:
        """Raise :class:`ConfigError` naming the stream when either stream holds too little to use."""
        if self.current.sample_count == 0:
            raise ConfigError(f"{self.path}: /current holds no samples (status {self.status})")
        if self.encoder.index.size < 2:
            raise ConfigError(f"{self.path}: /encoder holds {self.encoder.index.size} samples (status {self.status})")
