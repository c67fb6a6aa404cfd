"""The live view of ``acq record --live``: scrolling phase current, motor speed and position, counters, events.

Threads: Qt must own the main thread (its GUI objects live there, and the process's signals
arrive there), so the recorder runs in a worker thread and the window in the main one.
The recorder's listener hook (:class:`LiveFeed`, called in the recording thread after each
block is written and for each event stored) only counts samples and events and puts a reference
to the block into a bounded queue; when the queue is full the block is dropped *for display only*
(it is already on disk). A timer in the main thread drains the queue and redraws ~30 times a second.

Stopping: Ctrl-C, SIGTERM or SIGHUP (handled in the main thread: :func:`acq.ui.qt_signals.signals_in_qt_loop`) or
closing the window calls :meth:`acq.recording.recorder.Recorder.request_stop`; the recorder ends at its next
safe point with status ``interrupted`` — unless it already has all its samples.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import click
import numpy as np
import pyqtgraph as pg
from pyqtgraph.Qt import QtCore, QtGui, QtWidgets

from acq.process_signals import STOP_REASONS
from acq.recording.recorder import Recorder, RecordingResult
from acq.ui.qt_app import ensure_app
from acq.ui.qt_signals import signals_in_qt_loop
from acq.ui.view import has_display
from drivers.base import CurrentBlock, EncoderBlock, StreamEvent
from acqcore.errors import ConfigError

QUEUE_BLOCKS = 512
FRAME_INTERVAL_MS = 33
WINDOW_S = 5.0
NO_DISPLAY_MESSAGE = "--live needs a display (DISPLAY or WAYLAND_DISPLAY is unset); record without --live"


@dataclass(frozen=True)
class LiveStats:
    """What the live view did: frames drawn, display blocks dropped, time the recorder spent in the listener."""

    frames: int
    seconds: float
    dropped_blocks: int
    max_listener_s: float

    @property
    def frame_rate_hz(self) -> float:
        """Frames drawn per second of wall time."""
        return self.frames / self.seconds if self.seconds > 0 else 0.0


def require_display() -> None:
    """Raise :class:`ConfigError` (one line) when no window can be shown."""
    if not has_display():
        raise ConfigError(NO_DISPLAY_MESSAGE)


class LiveFeed:
    """The recorder's listener: counts, events and a bounded queue to the window (recording thread).

    Parameters
    ----------
    request_stop : callable
        Ends the recording as ``interrupted`` with a reason (:meth:`acq.recording.recorder.Recorder.request_stop`).
    maxsize : int
        Blocks held for display at most; more are dropped from the display, never from the file.
    """

    def __init__(self, request_stop: Callable[[str], None], maxsize: int = QUEUE_BLOCKS) -> None:
        self.blocks: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=maxsize)
        self.events: deque[StreamEvent] = deque()
        self.counts = {"current": 0, "encoder": 0}
        self.gaps = {"current": 0, "encoder": 0}
        self.dropped = 0
        self.max_listener_s = 0.0
        self.request_stop = request_stop

    def __call__(self, stream: str, block: CurrentBlock | EncoderBlock | StreamEvent) -> None:
        t0 = time.perf_counter()
        if isinstance(block, StreamEvent):
            if block.kind == "gap" and block.stream in self.gaps:
                self.gaps[block.stream] += 1
            self.events.append(block)
            return
        self.counts[stream] += block.count
        try:
            self.blocks.put_nowait((stream, block))
        except queue.Full:
            self.dropped += 1
        self.max_listener_s = max(self.max_listener_s, time.perf_counter() - t0)


class _Trace:
    """The last :data:`WINDOW_S` seconds of one signal, for display."""

    def __init__(self) -> None:
        self.t = np.zeros(0)
        self.y = np.zeros(0)

    def extend(self, t: np.ndarray, y: np.ndarray) -> None:
        self.t = np.concatenate([self.t, t])
        self.y = np.concatenate([self.y, y])
        keep = self.t >= self.t[-1] - WINDOW_S if self.t.size else slice(None)
        self.t, self.y = self.t[keep], self.y[keep]


class LiveWindow(QtWidgets.QWidget):
    """Scrolling phase current, motor speed and position (x axes linked), counters and an event log.

    Parameters
    ----------
    feed : LiveFeed
        Where the blocks come from.
    rate_hz : float
        DAQ sample rate, Hz (the x axis of the current is its sample index over this rate).
    period_s : float
        Drive cycle, s (the x axis of the encoder plots is its cycle index times this).
    counts_per_rev : int
        Encoder counts per motor revolution.
    title : str
        Window heading.
    """

    def __init__(self, feed: LiveFeed, rate_hz: float, period_s: float, counts_per_rev: int, title: str) -> None:
        super().__init__()
        self.feed = feed
        self.rate_hz, self.period_s = rate_hz, period_s
        self.rad_per_count = 2.0 * math.pi / counts_per_rev
        self.frames = 0
        self.closed_by_user = False
        self.setWindowTitle(f"acq record --live — {title}")
        self.graphics = pg.GraphicsLayoutWidget()
        specs = (("current", "Phase current", ("i_a", "A")), ("speed", "Motor speed", ("ω_m", "rad/s")),
                 ("position", "Motor position", ("θ_m", "rad")))
        self.plots: dict[str, pg.PlotItem] = {}
        self.curves: dict[str, pg.PlotDataItem] = {}
        self.traces = {name: _Trace() for name, _, _ in specs}
        for row, (name, plot_title, (text, units)) in enumerate(specs):
            plot = self.graphics.ci.addPlot(row=row, col=0, title=plot_title)
            plot.setLabel("left", text, units=units)
            plot.setLabel("bottom", "t (own clock of the stream)", units="s")
            for side in ("left", "bottom"):
                plot.getAxis(side).enableAutoSIPrefix(False)
            if self.plots:
                plot.setXLink(self.plots["current"])
            curve = plot.plot(pen=pg.mkPen("#1f77b4", width=1), antialias=False)
            curve.setDownsampling(auto=True, method="peak")
            curve.setClipToView(True)
            self.plots[name], self.curves[name] = plot, curve
        self.counters = QtWidgets.QLabel()
        self.log = QtWidgets.QPlainTextEdit(readOnly=True)
        self.log.setMaximumHeight(110)
        self.log.setPlaceholderText("gaps and errors appear here as they happen")
        box = QtWidgets.QVBoxLayout(self)
        box.addWidget(self.graphics, stretch=1)
        box.addWidget(self.counters)
        box.addWidget(self.log)
        self.resize(1200, 850)

    def draw(self) -> None:
        """Take everything queued, extend the traces, redraw, update counters and the event log."""
        current_t, current_y, enc_index, enc_counts = [], [], [], []
        while True:
            try:
                stream, block = self.feed.blocks.get_nowait()
            except queue.Empty:
                break
            if stream == "current":
                current_t.append((block.first_index + np.arange(block.count)) / self.rate_hz)
                current_y.append(block.current_a[0])
            else:
                enc_index.append(np.asarray(block.index))
                enc_counts.append(np.asarray(block.position_counts))
        if current_t:
            self.traces["current"].extend(np.concatenate(current_t), np.concatenate(current_y))
        if enc_index:
            self._extend_encoder(np.concatenate(enc_index), np.concatenate(enc_counts))
        for name, trace in self.traces.items():
            self.curves[name].setData(trace.t, trace.y)
        while self.feed.events:
            e = self.feed.events.popleft()
            self.log.appendPlainText(f"{e.stream} {e.kind}: {e.detail}")
        self.frames += 1
        c, g = self.feed.counts, self.feed.gaps
        self.counters.setText(f"current {c['current']:,} samples · encoder {c['encoder']:,} samples · gaps "
                              f"{g['current']} current, {g['encoder']} encoder · display: {self.frames} frames, "
                              f"{self.feed.dropped} blocks not drawn")

    def _extend_encoder(self, index: np.ndarray, counts: np.ndarray) -> None:
        position = self.traces["position"]
        t = index * self.period_s
        theta = counts * self.rad_per_count
        if position.t.size:  # difference against the last sample already shown
            t_prev, theta_prev = np.r_[position.t[-1], t[:-1]], np.r_[position.y[-1], theta[:-1]]
        else:
            t_prev, theta_prev = np.r_[t[0] - self.period_s, t[:-1]], np.r_[theta[0], theta[:-1]]
        self.traces["speed"].extend(t, (theta - theta_prev) / (t - t_prev))
        position.extend(t, theta)

    def closeEvent(self, event: QtGui.QCloseEvent) -> None:  # noqa: N802 - Qt's name
        """Closing the window by hand ends the recording (status interrupted)."""
        if not self.closed_by_user:
            self.feed.request_stop("live view window closed")
        super().closeEvent(event)


class LiveView:
    """Attach a live window to a recorder; :meth:`run` records in a worker thread under the Qt loop.

    Raises :class:`~acqcore.errors.ConfigError` when there is no display (checked before any device starts).
    """

    def __init__(self, recorder: Recorder) -> None:
        require_display()
        current, drive = recorder.current_info, recorder.drive_info
        self.app = ensure_app()
        self.feed = LiveFeed(recorder.request_stop)
        recorder.listeners.append(self.feed)
        self.window = LiveWindow(self.feed, current.rate_hz, drive.period_s, drive.counts_per_rev,
                                 recorder.bench.joint)

    def run(self, record: Callable[[], RecordingResult]) -> tuple[RecordingResult, LiveStats]:
        """Run ``record`` in a worker thread while the window draws; return its result and the view's figures."""
        outcome: dict[str, Any] = {}

        def work() -> None:
            try:
                outcome["result"] = record()
            except BaseException as e:  # noqa: BLE001 - re-raised in the main thread
                outcome["error"] = e

        worker = threading.Thread(target=work, name="acq-live-recorder", daemon=True)
        timer = QtCore.QTimer()

        def tick() -> None:
            self.window.draw()
            if not worker.is_alive():
                timer.stop()
                self.window.closed_by_user = True
                self.window.close()
                self.app.quit()

        def on_signal(signum: int) -> None:
            self.feed.request_stop(STOP_REASONS[signum])

        timer.timeout.connect(tick)
        with signals_in_qt_loop(on_signal):
            self.window.show()
            t0 = time.monotonic()
            worker.start()
            timer.start(FRAME_INTERVAL_MS)
            self.app.exec()
            worker.join()
        stats = LiveStats(self.window.frames, time.monotonic() - t0, self.feed.dropped, self.feed.max_listener_s)
        if "error" in outcome:
            raise outcome["error"]
        return outcome["result"], stats

    def record(self, record: Callable[[], RecordingResult]) -> RecordingResult:
        """:meth:`run`, then print the frame rate drawn (one line on stderr)."""
        result, stats = self.run(record)
        click.echo(f"live view: {stats.frames} frames drawn in {stats.seconds:.1f} s ({stats.frame_rate_hz:.1f} "
                   f"frames/s); {stats.dropped_blocks} blocks not drawn (all recorded); recorder spent at most "
                   f"{stats.max_listener_s * 1e6:.0f} µs per block in the live listener", err=True)
        return result
