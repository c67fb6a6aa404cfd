"""Condition monitoring: capture windows of a running machine, identify each, trend K, raise the alarm.

A loop around the parts acq has (design §11): every ``every_s`` the recorder captures a window of
``window_s`` as an ordinary crash-safe session, passively (``[drive] motion = "external"``: no motion
command); a worker process analyses it while capture goes on (at most ``jobs`` running and one waiting:
a window beyond that is not analysed and says so — back-pressure, never an unbounded queue); the
outcome goes into the catalogue (:mod:`acq.monitoring.catalogue`, the batch's record of an outcome); the trend
(:mod:`acq.monitoring.trend`: baseline, threshold and EWMA rules) judges it; on entering alarm ``on_alarm`` runs
through the shell (``sh -c``, in the background) with ``ACQ_JOINT``, ``ACQ_K``, ``ACQ_BASELINE_K``,
``ACQ_CHANGE_PCT``, ``ACQ_SESSION`` in its environment; a command that fails is reported
(:attr:`MonitorStatus.alarm_command_failure`).

Each window is judged for excitation (:mod:`acq.monitoring.window_judge`): a window that does not excite is catalogued
with verdict ``not excited`` and the reason, without K. Windows are numbered (session tag ``monitor_window``) and
placed in machine time (``monitor_elapsed_s`` = number × ``every_s``); a restart after a crash resumes
the numbering, analyses the windows left unanalysed and marks a window whose capture was cut
``interrupted`` (not counted); it refuses a folder whose windows were captured with another bench or ``--window``
(:mod:`acq.monitoring.window_bench`) or judged by other alarm rules. In ``fast`` mode (simulated benches) machine
time is simulated: the loop does not sleep, and waits for the analysis instead of skipping (no real time passes
meanwhile).
"""

from __future__ import annotations

import math
import subprocess
import time
from collections.abc import Callable
from concurrent.futures import Future
from contextlib import AbstractContextManager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from acq.environment import user_environment
from acq.monitoring.batch import CATALOGUE_NAME, analysis_executor, session_meta
from acq.monitoring.catalogue import Catalogue, Entry, Outcome
from acq.monitoring.catalogue_backends import is_url
from acq.monitoring.folder_lock import folder_lock
from acq.monitoring.monitor_scope import (IDENTITY_FILE, MONITOR_TAG, WINDOW_TAG, check_user_tags, monitor_identity,
                                          own_windows)
from acq.monitoring.retention import WindowFiles, delete, folder_bytes, make_room, to_delete
from acq.monitoring.trend import ELAPSED_TAG, RULE_TAGS, AlarmRules, Trend, alarm_onsets, compute_trend, filed_rules
from acq.monitoring.window_bench import FACT_TAGS, differences, window_facts
from acq.monitoring.window_judge import analyse_window, excites, marked
from acq.offline.analyze import sha256_of
from acq.recording.recorder import Recorder, stop_on_signals
from acq.recording.reader import load
from acq.recording.repair import repair
from acqcore.errors import EXIT_INTERRUPTED, ConfigError
from analysis import AnalysisRequest
from drivers.config import Bench
from drivers.registry import open_bench

#: How long the ending monitor waits for an alarm command still running (a mail or a webhook takes seconds).
_ALARM_WAIT_S = 30.0
#: The exit codes POSIX shells give themselves (XCU 2.8.2): the command was not found / could not be executed.
_SHELL_EXITS = {127: "command not found", 126: "not executable"}
#: Expected window size = this × the data's raw size (HDF5 chunks, block tables, events): measured 1.1…1.2.
_SIZE_MARGIN = 1.5


@dataclass(frozen=True)
class MonitorSettings:
    """What ``acq monitor`` was asked for (SI units; sizes in bytes)."""

    bench: Bench
    out_dir: Path
    window_s: float
    every_s: float
    for_s: float | None = None
    on_alarm: str | None = None
    keep: int = 10
    max_disk_bytes: int | None = None
    fast: bool = False
    jobs: int = 1
    baseline_windows: int = 5
    threshold_pct: float = 10.0
    ewma_lambda: float = 0.2
    # a robot program excites the joint only in parts: the default request averages only the segments that excite
    # (analysis.segments) where acq did not command the motion — as acq analyze of a window does, under the same key
    request: AnalysisRequest = AnalysisRequest()
    # the catalogue every window is filed into (a SQLite file or a postgresql:// URL, shared with other monitors and
    # benches); None: out_dir/catalogue.sqlite
    catalogue: Path | str | None = None
    tags: dict[str, str | float] = field(default_factory=dict)  # --tag K=V, filed with every window (robot=r1)


@dataclass
class MonitorStatus:
    """The live figures of a monitor (shown by :func:`acq.ui.monitor_cli.status_table`)."""

    joint: str
    captured: int = 0  # in this run
    in_folder: int = 0  # windows the folder holds: those of earlier runs (a restart resumes them) and this run's
    resumed: int = 0  # of them, those of earlier runs
    excited: int = 0
    not_excited: int = 0
    analysed: int = 0
    skipped: int = 0  # captured, not analysed: the analysis fell behind
    not_captured: int = 0  # not captured: the disk budget would have been exceeded
    interrupted: int = 0
    alarms: int = 0
    alarm_command_failure: str | None = None  # the last --on-alarm command's problem: "alarm command failed: exit 1"
    machine_time_s: float = 0.0  # the start of the window being captured; its end once it is captured
    disk_bytes: int = 0
    last_K: float | None = None
    last_K_window: int | None = None  # the window last_K is of (not the last window when that had no K)
    last_K_ci: tuple[float | None, float | None] = (None, None)
    change_pct: float | None = None
    baseline_K: float | None = None
    state: str = "starting"
    baseline_warning: str | None = None  # the baseline's windows disagree beyond their intervals (Trend's)
    message: str = ""
    last_excited_fraction: float | None = None  # share of the last analysed window that excites the joint
    last_moves: tuple[dict[str, Any], ...] = ()  # its moves: index, start_s, duration_s, peak_rad_s, excited
    excited_fraction_sum: float = 0.0  # over the windows judged for excitation (for the share of the program)
    excitation_judged: int = 0

    @property
    def program_excited_fraction(self) -> float | None:
        """Share of the program's windows (time) that excites the joint, over the windows judged so far."""
        return self.excited_fraction_sum / self.excitation_judged if self.excitation_judged else None


def expected_window_bytes(bench: Bench, window_s: float) -> int:
    """Bytes a window's session file needs at most: current (f8 per channel) and encoder (5 columns of 8 bytes)."""
    current = bench.daq.rate_hz * len(bench.daq.channels) * 8
    encoder = 5 * 8 / bench.drive.period_s
    return int(_SIZE_MARGIN * window_s * (current + encoder)) + 200_000


class Monitor:
    """The monitor loop; :meth:`run` returns the exit code (3 when the last state is alarm, else 0)."""

    def __init__(self, settings: MonitorSettings, on_status: Callable[[MonitorStatus], None] | None = None) -> None:
        if settings.every_s < settings.window_s:
            raise ConfigError(f"--every {settings.every_s:g}: must be at least --window {settings.window_s:g} s")
        self.s = settings
        self.status = MonitorStatus(settings.bench.joint)
        self.on_status = on_status
        self._stop: str | None = None
        self._recorder: Recorder | None = None
        self._windows: dict[str, WindowFiles] = {}  # by session id (a moved folder is still the same monitor)
        self._pending: dict[Future[Outcome], str] = {}
        self._alarm_procs: list[subprocess.Popen[bytes]] = []
        self._in_alarm = False
        self._filed = 0  # catalogue rows written by this run
        self._size = expected_window_bytes(settings.bench, settings.window_s)
        # filed with every window: acq trend / fleet / view --trend of these windows judge them by the same rules
        self._rules = AlarmRules(settings.baseline_windows, settings.threshold_pct, settings.ewma_lambda)
        check_user_tags(settings.tags, (WINDOW_TAG, ELAPSED_TAG, *RULE_TAGS.values(), *FACT_TAGS))
        self._catalogue_location = settings.catalogue or settings.out_dir / CATALOGUE_NAME
        # windows filed before monitors had an identity are this monitor's only in its own folder's catalogue
        self._legacy = not is_url(self._catalogue_location) and \
            Path(self._catalogue_location).resolve() == (settings.out_dir / CATALOGUE_NAME).resolve()
        self._id = ""  # the monitor's identity (monitor_scope), read or made in its folder when it runs
        # the baseline's windows are kept whatever the budget (retention protects them), and the next window must fit
        # beside them: a budget of fewer skipped every window after the first ones, the alarm unseen (the second trial)
        need = (settings.baseline_windows + 1) * self._size
        if settings.max_disk_bytes is not None and settings.max_disk_bytes < need:
            daq, drive = settings.bench.daq, settings.bench.drive
            raise ConfigError(f"--max-disk {settings.max_disk_bytes / 1e6:g} MB: the {settings.baseline_windows} "
                              f"baseline windows acq keeps and the next one, {settings.window_s:g} s each, need "
                              f"{math.ceil(need / 1e5) / 10:g} MB ({math.ceil(self._size / 1e5) / 10:g} MB a window: "
                              f"current {daq.rate_hz:g} Hz × {len(daq.channels)} channel(s), encoder "
                              f"{1 / drive.period_s:g} Hz, with the files' overhead) — raise --max-disk, shorten "
                              "--window or lower --baseline-windows")

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
        own = None if self.s.catalogue is not None else self.s.out_dir / CATALOGUE_NAME
        made = [p for p in (own, self.s.out_dir / IDENTITY_FILE) if p is not None and not p.exists()]
        try:
            self._run()
        finally:
            if made and not self._filed:  # devices that failed to open: no empty catalogue left behind
                for path in made:
                    for left in (path, *(path.with_name(path.name + end) for end in ("-wal", "-shm", "-journal"))):
                        left.unlink(missing_ok=True)
        if self._stop is not None:
            return EXIT_INTERRUPTED
        return 3 if self._in_alarm else 0

    def _run(self) -> None:
        with folder_lock(self.s.out_dir), Catalogue(self._catalogue_location) as catalogue, \
                analysis_executor(self.s.jobs, None) as pool, self._signals():
            self.catalogue = catalogue
            self._id = monitor_identity(self.s.out_dir)
            first = self._resume(pool)
            wall0 = time.monotonic()
            n = first
            while self._stop is None and (self.s.for_s is None or (n - first) * self.s.every_s < self.s.for_s):
                if not self.s.fast:
                    self._wait_until(wall0 + (n - first) * self.s.every_s)
                    if self._stop is not None:
                        break
                self._window(n, pool)
                n += 1
            self._collect(at_most=0)
            self._reap_alarms(wait=True)
            self.status.state = "alarm" if self._in_alarm else self.status.state
            self.status.message = f"stopped: {self._stop}" if self._stop else "done"
            self._show()

    def _window(self, n: int, pool: Any) -> None:
        """Capture window ``n`` (if the disk budget allows) and hand it to the pool (if it keeps up)."""
        self.status.machine_time_s = n * self.s.every_s
        if not self._room_for_window():
            self.status.not_captured += 1
            self.status.message = f"window {n} not captured: the disk budget would be exceeded"
            self._show()
            return
        bench = self.s.bench
        if bench.sim is not None:  # a simulated machine runs on machine time (program phase, wear, noise)
            bench = bench.model_copy(update={"sim": bench.sim.model_copy(update={"elapsed_s": n * self.s.every_s})})
        current, drive = open_bench(bench, fast=self.s.fast)
        machine = getattr(drive, "machine_tags", dict)()  # what the machine says of the window (a robot's payload)
        recorder = Recorder(bench, None, current, drive, self.s.out_dir, self.s.window_s,
                            tags={**self.s.tags, **machine, WINDOW_TAG: n, ELAPSED_TAG: n * self.s.every_s,
                                  MONITOR_TAG: self._id, **self._rules.as_tags(),
                                  **window_facts(self.s.bench, self.s.window_s)})
        self._recorder = recorder
        if self._stop is not None:
            recorder.request_stop(self._stop)
        try:
            result = recorder.run()
        finally:
            self._recorder = None
        # a Ctrl-C the recorder's handler took once both streams were complete (its shutdown) left the window complete:
        # the monitor ends all the same (it went on capturing, the Ctrl-C lost: 1 of 30 runs, SIGINT 0.1…10 s in)
        self._stop = self._stop or recorder.stop_request
        key = str(load(result.path).meta.session_id)
        self._windows[key] = WindowFiles(n, result.path, False, False, key)
        self.status.in_folder += 1
        self._size = max(self._size, int(_SIZE_MARGIN * result.path.stat().st_size))
        if result.status != "complete":
            self._mark(key, "interrupted", f"window capture {result.status}: {result.stop_reason}")
            if result.status == "interrupted":  # Ctrl-C / SIGTERM reached the recorder's handler: the monitor ends
                self._stop = self._stop or result.stop_reason
            return
        self.status.captured += 1
        self.status.machine_time_s = n * self.s.every_s + self.s.window_s
        self._collect(at_most=self.s.jobs - 1 if self.s.fast else None)
        if len(self._pending) > self.s.jobs:  # jobs running and one waiting: no more (back-pressure)
            self._mark(key, "not analysed", f"the analysis fell behind the capture ({len(self._pending)} windows "
                                            "waiting): this window was skipped")
            self.status.skipped += 1
            return
        self._submit(pool, key)
        self._show()

    def _submit(self, pool: Any, key: str) -> None:
        path = self._windows[key].path
        self._pending[pool.submit(analyse_window, str(path.resolve()), sha256_of(path), self.s.request)] = key

    def _collect(self, at_most: int | None) -> None:
        """Record the finished analyses; first wait until at most ``at_most`` are left (None: do not wait)."""
        while self._pending:
            done = [f for f in self._pending if f.done()]
            if not done and at_most is not None and len(self._pending) > at_most:
                next(iter(self._pending)).exception()  # wait for the oldest
                continue
            if not done:
                break
            for future in done:
                key = self._pending.pop(future)
                try:
                    outcome = future.result()
                except Exception as e:  # noqa: BLE001 - the worker itself died: the window is marked, not lost
                    self._mark(key, "not analysed", f"worker failed: {type(e).__name__}: {e}")
                    continue
                self._record(key, outcome)

    def _mark(self, key: str, verdict: str, reason: str) -> None:
        path = self._windows[key].path
        try:
            meta = session_meta(load(path))
        except Exception:  # noqa: BLE001 - a window too broken to read is still marked
            meta = {}
        self._record(key, marked(str(path.resolve()), sha256_of(path), self.s.request, meta, verdict, [reason]))

    def _record(self, key: str, outcome: Outcome) -> None:
        """Catalogue one window, update the trend, the alarm and the figures, apply retention."""
        self.catalogue.record(outcome)
        self._filed += 1
        verdict = (outcome.doc or {}).get("quality", {}).get("verdict")
        self.status.analysed += verdict not in ("not analysed", "interrupted")
        self.status.excited += excites(outcome.doc)
        self.status.not_excited += verdict == "not excited"
        self.status.interrupted += verdict == "interrupted"
        self._excitation(outcome, verdict)
        self._windows[key] = replace(self._windows[key], done=True)
        trend = self._trend()
        self._judge(trend, key)
        self._reap_alarms(wait=False)  # an alarm command of an earlier window that ended meanwhile (--fast: no waits)
        self._retain(trend)
        self._show()

    def _excitation(self, outcome: Outcome, verdict: str | None) -> None:
        """Which share of the window and which moves excite (segment selection); a window the joint did not
        travel in excites nowhere."""
        excitation = (outcome.doc or {}).get("excitation")
        if excitation is None and verdict != "not excited":
            return
        st = self.status
        st.last_excited_fraction = excitation["excited_fraction"] if excitation else 0.0
        st.last_moves = tuple(excitation["moves"]) if excitation else ()
        st.excited_fraction_sum += st.last_excited_fraction
        st.excitation_judged += 1

    def _own_windows(self) -> list[Entry]:
        """This monitor's windows in the catalogue, oldest first — never another monitor's of a joint of the same name
        in a shared catalogue (its windows without an identity only in the catalogue of its own folder)."""
        windows = [e for e in self.catalogue.entries(self.s.bench.joint) if WINDOW_TAG in e.tags]
        return own_windows(windows, self._id, legacy=self._legacy)

    def _trend(self) -> Trend:
        entries = self._own_windows()
        if not entries:
            return Trend(self.s.bench.joint, [], None, "no windows yet", None, self.s.threshold_pct, self.s.ewma_lambda)
        return compute_trend(self.s.bench.joint, entries, baseline_sessions=self.s.baseline_windows,
                             threshold_pct=self.s.threshold_pct, ewma_lambda=self.s.ewma_lambda)

    def _judge(self, trend: Trend, key: str) -> None:
        st = self.status
        st.baseline_K = trend.baseline_K_Nm_per_rad
        with_k = [p for p in trend.points if p.state in ("before baseline", "baseline", "ok", "alarm")]
        if with_k:  # while the baseline is learned too: a person watching wants to see K from the first good window
            last = with_k[-1]
            st.last_K, st.last_K_ci, st.change_pct = last.entry.K_Nm_per_rad, last.entry.K_ci95, last.change_pct
            st.last_K_window = last.entry.tags.get(WINDOW_TAG)
        st.baseline_warning = trend.baseline_warning
        st.state = "alarm" if trend.alarm else ("ok" if trend.judged else
                                                "baseline" if trend.baseline_K_Nm_per_rad else "learning baseline")
        point = next((p for p in trend.points if p.entry.session_id == key), None)
        if point is None or point.state not in ("ok", "alarm"):
            return
        if point.state == "alarm" and not self._in_alarm:
            st.alarms += 1
            self._run_on_alarm(point.entry, trend)
        elif point.state == "alarm":  # still in alarm: the latest K (the one that raised it stays in the catalogue)
            st.message = _alarm_message(point.entry)
        self._in_alarm = point.state == "alarm"

    def _run_on_alarm(self, entry: Entry, trend: Trend) -> None:
        """Start ``on_alarm`` through ``sh -c`` (as cron, systemd and git hooks do: pipes, redirections and ``$ACQ_K``
        work; the values reach it only as environment variables, never in the command's text) and do not wait for it:
        a slow mail or webhook must not stop the capture; :meth:`_reap_alarms` reports how it ended."""
        self.status.message = _alarm_message(entry)
        if not self.s.on_alarm:
            return
        env = {**user_environment(), "ACQ_JOINT": trend.joint, "ACQ_K": f"{entry.K_Nm_per_rad:.6g}",
               "ACQ_BASELINE_K": f"{trend.baseline_K_Nm_per_rad:.6g}", "ACQ_SESSION": entry.path,
               "ACQ_CHANGE_PCT": f"{100 * (entry.K_Nm_per_rad / trend.baseline_K_Nm_per_rad - 1):.3g}"}  # type: ignore
        try:
            # a session of its own: the Ctrl-C that stops the monitor must not kill a mail or webhook mid-send
            self._alarm_procs.append(subprocess.Popen(["/bin/sh", "-c", self.s.on_alarm], env=env,
                                                      stdin=subprocess.DEVNULL, start_new_session=True))
        except OSError as e:
            self._alarm_failed(f"cannot start /bin/sh: {e.strerror or e}")
        self._reap_alarms(wait=False)

    def _reap_alarms(self, wait: bool) -> None:
        """Collect the alarm commands that ended and report those that failed; with ``wait`` (the monitor ends) give
        them together up to :data:`_ALARM_WAIT_S` and report one still running (it is left running: it may be
        mid-send)."""
        deadline = time.monotonic() + _ALARM_WAIT_S  # one for all: N slow commands must not hold the exit N × 30 s
        for proc in list(self._alarm_procs):
            if wait:
                try:
                    proc.wait(timeout=max(0.0, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    self._alarm_problem(f"alarm command still running after {_ALARM_WAIT_S:g} s when the monitor "
                                        f"ended (pid {proc.pid}, left running)")
                    self._alarm_procs.remove(proc)
                    continue
            code = proc.poll()
            if code is None:
                continue
            self._alarm_procs.remove(proc)
            if code > 0:
                self._alarm_failed(f"exit {code}" + (f" ({_SHELL_EXITS[code]})" if code in _SHELL_EXITS else ""))
            elif code < 0:
                self._alarm_failed(f"killed by signal {-code}")

    def _alarm_failed(self, why: str) -> None:
        """Report a failed --on-alarm command (exit ≠ 0, a signal, cannot start) in the status line and summary."""
        self._alarm_problem(f"alarm command failed: {why}")

    def _alarm_problem(self, what: str) -> None:
        """Report what went wrong with an --on-alarm command in the status line and the final summary."""
        self.status.alarm_command_failure = what
        self.status.message = f"{what}: {self.s.on_alarm}"
        self._show()

    # ---- retention and disk ----------------------------------------------------------------------------
    def _retain(self, trend: Trend) -> None:
        # "before baseline": good windows that will make the baseline once there are enough of them. Of an alarm only
        # the window that raised it is kept: a joint that stays in alarm for a weekend grew the folder by every window
        # (or, under --max-disk, stopped its capture once the budget was full); the catalogue keeps every K, and --keep
        # the latest raw windows
        protected = alarm_onsets(trend) | {p.entry.session_id for p in trend.points
                                           if p.state in ("baseline", "before baseline")}
        for key, w in self._windows.items():
            if (key in protected) != w.protected:
                self._windows[key] = replace(w, protected=key in protected)
        for w in to_delete(self._windows.values(), self.s.keep):
            delete(w)
            del self._windows[w.key]
        self.status.disk_bytes = folder_bytes(self.s.out_dir)

    def _room_for_window(self) -> bool:
        if self.s.max_disk_bytes is None:
            return True
        victims, fits = make_room(self._windows.values(), self.s.out_dir, self._size, self.s.max_disk_bytes)
        if fits:
            for w in victims:
                delete(w)
                del self._windows[w.key]
        self.status.disk_bytes = folder_bytes(self.s.out_dir)
        return fits

    # ---- resume after a crash --------------------------------------------------------------------------
    def _resume(self, pool: Any) -> int:
        """Mark or analyse the windows a previous run left; return the next window's number."""
        windows = sorted(own_windows((e for e in self.catalogue.entries() if WINDOW_TAG in e.tags), self._id,
                                     legacy=self._legacy), key=lambda e: int(e.tags[WINDOW_TAG]))
        known = {e.session_id: e for e in windows if e.joint == self.s.bench.joint}  # the same read, this joint's
        changed = differences(windows, self.s.bench, self.s.window_s)
        if changed:
            # K of another measurement chain, scale or window length would join the trend as if the joint had changed
            raise ConfigError(f"{self.s.out_dir}: its windows were captured with another bench or window "
                              f"({'; '.join(changed)}): their K is not comparable — start a new --out (or resume "
                              "with the same bench and --window)")
        filed = filed_rules(list(known.values()))
        if filed is not None and filed.as_tags() != self._rules.as_tags():
            # other rules midway re-baselined on windows judged before, the alarm cleared silently (the second trial)
            raise ConfigError(f"{self.s.out_dir}: its windows were judged with --baseline-windows "
                              f"{filed.baseline_sessions} --threshold-pct {filed.threshold_pct:g} --ewma-lambda "
                              f"{filed.ewma_lambda:g}: resume with the same, or start a new --out")
        numbers = [int(e.tags[WINDOW_TAG]) for e in known.values()]
        self._resumed(numbers)
        # an alarm raised before the restart goes on: its command is not run again for the same episode (a power cut
        # in alarm announced it once more and counted it twice — the third trial)
        self._in_alarm = bool(known) and self._trend().alarm
        for path in sorted(self.s.out_dir.glob("*.h5")):
            try:
                session = load(path)
            except Exception:  # noqa: BLE001 - not a readable session: not ours to judge
                continue
            if WINDOW_TAG not in session.tags:
                continue
            n, key = int(session.tags[WINDOW_TAG]), str(session.meta.session_id)
            numbers.append(n)
            self._windows[key] = WindowFiles(n, path, key in known, False, key)
            if key in known:
                continue
            if session.status == "recording":
                repair(path, "the monitor stopped during this window's capture (found on restart)")
                self._mark(key, "interrupted", "the monitor stopped during this window's capture (found on restart)")
            elif session.status != "complete":
                self._mark(key, "interrupted", f"window capture {session.status}: {session.meta.stop_reason}")
            else:
                self._submit(pool, key)
        trend = self._trend()
        self._retain(trend)
        self._collect(at_most=0)
        self._resumed(numbers)
        if numbers:  # the resumed trend's figures (last K, baseline, state) from the first status line on
            self._judge(self._trend(), "")
            self._show()
        return max(numbers, default=-1) + 1

    def _resumed(self, numbers: list[int]) -> None:
        """The folder's windows (``numbers``) in the status: their count, and machine time from the end of the last
        (the first status line of a restart said "0 s", then jumped)."""
        self.status.in_folder = self.status.resumed = len(set(numbers))
        if numbers:
            self.status.machine_time_s = max(numbers) * self.s.every_s + self.s.window_s

    # ---- time, signals, display ----------------------------------------------------------------------
    def _wait_until(self, deadline: float) -> None:
        while self._stop is None and time.monotonic() < deadline:
            self._collect(at_most=None)
            self._reap_alarms(wait=False)
            time.sleep(min(0.2, max(deadline - time.monotonic(), 0.0)))

    def _signals(self) -> AbstractContextManager[None]:
        """Ctrl-C / SIGTERM end the monitor cleanly (a second one quits at once: acq check repairs the window)."""
        return stop_on_signals(self.request_stop)

    def _show(self) -> None:
        if self.on_status is not None:
            self.on_status(self.status)


def _alarm_message(entry: Entry) -> str:
    """The status line of a window in alarm: its K, its number and its file."""
    window = f" in window {entry.tags[WINDOW_TAG]}" if WINDOW_TAG in entry.tags else ""
    return f"ALARM: K {entry.K_Nm_per_rad:.1f} N·m/rad{window} ({entry.path})"

