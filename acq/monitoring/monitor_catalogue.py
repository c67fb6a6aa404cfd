"""A monitor's catalogue: where it is, the monitor's identity bound to it, the monitor's windows in it and their trend.

Apart from the loop (:mod:`acq.monitoring.monitor`), which files into it: :meth:`MonitorCatalogue.opened` reads or
makes the folder's identity (:mod:`acq.monitoring.monitor_scope`), binds it to the catalogue (a restart's checks:
:mod:`acq.monitoring.monitor_restart`) and files first the windows a run left waiting in the spool while the
catalogue was out of reach (:mod:`acq.monitoring.catalogue_spool`); :meth:`MonitorCatalogue.trend` judges the
monitor's windows by its alarm rules (:mod:`acq.monitoring.trend`).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from acq.monitoring.alarm_rules import AlarmRules
from acq.monitoring.catalogue import Catalogue, Entry
from acq.monitoring.catalogue_backends import is_url
from acq.monitoring.catalogue_spool import SPOOL_NAME, FilingQueue
from acq.monitoring.monitor_restart import catalogue_text, check_comparable, open_bound
from acq.monitoring.monitor_scope import Identity, bound_identity, own_windows
from acq.monitoring.monitor_status import MonitorSettings
from acq.monitoring.session_outcome import CATALOGUE_NAME
from acq.monitoring.trend import Trend, compute_trend
from acqcore.errors import StorageError


class MonitorCatalogue:
    """The catalogue of the monitor of ``settings``, open as :attr:`catalogue` (with :attr:`filing`, the queue of the
    windows waiting for it) inside :meth:`opened`; ``rules``: the alarm rules its windows are filed with."""

    def __init__(self, settings: MonitorSettings, rules: AlarmRules) -> None:
        self.s = settings
        self.rules = rules
        self.location = settings.catalogue or settings.out_dir / CATALOGUE_NAME
        # windows filed before monitors had an identity are this monitor's only in its own folder's catalogue
        self.legacy = not is_url(self.location) and \
            Path(self.location).resolve() == (settings.out_dir / CATALOGUE_NAME).resolve()
        self.monitor_id = ""  # the monitor's identity (monitor_scope), read or made in its folder by opened()
        self.alarm_before_spool: bool | None = None  # the alarm state before the spool's windows were filed
        self.catalogue: Catalogue
        self.filing: FilingQueue

    @property
    def spool(self) -> Path:
        """The file that keeps the windows waiting for a catalogue out of reach (:mod:`acq.monitoring.catalogue_spool`)."""
        return self.s.out_dir / SPOOL_NAME

    @contextmanager
    def opened(self) -> Iterator[tuple[list[Entry], list[str]]]:
        """This folder's identity (a copied folder refused), bound to its catalogue (its windows filed elsewhere
        refused, or moved here with ``move_catalogue``; windows not comparable refused) and written; the catalogue
        open as :attr:`catalogue` inside; yields its windows in the catalogue and the keys of the windows filed from
        the spool, in filing order (their alarm still to judge). A refusal makes and writes nothing."""
        s = self.s
        identity: Identity = bound_identity(s.out_dir, new_identity=s.new_identity, moved=s.moved)
        self.monitor_id = identity.monitor_id
        self.catalogue, windows = open_bound(
            s.out_dir, identity, self.location, move=s.move_catalogue,
            own_catalogue=s.out_dir / CATALOGUE_NAME, legacy=self.legacy,
            check=lambda ws: check_comparable(s.out_dir, ws, s.bench, s.window_s, self.rules))
        with self.catalogue:
            self.filing = FilingQueue(self.catalogue, self.spool)
            from_spool: list[str] = []
            if self.filing.waiting:  # windows a run stopped while its catalogue was out of reach: filed first
                with suppress(*self.catalogue.errors):  # still out of reach: the flush below says so
                    self.alarm_before_spool = self.trend().alarm  # their alarm is judged on resuming, not assumed
                from_spool = [w.key for w in self.filing.flush(force=True)]
                if self.filing.waiting:
                    raise StorageError(f"{catalogue_text(self.location)}: {self.filing.problem} — "
                                       f"{len(self.filing.waiting)} windows wait in {self.filing.spool}")
                windows = self.own_windows(None)
            yield windows, from_spool

    def own_windows(self, joint: str | None) -> list[Entry]:
        """This monitor's windows in the catalogue (of ``joint``; None: any), oldest first (:func:`own_windows`)."""
        return own_windows(self.catalogue, self.monitor_id, joint, unowned=self.legacy)

    def trend(self) -> Trend:
        """The trend of this monitor's windows of its joint, judged by its alarm rules."""
        s = self.s
        entries = self.own_windows(s.bench.joint)
        if not entries:
            return Trend(s.bench.joint, [], None, "no windows yet", None, s.threshold_pct, s.ewma_lambda)
        return compute_trend(s.bench.joint, entries, baseline_sessions=s.baseline_windows,
                             threshold_pct=s.threshold_pct, ewma_lambda=s.ewma_lambda)
