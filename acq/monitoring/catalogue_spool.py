"""A monitor's windows on their way into a catalogue that may be out of reach for a while (a PostgreSQL server stopped
or restarted, the network down): filed in order as soon as it answers, kept meanwhile in memory and in a spool file
in the monitor's folder, so that a monitor stopped during the outage loses none of them — its next start files them.

The trial: ``pg_ctl stop -m fast`` under a running ``acq monitor --catalogue postgresql://…`` ended the monitor with
"acq: error: terminating connection due to administrator command", exit 1. A window is filed exactly once: a write
whose COMMIT reached the server before the connection broke is filed again on the next try, which the catalogue's
upsert (one row per session and request) makes the same row. A window that waited is not filed over an analysis of it
made later (``acq analyze`` of its file filed meanwhile, by a host that reached the catalogue): the later one is
kept and a note (:attr:`FilingQueue.notes`) says so.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from acq.monitoring.catalogue import Catalogue, Outcome
from acq.recording.storage import atomic_path
from acqcore.errors import ConfigError, StorageError

#: Name of the spool file in the monitor's folder (JSON lines: one window waiting for the catalogue each).
SPOOL_NAME = "catalogue-spool.jsonl"
#: The wait before the first reconnection, s, doubled after each failed one up to :data:`MAX_BACKOFF_S`: a restart
#: of the server (a few seconds) is met within a second or two, and a long outage costs one connection attempt (a
#: 10 s connect timeout at most, :class:`acq.monitoring.catalogue_backends.PostgreSQLDialect`) per 30 s.
FIRST_BACKOFF_S = 1.0
MAX_BACKOFF_S = 30.0


@dataclass(frozen=True)
class Waiting:
    """A window waiting to be filed: its session id (the monitor's key), its outcome and how it counts (the kind
    :meth:`acq.monitoring.monitor_status.MonitorStatus.count` takes, None: by its verdict)."""

    key: str
    outcome: Outcome
    kind: str | None = None


class FilingQueue:
    """Files windows into ``catalogue`` in order; while its server is out of reach keeps them (:attr:`waiting`, and
    the spool file ``spool``) and tries again with a bounded backoff (:meth:`flush`).

    ``clock``: the wall clock, s (time.monotonic; tests may pass another)."""

    def __init__(self, catalogue: Catalogue, spool: Path, clock: Callable[[], float] = time.monotonic) -> None:
        self.catalogue = catalogue
        self.spool = spool
        self._clock = clock
        self.waiting: list[Waiting] = _read(spool)  # those a stopped monitor left: filed first
        self.down_since_utc: str | None = None  # when the catalogue was found out of reach (HH:MM:SS UTC)
        self.problem = ""  # the driver's one line of why
        self._next_try = 0.0
        self._backoff_s = FIRST_BACKOFF_S
        #: one line per window not filed because the catalogue holds a later analysis of it (read and cleared by the
        #: caller): "<file>: not filed — the catalogue holds a later analysis of it (<time>; this one <time>)"
        self.notes: list[str] = []

    @property
    def down(self) -> bool:
        """True while the catalogue is out of reach."""
        return self.down_since_utc is not None

    def file(self, window: Waiting) -> list[Waiting]:
        """Queue ``window`` and file what may be filed now (:meth:`flush`); return the windows filed (or kept out by a
        later analysis: :attr:`notes`). Its analysis time is fixed now (an outcome without one would be stamped when
        filed, and one that waited would look newer than an analysis made meanwhile)."""
        from acq.recording.layout import analysis_time_utc  # here, not at the top: `acq --help` loads no h5py

        outcome = window.outcome
        if outcome.analyzed_utc is None:
            window = replace(window, outcome=replace(
                outcome, analyzed_utc=(outcome.doc or {}).get("analyzed_utc") or analysis_time_utc()))
        self.waiting.append(window)
        filed = self.flush()
        if self.waiting:
            self._write_spool()
        return filed

    def flush(self, force: bool = False) -> list[Waiting]:
        """File the waiting windows in order, reconnecting first if the catalogue was out of reach (not before the
        backoff's time unless ``force``); return those filed. A write that fails for another reason than a lost
        connection (the disk of a SQLite file full, a constraint) raises as before."""
        if not self.waiting or (self.down and not force and self._clock() < self._next_try):
            return []
        filed: list[Waiting] = []
        try:
            if self.down:
                self.catalogue.reconnect()
            while self.waiting:
                outcome = self.waiting[0].outcome
                kept = self.catalogue.record(outcome, keep_newer=True)
                if kept is not None and outcome.analyzed_utc is not None and kept > outcome.analyzed_utc:
                    self.notes.append(f"{Path(outcome.path).name}: not filed — the catalogue holds a later analysis "
                                      f"of it ({kept}; this one {outcome.analyzed_utc})")
                filed.append(self.waiting.pop(0))
        except (StorageError, ConfigError, *self.catalogue.errors) as e:
            if not (self.down or self.catalogue.connection_lost):
                raise
            self._went_down(str(e))
        else:
            self.down_since_utc, self.problem, self._backoff_s = None, "", FIRST_BACKOFF_S
        self._write_spool()
        return filed

    def lost_connection(self, error: BaseException) -> bool:
        """Whether ``error`` (of a read) is the catalogue out of reach — then it is marked so, and retried."""
        if not self.catalogue.connection_lost:
            return False
        self._went_down(str(error))
        return True

    def _went_down(self, problem: str) -> None:
        if self.down_since_utc is None:
            self.down_since_utc = time.strftime("%H:%M:%S", time.gmtime())
            self._backoff_s = FIRST_BACKOFF_S
        else:
            self._backoff_s = min(2 * self._backoff_s, MAX_BACKOFF_S)
        self.problem = problem.splitlines()[0] if problem else ""
        self._next_try = self._clock() + self._backoff_s

    def _write_spool(self) -> None:
        """The waiting windows in the spool file (atomically replaced), or no file when none waits."""
        if not self.waiting:
            self.spool.unlink(missing_ok=True)
            return
        with atomic_path(self.spool) as tmp:
            tmp.write_text("".join(json.dumps({"key": w.key, "kind": w.kind, "outcome": asdict(w.outcome)}) + "\n"
                                   for w in self.waiting))


def _read(spool: Path) -> list[Waiting]:
    """The windows a spool file keeps (none when there is no file)."""
    if not spool.is_file():
        return []
    rows = [json.loads(line) for line in spool.read_text().splitlines() if line.strip()]
    return [Waiting(r["key"], Outcome(**r["outcome"]), r["kind"]) for r in rows]
