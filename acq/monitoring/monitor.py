"""Condition monitoring: capture windows of a running machine, identify each, trend K, raise the alarm.

A loop around the parts acq has (design §11): every ``every_s`` the recorder captures a window of
``window_s`` as an ordinary crash-safe session, passively (``[drive] motion = "external"``: no motion
command); a worker process analyses it while capture goes on (at most ``jobs`` running and one waiting:
a window beyond that is not analysed and says so — back-pressure, never an unbounded queue); the
outcome goes into the catalogue (:mod:`acq.monitoring.catalogue`, the batch's record of an outcome); the trend
(:mod:`acq.monitoring.trend`: baseline, threshold and EWMA rules) judges it; on entering alarm ``on_alarm`` runs
through the shell (``sh -c``, in the background) with ``ACQ_JOINT``, ``ACQ_K``, ``ACQ_BASELINE_K``,
``ACQ_CHANGE_PCT``, ``ACQ_SESSION``, ``ACQ_WINDOW`` (the window's number, from 1) in its environment; a command that
fails is reported (:attr:`MonitorStatus.alarm_command_failure`).

Each window is judged for excitation (:mod:`acq.monitoring.window_judge`): a window that does not excite is catalogued
with verdict ``not excited`` and the reason, without K. Windows are numbered (session tag ``monitor_window``, from 0;
shown from 1: :func:`acq.monitoring.monitor_scope.window_number`) and
placed in machine time (``monitor_elapsed_s``: number × ``every_s``, after a restart going on from the last window at
the new ``every_s``); a restart after a crash resumes
the numbering, analyses the windows left unanalysed and marks a window whose capture was cut
``interrupted`` (not counted): what it finds in the folder is read by :mod:`acq.monitoring.monitor_leftovers`; what
a restart must agree with (bench, ``--window``, alarm rules, catalogue) is in
:mod:`acq.monitoring.monitor_restart`, the catalogue opened with it, the monitor's windows there and their trend in
:mod:`acq.monitoring.monitor_catalogue`, the monitor's identity (a copied folder is refused) in
:mod:`acq.monitoring.monitor_scope`, the alarm in :mod:`acq.monitoring.monitor_alarm` and its command in
:mod:`acq.monitoring.alarm_command`, which raw windows it keeps and deletes (retention, the disk budget, the file
system's room; two windows in a row the storage refuses stop it, exit 1) in :mod:`acq.monitoring.monitor_windows`,
the windows waiting for a catalogue out of reach in :mod:`acq.monitoring.catalogue_spool`. In ``fast`` mode
(simulated benches) machine time is simulated: the loop does not sleep, and waits for the analysis instead of skipping
(no real time passes meanwhile).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import AbstractContextManager, ExitStack
from pathlib import Path

from acq.config import check_duration
from acq.monitoring.alarm_command import AlarmCommands
from acq.monitoring.alarm_rules import RULE_TAGS, AlarmRules
from acq.monitoring.catalogue import Entry, Outcome
from acq.monitoring.catalogue_spool import Waiting
from acq.monitoring.folder_lock import folder_lock, removed_unless_used
from acq.monitoring.monitor_alarm import AlarmState
from acq.monitoring.monitor_catalogue import MonitorCatalogue
from acq.monitoring.monitor_leftovers import leftovers
from acq.monitoring.monitor_restart import EVERY_TAG, MachineClock
from acq.monitoring.monitor_scope import IDENTITY_FILE, MONITOR_TAG, WINDOW_TAG, check_user_tags
from acq.monitoring.monitor_status import MonitorSettings, MonitorStatus
from acq.recording.room import SIZE_MARGIN, expected_session_bytes, require_file_size_limit
from acq.monitoring.monitor_windows import FolderWindows, StorageFailures, check_budget, refused_as_damaged, write_cause
from acq.monitoring.retention import WindowFiles
from acq.monitoring.session_outcome import CATALOGUE_NAME
from acq.monitoring.trend import ELAPSED_TAG, Trend
from acq.monitoring.window_analyses import WindowAnalyses
from acq.monitoring.window_bench import FACT_TAGS, window_recorder
from acq.monitoring.window_judge import marked_file
from acq.recording.recorder import RAW_LOG_NOT_KEPT, Recorder, stop_on_signals
from acq.recording.reader import load
from acqcore.errors import EXIT_INTERRUPTED, AcqError, ConfigError, StorageError

class Monitor:
    """The monitor loop; :meth:`run` returns the exit code (3 when the last state is alarm, else 0)."""

    def __init__(self, settings: MonitorSettings, on_status: Callable[[MonitorStatus], None] | None = None) -> None:
        check_duration(settings.window_s, "--window")  # a window is a recording: record's limit (24 h)
        if settings.every_s < settings.window_s:
            raise ConfigError(f"--every {settings.every_s:g}: must be at least --window {settings.window_s:g} s")
        if settings.for_s is not None and settings.for_s < settings.window_s:  # it recorded the whole window
            raise ConfigError(f"--for {settings.for_s:g}: must be at least --window {settings.window_s:g} s "
                              "(the run records whole windows)")
        self.s = settings
        self.status = MonitorStatus(settings.bench.joint)
        self.on_status = on_status
        self._stop: str | None = None
        self._recorder: Recorder | None = None
        self._windows = FolderWindows(settings.out_dir, settings.keep)  # their raw files, retention
        self._analyses: WindowAnalyses | None = None  # the analyses under way, in the run's pools
        self._storage = StorageFailures(settings.out_dir)  # windows in a row the folder's storage refused
        self._earlier: set[str] = set()  # windows of earlier runs a restart files (cut, or not analysed)
        self._failure: int | None = None  # the window (from 1) after whose storage failure the monitor stops (exit 1)
        self._alarms = AlarmCommands(settings.on_alarm, self._alarm_problem)
        self._alarm = AlarmState(self.status, self._alarms)
        self._filed = 0  # catalogue rows written by this run
        self._size = expected_session_bytes(settings.bench, settings.window_s)
        # filed with every window: acq trend / fleet / view --trend of these windows judge them by the same rules
        self._rules = AlarmRules(settings.baseline_windows, settings.threshold_pct, settings.ewma_lambda)
        check_user_tags(settings.tags, (WINDOW_TAG, ELAPSED_TAG, EVERY_TAG, *RULE_TAGS.values(), *FACT_TAGS))
        self._catalogue = MonitorCatalogue(settings, self._rules)  # its identity, windows and trend; open while it runs
        self._clock = MachineClock(settings.every_s)  # a restart goes on from its last window (monitor_restart)
        # a window that cannot be written whole under ulimit -f: refused now, not every window failed for hours
        require_file_size_limit(self._size, f"a {settings.window_s:g} s window", "shorten --window")
        check_budget(settings, self._size)

    @property
    def spool(self) -> Path:
        """The file of the windows waiting for a catalogue out of reach (:attr:`MonitorCatalogue.spool`)."""
        return self._catalogue.spool

    @property
    def stopped_by(self) -> str | None:
        """Why the monitor was stopped before its ``for_s`` (Ctrl-C, SIGTERM, a stop request); None if it was not."""
        return self._stop

    def request_stop(self, reason: str) -> None:
        """End after the window being captured (which ends as interrupted) and the analyses under way."""
        self._stop = self._stop or reason
        if self._recorder is not None:
            self._recorder.request_stop(reason)

    # ---- the loop ------------------------------------------------------------------------------------
    def run(self) -> int:
        """Monitor until ``for_s`` has passed or a stop is requested; always leaves the catalogue consistent.

        Returns 130 when stopped (:attr:`stopped_by`: Ctrl-C, SIGTERM, a stop request), else 3 when the last
        state is alarm, else 0."""
        # a catalogue file or identity this run made: only the folder's own catalogue (a --catalogue file other monitors
        # may be writing to — they start together — or a database of a URL is not ours to remove: the second read)
        own = [] if self.s.catalogue is not None else [self.s.out_dir / CATALOGUE_NAME]
        with removed_unless_used([*own, self.s.out_dir / IDENTITY_FILE], self.s.out_dir, lambda: self._filed > 0):
            self._run()
        if self._stop is not None:
            return EXIT_INTERRUPTED
        return 3 if self._alarm.active else 0

    def _run(self) -> None:
        with folder_lock(self.s.out_dir), self._catalogue.opened() as (windows, from_spool), ExitStack() as pools, \
                self._signals():
            self._analyses = WindowAnalyses(pools, self.s.jobs)
            first = self._resume(windows, from_spool)
            wall0 = time.monotonic()
            n = first
            while self._stop is None and self._failure is None and (
                    self.s.for_s is None or (n - first) * self.s.every_s < self.s.for_s):
                if not self.s.fast:
                    self._wait_until(wall0 + (n - first) * self.s.every_s)
                    if self._stop is not None:
                        break
                self._window(n)
                n += 1
            self._collect(at_most=0)
            self._flush(force=True)  # once more: what still waits stays in the spool file, filed by the next start
            self._alarms.reap(wait=True)
            self.status.state = "alarm" if self._alarm.active else self.status.state
            # the windows of this monitor the catalogue holds, the analyses under way filed
            failure = None if self._failure is None else self._storage.error(self._failure, sum(
                e.verdict not in ("interrupted", "not analysed") for e in self._catalogue.own_windows(None)))
            self.status.message = (f"stopped: {failure}" if failure else
                                   f"stopped: {self._stop}" if self._stop else "done")
            self._show()
            if failure is not None:
                raise failure

    def _window(self, n: int) -> None:
        """Capture window ``n`` (if the disk budget allows) and hand it to the pool (if it keeps up)."""
        self.status.machine_time_s = self._clock.at(n)
        self._flush()
        if not self._room_for_window():
            self.status.not_captured += 1
            kept = self._windows.kept_copies()
            why = (f" — {kept} windows of another monitor copied here are its baseline or alarms, never deleted "
                   "(raise --max-disk or move them out)") if kept else ""
            self.status.message = f"window {n + 1} not captured: the disk budget would be exceeded{why}"
            self._show()
            return
        fits, free, need = self._windows.room_on_disk(self._size)
        if not fits:
            self.status.no_room += 1
            self._storage_failed(n, "disk full", f"window {n + 1} not captured: disk full: {self.s.out_dir} has "
                                                 f"{free / 1e6:.1f} MB free, a window needs {need / 1e6:.1f} MB")
            return
        tags = {**self.s.tags, WINDOW_TAG: n, ELAPSED_TAG: self._clock.at(n), EVERY_TAG: self.s.every_s,
                MONITOR_TAG: self._catalogue.monitor_id, **self._rules.as_tags()}
        recorder = window_recorder(self.s.bench, self.s.out_dir, self.s.window_s, self._clock.at(n), fast=self.s.fast,
                                   tags=tags)
        self._recorder = recorder
        if self._stop is not None:
            recorder.request_stop(self._stop)
        try:
            result = recorder.run()
        except AcqError as e:
            if recorder.session_path is None:  # a set-up error before its file existed: the monitor stops, as before
                raise
            self._failed_at_start(n, recorder.session_path, e)
            return
        finally:
            self._recorder = None
        # a Ctrl-C the recorder's handler took once both streams were complete (its shutdown) left the window complete:
        # the monitor ends all the same (it went on capturing, the Ctrl-C lost: 1 of 30 runs, SIGINT 0.1…10 s in)
        self._stop = self._stop or recorder.stop_request
        key = str(load(result.path).meta.session_id)
        self._windows.add(WindowFiles(n, result.path, False, False, key))
        self._size = max(self._size, int(SIZE_MARGIN * result.path.stat().st_size))
        if result.write_failed:  # the storage refused a write (disk full, I/O error): not one more "interrupted"
            self._mark(key, "interrupted", f"window capture failed: {result.stop_reason}", kind="write failed")
            self._storage_failed(n, write_cause(result.stop_reason),
                                 f"window {n + 1} capture failed: {result.stop_reason}")
            return
        if result.status != "complete":
            self._mark(key, "interrupted", f"window capture {result.status}: {result.stop_reason}")
            if result.status == "interrupted":  # Ctrl-C / SIGTERM reached the recorder's handler: the monitor ends
                self._stop = self._stop or result.stop_reason
            return
        self._storage.succeeded()
        self.status.captured += 1
        self.status.machine_time_s = self._clock.at(n) + self.s.window_s
        self._collect(at_most=self.s.jobs - 1 if self.s.fast else None)
        waiting = len(self._analyses or ())
        if waiting > self.s.jobs:  # jobs running and one waiting: no more (back-pressure)
            self._mark(key, "not analysed", f"the analysis fell behind the capture ({waiting} windows "
                                            "waiting): this window was skipped", kind="skipped")
            return
        self._submit(key)
        self._show()

    def _failed_at_start(self, n: int, path: Path, error: AcqError) -> None:
        """Window ``n``'s file, finished failed at its start (the drive's raw frame log not kept), catalogued with its
        reason as a capture that failed (before: never filed, the fleet did not learn of it); then a write failure
        goes as any (:meth:`_storage_failed`), a device's stops the monitor with its one line."""
        try:
            session = load(path)
        except AcqError:  # not readable as a session: its error is the one to tell
            raise error from None
        key, reason = str(session.meta.session_id), session.meta.stop_reason
        self._windows.add(WindowFiles(n, path, False, False, key))
        storage = isinstance(error, StorageError)
        self._mark(key, "interrupted", f"window capture failed: {reason}", kind="write failed" if storage else None)
        if not storage:
            raise error
        self._storage_failed(n, write_cause(reason.removeprefix(f"{RAW_LOG_NOT_KEPT}: ")),
                             f"window {n + 1} capture failed: {reason}")

    def _submit(self, key: str) -> None:
        assert self._analyses is not None  # _run made them before any window
        self._analyses.submit(key, self._windows.path(key), self.s.request)

    def _collect(self, at_most: int | None) -> None:
        """Record the finished analyses; first wait until at most ``at_most`` are left (None: do not wait)."""
        for key, outcome in self._analyses.finished(at_most) if self._analyses is not None else ():
            if isinstance(outcome, Exception):
                self._unfinished(key, outcome)
            else:
                self._record(key, outcome)

    def _unfinished(self, key: str, error: Exception) -> None:
        """A window whose analysis did not complete (its worker died): left unfiled, so that a restart (or acq analyze
        of the folder) analyses it; filed "not analysed", it was never analysed again (the trial: SIGTERM killed
        the worker, "worker failed: BrokenProcessPool", and the window's K was lost for good)."""
        self.status.unfinished += 1
        number = self._windows.number(key) + 1
        self.status.message = (f"window {number}: its analysis did not complete ({type(error).__name__}) — left "
                               "unfiled: a restart analyses it")
        self._show()

    def _mark(self, key: str, verdict: str, reason: str, kind: str | None = None) -> None:
        self._record(key, marked_file(self._windows.path(key), self.s.request, verdict, reason), kind)

    def _record(self, key: str, outcome: Outcome, kind: str | None = None) -> None:
        """Catalogue one window (``kind``: how it counts when not by its verdict, :meth:`MonitorStatus.count`) — or,
        while the catalogue is out of reach, keep it waiting (:class:`FilingQueue`) — and file those waiting."""
        self._filed_now(self._catalogue.filing.file(Waiting(key, outcome, kind)))

    def _flush(self, force: bool = False) -> None:
        """File the windows waiting for the catalogue, if it is back (``force``: without waiting for the backoff)."""
        if self._catalogue.filing.waiting:
            self._filed_now(self._catalogue.filing.flush(force))

    def _filed_now(self, filed: list[Waiting]) -> None:
        for window in filed:
            self._filed_one(window)
        st, filing = self.status, self._catalogue.filing
        if filing.notes:  # a window that waited, kept out by a later analysis of it
            st.message = "; ".join(filing.notes)
            filing.notes.clear()
            self._show()
        if (st.catalogue_down_since, st.waiting) != (filing.down_since_utc, len(filing.waiting)):
            st.catalogue_down_since, st.waiting = filing.down_since_utc, len(filing.waiting)
            st.catalogue_problem = filing.problem
            self._show()

    def _filed_one(self, window: Waiting) -> None:
        """A window just filed: count it, update the trend, the alarm and the figures, apply retention."""
        key = window.key
        self._filed += 1
        self.status.count(window.outcome, window.kind, earlier=key in self._earlier)
        verdict = (window.outcome.doc or {}).get("quality", {}).get("verdict")
        self._windows.done(key, refused_as_damaged(self._windows.path(key), window.outcome.error, verdict))
        self._alarm.unjudged.append(key)
        try:
            trend = self._catalogue.trend()
        except self._catalogue.catalogue.errors as e:  # the server went away right after the write: judged once back
            if not self._catalogue.filing.lost_connection(e):
                raise
            return
        self._alarm.judge_unjudged(trend)
        self._alarms.reap(wait=False)  # an alarm command of an earlier window that ended meanwhile (--fast: no waits)
        self._retain(trend)
        self._show()

    def _alarm_problem(self, what: str) -> None:
        """Report what went wrong with an --on-alarm command in the status line and the final summary."""
        self.status.alarm_command_failure = what
        self.status.message = f"{what}: {self.s.on_alarm}"
        self._show()

    # ---- retention and disk ----------------------------------------------------------------------------
    def _retain(self, trend: Trend) -> None:
        self._windows.retain(trend)
        self.status.disk_bytes = self._windows.disk_bytes()
        self.status.damaged_kept = self._windows.refused()

    def _room_for_window(self) -> bool:
        if self.s.max_disk_bytes is None:
            return True
        fits, copied_deleted = self._windows.make_room(self._size, self.s.max_disk_bytes)
        self.status.copied_deleted += copied_deleted
        self.status.disk_bytes = self._windows.disk_bytes()
        return fits

    def _storage_failed(self, n: int, cause: str, what: str) -> None:
        """Window ``n`` was lost to the storage (``what`` says how): the next window is tried once retention made room
        (:meth:`FolderWindows.room_on_disk`); a second in a row stops the monitor (exit 1)."""
        if self._storage.failed(cause):
            self._failure = n + 1
            self.status.message = f"{what} — the second in a row: the monitor stops"
        else:
            self.status.message = f"{what} — the next window is tried once room is made; a second failure stops"
            self._collect(at_most=0)  # the analyses under way filed: retention may delete their windows for the room
        self._show()

    # ---- resume after a crash --------------------------------------------------------------------------
    def _resume(self, windows: list[Entry], from_spool: list[str]) -> int:
        """Mark or analyse the windows a previous run left (``windows``: its windows in the catalogue; ``from_spool``:
        those just filed from the spool, their alarm still to judge); return the next window's number."""
        self._alarm.unjudged += from_spool
        windows = sorted(windows, key=lambda e: int(e.tags[WINDOW_TAG]))
        known = {e.session_id: e for e in windows if e.joint == self.s.bench.joint}  # the same read, this joint's
        self._clock = MachineClock.resumed(windows, self.s.every_s)
        numbers = [int(e.tags[WINDOW_TAG]) for e in known.values()]
        self.status.earlier_filed = len(known)
        self._resumed(numbers)
        # an alarm raised before the restart goes on: its command is not run again for the same episode (a power cut
        # in alarm announced it once more and counted it twice — the third trial)
        trend = self._catalogue.trend() if known else None
        spooled = self._catalogue.alarm_before_spool
        before = spooled if spooled is not None else trend is not None and trend.alarm
        self._alarm.active = bool(known) and before
        if trend is not None and self._alarm.unjudged:  # windows filed from the spool: an alarm in them was never raised
            self._alarm.judge_unjudged(trend)
        for found in leftovers(self.s.out_dir, self._catalogue.monitor_id, known, self._catalogue.catalogue):
            self._windows.add(found.files)
            if found.files.copied:
                continue  # another monitor's: retention's only
            key = found.files.key
            numbers.append(found.files.index)
            if not found.unfiled:
                continue
            self._earlier.add(key)
            if found.interrupted is not None:
                self._mark(key, "interrupted", found.interrupted)
            else:
                self._submit(key)
        trend = self._catalogue.trend()
        self._retain(trend)
        self._collect(at_most=0)
        self._resumed(numbers)
        if numbers:  # the resumed trend's figures (last K, baseline, state) from the first status line on
            self._alarm.judge(self._catalogue.trend(), "")
            self._show()
        return max(numbers, default=-1) + 1

    def _resumed(self, numbers: list[int]) -> None:
        """The folder's windows (``numbers``) in the status: their count, and machine time from the end of the last
        (the first status line of a restart said "0 s", then jumped)."""
        self.status.resumed = len(set(numbers))
        if numbers:
            self.status.machine_time_s = self._clock.at(max(numbers)) + self.s.window_s

    # ---- time, signals, display ----------------------------------------------------------------------
    def _wait_until(self, deadline: float) -> None:
        while self._stop is None and time.monotonic() < deadline:
            self._collect(at_most=None)
            self._flush()
            self._alarms.reap(wait=False)
            time.sleep(min(0.2, max(deadline - time.monotonic(), 0.0)))

    def _signals(self) -> AbstractContextManager[None]:
        """Ctrl-C / SIGTERM end the monitor cleanly (a second one quits at once: acq check repairs the window)."""
        return stop_on_signals(self.request_stop)

    def _show(self) -> None:
        if self.on_status is not None:
            self.on_status(self.status)

