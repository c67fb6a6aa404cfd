"""The raw window files in a monitor's folder, and which of them go (retention, the disk budget).

The monitor loop (:mod:`acq.monitoring.monitor`) tells :class:`FolderWindows` of each window it captures, finds on a
restart or files; this keeps which are protected — the baseline's windows and the one that raised each alarm
(:func:`kept_windows`), those the analysis refused as damaged (:func:`refused_as_damaged`), and of another monitor's
windows copied here those that monitor keeps
(:func:`copies_deletable`, by its rows in this catalogue) — and deletes by the rules of
:mod:`acq.monitoring.retention`; :func:`check_budget` refuses a ``--max-disk`` too small for the baseline.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from acq.recording.reader import load
from acq.recording.room import bytes_to_record
from acq.recording.storage import free_bytes

from acq.monitoring.catalogue import Catalogue
from acq.monitoring.monitor_scope import own_windows
from acq.monitoring.monitor_status import MonitorSettings
from acq.monitoring.retention import WindowFiles, delete, folder_bytes, make_room, to_delete
from acq.monitoring.trend import Trend, alarm_onsets, compute_trend
from acqcore.errors import AcqError, ConfigError, StorageError

#: Storage failures in a row after which a monitor stops (exit 1): after the first, retention makes room and the next
#: window is tried; a second shows that the room is not there (the trial's monitor lost 8 windows of 12 on a full
#: disk, exit 0, "disk full" never shown).
STORAGE_FAILURES_TO_STOP = 2


def check_budget(settings: MonitorSettings, window_bytes: int) -> None:
    """Refuse (:class:`ConfigError`) a ``--max-disk`` budget that cannot hold the baseline's windows and the next one,
    ``window_bytes`` each (the expected size of a window, bytes).

    The baseline's windows are kept whatever the budget (retention protects them), and the next window must fit beside
    them: a budget of fewer skipped every window after the first ones, the alarm unseen (the second trial)."""
    need = (settings.baseline_windows + 1) * window_bytes
    if settings.max_disk_bytes is not None:
        _check_disk_holds(settings.out_dir, settings.max_disk_bytes)
    if settings.max_disk_bytes is not None and settings.max_disk_bytes < need:
        daq, drive = settings.bench.daq, settings.bench.drive
        raise ConfigError(f"--max-disk {settings.max_disk_bytes / 1e6:g} MB: the {settings.baseline_windows} "
                          f"baseline windows acq keeps and the next one, {settings.window_s:g} s each, need "
                          f"{math.ceil(need / 1e5) / 10:g} MB ({math.ceil(window_bytes / 1e5) / 10:g} MB a window: "
                          f"current {daq.rate_hz:g} Hz × {len(daq.channels)} channel(s), encoder "
                          f"{1 / drive.period_s:g} Hz, with the files' overhead) — raise --max-disk, shorten "
                          "--window or lower --baseline-windows")


def _check_disk_holds(out_dir: Path, budget_bytes: int) -> None:
    """Refuse a ``--max-disk`` the file system cannot hold: more than its free space and what ``out_dir`` holds.

    Refused rather than warned of: the budget is the history the user asked to keep ("never exceeded"), and on a disk
    that is full first the monitor deletes windows for the disk's sake and then stops, so the number given would be
    a promise acq cannot keep (the trial: --max-disk 100MB on a 6 MB tmpfs)."""
    existing = next(f for f in (out_dir, *out_dir.parents) if f.exists())
    room = free_bytes(existing) + folder_bytes(out_dir)
    if budget_bytes > room:
        held = folder_bytes(out_dir)
        raise ConfigError(f"--max-disk {budget_bytes / 1e6:g} MB: the file system of {out_dir} has "
                          f"{free_bytes(existing) / 1e6:.1f} MB free" + (f" and the folder holds {held / 1e6:.1f} MB"
                                                                        if held else "")
                          + f" — the disk would be full before the budget: give --max-disk {math.floor(room / 1e5) / 10:g}MB "
                          "or less, or free space there")


class StorageFailures:
    """The windows in a row whose capture the folder's storage refused (disk full, I/O error, read-only)."""

    def __init__(self, out_dir: Path) -> None:
        self.out_dir = out_dir
        self.in_a_row = 0
        self.cause = ""

    def succeeded(self) -> None:
        """A window was captured whole."""
        self.in_a_row = 0

    def failed(self, cause: str) -> bool:
        """A window failed for ``cause`` ("disk full"); True when the monitor must stop
        (:data:`STORAGE_FAILURES_TO_STOP` in a row)."""
        self.in_a_row += 1
        self.cause = cause
        return self.in_a_row >= STORAGE_FAILURES_TO_STOP

    def error(self, last_window: int, kept: int) -> StorageError:
        """The monitor's one line (exit 1): "disk full: <folder> — monitor stopped after window N (K windows kept)",
        N the last window tried (from 1), K the windows of this monitor its catalogue holds analysed (not those it
        holds as cut)."""
        return StorageError(f"{self.cause}: {self.out_dir} — monitor stopped after window {last_window} "
                            f"({kept} window{'s' if kept != 1 else ''} kept)")


def write_cause(stop_reason: str) -> str:
    """The cause of a recording that failed because a write failed: its reason starts with the writer's
    :class:`StorageError`, "<cause>: <file> — <s> s kept" (:func:`acq.recording.storage.storage_error`)."""
    return stop_reason.split(": ", 1)[0]


class FolderWindows:
    """The raw files of the windows in a monitor's ``out_dir`` (its own and another monitor's copied here), by
    session id (a moved folder is still the same monitor); this monitor's done windows beyond the last ``keep`` go."""

    def __init__(self, out_dir: Path, keep: int) -> None:
        self.out_dir = out_dir
        self.keep = keep
        self._files: dict[str, WindowFiles] = {}

    def add(self, window: WindowFiles) -> None:
        """A window captured, or found in the folder on a restart (:attr:`WindowFiles.key`: its session id)."""
        self._files[window.key] = window

    def path(self, key: str) -> Path:
        """The session file of the window of session id ``key``."""
        return self._files[key].path

    def number(self, key: str) -> int:
        """The number of the window of session id ``key`` (from 0)."""
        return self._files[key].index

    def done(self, key: str, refused: bool = False) -> None:
        """The window's catalogue row is written: retention may delete its raw files (``refused``: its analysis
        refused it as damaged, :func:`refused_as_damaged`; kept)."""
        self._files[key] = replace(self._files[key], done=True, refused=refused)

    def refused(self) -> int:
        """How many of this monitor's windows are kept as refused for damage (:func:`refused_as_damaged`)."""
        return sum(w.refused for w in self._files.values())

    def kept_copies(self) -> int:
        """How many windows of another monitor copied here are its baseline or alarms (never deleted)."""
        return sum(w.copied and w.protected for w in self._files.values())

    def retain(self, trend: Trend) -> int:
        """Protect this monitor's windows ``trend`` keeps (:func:`kept_windows`), delete the raw files of those done
        and beyond ``keep``."""
        protected = kept_windows(trend)
        for key, w in self._files.items():
            if not w.copied and (key in protected) != w.protected:
                self._files[key] = replace(w, protected=key in protected)
        for w in to_delete(self._files.values(), self.keep):
            self._remove(w)

    def disk_bytes(self) -> int:
        """The size of the folder's files, bytes."""
        return folder_bytes(self.out_dir)

    def room_on_disk(self, window_bytes: int) -> tuple[bool, int, int]:
        """Whether a window of ``window_bytes`` fits on the folder's file system as the writer judges room, once
        windows are deleted as for the budget (:meth:`make_room`: the disk outranks ``keep`` as the budget does); the
        file system's free bytes then, and the bytes a window needs (:func:`acq.recording.room.bytes_to_record`)."""
        need = bytes_to_record(window_bytes)
        fits, _ = self.make_room(need, self.disk_bytes() + free_bytes(self.out_dir))
        return fits, free_bytes(self.out_dir), need

    def make_room(self, need_bytes: int, budget_bytes: int) -> tuple[bool, int]:
        """Whether ``need_bytes`` more fit in the folder's ``budget_bytes``, once the windows the budget takes
        (:func:`acq.monitoring.retention.make_room`) are deleted — only if they then fit; and how many of those
        deleted were another monitor's copied here."""
        victims, fits = make_room(self._files.values(), self.out_dir, need_bytes, budget_bytes)
        if not fits:
            return False, 0
        for w in victims:
            self._remove(w)
        return True, sum(w.copied for w in victims)

    def _remove(self, window: WindowFiles) -> None:
        delete(window)
        del self._files[window.key]


def refused_as_damaged(path: Path, error: str | None, verdict: str | None) -> bool:
    """Whether the window at ``path``, filed without a K — its analysis failed (``error``) or its capture was cut
    (``verdict`` interrupted: the monitor killed during it) — has a file that is damaged (``Session.damage``) or
    cannot be read as a session at all: retention keeps its raw file, the only copy of what it recorded and the
    evidence of the damage (a killed window found damaged on a restart was marked, then deleted by --keep). A window
    without a K for another reason (not excited, a write that failed on a sound disk) is not."""
    if error is None and verdict != "interrupted":
        return False
    try:
        return bool(load(path).damage)
    except (AcqError, OSError):
        return True


def kept_windows(trend: Trend) -> set[str]:
    """The session ids of a monitor's windows whose raw files retention never deletes: the baseline's, and the window
    that raised each alarm.

    "before baseline": good windows that will make the baseline once there are enough of them. Of an alarm only the
    window that raised it is kept: a joint that stays in alarm for a weekend grew the folder by every window (or, under
    --max-disk, stopped its capture once the budget was full); the catalogue keeps every K, and --keep the latest raw
    windows."""
    return alarm_onsets(trend) | {p.entry.session_id for p in trend.points if p.state in ("baseline", "before baseline")}


def copies_deletable(catalogue: Catalogue, monitor: str) -> set[str]:
    """The windows of another ``monitor`` (copied here) that it does not keep (:func:`kept_windows`), judged from
    its rows in ``catalogue`` by the rules it filed them with: only these may go for the budget. A copied window
    without a row here is not among them: nothing says it is not that monitor's baseline or alarm."""
    entries = own_windows(catalogue, monitor, unowned=False)
    deletable: set[str] = set()
    for joint in {e.joint for e in entries}:
        of_joint = [e for e in entries if e.joint == joint]
        # no rule given: compute_trend judges by the rules the windows were filed with (alarm_rules.rules_for)
        deletable |= {e.session_id for e in of_joint} - kept_windows(compute_trend(str(joint), of_joint))
    return deletable
