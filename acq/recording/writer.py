"""Write a session file (layout: :mod:`acq.recording.layout`): create it, append blocks in order, flush, finish.

Crash safety: the writer creates every dataset, then switches to SWMR mode (libver v110) and
flushes regularly, so a killed recorder leaves a file that opens (``swmr=True``) with every
flushed sample. ``status`` is ``recording`` until :meth:`SessionWriter.finish` reopens the file
and writes the footer. :func:`acq.recording.repair.repair` rewrites a killed session into a clean file; a
live one it leaves alone: the writer marks its file as being recorded until finished (:mod:`acq.recording.live`).

Durability (a power cut, a kernel crash): HDF5's flush only hands the file to the kernel's page cache, which writes
it back in any order. Each commit is therefore made durable in order — the samples written and flushed, the file's
data synced (fdatasync), only then the ``/flushes`` row counting them, flushed and synced again — so a row on the
disk never counts samples that are not, and whatever the writer reports as committed is on the disk. The file's
layout is synced and its folder too when it is created (its name is durable from then on), and the footer when it
is written. A failed sync is a failed write (on Linux the pages it could not write may be dropped already).

A failed write (disk full, I/O error, the file vanished) stops the writer at once: nothing after it is written or
counted (:attr:`SessionWriter.failure`) but the footer, which overwrites its attributes in place (a full disk has no
new byte to give, and needs none).
"""

from __future__ import annotations

import json
import os
import time
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from acq import __version__
from acq.recording.h5safe import abandon, open_abandoned
from acq.recording.live import create_marked
from acq.recording.layout import (EVENT_DTYPE, FLUSH_DTYPE, FORMAT, FORMAT_VERSION, LIBVER, OPTIONAL_ENCODER, Status,
                                  committed_rows, footer_unwritten, utc_now_iso, write_footer)
from acq.recording.pending import Column, PendingColumns
from acq.recording.storage import cause_of, free_bytes, out_of_room, storage_error, sync_file, sync_folder
from drivers.base import CurrentBlock, CurrentSourceInfo, DriveInfo, EncoderBlock, StreamEvent
from drivers.config import Bench, Profile
from acqcore.errors import ConfigError, StorageError

#: Free bytes kept for HDF5's metadata beyond what a flush writes (the footer needs none: it is written in place); a
#: flush that would leave
#: less fails the recording as "disk full" before HDF5 sees an ENOSPC (which leaves HDF5 unreliable, see
#: acq.recording.h5safe). 1 MiB is ~10x the metadata a 60 s session's footer and chunk indexes grow by per flush.
RESERVE_BYTES = 1 << 20
_F8, _I8 = np.dtype(np.float64), np.dtype(np.int64)


def _extendable(group: h5py.Group, name: str, dtype: Any, chunk: int) -> h5py.Dataset:
    return group.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dtype, chunks=(chunk,), fletcher32=True)


class SessionExists(ConfigError):
    """The session file to create exists (another writer took the name first)."""


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
        self._pending = PendingColumns()
        self._nans = np.zeros(0)
        self._rate_hz = float(current_info.rate_hz)
        #: Totals on disk after the last successful flush: the only counts ever reported or written in the footer.
        self.committed = {"current_samples": 0, "current_blocks": 0, "encoder_samples": 0, "events": 0}
        #: The write error that stopped this writer (None while writing works).
        self.failure: StorageError | None = None
        self._abandoned = False
        #: The write HDF5 failed in was refused for room only: the abandoned file may still be finished in place.
        self._out_of_room = False
        try:
            # No chunk cache: a flush writes whole chunks but for the last of each dataset, and a cached chunk is only
            # copied into HDF5's memory to be checksummed and written at the H5Fflush that follows anyway (chunk buffers
            # allocated anew each flush); without it the write goes straight through (a --fast 10 s session: the
            # recording thread's CPU −1.7 ms of 38, medians of 10 at load 5). A partial last chunk is read back (its
            # checksum verified) when the next flush completes it.
            # The name is taken and marked as being recorded (until finish) before HDF5 writes into it: acq check
            # never rewrites a file in that state.
            self._marker = create_marked(self.path)
        except FileExistsError:
            raise SessionExists(f"{self.path}: a file of that name exists") from None
        except OSError as e:
            raise storage_error(e, self.path) from None
        try:
            f = h5py.File(self.path, "w", libver=LIBVER, rdcc_nbytes=0)
        except OSError as e:
            self._marker.close()
            self.path.unlink(missing_ok=True)
            raise storage_error(e, self.path) from None
        self._file = f
        try:
            datasets = self._create_layout(f, bench, profile, current_info, drive_info, host_ns_at_start, operator,
                                           tags, origin, host_clock_shared, session_id, created_utc, bulk)
            self._sync()
            sync_folder(self.path.parent)  # the new name durable: once per session
        except Exception as e:  # the disk filled (or a sync failed) while the layout was created: no session at all
            abandon(f)
            self._marker.close()
            self.path.unlink(missing_ok=True)
            raise storage_error(e, self.path) from None
        self._inode = os.stat(self.path).st_ino
        # Handles held open until the file is closed: HDF5 writes a dataset's cached chunks when its handle
        # closes, and a write error there (inside h5py's deallocation) cannot be caught and corrupts HDF5's state.
        self._columns = {ds.name.lstrip("/"): Column(ds) for ds in datasets}
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
                "host_monotonic_ns_at_start": np.int64(host_ns_at_start),
                "acq_version": __version__,
                "bench_json": bench.model_dump_json(),
                "profile_json": profile.model_dump_json() if profile is not None else "null",
                "joint": bench.joint,
                "operator": operator,
                "tags_json": json.dumps(tags or {}),
                "origin_json": json.dumps(origin or {"kind": "recorded"}),
                "host_clock_shared": bool(host_clock_shared),
                **footer_unwritten(),  # every attribute now: the footer overwrites them in place
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
        for name in OPTIONAL_ENCODER:
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

    def failure_reason(self) -> str:
        """The stop reason after a failed write: the failure and what the file keeps ("disk full: /data/x.h5 — 3.2 s
        kept"); nothing when the file is no longer at its path (it or its folder was deleted: "— 3.2 s kept" named a
        file that did not exist)."""
        try:
            here = os.stat(self.path).st_ino == self._inode
        except OSError:
            here = False
        kept = f"{self.seconds_kept:.1f} s kept" if here else "nothing kept (the file or its folder was deleted)"
        return f"{self.failure} — {kept}"

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
        for name in OPTIONAL_ENCODER:
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
        """Write everything appended so far, then a ``/flushes`` row committing it; make it durable and visible, in
        that order (the samples on the disk before the row that counts them, the row before this returns).

        Raises :class:`StorageError` ("disk full: <file>") when the disk lacks room for it (checked first,
        nothing written), the file vanished, HDF5 reports a write error or a sync fails; the writer is then stopped
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
            self._sync()
            self._columns["flushes"].append(row)  # only after the samples it counts are on disk
            self._file.flush()
            self._sync()
        except Exception as e:  # noqa: BLE001 - h5py reports write errors as OSError or RuntimeError
            self._out_of_room = out_of_room(e)
            self._stop(storage_error(e, self.path), abandon_file=True)
        self.committed = totals

    def _sync(self) -> None:
        """fdatasync the open file through HDF5's own descriptor (the sec2 driver's,
        :meth:`h5py.h5f.FileID.get_vfd_handle`): what HDF5 flushed is on the disk when this returns."""
        os.fdatasync(self._file.id.get_vfd_handle())

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
        """Close the SWMR file and write the footer: status, reason, stop time, committed sample counts; the footer is
        on the disk when this returns.

        After a write failure the status is ``failed`` with the failure and the seconds kept as reason
        ("disk full: /data/x.h5 — 3.2 s kept"). The footer takes no new byte of the disk (its strings are created at
        full size and overwritten in place, :mod:`acq.recording.layout`), so a full disk still gets it, also a file
        HDF5 itself failed to write for room (abandoned: reopened with its status flags cleared, every column cut to
        the committed rows). After an I/O error inside HDF5 nothing more is written, and a file that cannot be
        reopened is left too: it stays ``recording``, and its ``/flushes`` rows tell readers (and ``acq check``) what
        is stored. The file is no longer marked as being recorded after this.
        """
        try:
            self._finish(status, stop_reason)
        finally:
            self._marker.close()

    def _finish(self, status: Status, stop_reason: str) -> None:
        """:meth:`finish` while the file is still marked as being recorded."""
        try:
            self.flush()
        except StorageError:
            pass
        if self.failure is not None:
            status, stop_reason = "failed", self.failure_reason()
        else:
            self._file.close()
        if self._abandoned:  # HDF5 itself met the full disk: its flags cleared, every column cut to the commits
            if not self._out_of_room:
                return  # an I/O error: nothing more is written (the /flushes rows say what is stored)
            try:
                if os.stat(self.path).st_ino != self._inode:
                    return  # not this writer's file any more
                f = open_abandoned(self.path, LIBVER)
            except Exception:  # noqa: BLE001 - not reopened: as HDF5 left it, the /flushes rows say what is stored
                return
            longer = None
        else:
            f = self._reopen()
            # only a column longer than what was committed is opened to be cut (the writer knows each length)
            counted = {name: committed_rows(name, self.committed) for name in self._columns}
            longer = [name for name, n in counted.items() if n is not None and self._columns[name].length > n]
        try:
            write_footer(f, status, stop_reason, self._filled_optional, self.committed, longer)
            f.close()
            sync_file(self.path)  # after the close: closing rewrites the superblock (no longer open for writing)
        except Exception as e:  # noqa: BLE001 - the footer could not be written (or synced): the flush rows still hold
            abandon(f)
            if longer is None and isinstance(e, OSError):
                return  # the write error that abandoned the file stays the one reported
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
