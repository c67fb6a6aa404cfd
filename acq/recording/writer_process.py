"""The session file written by a child process: :class:`WriterProcess` stands in for
:class:`acq.recording.writer.SessionWriter` in the recorder and hands each block to a forked child that writes it.

Why: on two cores the HDF5 writing (copies, Fletcher32, the commits' syncs) then runs beside the simulator or the
drivers instead of taking turns with them for one interpreter's lock.

The child is forked when the session is opened, before any reader thread exists; it ignores SIGINT and SIGTERM (a
stop is the recorder's to decide) and creates, marks (the live lock, :mod:`acq.recording.live`), writes and finishes
the file with an unchanged :class:`SessionWriter`. Blocks go to it through a pipe (pickle protocol 5, the arrays'
bytes written straight from their buffers); it answers each commit with the totals on the disk and, on a failed
write, with the failure, which this side raises as the writer would have. What is reported as committed is only what
the child confirmed; :meth:`WriterProcess.finish` returns once the child has finished the file and ended. When the
recording process ends without finishing (killed), the child reads the end of its pipe, commits what it holds and
finishes the file as ``interrupted``; a killed child is a failed write ("session writer ended …") and its file, its
last commit intact, is repaired by ``acq check``.
"""

from __future__ import annotations

import fcntl
import mmap
import os
import pickle
import select
import signal
import struct
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from acq.recording.layout import EVENT_DTYPE, OPTIONAL_ENCODER, Status
from acq.recording.writer import SessionWriter
from acqcore.errors import StorageError
from drivers.base import CurrentBlock, EncoderBlock, StreamEvent

#: Pipe capacity asked for, bytes (Linux ``F_SETPIPE_SZ``; an unprivileged process may get up to
#: /proc/sys/fs/pipe-max-size, 1 MiB by default): ~8 blocks of 3 × 5120 float64 before the recording thread waits.
PIPE_BYTES = 1 << 20
#: How often the child looks whether the recording process still lives while its pipe is silent, s.
PARENT_CHECK_S = 1.0
_HEAD = struct.Struct("<II")  # pickle bytes, out-of-band buffers
_RING_HEAD = 64
#: Shared memory for the arrays in flight, bytes: 2 commits of 2 MiB (FLUSH_BYTES), so the recording thread waits only
#: when the child is that far behind.
RING_BYTES = 4 << 20
_ENCODER_ROW = 8 * (3 + len(OPTIONAL_ENCODER))  # bytes a stored encoder sample takes, all columns


class _Ring:
    """Shared memory the arrays of the messages go through (mapped before the fork: both processes see it); the
    child stores in its first 8 bytes how many bytes it has taken, the parent waits for room."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.map = mmap.mmap(-1, _RING_HEAD + size, flags=mmap.MAP_SHARED)
        self.view = memoryview(self.map)
        self.taken = np.frombuffer(self.map, np.int64, 1, 0)  # bytes the child has taken (padding included)
        self.written = 0

    def put(self, raw: memoryview, alive: Any) -> tuple[int, int]:
        """Copy ``raw`` into the ring (waiting for room); its (offset, bytes)."""
        n = raw.nbytes
        if n > self.size:
            raise ValueError(f"{n} bytes do not fit the writer's ring of {self.size}")
        pos = self.written % self.size
        pad = self.size - pos if pos + n > self.size else 0
        while self.written + pad + n - int(self.taken[0]) > self.size:
            alive()
            time.sleep(0.0005)
        self.written += pad
        off = self.written % self.size
        self.view[_RING_HEAD + off:_RING_HEAD + off + n] = raw
        self.written += n
        return off, n


def _send_ring(fd: int, ring: _Ring, obj: Any, alive: Any) -> None:
    buffers: list[pickle.PickleBuffer] = []
    meta = pickle.dumps(obj, protocol=5, buffer_callback=buffers.append)
    spans = [ring.put(b.raw(), alive) for b in buffers]
    _send(fd, (meta, spans, ring.written))


def _recv_ring(fd: int, ring: _Ring) -> tuple[Any, int] | None:
    message = _recv(fd)
    if message is None:
        return None
    meta, spans, end = message
    return pickle.loads(meta, buffers=[ring.view[_RING_HEAD + off:_RING_HEAD + off + n] for off, n in spans]), end


def _send(fd: int, obj: Any) -> None:
    """Write ``obj`` to ``fd`` (a small pickle)."""
    meta = pickle.dumps(obj, protocol=5)
    view = memoryview(_HEAD.pack(len(meta), 0) + meta)
    while view.nbytes:
        view = view[os.write(fd, view):]


def _read_exactly(fd: int, n: int) -> bytearray | None:
    """``n`` bytes from ``fd``; None at the end of the pipe."""
    out = bytearray(n)
    view, got = memoryview(out), 0
    while got < n:
        k = os.readv(fd, [view[got:]])
        if k == 0:
            return None
        got += k
    return out


def _recv(fd: int) -> Any:
    """One object written by :func:`_send`; None at the end of the pipe."""
    head = _read_exactly(fd, _HEAD.size)
    if head is None:
        return None
    meta = _read_exactly(fd, _HEAD.unpack(head)[0])
    return None if meta is None else pickle.loads(meta)


class WriterProcess:
    """A :class:`SessionWriter` in a child process, as far as the recorder uses one (see module doc).

    Parameters: ``path`` and the keyword arguments of :class:`SessionWriter`. Raises what its constructor raises
    (:class:`acq.recording.writer.SessionExists`, a :class:`StorageError`, …), the child then ended.
    """

    def __init__(self, path: Path, **writer_args: Any) -> None:
        self.path = Path(path)
        self._rate_hz = float(writer_args["current_info"].rate_hz)
        self._channels = len(writer_args["current_info"].channels)
        self.committed = {"current_samples": 0, "current_blocks": 0, "encoder_samples": 0, "events": 0}
        self.failure: StorageError | None = None
        self._unraised: StorageError | None = None  # a failure found while sending, for the next flush to raise
        self.pending_bytes = 0
        to_child, from_parent = os.pipe()[::-1]
        from_child, to_parent = os.pipe()
        try:
            fcntl.fcntl(to_child, fcntl.F_SETPIPE_SZ, PIPE_BYTES)
        except OSError:
            pass  # the default capacity: the recording thread waits for the child more often
        self._ring = ring = _Ring(RING_BYTES)
        parent = os.getpid()
        with h5py._objects.phil:  # no other thread inside HDF5 while forking: the child could never take its lock
            pid = os.fork()
        if pid == 0:  # the child: never returns
            os.close(to_child)
            os.close(from_child)
            _child(from_parent, to_parent, parent, ring, self.path, writer_args)
        os.close(from_parent)
        os.close(to_parent)
        self._pid, self._to_child, self._from_child = pid, to_child, from_child
        answer = self._answer()
        if isinstance(answer, BaseException):
            self._end()
            raise answer

    def _answer(self) -> Any:
        """The child's next answer (blocking); a child that ended without one is a failed write."""
        answer = _recv(self._from_child)
        if answer is None:
            return StorageError(f"session writer ended unexpectedly ({self._how_it_ended()}): {self.path}")
        return answer

    def _how_it_ended(self) -> str:
        if not self._pid:
            return "ended"
        _, status = os.waitpid(self._pid, 0)
        self._pid = 0
        if os.WIFSIGNALED(status):
            return f"killed by {signal.Signals(os.WTERMSIG(status)).name}"
        return f"exit status {os.waitstatus_to_exitcode(status)}"

    def _end(self) -> None:
        """Close both pipes and reap the child (it ends when its pipe closes)."""
        for fd in (self._to_child, self._from_child):
            if fd >= 0:
                os.close(fd)
        self._to_child = self._from_child = -1
        if self._pid:
            os.waitpid(self._pid, 0)
            self._pid = 0

    def _put(self, message: tuple[Any, ...]) -> None:
        """Send ``message`` to the child; nothing after a failure. A child that ended is a failure raised by the next
        :meth:`flush` (an append never raises, as the writer's do not)."""
        if self.failure is not None:
            return
        try:
            _send_ring(self._to_child, self._ring, message, self._alive)
        except BrokenPipeError:
            self.failure = self._unraised = StorageError(
                f"session writer ended unexpectedly ({self._how_it_ended()}): {self.path}")

    def _alive(self) -> None:
        """Raise BrokenPipeError when the child has ended (while waiting for room in the ring)."""
        if self._pid and os.waitpid(self._pid, os.WNOHANG)[0]:
            self._pid = 0
            raise BrokenPipeError

    @property
    def seconds_kept(self) -> float:
        """Seconds of current committed to disk (as the child confirmed)."""
        return self.committed["current_samples"] / self._rate_hz

    def append_current(self, block: CurrentBlock) -> None:
        """As :meth:`SessionWriter.append_current`."""
        self.pending_bytes += block.count * 8 * self._channels + 24
        self._put(("current", block))

    def append_encoder(self, block: EncoderBlock) -> None:
        """As :meth:`SessionWriter.append_encoder`."""
        self.pending_bytes += block.count * _ENCODER_ROW
        self._put(("encoder", block))

    def add_event(self, event: StreamEvent) -> None:
        """As :meth:`SessionWriter.add_event`."""
        self.pending_bytes += EVENT_DTYPE.itemsize
        self._put(("event", event))

    def _take(self, answer: Any) -> Any:
        """Note one answer of the child: a commit's totals, or a failure (kept, returned)."""
        if isinstance(answer, StorageError):
            self.failure = self.failure or answer
        elif isinstance(answer, dict):
            self.committed = answer
        return answer

    def flush(self) -> None:
        """Ask the child to commit everything sent so far (it answers when that is on the disk); first raise the
        failure of an earlier commit (:class:`StorageError`, as :meth:`SessionWriter.flush` raises its own). Does
        nothing after a failure once raised."""
        if self._unraised is not None:
            error, self._unraised = self._unraised, None
            raise error
        if self.failure is not None:
            return
        while select.select([self._from_child], [], [], 0)[0]:
            if isinstance(self._take(self._answer()), StorageError):
                raise self.failure  # type: ignore[misc]
        self.pending_bytes = 0
        self._put(("flush",))

    def finish(self, status: Status, stop_reason: str) -> None:
        """As :meth:`SessionWriter.finish`: returns once the child has committed everything, written the footer and
        ended; what it reports is in :attr:`committed` and :attr:`failure` (a child that ended without finishing the
        file: a failure, its file left ``recording`` with its commits, for ``acq check``)."""
        try:
            if not self._pid:
                return
            try:
                _send_ring(self._to_child, self._ring, ("finish", status, stop_reason), self._alive)
            except BrokenPipeError:
                pass
            while True:
                answer = self._take(self._answer())
                if isinstance(answer, tuple):
                    break
                if self._pid == 0:  # the child ended without finishing
                    return
            self.committed, failure, raised = answer
            if failure is not None and self.failure is None:
                self.failure = StorageError(failure)
            if raised is not None:
                raise StorageError(raised)
        finally:
            self._end()


def _child(from_parent: int, to_parent: int, parent: int, ring: _Ring, path: Path, writer_args: dict[str, Any]) -> None:
    """The child's whole life (see module doc); ends the process."""
    code = 0
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        try:
            writer = SessionWriter(path, **writer_args)
        except BaseException as e:  # noqa: BLE001 - the parent raises it
            _send(to_parent, e if _picklable(e) else StorageError(f"{type(e).__name__}: {e}"))
            return
        _send(to_parent, writer.committed)
        _serve(writer, from_parent, to_parent, parent, ring)
    except BaseException:  # noqa: BLE001 - a bug: the parent sees the pipe end
        code = 1
    finally:
        os._exit(code)


def _serve(writer: SessionWriter, from_parent: int, to_parent: int, parent: int, ring: _Ring) -> None:
    appends = {"current": writer.append_current, "encoder": writer.append_encoder, "event": writer.add_event}
    while True:
        while not select.select([from_parent], [], [], PARENT_CHECK_S)[0]:
            if os.getppid() != parent:  # the recording process ended; its pipe may live on in a process it forked
                break
        got = _recv_ring(from_parent, ring) if os.getppid() == parent else None
        if got is None:  # the recording process ended without finishing the file
            writer.add_event(StreamEvent(time.monotonic_ns(), "recorder", "info",
                                         "stopped: the recording process ended"))
            writer.finish("interrupted", "the recording process ended before finishing the file")
            return
        message, end = got
        kind = message[0]
        if kind in appends:
            appends[kind](message[1])  # copied: the ring's bytes are free again
            ring.taken[0] = end
        elif kind == "flush":
            try:
                writer.flush()
                _send(to_parent, writer.committed)
            except StorageError as e:
                _send(to_parent, e)
        elif kind == "finish":
            raised = None
            try:
                writer.finish(message[1], message[2])
            except StorageError as e:
                raised = str(e)
            failure = None if writer.failure is None else str(writer.failure)
            _send(to_parent, (writer.committed, failure, raised))
            return


def _picklable(e: BaseException) -> bool:
    try:
        pickle.loads(pickle.dumps(e))
    except Exception:  # noqa: BLE001
        return False
    return True
