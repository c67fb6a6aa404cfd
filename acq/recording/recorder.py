"""Record a session: run both streams, execute the profile, write everything raw, end cleanly.

One reader thread per stream (:mod:`acq.recording.device_reader`) only reads its device and queues what it
got; the calling thread checks stream indices (:mod:`acq.recording.stream_check`: gaps by counters, never
by timing), writes through :class:`acq.recording.writer.SessionWriter`, flushes at least every 0.5 s and
always finishes the file: ``complete`` when both streams have the requested duration, ``interrupted`` on
Ctrl-C / SIGTERM, ``failed`` on a device error or a failed write (disk full, I/O error: the drive is
stopped at once and only the samples committed before the failure count). Timestamps are never altered:
raw indices and host stamps go to disk.
"""

from __future__ import annotations

import math
import queue
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from acq.process_signals import STOP_REASONS, handled, repeated_hangup, stop_reason
from acq.recording.device_reader import READ_TIMEOUT_S, DeviceReader
from acq.recording.layout import Status, utc_now_iso
from acq.recording.one_cpu import on_one_cpu
from acq.recording.paths import new_session_path
from acq.recording.room import FLUSH_BYTES
from acq.recording.stream_check import StreamChecker, join_encoder_blocks
from acq.recording.writer import SessionExists, SessionWriter
from drivers.base import CurrentSource, CurrentSourceInfo, Drive, DriveInfo, EncoderBlock, StreamEvent
from drivers.config import Bench, Profile
from drivers.limits import refuse_beyond_limits
from drivers.motion import with_dither_seed
from acq.recording.storage import WRITE_FAILURES, cause_of, make_folders, storage_error
from acqcore.errors import AcqError, ConfigError, DeviceError, StorageError

FLUSH_INTERVAL_S = 0.5
#: The recording thread takes what the readers queued once per this interval, all of it, instead of waking for each
#: block: a wake-up (and the GIL handed over to it) per batch. Real time: a block waits at most this long (the
#: flush interval is 0.5 s, a display frame ~30 ms); --fast: ~35 blocks a batch instead of one.
HANDOFF_S = 0.01
STALL_TIMEOUT_S = 5.0
SHUTDOWN_TIMEOUT_S = 5.0

#: Called in the recording thread after each block is written, ``("current" | "encoder", block)`` (encoder blocks
#: that were queued one after another come joined as one), and for each event stored, ``("event", StreamEvent)``
#: (gaps found from the indices, device events).
Listener = Callable[[str, Any], None]


#: How the reason of a session finished failed at its start because the drive's raw frame log failed begins.
RAW_LOG_NOT_KEPT = "raw frame log not kept"


class Interrupted(Exception):
    """Ends a recording as ``interrupted`` (a stop was requested: Ctrl-C, SIGTERM, a live window closed)."""


@dataclass(frozen=True)
class RecordingResult:
    """What a finished recording reports (the session file holds the rest)."""

    path: Path
    status: Status
    stop_reason: str
    current_samples: int
    encoder_samples: int
    current_gaps: int
    encoder_gaps: int
    write_failed: bool = False  # a write to the session file failed (disk full, I/O error): nothing more is stored


@contextmanager
def stop_on_signals(request_stop: Callable[[str], None]) -> Iterator[None]:
    """While recording (main thread only), Ctrl-C, SIGTERM and SIGHUP (:data:`acq.process_signals.STOP_REASONS`) ask
    for a stop at the next safe point.

    The handlers never raise: an exception in the middle of a flush could write a part twice or lose one.
    A second Ctrl-C (SIGTERM) is the previous handler's again: it quits at once; a second SIGHUP is ignored.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    reasons = {s: reason for s, reason in STOP_REASONS.items() if handled(s)}

    def handler(signum: int, frame: object) -> None:
        if repeated_hangup(signum):
            return
        request_stop(reasons[signum])
        if signum != signal.SIGHUP:
            signal.signal(signum, previous[signum])  # the same signal again quits at once (acq check repairs the file)

    previous = {sig: signal.signal(sig, handler) for sig in reasons}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


class Recorder:
    """Record ``duration_s`` of both streams while the drive executes ``profile``.

    Parameters
    ----------
    bench, profile : the configs (stored in the session). ``profile`` None records passively: no motion command
        at all (``[drive] motion = "external"``: the machine's controller moves the joint); it must be None then.
        A dithered profile without a ``dither_seed`` gets one drawn here, so the session stores the seed the drive uses.
    current, drive : the devices (real or simulated; the recorder cannot tell).
    out_dir : folder for the session file, named ``<UTC start>_<joint>.h5``.
    duration_s : seconds of data wanted in each stream (counted in samples, not wall time).
    listeners : called with each block written and each event stored (see :data:`Listener`).
    progress : called with the fraction recorded (0..1) as data arrives.
    one_cpu : run the recording thread and its readers on one CPU (:mod:`acq.recording.one_cpu`): for a simulated
        bench in --fast mode, whose readers compute rather than wait.
    """

    def __init__(
        self,
        bench: Bench,
        profile: Profile | None,
        current: CurrentSource,
        drive: Drive,
        out_dir: Path,
        duration_s: float,
        *,
        operator: str = "",
        tags: dict[str, Any] | None = None,
        listeners: list[Listener] | None = None,
        progress: Callable[[float], None] | None = None,
        one_cpu: bool = False,
    ) -> None:
        external = bench.listens()
        if external != (profile is None):
            raise ConfigError("[drive] motion = \"external\": acq must not command motion, record without a profile"
                              if external else "a recording without a profile needs [drive] motion = \"external\"")
        if profile is not None:  # the commands check with the files' names before opening the devices; this for any caller
            refuse_beyond_limits(profile, bench)
        self.bench, self.profile = bench, (with_dither_seed(profile) if profile is not None else None)
        self.current, self.drive = current, drive
        self.out_dir = Path(out_dir)
        self.duration_s = duration_s
        self.operator, self.tags = operator, tags
        self.listeners = listeners or []
        self.progress = progress
        self.one_cpu = one_cpu
        self._started = False
        self._writer: SessionWriter | None = None
        self.session_path: Path | None = None  # the session file once created (also one finished failed at its start)
        self._ran = False
        self._stop_request: str | None = None
        self._shutting_down = False

    def request_stop(self, reason: str) -> None:
        """Ask the recording to end as ``interrupted`` with ``reason`` at the next safe point (any thread)."""
        if self._stop_request is None:
            self._stop_request = reason

    @property
    def stop_request(self) -> str | None:
        """The stop asked for (Ctrl-C, SIGTERM, :meth:`request_stop`), also one that came once both streams were
        complete, which leaves the recording ``complete``; None if none was."""
        return self._stop_request

    def start_devices(self) -> None:
        """Start both devices (idempotent); a set-up error raises here, before any file exists."""
        if self._started:
            return
        try:
            self._cur_info = self.current.start()
            self._drive_info = self.drive.start()
        except BaseException:
            self._release_devices()
            raise
        self._started = True

    @property
    def current_info(self) -> CurrentSourceInfo:
        """What the started current source reported (coerced rate, channels)."""
        self.start_devices()
        return self._cur_info

    @property
    def drive_info(self) -> DriveInfo:
        """What the started drive reported (period, counts per revolution)."""
        self.start_devices()
        return self._drive_info

    def _release_devices(self) -> None:
        self.drive.stop()
        self.current.stop()

    def open_session(self) -> SessionWriter:
        """Start the devices and create the session file (and the drive's raw log beside it); idempotent.
        A failure releases the devices and raises before anything is recorded; once the session file exists (the raw
        log failed) it is finished first, as ``failed`` with the raw log's problem as reason."""
        self.start_devices()
        if self._writer is not None:
            return self._writer
        try:
            make_folders(self.out_dir)
            for _ in range(100):  # another recorder may take the name between the check and the create
                path = new_session_path(self.out_dir, self.bench.joint, utc_now_iso())
                try:
                    writer = SessionWriter(path, bench=self.bench, profile=self.profile, current_info=self._cur_info,
                                           drive_info=self._drive_info, host_ns_at_start=time.monotonic_ns(),
                                           operator=self.operator, tags=self.tags)
                except SessionExists:
                    continue
                break
            else:
                raise ConfigError(f"{self.out_dir}: no free session file name for joint {self.bench.joint}")
            self.session_path = path
            keep_raw = getattr(self.drive, "keep_raw_frames", None)  # transports that can log their raw traffic
            if keep_raw is not None:
                try:
                    keep_raw(path)
                except KeyboardInterrupt as e:
                    writer.finish("interrupted", stop_reason(e))
                    raise
                except Exception as e:
                    # The session file exists (its layout on disk) but holds nothing: finished as failed with the
                    # reason, like any file once it exists (acq check never sees it "recording"), then one line.
                    where = getattr(e, "filename", None) or f"the drive's raw frame log beside {path.name}"
                    reason = f"{RAW_LOG_NOT_KEPT}: {cause_of(e)}: {where}"
                    writer.finish("failed", reason)
                    error = StorageError if isinstance(e, OSError) and e.errno in WRITE_FAILURES else DeviceError
                    raise error(f"{reason} (nothing recorded; {path.name} finished as failed)") from None
            self._writer = writer
            return self._writer
        except OSError as e:
            self._release_devices()
            if e.errno in WRITE_FAILURES:  # the folder could not be made or written (read-only, full): a failed write
                raise storage_error(e, self.out_dir) from None
            raise ConfigError(f"{self.out_dir}: cannot write a session there ({e.strerror or e})") from None
        except BaseException:
            self._release_devices()
            raise

    def abort(self, reason: str) -> None:
        """End a session that was opened but never run (e.g. Ctrl-C while a window was being built): the file is
        finished as ``interrupted`` with ``reason`` and the devices are released. Nothing after :meth:`run`."""
        if self._writer is None or self._ran:
            return
        self._ran = True
        self._release_devices()
        self._writer.finish("interrupted", reason)

    def run(self) -> RecordingResult:
        """Record; always returns with the file finished (device set-up errors raise before a file exists)."""
        writer = self.open_session()
        cur_info, drive_info = self._cur_info, self._drive_info
        path = writer.path
        inbox: queue.SimpleQueue[tuple[str, Any]] = queue.SimpleQueue()  # C: a fraction of Queue's cost per item
        readers = {
            "current": DeviceReader("current", self.current, math.ceil(self.duration_s * cur_info.rate_hz), inbox),
            "encoder": DeviceReader("encoder", self.drive, math.ceil(self.duration_s / drive_info.period_s), inbox),
        }
        checker = StreamChecker()
        counts = {"current": 0, "encoder": 0}
        status: Status = "complete"
        reason = f"recorded {self.duration_s:g} s"
        with stop_on_signals(self.request_stop), on_one_cpu(self.one_cpu):  # the readers started inside inherit it
            # from here a stop signal raises nothing and the file is finished below; one before (a KeyboardInterrupt)
            # leaves it to abort() — _ran was set before the handlers, and one in between left the file "recording"
            self._ran = True
            try:
                # Motion first: the started devices buffer their samples meanwhile, and a simulated
                # bench then starts the motion at the same point of its record in every run.
                if self.profile is not None:  # None: the machine's own controller moves the joint; acq only listens
                    self.drive.start_motion(self.profile)
                for r in readers.values():
                    r.start()
                self._pump(inbox, readers, writer, checker, counts)
            except Interrupted as e:
                status, reason = "interrupted", str(e)
            except KeyboardInterrupt as e:  # raised by code that embeds the recorder, or where no handler could be set
                status, reason = "interrupted", stop_reason(e)
            except AcqError as e:
                status, reason = "failed", str(e)
            except Exception as e:  # noqa: BLE001 - keep the data whatever went wrong, and say what
                status, reason = "failed", f"{type(e).__name__}: {e}"
            finally:
                status, reason = self._shut_down(inbox, readers, writer, checker, counts, status, reason)
        stored = writer.committed  # only what is on disk is reported, never what was received
        return RecordingResult(path, status, reason, stored["current_samples"], stored["encoder_samples"],
                               checker.current_gaps, checker.encoder_gaps, writer.failure is not None)

    def _pump(self, inbox: queue.SimpleQueue[tuple[str, Any]], readers: dict[str, DeviceReader],
              writer: SessionWriter, checker: StreamChecker, counts: dict[str, int]) -> None:
        done: set[str] = set()
        last_flush = last_data = time.monotonic()
        while len(done) < len(readers):
            time.sleep(HANDOFF_S)
            now = time.monotonic()
            run: list[EncoderBlock] = []  # encoder blocks queued one after another: checked and stored as one
            while len(done) < len(readers):  # one item at a time: what an error leaves queued, _shut_down stores
                if self._stop_request is not None and any(r.covered < r.target for r in readers.values()):
                    self._store_run(run, writer, checker, counts)
                    raise Interrupted(self._stop_request)  # a stop once both streams are complete changes nothing
                try:
                    kind, item = inbox.get_nowait()
                except queue.Empty:
                    break
                if kind == "encoder":
                    run.append(item)
                    last_data = now
                    continue
                self._store_run(run, writer, checker, counts)  # before anything queued after it
                if kind == "error":
                    raise item if isinstance(item, AcqError) else DeviceError(f"{type(item).__name__}: {item}")
                if kind == "done":
                    done.add(item)
                else:
                    self._store(kind, item, writer, checker, counts)
                    last_data = now
                if writer.pending_bytes >= FLUSH_BYTES:
                    writer.flush()
                    last_flush = now
            self._store_run(run, writer, checker, counts)
            if now - last_data > STALL_TIMEOUT_S:
                silent = [n for n, r in readers.items() if n not in done]
                raise DeviceError(f"no data from {', '.join(silent)} for {STALL_TIMEOUT_S:g} s")
            if now - last_flush >= FLUSH_INTERVAL_S or writer.pending_bytes >= FLUSH_BYTES:
                writer.flush()
                last_flush = now

    def _store_run(self, run: list[EncoderBlock], writer: SessionWriter, checker: StreamChecker,
                   counts: dict[str, int]) -> None:
        """Store encoder blocks that arrived one after another as one block (emptying ``run``): one check, one append
        and one call to each listener for the lot (a --fast bench queues ~20 blocks of 40 cycles in a row)."""
        if run:
            block = run[0] if len(run) == 1 else join_encoder_blocks(run)
            run.clear()
            self._store("encoder", block, writer, checker, counts)

    def _store(self, kind: str, item: Any, writer: SessionWriter, checker: StreamChecker,
               counts: dict[str, int]) -> None:
        if kind == "event":
            self._event(writer, item)
            return
        block, events = checker.current(item) if kind == "current" else checker.encoder(item)
        for event in events:
            self._event(writer, event)
        if block is None:
            return
        if kind == "current":
            writer.append_current(block)
        else:
            writer.append_encoder(block)
        counts[kind] += block.count
        self._notify(kind, block)
        if self.progress is not None and kind == "current":
            self._call_out(self.progress, min(1.0, counts["current"] / (self.duration_s * self._cur_info.rate_hz)))

    def _event(self, writer: SessionWriter, event: StreamEvent) -> None:
        """Store an event and show it to the listeners as ``("event", event)``."""
        writer.add_event(event)
        self._notify("event", event)

    def _notify(self, kind: str, item: Any) -> None:
        for listener in self.listeners:
            self._call_out(listener, kind, item)

    def _call_out(self, callback: Callable[..., None], *args: Any) -> None:
        """Call a listener or the progress callback; while shutting down nothing it raises may keep the file
        from being finished."""
        try:
            callback(*args)
        except Exception:
            if not self._shutting_down:
                raise

    def _shut_down(self, inbox: queue.SimpleQueue[tuple[str, Any]], readers: dict[str, DeviceReader],
                   writer: SessionWriter, checker: StreamChecker, counts: dict[str, int], status: Status,
                   reason: str) -> tuple[Status, str]:
        """Stop motion first (safety); store everything the readers still deliver until each has ended; then
        stop the devices, store what is left and finish the file."""
        self._shutting_down = True
        try:
            try:
                if self.profile is not None:
                    self.drive.stop_motion()
            except Exception as e:  # noqa: BLE001 - the file must still be finished
                writer.add_event(StreamEvent(time.monotonic_ns(), "drive", "error", f"stop motion failed: {e}"))
            for r in readers.values():
                r.stop_requested.set()
            deadline = time.monotonic() + SHUTDOWN_TIMEOUT_S
            while any(r.is_alive() for r in readers.values()) and time.monotonic() < deadline:
                status, reason = self._drain(inbox, writer, checker, counts, status, reason, wait_s=READ_TIMEOUT_S)
            for stop in (self.current.stop, self.drive.stop):
                try:
                    stop()
                except Exception as e:  # noqa: BLE001
                    writer.add_event(StreamEvent(time.monotonic_ns(), "recorder", "error", f"device stop failed: {e}"))
            for r in readers.values():
                if r.is_alive():
                    r.join(timeout=READ_TIMEOUT_S)
            status, reason = self._drain(inbox, writer, checker, counts, status, reason, wait_s=0.0)
            for device in (self.current, self.drive):
                for event in device.events():
                    writer.add_event(event)
        except Exception as e:  # noqa: BLE001 - e.g. the disk filled: the footer still says what happened
            if status == "complete":
                status, reason = "failed", f"{type(e).__name__}: {e}"
        finally:
            if status != "complete":
                writer.add_event(StreamEvent(time.monotonic_ns(), "recorder", "info", f"stopped: {reason}"))
            writer.finish(status, reason)
            if writer.failure is not None:  # a write failed (now or earlier): the recording failed, whatever else
                status, reason = "failed", writer.failure_reason()
        return status, reason

    def _drain(self, inbox: queue.SimpleQueue[tuple[str, Any]], writer: SessionWriter, checker: StreamChecker,
               counts: dict[str, int], status: Status, reason: str, wait_s: float) -> tuple[Status, str]:
        """Store what the readers queued (waiting up to ``wait_s`` for the first item); a late error fails
        a recording that was complete."""
        try:
            item = inbox.get(timeout=wait_s) if wait_s > 0 else inbox.get_nowait()
        except queue.Empty:
            return status, reason
        while True:
            kind, payload = item
            if kind in ("current", "encoder", "event"):
                self._store(kind, payload, writer, checker, counts)
            elif kind == "error" and status == "complete":
                status, reason = "failed", str(payload)
            try:
                item = inbox.get_nowait()
            except queue.Empty:
                return status, reason
