"""The session file: HDF5 via h5py. This module is the only code that knows the layout.

Layout (``format = "acq-session"``, ``format_version = 1``)::

    /                   attrs: format, format_version, session_id, created_utc, stopped_utc,
                               host_monotonic_ns_at_start, acq_version, status, stop_reason,
                               bench_json, profile_json, joint, operator, tags_json, origin_json,
                               host_clock_shared (both streams' host_ns on one host clock; absent in
                               older files: true for recordings, false for imports)
                               (profile_json holds the profile as executed: a dithered motion's speed_dither
                               and the dither_seed its drive used, drawn by the recorder if the file had none)
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
        velocity_demand_counts_per_s  float64, optional (the drive's speed reference, CiA 402 0x606B)
    /events             compound rows (host_ns, stream, kind, detail)

    /flushes            compound rows (host_ns, current_samples, current_blocks, encoder_samples, events):
                        the totals committed by each flush, written after the samples they count

Crash safety: the writer creates every dataset, then switches to SWMR mode (libver v110) and
flushes regularly, so a killed recorder leaves a file that opens (``swmr=True``) with every
flushed sample. ``status`` is ``recording`` until :meth:`SessionWriter.finish` reopens the file
and writes the footer. :func:`repair` rewrites a killed session into a clean file.

Integrity: every dataset carries HDF5 Fletcher32 checksums per chunk. A reader trusts only what
was committed (the footer's counts, or the last ``/flushes`` row of a session still ``recording``),
reads chunk by chunk with bounded metadata reads (:mod:`acq.recording.h5safe`) and reports what it could not
read as :attr:`Session.damage` ("current: samples 62 550–102 399 unreadable"), keeping the intact
part before the first damaged sample of each stream. A failed write (disk full, I/O error, the file
vanished) stops the writer at once: nothing after it is written or counted
(:attr:`SessionWriter.failure`).
"""

from __future__ import annotations

import contextlib
import json
import os
import time
import uuid
import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np
from pydantic import ValidationError

from acq import __version__
from acq.recording.h5safe import abandon, open_read, superblock_eof
from acq.recording.paths import require_session_file
from acq.recording.storage import atomic_path, cause_of, free_bytes, storage_error
from drivers.base import CurrentBlock, CurrentSourceInfo, DriveInfo, EncoderBlock, StreamEvent
from drivers.config import Bench, Profile
from acqcore.errors import ConfigError, StorageError

FORMAT = "acq-session"
FORMAT_VERSION = 1
LIBVER = ("v110", "latest")
Status = Literal["recording", "complete", "interrupted", "failed"]

EVENT_DTYPE = np.dtype([("host_ns", "<i8"), ("stream", "S16"), ("kind", "S16"), ("detail", "S240")])
FLUSH_DTYPE = np.dtype([("host_ns", "<i8"), ("current_samples", "<i8"), ("current_blocks", "<i8"),
                        ("encoder_samples", "<i8"), ("events", "<i8")])
#: Free bytes kept for the footer and HDF5's metadata beyond what a flush writes; a flush that would leave
#: less fails the recording as "disk full" before HDF5 sees an ENOSPC (which leaves HDF5 unreliable, see
#: acq.recording.h5safe). 1 MiB is ~10x the metadata a 60 s session's footer and chunk indexes grow by per flush.
RESERVE_BYTES = 1 << 20
_OPTIONAL_ENCODER = ("drive_time_s", "velocity_counts_per_s", "velocity_demand_counts_per_s")
_F8, _I8 = np.dtype(np.float64), np.dtype(np.int64)


def utc_now_iso() -> str:
    """The current UTC time as ISO 8601 with seconds."""
    return datetime.now(UTC).isoformat(timespec="seconds")


def new_session_path(out_dir: Path, joint: str, created_utc: str) -> Path:
    """``<out_dir>/<UTC start>_<joint>.h5`` (file-system safe), ``_2``, ``_3`` … if taken."""
    stamp = created_utc.replace("+00:00", "").replace(":", "-")
    path = Path(out_dir) / f"{stamp}_{joint}.h5"
    if path.resolve().parent != Path(out_dir).resolve() or "/" in joint or "\0" in joint:
        raise ConfigError(f"joint {joint!r}: not usable in a file name (the session must stay in {out_dir})")
    n = 2
    while path.exists():
        path = Path(out_dir) / f"{stamp}_{joint}_{n}.h5"
        n += 1
    return path


def _extendable(group: h5py.Group, name: str, dtype: Any, chunk: int) -> h5py.Dataset:
    return group.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dtype, chunks=(chunk,), fletcher32=True)


class _Column:
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


class SessionExists(ConfigError):
    """The session file to create exists (another writer took the name first)."""


class _PendingColumns:
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

    def write_to(self, columns: dict[str, _Column]) -> None:
        self.nbytes = 0
        for name in [*self._used, *(n for n in self._parts if n not in self._used)]:
            parts = self._parts.pop(name, [])
            used = self._used.pop(name, 0)  # taken before writing: an interrupted flush never repeats a part
            if used:
                parts.append(self._buffers[name][:used])
            if parts:
                columns[name].append(parts[0] if len(parts) == 1 else np.concatenate(parts))


class SessionWriter:
    """Write one session: create the layout, append blocks in order, finish with a footer.

    Parameters
    ----------
    path : Path
        The ``.h5`` file to create (must not exist).
    bench, profile : the configs as used (stored as JSON; profile None: the machine moved the joint, not acq).
    current_info, drive_info : what the started devices reported (coerced rate, period, ...).
    operator : optional name of the person at the bench.
    tags : optional free-form tags (pose, payload_kg, temperature_C, ...).
    origin : optional description of where the data came from (e.g. imported files).
    host_clock_shared : whether both streams' host stamps are arrival times on one host clock (True for a
        recording; an import of files from separate tools is False).
    session_id, created_utc : the identity and start time (ISO 8601, UTC) of a session recorded earlier and
        restored by an import; by default a new UUID4 and now.
    bulk : all samples come before one flush (an import): the sample datasets get 10x longer chunks.
    """

    def __init__(
        self,
        path: Path,
        *,
        bench: Bench,
        profile: Profile | None,
        current_info: CurrentSourceInfo,
        drive_info: DriveInfo,
        host_ns_at_start: int,
        operator: str = "",
        tags: dict[str, Any] | None = None,
        origin: dict[str, Any] | None = None,
        host_clock_shared: bool = True,
        session_id: str | None = None,
        created_utc: str | None = None,
        bulk: bool = False,
    ) -> None:
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise ConfigError(f"{self.path.parent}: no such folder for the session file")
        self._channels = current_info.channels
        self._filled_optional: set[str] = set()
        self._pending = _PendingColumns()
        self._nans = np.zeros(0)
        self._rate_hz = float(current_info.rate_hz)
        #: Totals on disk after the last successful flush: the only counts ever reported or written in the footer.
        self.committed = {"current_samples": 0, "current_blocks": 0, "encoder_samples": 0, "events": 0}
        #: The write error that stopped this writer (None while writing works).
        self.failure: StorageError | None = None
        self._abandoned = False
        try:
            # No chunk cache: a flush writes whole chunks but for the last of each dataset, and a cached chunk is only
            # copied into HDF5's memory to be checksummed and written at the H5Fflush that follows anyway (chunk buffers
            # allocated anew each flush); without it the write goes straight through (a --fast 10 s session: the
            # recording thread's CPU −1.7 ms of 38, medians of 10 at load 5). A partial last chunk is read back (its
            # checksum verified) when the next flush completes it.
            f = h5py.File(self.path, "w-", libver=LIBVER, rdcc_nbytes=0)
        except FileExistsError:
            raise SessionExists(f"{self.path}: a file of that name exists") from None
        except OSError as e:
            raise storage_error(e, self.path) from None
        self._file = f
        try:
            datasets = self._create_layout(f, bench, profile, current_info, drive_info, host_ns_at_start, operator,
                                           tags, origin, host_clock_shared, session_id, created_utc, bulk)
        except Exception as e:  # the disk filled while the layout was created: no session at all
            abandon(f)
            self.path.unlink(missing_ok=True)
            raise storage_error(e, self.path) from None
        self._inode = os.stat(self.path).st_ino
        # Handles held open until the file is closed: HDF5 writes a dataset's cached chunks when its handle
        # closes, and a write error there (inside h5py's deallocation) cannot be caught and corrupts HDF5's state.
        self._columns = {ds.name.lstrip("/"): _Column(ds) for ds in datasets}
        # worst-case growth of a flush beyond its payload: one partial chunk per dataset rewritten elsewhere
        self._chunk_bytes = sum(c.ds.chunks[0] * c.ds.dtype.itemsize for c in self._columns.values())

    def _create_layout(self, f: h5py.File, bench: Bench, profile: Profile | None, current_info: CurrentSourceInfo,
                       drive_info: DriveInfo, host_ns_at_start: int, operator: str, tags: dict[str, Any] | None,
                       origin: dict[str, Any] | None, host_clock_shared: bool, session_id: str | None,
                       created_utc: str | None, bulk: bool) -> list[h5py.Dataset]:
        """Attributes and groups; return the datasets created."""
        created = created_utc or utc_now_iso()
        made: list[h5py.Dataset] = []
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
                "profile_json": profile.model_dump_json() if profile is not None else "null",
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
        # A recording flushes every 0.5 s: chunks of 0.1 s of current and 0.5 s of encoder keep small the partial chunk
        # each flush rewrites. Written at once (bulk), 10x longer chunks: each costs a checksum, an index entry and a
        # write call (a 60 s import: ≈ 10 ms CPU less, 7 % of it).
        scale = 10 if bulk else 1
        chunk = max(1024, int(scale * current_info.rate_hz // 10))
        for ch in self._channels:
            made.append(_extendable(cur, f"{ch}_A", "f8", chunk))
        blocks = cur.create_group("blocks")
        for name in ("first_index", "count", "host_ns"):
            made.append(_extendable(blocks, name, "i8", 256))
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
        enc_chunk = max(256, int(scale * 0.5 / drive_info.period_s))
        for name in ("position_counts", "index", "host_ns"):
            made.append(_extendable(enc, name, "i8", enc_chunk))
        for name in _OPTIONAL_ENCODER:
            made.append(_extendable(enc, name, "f8", enc_chunk))
        made.append(_extendable(f, "events", EVENT_DTYPE, 64))
        made.append(_extendable(f, "flushes", FLUSH_DTYPE, 64))
        f.swmr_mode = True
        return made

    @property
    def pending_bytes(self) -> int:
        """Bytes appended since the last flush."""
        return self._pending.nbytes

    @property
    def seconds_kept(self) -> float:
        """Seconds of current committed to disk."""
        return self.committed["current_samples"] / self._rate_hz

    def append_current(self, block: CurrentBlock) -> None:
        """Append one DAQ block (caller guarantees increasing, non-overlapping indices); ignored after a failure."""
        if self.failure is not None:
            return
        for row, ch in enumerate(self._channels):
            self._pending.add(f"current/{ch}_A", block.current_a[row], _F8)
        self._pending.add_value("current/blocks/first_index", block.first_index, _I8)
        self._pending.add_value("current/blocks/count", block.count, _I8)
        self._pending.add_value("current/blocks/host_ns", block.host_ns, _I8)

    def append_current_blocks(self, current_a: Sequence[np.ndarray], first_index: np.ndarray, count: np.ndarray,
                              host_ns: np.ndarray) -> None:
        """Append many DAQ blocks at once (an import): as :meth:`append_current` of each, without a call per block.

        Parameters
        ----------
        current_a : one array per channel (in the writer's channel order), A, the blocks' samples back to back.
        first_index, count, host_ns : the block table, one row per block (as in :class:`CurrentBlock`).
        """
        if self.failure is not None:
            return
        n = int(np.sum(count))
        if len(current_a) != len(self._channels) or any(np.shape(v) != (n,) for v in current_a) or not (
                np.shape(first_index) == np.shape(host_ns) == np.shape(count)):
            raise ValueError(f"current_a: {len(self._channels)} channels of {n} samples and a block table of equal "
                             "columns expected")
        for ch, values in zip(self._channels, current_a):
            self._pending.add(f"current/{ch}_A", np.asarray(values), _F8)
        for name, column in (("first_index", first_index), ("count", count), ("host_ns", host_ns)):
            self._pending.add(f"current/blocks/{name}", np.asarray(column), _I8)

    def append_encoder(self, block: EncoderBlock) -> None:
        """Append encoder samples (caller guarantees strictly increasing ``index``); ignored after a failure."""
        if self.failure is not None:
            return
        self._pending.add("encoder/position_counts", np.asarray(block.position_counts), _I8)
        self._pending.add("encoder/index", np.asarray(block.index), _I8)
        self._pending.add("encoder/host_ns", np.asarray(block.host_ns), _I8)
        for name in _OPTIONAL_ENCODER:
            values = getattr(block, name)
            if values is not None:
                self._filled_optional.add(name)
                self._pending.add(f"encoder/{name}", np.asarray(values), _F8)
            else:
                self._pending.add(f"encoder/{name}", self._nan_filler(block.count), _F8)

    def _nan_filler(self, count: int) -> np.ndarray:
        """``count`` NaN for an optional column a block lacks: a view of one read-only buffer, not a new array."""
        if self._nans.size < count:
            self._nans = np.full(max(count, 2 * self._nans.size), np.nan)
            self._nans.flags.writeable = False
        return self._nans[:count]

    def add_event(self, event: StreamEvent) -> None:
        """Append one event row; ignored after a failure."""
        if self.failure is not None:
            return
        detail = event.detail.encode()[:240].decode("utf-8", "ignore").encode()  # never split a character
        row = np.array([(event.host_ns, event.stream.encode(), event.kind.encode(), detail)], dtype=EVENT_DTYPE)
        self._pending.add("events", row, EVENT_DTYPE)

    def flush(self) -> None:
        """Write everything appended so far, then a ``/flushes`` row committing it; make it durable and visible.

        Raises :class:`StorageError` ("disk full: <file>") when the disk lacks room for it (checked first,
        nothing written), the file vanished, or HDF5 reports a write error; the writer is then stopped
        (:attr:`failure`) and only what earlier flushes committed counts. Does nothing after a failure.
        """
        if self.failure is not None:
            return
        pending = self._pending
        added = {"current_samples": pending.count(f"current/{self._channels[0]}_A"),
                 "current_blocks": pending.count("current/blocks/count"),
                 "encoder_samples": pending.count("encoder/index"), "events": pending.count("events")}
        self._check_room(pending.nbytes)
        totals = {k: self.committed[k] + added[k] for k in self.committed}
        row = np.array([(time.monotonic_ns(), totals["current_samples"], totals["current_blocks"],
                         totals["encoder_samples"], totals["events"])], dtype=FLUSH_DTYPE)
        try:
            pending.write_to(self._columns)
            self._file.flush()
            self._columns["flushes"].append(row)  # only after the samples it counts are on disk
            self._file.flush()
        except Exception as e:  # noqa: BLE001 - h5py reports write errors as OSError or RuntimeError
            self._stop(storage_error(e, self.path), abandon_file=True)
        self.committed = totals

    def _check_room(self, payload_bytes: int) -> None:
        try:
            inode = os.stat(self.path).st_ino
        except OSError:
            inode = None
        if inode != self._inode:
            self._stop(StorageError(f"session file vanished: {self.path}"), abandon_file=True)
        try:
            free = free_bytes(self.path.parent)
        except OSError as e:
            self._stop(storage_error(e, self.path), abandon_file=True)
        if free < 2 * payload_bytes + self._chunk_bytes + RESERVE_BYTES:
            self._stop(StorageError(f"disk full: {self.path}"), abandon_file=False)

    def _stop(self, error: StorageError, *, abandon_file: bool) -> None:
        """Stop writing for good: drop what is pending, close the file, raise ``error``."""
        self.failure = error
        self._pending.clear()
        if abandon_file:
            self._abandoned = True
            abandon(self._file)
        else:
            try:
                self._file.close()
            except Exception:  # noqa: BLE001 - the close itself failed: nothing more may be written
                self._abandoned = True
                abandon(self._file)
        raise error

    def finish(self, status: Status, stop_reason: str) -> None:
        """Close the SWMR file and write the footer: status, reason, stop time, committed sample counts.

        After a write failure the status is ``failed`` with the failure and the seconds kept as reason
        ("disk full: /data/x.h5 — 3.2 s kept"); the footer is written when the disk has room for it and
        the file could be closed cleanly, else the file stays ``recording`` and its ``/flushes`` rows
        tell readers (and ``acq check``) what is stored.
        """
        try:
            self.flush()
        except StorageError:
            pass
        if self.failure is not None:
            status, stop_reason = "failed", f"{self.failure} — {self.seconds_kept:.1f} s kept"
        else:
            self._file.close()
        if self._abandoned:
            return
        with contextlib.suppress(OSError):
            if free_bytes(self.path.parent) < RESERVE_BYTES // 4:
                return  # no room for a footer: the /flushes rows say what is stored
        f = self._reopen()
        try:
            # only a column longer than what was committed is opened to be cut (the writer knows each length)
            counted = {name: _committed_rows(name, self.committed) for name in self._columns}
            longer = [name for name, n in counted.items() if n is not None and self._columns[name].length > n]
            _write_footer(f, status, stop_reason, self._filled_optional, self.committed, longer)
            f.close()
        except Exception as e:  # noqa: BLE001 - the footer could not be written: the flush rows still hold
            abandon(f)
            self.failure = storage_error(e, self.path)
            raise StorageError(f"{self.failure} (footer not written; the samples are stored, acq check repairs "
                               "the file)") from None

    def _reopen(self) -> h5py.File:
        """The closed file opened for the footer; a reader holding it open briefly is waited for (2 s)."""
        cause = ""
        for _ in range(10):
            try:
                return h5py.File(self.path, "r+", libver=LIBVER)
            except OSError as e:
                cause = cause_of(e)
                time.sleep(0.2)
        raise StorageError(f"{self.path}: cannot reopen it to write the footer ({cause}); the samples are stored, "
                           "acq check repairs the file")


def _datasets(f: h5py.File) -> list[h5py.Dataset]:
    found: list[h5py.Dataset] = []
    f.visititems(lambda name, obj: found.append(obj) if isinstance(obj, h5py.Dataset) else None)
    return found


def _committed_rows(name: str, committed: dict[str, int]) -> int | None:
    """Rows of dataset ``name`` (no leading /) that the ``committed`` totals count; None for one they do not."""
    group = name.rsplit("/", 1)[0] if "/" in name else name
    return {"current/blocks": committed["current_blocks"], "current": committed["current_samples"],
            "encoder": committed["encoder_samples"], "events": committed["events"]}.get(group)


def _write_footer(f: h5py.File, status: Status, stop_reason: str, filled_optional: set[str],
                  committed: dict[str, int] | None = None, datasets: Sequence[str] | None = None) -> None:
    """Status, reason, stop time and sample counts; with ``committed``, the ``datasets`` named (default: every
    dataset in the file) are first cut to the committed totals (rows written by a flush that did not complete are
    not kept)."""
    if committed is not None:
        for ds in _datasets(f) if datasets is None else [f[name] for name in datasets]:
            n = _committed_rows(ds.name.lstrip("/"), committed)
            if n is not None and ds.shape[0] > n:
                ds.resize((n,))
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
        """From the root attributes as read (``load`` has checked that ``tags_json`` is JSON)."""
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
    #: What could not be read, one line per stream ("current: samples 62 550–102 399 unreadable"); the streams
    #: above hold the intact part before the first damaged sample.
    damage: tuple[str, ...] = ()

    @functools.cached_property
    def meta(self) -> SessionMeta:
        """The root attributes, typed (the way to read them outside this module)."""
        return SessionMeta.from_attrs(self.attrs)

    @property
    def status(self) -> str:
        return self.meta.status

    def require_usable(self, *, partial: bool = False) -> None:
        """Raise :class:`ConfigError` for a session still ``recording`` or damaged, unless ``partial``.

        ``partial`` accepts them: the intact part is used (the caller marks its result partial).
        """
        if partial:
            return
        if self.damage:
            raise ConfigError(f"{self.path}: damaged ({'; '.join(self.damage)}) — run acq check, or use --partial "
                              "to analyse the intact part")
        if self.status == "recording":
            raise ConfigError(f"{self.path}: status recording (still being recorded, or the recorder was killed) — "
                              "run acq check, or use --partial to analyse what is stored")

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


def _attr(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _open_for_reading(path: Path) -> tuple[h5py.File, list[str]]:
    """Open a session for reading with bounds; a file shorter than its superblock says is reported as cut."""
    require_session_file(path)
    notes: list[str] = []
    size = path.stat().st_size
    try:
        eof = superblock_eof(path)
    except OSError as e:
        raise ConfigError(f"{path}: cannot read ({cause_of(e)})") from None
    if eof is not None and size < eof:
        notes.append(f"file cut: {size:,} of {eof:,} bytes".replace(",", " "))
    try:
        return open_read(path), notes
    except (OSError, RuntimeError) as e:
        first_line = str(e).splitlines()[0] if str(e) else type(e).__name__
        why = notes[0] if notes else first_line
        raise ConfigError(f"{path}: not a readable HDF5 session file ({why})") from None


def _span(stream: str, first: int, end: int, what: str = "unreadable") -> str:
    return f"{stream}: samples {first:,}–{end - 1:,} {what}".replace(",", " ")


class _Reader:
    """Reads datasets of one open file chunk by chunk, up to the committed length; never past the file's end."""

    def __init__(self, f: h5py.File, path: Path, notes: list[str]) -> None:
        self.f, self.path, self.notes = f, path, notes
        self.size = path.stat().st_size

    def node(self, name: str) -> Any:
        try:
            return self.f[name]
        except (KeyError, OSError, RuntimeError):
            what = "damaged" if self.notes else "malformed session"
            why = f" ({self.notes[0]})" if self.notes else ""
            raise ConfigError(f"{self.path}: {what}: /{name} is missing or unreadable{why}") from None

    def column(self, name: str, n: int | None) -> tuple[np.ndarray, int | None]:
        """The first ``n`` rows (all stored if None) of dataset ``name`` and the first row not readable (or None).

        Rows are read one chunk at a time; a chunk whose checksum fails, that lies beyond the end of the file,
        or that was never written (its rows would read as zeros) ends the intact part.
        """
        ds = self.node(name)
        if not isinstance(ds, h5py.Dataset) or ds.ndim != 1:
            raise ConfigError(f"{self.path}: malformed session: /{name} is not a 1-D dataset")
        stored = ds.shape[0]
        want = stored if n is None else n
        have = min(want, stored)
        out = np.empty(have, dtype=ds.dtype)
        step = ds.chunks[0] if ds.chunks else max(have, 1)
        if have and ds.chunks and self._all_on_disk(ds, have, step):
            try:  # the usual case, an intact file: one read (checksums verified), 4× faster than chunk by chunk
                ds.read_direct(out, np.s_[0:have], np.s_[0:have])
                return out, (have if have < want else None)
            except (OSError, RuntimeError, ValueError):
                pass  # a checksum fails somewhere: find where, chunk by chunk
        for start in range(0, have, step):
            stop = min(start + step, have)
            try:
                if ds.chunks and not self._on_disk(ds.id.get_chunk_info_by_coord((start,))):
                    return out[:start], start
                out[start:stop] = ds[start:stop]
            except (OSError, RuntimeError, ValueError):
                return out[:start], start
        return out, (have if have < want else None)

    def _on_disk(self, info: Any) -> bool:
        """A chunk (HDF5's chunk info) was written and lies inside the file (a never-written one reads as zeros)."""
        return info.byte_offset is not None and info.byte_offset + info.size <= self.size

    def _all_on_disk(self, ds: h5py.Dataset, rows: int, step: int) -> bool:
        """Every chunk holding the first ``rows`` rows was written and lies inside the file (HDF5's chunk
        iteration: one pass over the chunk index, ≈ 1 µs a chunk); False when it cannot tell."""
        if not hasattr(ds.id, "chunk_iter"):  # HDF5 < 1.12.3
            return False
        inside: list[bool] = []

        def visit(info: Any) -> None:
            if info.chunk_offset[0] < rows:
                inside.append(self._on_disk(info))

        try:
            ds.id.chunk_iter(visit)
        except (OSError, RuntimeError, ValueError):
            return False
        return len(inside) == -(-rows // step) and all(inside)


def _committed(f: h5py.File, reader: _Reader) -> dict[str, int] | None:
    """What the writer committed: the footer's counts, else the last ``/flushes`` row; None if neither exists."""
    status = _attr(f.attrs.get("status"))
    if status != "recording" and "current_samples" in f.attrs and "encoder_samples" in f.attrs:
        return {"current_samples": int(f.attrs["current_samples"]), "encoder_samples": int(f.attrs["encoder_samples"])}
    if "flushes" not in f:
        return None
    rows, _ = reader.column("flushes", None)
    if rows.size == 0:
        return {"current_samples": 0, "current_blocks": 0, "encoder_samples": 0, "events": 0}
    return {name: int(rows[-1][name]) for name in FLUSH_DTYPE.names if name != "host_ns"}


def _read_current(reader: _Reader, committed: dict[str, int] | None, damage: list[str]) -> CurrentData:
    g = reader.node("current")
    n_blocks = None if committed is None else committed.get("current_blocks")
    counts, bad_c = reader.column("current/blocks/count", n_blocks)
    first, bad_f = reader.column("current/blocks/first_index", n_blocks)
    host, bad_h = reader.column("current/blocks/host_ns", n_blocks)
    try:
        rate_hz, device = float(g.attrs["rate_hz"]), str(_attr(g.attrs["device"]))
        channels = [c for c in str(_attr(g.attrs["channels"])).split(",") if c]
    except (KeyError, ValueError, TypeError):
        raise ConfigError(f"{reader.path}: malformed session: /current lacks a valid rate_hz, device or channels "
                          "attribute") from None
    if not channels:
        raise ConfigError(f"{reader.path}: malformed session: /current names no channels")
    want = None if committed is None else committed["current_samples"]
    phases: dict[str, np.ndarray] = {}
    bad_samples: int | None = None
    for ch in channels:
        phases[ch], bad = reader.column(f"current/{ch}_A", want)
        if bad is not None:
            bad_samples = bad if bad_samples is None else min(bad_samples, bad)
    stored = min(len(first), len(counts), len(host))
    counts, first, host = counts[:stored], first[:stored], host[:stored]
    n = min([int(counts.sum())] + [len(v) for v in phases.values()])
    while stored and int(counts.sum()) > n:  # a kill between writing samples and the block row, or damage
        stored -= 1
        counts, first, host = counts[:stored], first[:stored], host[:stored]
    n = int(counts.sum())
    total = want if want is not None else max([n] + [len(v) for v in phases.values()])
    if (bad_samples is not None or any(b is not None for b in (bad_c, bad_f, bad_h))) and n < total:
        damage.append(_span("current", n, total))
    return CurrentData(rate_hz=rate_hz, device=device, phases_a={ch: v[:n] for ch, v in phases.items()},
                       block_first_index=first, block_count=counts, block_host_ns=host)


def _read_encoder(reader: _Reader, committed: dict[str, int] | None, damage: list[str]) -> EncoderData:
    g = reader.node("encoder")
    want = None if committed is None else committed["encoder_samples"]
    columns = {name: reader.column(f"encoder/{name}", want) for name in ("position_counts", "index", "host_ns")}
    for name in _OPTIONAL_ENCODER:
        if name in g:
            columns[name] = reader.column(f"encoder/{name}", want)
    n = min(len(v) for v, _ in columns.values())
    total = want if want is not None else max(len(v) for v, _ in columns.values())
    if any(bad is not None for _, bad in columns.values()) and n < total:
        damage.append(_span("encoder", n, total))

    def optional(name: str) -> np.ndarray | None:
        """The column, None when absent or all NaN: the writer creates every optional column and fills what a drive
        does not give with NaN until :func:`_write_footer` deletes it, so while a session records (or after its
        recorder was killed) a column of NaN only is one the drive has not given."""
        values = columns[name][0][:n] if name in columns else None
        return None if values is None or np.isnan(values).all() else values

    try:
        period_s, counts_per_rev = float(g.attrs["period_s"]), int(g.attrs["counts_per_rev"])
        transport, kind = str(_attr(g.attrs["transport"])), str(_attr(g.attrs["timestamp_kind"]))
        device = str(_attr(g.attrs["device"]))
    except (KeyError, ValueError, TypeError):
        raise ConfigError(f"{reader.path}: malformed session: /encoder lacks a valid period_s, counts_per_rev, "
                          "transport, timestamp_kind or device attribute") from None
    return EncoderData(
        period_s=period_s, counts_per_rev=counts_per_rev, transport=transport, timestamp_kind=kind, device=device,
        position_counts=columns["position_counts"][0][:n], index=columns["index"][0][:n],
        host_ns=columns["host_ns"][0][:n], **{name: optional(name) for name in _OPTIONAL_ENCODER},
    )


def _read_events(reader: _Reader, committed: dict[str, int] | None, damage: list[str]) -> list[StreamEvent]:
    rows, bad = reader.column("events", None if committed is None else committed.get("events"))
    if bad is not None:
        damage.append(_span("events", len(rows), bad + 1 if bad >= len(rows) else len(rows) + 1, "lost"))
    return [
        StreamEvent(int(r["host_ns"]), r["stream"].decode("utf-8", "replace"), r["kind"].decode("utf-8", "replace"),  # type: ignore[arg-type]
                    r["detail"].decode("utf-8", "replace"))
        for r in rows
    ]


def _config_attr(p: Path, attrs: dict[str, Any], name: str, model: type[Bench] | type[Profile]) -> Any:
    text = attrs.get(name)
    if not isinstance(text, str):
        raise ConfigError(f"{p}: malformed session: attribute {name} is missing")
    try:
        return model.model_validate_json(text)
    except ValidationError as e:
        err = e.errors()[0]
        where = ".".join(str(part) for part in err["loc"])
        detail = f"{where}: {err['msg']}" if where else err["msg"]
        raise ConfigError(f"{p}: malformed session: attribute {name} is not a valid {model.__name__.lower()} "
                          f"({detail})") from None


def read_status(path: Path | str) -> str:
    """The ``status`` attribute alone (cheap: no data read); ``""`` when the file has none."""
    p = Path(path)
    f, _ = _open_for_reading(p)
    with f:
        try:
            return str(_attr(f.attrs.get("status", "")))
        except (OSError, RuntimeError):
            return ""


def load(path: Path | str) -> Session:
    """Read a whole session (also one still being recorded, left by a killed recorder, or damaged).

    Only committed samples are read (see the module doc); what cannot be read is listed in
    :attr:`Session.damage`. A file that is not a session, or lacks a group or attribute, raises
    :class:`ConfigError` naming the file and what is wrong.
    """
    p = Path(path)
    f, notes = _open_for_reading(p)
    try:
        with f:
            return _load_open(p, f, notes)
    except (OSError, RuntimeError, KeyError, ValueError) as e:  # h5py's errors for metadata it cannot read
        first = (str(e).splitlines() or [type(e).__name__])[0].strip("'\"")
        why = f"{notes[0]}: {first}" if notes else first
        raise ConfigError(f"{p}: damaged, cannot be read ({why})") from None


def _load_open(p: Path, f: h5py.File, notes: list[str]) -> Session:
    try:
        raw = dict(f.attrs.items())
    except (OSError, RuntimeError, KeyError):
        why = f"{notes[0]}, root attributes lost" if notes else "root attributes unreadable"
        raise ConfigError(f"{p}: not a readable HDF5 session file ({why})") from None
    attrs = {k: _attr(v) for k, v in raw.items()}
    if attrs.get("format") != FORMAT:
        raise ConfigError(f"{p}: not an acq session (format attribute is {attrs.get('format')!r})")
    try:
        version = int(attrs.get("format_version", 0))
    except (TypeError, ValueError):
        raise ConfigError(f"{p}: malformed session: format_version {attrs.get('format_version')!r}") from None
    if version > FORMAT_VERSION:
        raise ConfigError(f"{p}: format_version {version} is newer than this acq reads ({FORMAT_VERSION})")
    try:
        json.loads(attrs.get("tags_json", "{}"))
    except (TypeError, ValueError):
        raise ConfigError(f"{p}: malformed session: attribute tags_json is not JSON") from None
    bench = _config_attr(p, attrs, "bench_json", Bench)
    profile = None if attrs.get("profile_json") == "null" else _config_attr(p, attrs, "profile_json", Profile)
    reader = _Reader(f, p, notes)
    committed = _committed(f, reader)
    damage: list[str] = []
    current = _read_current(reader, committed, damage)
    encoder = _read_encoder(reader, committed, damage)
    events = _read_events(reader, committed, damage)
    if notes and not damage:
        damage.extend(notes)
    return Session(path=p, attrs=attrs, bench=bench, profile=profile, current=current, encoder=encoder,
                   events=events, damage=tuple(damage))


def repair(path: Path | str, stop_reason: str) -> Session:
    """Rewrite a session left with status ``recording`` (writer killed) as ``interrupted``; return it as read.

    HDF5 keeps a crashed SWMR writer's file marked as open for writing, so it cannot be reopened
    for writing in place: every committed, intact sample is copied into a fresh file beside it
    (uneven column lengths cut to the common length), which then atomically replaces the original.
    A write failure leaves the original untouched and no temp file.
    """
    p = Path(path)
    session = load(p)
    if session.damage:
        stop_reason = f"{stop_reason}; kept the intact part ({'; '.join(session.damage)})"
    with open_read(p) as src:
        group_attrs = {name: dict(src[name].attrs) for name in ("current", "encoder")}
    with atomic_path(p) as tmp:
        try:
            with h5py.File(tmp, "w", libver=LIBVER) as dst:
                _write_copy(dst, session, stop_reason, group_attrs)
        except OSError:
            raise
        except Exception as e:  # noqa: BLE001 - h5py reports write errors as RuntimeError too
            raise storage_error(e, p) from None
    return load(p)


def _write_copy(dst: h5py.File, session: Session, stop_reason: str, group_attrs: dict[str, dict[str, Any]]) -> None:
    def column(group: h5py.Group, name: str, values: np.ndarray) -> None:
        group.create_dataset(name, data=values, maxshape=(None,), chunks=True, fletcher32=True)

    attrs = {k: v for k, v in session.attrs.items() if k not in ("current_samples", "encoder_samples")}
    dst.attrs.update(attrs)
    cur = dst.create_group("current")
    c = session.current
    cur.attrs.update(group_attrs["current"])
    for ch, values in c.phases_a.items():
        column(cur, f"{ch}_A", values)
    blocks = cur.create_group("blocks")
    for name, values in (("first_index", c.block_first_index), ("count", c.block_count),
                         ("host_ns", c.block_host_ns)):
        column(blocks, name, values)
    enc = dst.create_group("encoder")
    e = session.encoder
    enc.attrs.update(group_attrs["encoder"])
    for name in ("position_counts", "index", "host_ns", *_OPTIONAL_ENCODER):
        values = getattr(e, name)
        if values is not None:
            column(enc, name, values)
    rows = np.array([(ev.host_ns, ev.stream.encode(), ev.kind.encode(), ev.detail.encode()[:240])
                     for ev in session.events], dtype=EVENT_DTYPE)
    column(dst, "events", rows)
    _write_footer(dst, "interrupted", stop_reason, {n for n in _OPTIONAL_ENCODER if n in enc})
