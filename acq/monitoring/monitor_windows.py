"""The raw window files in a monitor's folder, and which of them go (retention, the disk budget).

The monitor loop (:mod:`acq.monitoring.monitor`) tells :class:`FolderWindows` of each window it captures, finds on a
restart or files; this keeps which are protected — the baseline's windows and the one that raised each alarm
(:func:`kept_windows`), and of another monitor's windows copied here those that monitor keeps
(:func:`copies_deletable`, by its rows in this catalogue) — and deletes by the rules of
:mod:`acq.monitoring.retention`; :func:`check_budget` refuses a ``--max-disk`` too small for the baseline.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from acq.monitoring.catalogue import Catalogue
from acq.monitoring.monitor_scope import own_windows
from acq.monitoring.monitor_status import MonitorSettings
from acq.monitoring.retention import WindowFiles, delete, folder_bytes, make_room, to_delete
from acq.monitoring.trend import Trend, alarm_onsets, compute_trend
from acqcore.errors import ConfigError


def check_budget(settings: MonitorSettings, window_bytes: int) -> None:
    """Refuse (:class:`ConfigError`) a ``--max-disk`` budget that cannot hold the baseline's windows and the next one,
    ``window_bytes`` each (the expected size of a window, bytes).

    The baseline's windows are kept whatever the budget (retention protects them), and the next window must fit beside
    them: a budget of fewer skipped every window after the first ones, the alarm unseen (the second trial)."""
    need = (settings.baseline_windows + 1) * window_bytes
    if settings.max_disk_bytes is not None and settings.max_disk_bytes < need:
        daq, drive = settings.bench.daq, settings.bench.drive
        raise ConfigError(f"--max-disk {settings.max_disk_bytes / 1e6:g} MB: the {settings.baseline_windows} "
                          f"baseline windows acq keeps and the next one, {settings.window_s:g} s each, need "
                          f"{math.ceil(need / 1e5) / 10:g} MB ({math.ceil(window_bytes / 1e5) / 10:g} MB a window: "
                          f"current {daq.rate_hz:g} Hz × {len(daq.channels)} channel(s), encoder "
                          f"{1 / drive.period_s:g} Hz, with the files' overhead) — raise --max-disk, shorten "
                          "--window or lower --baseline-windows")


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

    def done(self, key: str) -> None:
        """The window's catalogue row is written: retention may delete its raw files."""
        self._files[key] = replace(self._files[key], done=True)

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
