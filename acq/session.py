"""The session file: HDF5 via h5py. This module is the only code that knows the layout.

Layout (``format = "acq-session"``, ``format_version = 1``)::

    /                   attrs: format, format_version, session_id, created_utc, stopped_utc,
                               host_monotonic_ns_at_start, acq_version, status, stop_reason,
                               bench_json, profile_json, joint, operator, tags_json, origin_json,
                               host_clock_shared (both streams' host_ns on one host clock; absent in
                               older files: true for recordings, false for imports)
    /current            attrs: rate_hz (coerced by the card), device, channels, units
        i_a_A [, i_b_A, i_c_A]   float64, A, one entry per stored sample
        blocks/first_index       int64, cumulative DAQ sample index of each read's first sample
        blocks/count             int64, samples per channel in that read
        blocks/host_ns           int64, host monotonic time when the read returned
    /encoder            attrs: period_s, counts_per_rev, transport, timestamp_kind, device
        position_counts          int64, unwrapped raw position register
        index                    int64, cumulative drive cycle (SYNC counter / sequence)
        host_ns                  int64, host arrival time of each sample
        drive_time_s             float64, optional (the drive's own stamp)
        velocity_counts_per_s    float64, optional
    /events             compound rows (host_ns, stream, kind, detail)

Crash safety: the writer creates every dataset, then switches to SWMR mode (libver v110) and
flushes regularly, so a killed recorder leaves a file that opens (``swmr=True``) with every
flushed sample. ``status`` is ``recording`` until :meth:`SessionWriter.finish` reopens the file
and writes the footer. :func:`repair` rewrites a killed session into a clean file.
"""

from __future__ import annotations

import json
import os
import uuid
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np

from acq import __version__
from drivers.base import CurrentBlock, CurrentSourceInfo, DriveInfo, EncoderBlock, StreamEvent
from drivers.config import Bench, Profile
from drivers.errors import ConfigError

FORMAT = "acq-session"
FORMAT_VERSION = 1
LIBVER = ("v110", "latest")
Status = Literal["recording", "complete", "interrupted", "failed"]

EVENT_DTYPE = np.dtype([("host_ns", "<i8"), ("stream", "S16"), ("kind", "S16"), ("detail", "S240")])
_OPTIONAL_ENCODER = ("drive_time_s", "velocity_counts_per_s")


def utc_now_iso() -> str:
    """The current UTC time as ISO 8601 with seconds."""
    return datetime.now(UTC).isoformat(timespec="seconds")


def new_session_path(out_dir: Path, joint: str, created_utc: str) -> Path:
    """``<out_dir>/<UTC start>_<joint>.h5`` (file-system safe), ``_2``, ``_3`` … if taken."""
    stamp = created_utc.replace("+00:00", "").replace(":", "-")
    path = Path(out_dir) / f"{stamp}_{joint}.h5"
    n = 2
    while path.exists():
        path = Path(out_dir) / f"{stamp}_{joint}_{n}.h5"
        n += 1
    return path


def _extendable(group: h5py.Group, name: str, dtype: Any, chunk: int) -> h5py.Dataset:
    return group.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dtype, chunks=(chunk,))


def _append(ds: h5py.Dataset, values: np.ndarray) -> None:
    n = ds.shape[0]
    ds.resize((n + values.shape[0],))
    ds[n:] = values


class _PendingColumns:
    """Appends held in memory until the next flush, so each dataset grows once per flush."""

    def __init__(self) -> None:
        self._parts: dict[str, list[np.ndarray]] = {}

    def add(self, name: str, values: np.ndarray) -> None:
        self._parts.setdefault(name, []).append(values)

    def write_to(self, f: h5py.File) -> None:
        while self._parts:
            name, parts = self._parts.popitem()  # taken before writing: an interrupted flush never repeats a part
            _append(f[name], np.concatenate(parts))


class SessionWriter:
    """Write one session: create the layout, append blocks in order, finish with a footer.

    Parameters
    ----------
    path : Path
        The ``.h5`` file to create (must not exist).
    bench, profile : the configs as used (stored as JSON).
    current_info, drive_info : what the started devices reported (coerced rate, period, ...).
    operator : optional name of the person at the bench.
    tags : optional free-form tags (pose, payload_kg, temperature_C, ...).
    origin : optional description of where the data came from (e.g. imported files).
    host_clock_shared : whether both streams' host stamps are arrival times on one host clock (True for a
        recording; an import of files from separate tools is False).
    session_id, created_utc : the identity and start time (ISO 8601, UTC) of a session recorded earlier and
        restored by an import; by default a new UUID4 and now.
    """

    def __init__(
        self,
        path: Path,
        *,
        bench: Bench,
        profile: Profile,
        current_info: CurrentSourceInfo,
        drive_info: DriveInfo,
        host_ns_at_start: int,
        operator: str = "",
        tags: dict[str, Any] | None = None,
        origin: dict[str, Any] | None = None,
        host_clock_shared: bool = True,
        session_id: str | None = None,
        created_utc: str | None = None,
    ) -> None:
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise ConfigError(f"{self.path.parent}: no such folder for the session file")
        self._channels = current_info.channels
        self._filled_optional: set[str] = set()
        self._pending = _PendingColumns()
        f = h5py.File(self.path, "w-", libver=LIBVER)
        self._file = f
        created = created_utc or utc_now_iso()
        f.attrs.update(
            {
                "format": FORMAT,
                "format_version": FORMAT_VERSION,
                "session_id": session_id or str(uuid.uuid4()),
                "created_utc": created,
                "stopped_utc": "",
                "host_monotonic_ns_at_start": np.int64(host_ns_at_start),
                "acq_version": __version__,
                "status": "recording",
                "stop_reason": "",
                "bench_json": bench.model_dump_json(),
                "profile_json": profile.model_dump_json(),
                "joint": bench.joint,
                "operator": operator,
                "tags_json": json.dumps(tags or {}),
                "origin_json": json.dumps(origin or {"kind": "recorded"}),
                "host_clock_shared": bool(host_clock_shared),
            }
        )
        cur = f.create_group("current")
        cur.attrs.update(
            {
                "rate_hz": float(current_info.rate_hz),
                "device": current_info.device,
                "channels": ",".join(current_info.channels),
                "units": current_info.units,
            }
        )
        chunk = max(1024, int(current_info.rate_hz // 10))
        for ch in self._channels:
            _extendable(cur, f"{ch}_A", "f8", chunk)
        blocks = cur.create_group("blocks")
        for name in ("first_index", "count", "host_ns"):
            _extendable(blocks, name, "i8", 256)
        enc = f.create_group("encoder")
        enc.attrs.update(
            {
                "period_s": float(drive_info.period_s),
                "counts_per_rev": int(drive_info.counts_per_rev),
                "transport": drive_info.transport,
                "timestamp_kind": drive_info.timestamp_kind,
                "device": drive_info.device,
            }
        )
        enc_chunk = max(256, int(0.5 / drive_info.period_s))
        for name in ("position_counts", "index", "host_ns"):
            _extendable(enc, name, "i8", enc_chunk)
        for name in _OPTIONAL_ENCODER:
            _extendable(enc, name, "f8", enc_chunk)
        _extendable(f, "events", EVENT_DTYPE, 64)
        f.swmr_mode = True

    def append_current(self, block: CurrentBlock) -> None:
        """Append one DAQ block (caller guarantees increasing, non-overlapping indices)."""
        for row, ch in enumerate(self._channels):
            self._pending.add(f"current/{ch}_A", np.asarray(block.current_a[row], dtype=np.float64))
        self._pending.add("current/blocks/first_index", np.array([block.first_index], dtype=np.int64))
        self._pending.add("current/blocks/count", np.array([block.count], dtype=np.int64))
        self._pending.add("current/blocks/host_ns", np.array([block.host_ns], dtype=np.int64))

    def append_encoder(self, block: EncoderBlock) -> None:
        """Append encoder samples (caller guarantees strictly increasing ``index``)."""
        self._pending.add("encoder/position_counts", np.asarray(block.position_counts, dtype=np.int64))
        self._pending.add("encoder/index", np.asarray(block.index, dtype=np.int64))
        self._pending.add("encoder/host_ns", np.asarray(block.host_ns, dtype=np.int64))
        for name, values in zip(_OPTIONAL_ENCODER, (block.drive_time_s, block.velocity_counts_per_s)):
            if values is not None:
                self._filled_optional.add(name)
            filler = np.full(block.count, np.nan) if values is None else np.asarray(values, dtype=np.float64)
            self._pending.add(f"encoder/{name}", filler)

    def add_event(self, event: StreamEvent) -> None:
        """Append one event row."""
        detail = event.detail.encode()[:240].decode("utf-8", "ignore").encode()  # never split a character
        row = np.array([(event.host_ns, event.stream.encode(), event.kind.encode(), detail)], dtype=EVENT_DTYPE)
        self._pending.add("events", row)

    def flush(self) -> None:
        """Write everything appended so far; make it durable and visible to SWMR readers."""
        self._pending.write_to(self._file)
        self._file.flush()

    def finish(self, status: Status, stop_reason: str) -> None:
        """Close the SWMR file and write the footer: status, reason, stop time, sample counts."""
        self.flush()
        self._file.close()
        with h5py.File(self.path, "r+", libver=LIBVER) as f:
            _write_footer(f, status, stop_reason, self._filled_optional)


def _write_footer(f: h5py.File, status: Status, stop_reason: str, filled_optional: set[str]) -> None:
    for name in _OPTIONAL_ENCODER:
        if name in f["encoder"] and name not in filled_optional:
            del f["encoder"][name]
    f.attrs["status"] = status
    f.attrs["stop_reason"] = stop_reason
    f.attrs["stopped_utc"] = utc_now_iso()
    f.attrs["current_samples"] = np.int64(f["current/blocks/count"][...].sum())
    f.attrs["encoder_samples"] = np.int64(f["encoder/index"].shape[0])


# --------------------------------------------------------------------------------------- reading


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
    """The encoder stream as stored (counts, drive cycle index, host arrival ns)."""

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


@dataclass(frozen=True)
class Session:
    """A session file read back: root attributes, configs as used, both streams and the events."""

    path: Path
    attrs: dict[str, Any]
    bench: Bench
    profile: Profile
    current: CurrentData
    encoder: EncoderData
    events: list[StreamEvent] = field(default_factory=list)

    @property
    def status(self) -> str:
        return str(self.attrs.get("status", ""))

    @property
    def tags(self) -> dict[str, Any]:
        return json.loads(self.attrs.get("tags_json", "{}"))

    @property
    def host_clock_shared(self) -> bool:
        """Whether both streams' host stamps are arrival times on one host clock (older files: recordings are)."""
        if "host_clock_shared" in self.attrs:
            return bool(self.attrs["host_clock_shared"])
        return json.loads(self.attrs.get("origin_json", "{}")).get("kind", "recorded") != "imported"

    def require_samples(self) -> None:
        """Raise :class:`ConfigError` naming the stream when either stream holds too little to use."""
        if self.current.sample_count == 0:
            raise ConfigError(f"{self.path}: /current holds no samples (status {self.status})")
        if self.encoder.index.size < 2:
            raise ConfigError(f"{self.path}: /encoder holds {self.encoder.index.size} samples (status {self.status})")


def _attr(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _open_for_reading(path: Path) -> h5py.File:
    if not path.exists():
        raise ConfigError(f"{path}: no such session file")
    if path.is_dir():
        raise ConfigError(f"{path}: is a folder, not a session file")
    try:
        return h5py.File(path, "r", swmr=True)
    except OSError as e:
        first_line = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ConfigError(f"{path}: not a readable HDF5 session file ({first_line})") from None


def _lengths_consistent(f: h5py.File) -> int:
    """Length of the encoder stream shared by all its columns (a kill may leave them uneven)."""
    enc = f["encoder"]
    return min(enc[name].shape[0] for name in enc if isinstance(enc[name], h5py.Dataset))


def _read_current(g: h5py.Group) -> CurrentData:
    counts = g["blocks/count"][...]
    first = g["blocks/first_index"][...]
    host = g["blocks/host_ns"][...]
    channels = [c for c in str(_attr(g.attrs["channels"])).split(",") if c]
    phases = {ch: g[f"{ch}_A"][...] for ch in channels}
    stored = min([len(first), len(counts), len(host)])
    counts, first, host = counts[:stored], first[:stored], host[:stored]
    n = min([int(counts.sum())] + [len(v) for v in phases.values()])
    while stored and int(counts.sum()) > n:  # a kill between writing samples and the block row
        stored -= 1
        counts, first, host = counts[:stored], first[:stored], host[:stored]
    n = int(counts.sum())
    return CurrentData(
        rate_hz=float(g.attrs["rate_hz"]),
        device=str(_attr(g.attrs["device"])),
        phases_a={ch: v[:n] for ch, v in phases.items()},
        block_first_index=first,
        block_count=counts,
        block_host_ns=host,
    )


def _read_encoder(g: h5py.Group, n: int) -> EncoderData:
    def optional(name: str) -> np.ndarray | None:
        return g[name][:n] if name in g else None

    return EncoderData(
        period_s=float(g.attrs["period_s"]),
        counts_per_rev=int(g.attrs["counts_per_rev"]),
        transport=str(_attr(g.attrs["transport"])),
        timestamp_kind=str(_attr(g.attrs["timestamp_kind"])),
        device=str(_attr(g.attrs["device"])),
        position_counts=g["position_counts"][:n],
        index=g["index"][:n],
        host_ns=g["host_ns"][:n],
        drive_time_s=optional("drive_time_s"),
        velocity_counts_per_s=optional("velocity_counts_per_s"),
    )


def _read_events(ds: h5py.Dataset) -> list[StreamEvent]:
    return [
        StreamEvent(int(r["host_ns"]), r["stream"].decode(), r["kind"].decode(),  # type: ignore[arg-type]
                    r["detail"].decode("utf-8", "replace"))
        for r in ds[...]
    ]


def load(path: Path | str) -> Session:
    """Read a whole session (also one still being recorded, or left by a killed recorder)."""
    p = Path(path)
    with _open_for_reading(p) as f:
        if _attr(f.attrs.get("format")) != FORMAT:
            raise ConfigError(f"{p}: not an acq session (format attribute is {_attr(f.attrs.get('format'))!r})")
        version = int(f.attrs.get("format_version", 0))
        if version > FORMAT_VERSION:
            raise ConfigError(f"{p}: format_version {version} is newer than this acq reads ({FORMAT_VERSION})")
        attrs = {k: _attr(v) for k, v in f.attrs.items()}
        bench = Bench.model_validate_json(attrs["bench_json"])
        profile = Profile.model_validate_json(attrs["profile_json"])
        return Session(
            path=p,
            attrs=attrs,
            bench=bench,
            profile=profile,
            current=_read_current(f["current"]),
            encoder=_read_encoder(f["encoder"], _lengths_consistent(f)),
            events=_read_events(f["events"]),
        )


def repair(path: Path | str, stop_reason: str) -> None:
    """Rewrite a session left with status ``recording`` (writer killed) as ``interrupted``.

    HDF5 keeps a crashed SWMR writer's file marked as open for writing, so it cannot be reopened
    for writing in place: every flushed sample is copied into a fresh file beside it (uneven column
    lengths cut to the common length), which then atomically replaces the original.
    """
    p = Path(path)
    session = load(p)
    tmp = p.with_suffix(".repair.h5")
    with h5py.File(p, "r", swmr=True) as src, h5py.File(tmp, "w", libver=LIBVER) as dst:
        dst.attrs.update(dict(src.attrs))
        cur = dst.create_group("current")
        cur.attrs.update(dict(src["current"].attrs))
        for ch, values in session.current.phases_a.items():
            cur.create_dataset(f"{ch}_A", data=values, maxshape=(None,), chunks=True)
        blocks = cur.create_group("blocks")
        for name, values in (
            ("first_index", session.current.block_first_index),
            ("count", session.current.block_count),
            ("host_ns", session.current.block_host_ns),
        ):
            blocks.create_dataset(name, data=values, maxshape=(None,), chunks=True)
        enc = dst.create_group("encoder")
        enc.attrs.update(dict(src["encoder"].attrs))
        e = session.encoder
        for name, values in (
            ("position_counts", e.position_counts),
            ("index", e.index),
            ("host_ns", e.host_ns),
            ("drive_time_s", e.drive_time_s),
            ("velocity_counts_per_s", e.velocity_counts_per_s),
        ):
            if values is not None:
                enc.create_dataset(name, data=values, maxshape=(None,), chunks=True)
        dst.create_dataset("events", data=src["events"][...], maxshape=(None,), chunks=True)
        filled = {n for n in _OPTIONAL_ENCODER if n in enc and not np.all(np.isnan(enc[n][...]))}
        _write_footer(dst, "interrupted", stop_reason, filled)
    os.replace(tmp, p)
