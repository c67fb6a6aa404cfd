"""The catalogue: one database of every session analysed, the health history of the joints.

Two tables. ``sessions`` holds what identifies a recording (id, path, joint, start time, tags);
``analyses`` one row per session and analysis request: the file's SHA-256, the options asked for
(``request_key``) and resolved, K, J_m, J_l, C with their 95 % intervals, f_a, f_r, verdict and
reasons, clock figures, software version — or the error when the analysis failed.

The database is a SQLite file (the default) or, for several hosts sharing one history, a
PostgreSQL server (``--catalogue postgresql://user@host/db``); the few things that differ between
the two are in :mod:`acq.monitoring.catalogue_backends`. :data:`~acq.monitoring.catalogue_schema.MIGRATIONS` brings an older database up to
:data:`SCHEMA_VERSION` step by step, each step in its own transaction, serialised between processes
(SQLite's write lock, PostgreSQL's advisory lock). Every write is one transaction per session, an
upsert, so several processes on one host (SQLite, WAL mode, busy timeout) or on many (PostgreSQL)
can share a catalogue. Keep a SQLite file on a local disk — its locking is unreliable on network shares.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from acq.monitoring.catalogue_backends import one_line, open_catalogue_db, open_error
from acq.monitoring.catalogue_damage import integrity_error, json_column, read_error
from acq.monitoring.catalogue_schema import MIGRATIONS, MONITOR_COLUMN_VERSION, SCHEMA_VERSION
from acq.recording.storage import cause_of
from acqcore.errors import ConfigError, StorageError

#: Session tag of a monitor's window: the identity of the monitor that captured it (also the column ``monitor_id``).
MONITOR_TAG = "monitor_id"

_PARAM_COLUMNS = (("K_Nm_per_rad", "K"), ("Jm_kgm2", "Jm"), ("Jl_kgm2", "Jl"), ("C_Nms_per_rad", "C"))


@dataclass(frozen=True)
class Outcome:
    """What analysing one session gave: the result document, or the error.

    Attributes
    ----------
    path : str
        Session file as given to the worker.
    sha256 : str
        SHA-256 of the file when the batch looked at it.
    request_key : str
        The analysis options asked for, canonical JSON (see :meth:`analysis.AnalysisRequest.key`).
    session : dict
        ``session_id``, ``joint``, ``created_utc``, ``start_monotonic_ns``, ``status``, ``tags``
        (empty when the file could not be read at all).
    doc : dict or None
        The ``.result.json`` document; None when the analysis failed.
    error : str or None
        One line saying why the analysis failed.
    seconds : float
        Wall time of the analysis, s.
    analyzed_utc : str or None
        When it was analysed (ISO 8601, UTC); None: the document's ``analyzed_utc``, else the time it is filed.
    """

    path: str
    sha256: str
    request_key: str
    session: dict[str, Any]
    doc: dict[str, Any] | None
    error: str | None
    seconds: float
    analyzed_utc: str | None = None


@dataclass(frozen=True)
class Entry:
    """One analysis of a session as the trend reads it (SI units, None where unknown)."""

    session_key: str
    session_id: str | None
    path: str
    joint: str | None
    created_utc: str | None
    tags: dict[str, Any]
    verdict: str | None
    reasons: list[str]
    error: str | None
    K_Nm_per_rad: float | None
    K_ci95: tuple[float | None, float | None]
    f_a_hz: float | None
    f_r_hz: float | None
    request_key: str
    analyzed_utc: str
    truth_K_Nm_per_rad: float | None


class Catalogue:
    """An open catalogue database (created and migrated on open); use as a context manager.

    Parameters
    ----------
    path : Path or str
        The SQLite file (created with its folder if missing), or a ``postgresql://`` URL.
    read_only : bool, optional
        Only read it (``acq trend``, ``acq fleet``, ``acq view --trend``): a SQLite file in a folder this process may
        not write into (a read-only mount) is then opened read-only and not migrated (one of an older schema is
        refused, naming what migrates it).

    Attributes
    ----------
    path : Path or str
        The SQLite file, or the URL without its password (for messages).
    """

    def __init__(self, path: Path | str, *, read_only: bool = False):
        self.path: Path | str
        self._location = path  # as given (a URL with its password): what reconnect() opens again
        self._dialect, self._db, self.path = open_catalogue_db(path, read_only)
        try:
            if self._dialect.read_only:
                self._require_current_schema()
            else:
                self._migrate()
            if read_only and self._dialect.name == "sqlite" and (damaged := integrity_error(self.path, self._db)):
                raise damaged
        except (*self._dialect.errors, UnicodeDecodeError) as e:
            damaged = self._damage(e)
            self._db.close()
            raise damaged or open_error(self.path, e, "not a usable catalogue") from None
        except BaseException:
            self._db.close()
            raise

    def __enter__(self) -> Catalogue:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the database."""
        self._db.close()

    @property
    def errors(self) -> tuple[type[Exception], ...]:
        """The exceptions of its database driver (a read that fails raises one of them)."""
        return self._dialect.errors

    @property
    def connection_lost(self) -> bool:
        """True when the connection to a PostgreSQL server broke (the server stopped or restarted, the network
        failed): :meth:`reconnect` may make it usable again. Never for a SQLite file."""
        return bool(getattr(self._db, "broken", False) or getattr(self._db, "closed", False))

    def reconnect(self) -> None:
        """Open the connection again (:class:`ConfigError` naming the URL while the server does not answer)."""
        with suppress(Exception):
            self._db.close()
        self._dialect, self._db, self.path = open_catalogue_db(self._location, self._dialect.read_only)

    def _execute(self, sql: str, params: Iterable[Any] = ()) -> Any:
        """Run one statement written with ``?`` placeholders; return the cursor. Booleans go in as 0/1, as SQLite
        stores them (PostgreSQL refuses a boolean for an integer column)."""
        values = tuple(int(p) if isinstance(p, bool) else p for p in params)
        return self._db.execute(self._dialect.sql(sql), values)

    @contextmanager
    def _reading(self) -> Iterator[None]:
        """Reads of a SQLite file damaged on disk raise one line naming it, the table, row and column
        (:func:`~acq.monitoring.catalogue_damage.read_error`); any other error goes on as it is."""
        try:
            yield
        except (*self._dialect.errors, UnicodeDecodeError) as e:
            damaged = self._damage(e)
            if damaged is None:
                raise
            raise damaged from None

    def _damage(self, e: BaseException) -> ConfigError | None:
        """The one line for ``e`` when it is a SQLite file's damage on disk (:func:`read_error`), else None (a
        PostgreSQL server's errors are never a damaged file)."""
        return read_error(self.path, self._db, e) if self._dialect.name == "sqlite" else None

    @contextmanager
    def _transaction(self) -> Iterator[Any]:
        """One write transaction (on SQLite holding the write lock from its start: waits for others)."""
        self._db.execute(self._dialect.begin)
        try:
            yield self._db
        except BaseException:
            self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    @property
    def schema_version(self) -> int:
        """The database's schema version."""
        return self._dialect.schema_version(self._db)

    def _require_current_schema(self) -> None:
        """A catalogue opened read-only is read as it is: one of another schema version is refused."""
        version = self.schema_version
        if version > SCHEMA_VERSION:
            raise ConfigError(f"{self.path}: catalogue schema version {version} is newer than this acq knows "
                              f"({SCHEMA_VERSION}) — update acq")
        if version < SCHEMA_VERSION:
            raise ConfigError(f"{self.path}: catalogue schema version {version} is older than this acq's "
                              f"({SCHEMA_VERSION}) and its folder may not be written to migrate it — run acq trend "
                              "once where it may be written (a copy of the folder)")

    def _migrate(self) -> None:
        while True:
            with self._transaction() as db:
                self._dialect.lock_schema(db)
                version = self.schema_version  # read under the lock: another process may have migrated
                if version > SCHEMA_VERSION:
                    raise ConfigError(f"{self.path}: catalogue schema version {version} is newer than this acq "
                                      f"knows ({SCHEMA_VERSION}) — update acq")
                if version == SCHEMA_VERSION:
                    return
                for statement in MIGRATIONS[version].split(";"):
                    if statement.strip():
                        db.execute(self._dialect.ddl(statement))
                if version + 1 == MONITOR_COLUMN_VERSION:
                    self._fill_monitor_ids()
                self._dialect.set_schema_version(db, version + 1)

    def current(self, request_key: str) -> set[str]:
        """SHA-256 of the files already analysed successfully with this request."""
        with self._reading():
            return {r[0] for r in self._execute("SELECT sha256 FROM analyses WHERE request_key = ? AND error IS NULL",
                                                (request_key,))}

    def record(self, outcome: Outcome, *, keep_newer: bool = False) -> str | None:
        """Store one analysis (replacing that session's earlier one with the same request) — but a failure, or a
        ``--partial`` analysis, of another file of the same session (a copy, damaged) does not replace the analysis of
        a file that succeeded whole:
        copies share the session id, and the last one written had hidden an intact copy's result (the trial). A
        failure of the same file (damaged in place) does replace it. With ``keep_newer`` an analysis made later than
        this one (its ``analyzed_utc``) is not replaced either: a window that waited for the catalogue
        (:mod:`acq.monitoring.catalogue_spool`) while ``acq analyze`` filed a new analysis of it.

        Returns None when stored, else the ``analyzed_utc`` of the analysis the catalogue kept."""
        from acq.recording.layout import analysis_time_utc  # here, not at the top: `acq --help` loads no h5py

        meta, doc = outcome.session, outcome.doc or {}
        key = meta.get("session_id") or f"path:{Path(outcome.path).resolve()}"
        values: dict[str, Any] = {
            "session_key": key, "sha256": outcome.sha256, "request_key": outcome.request_key,
            "file_path": str(Path(outcome.path).resolve()),
            "options_json": json.dumps(doc["options"]) if doc else None,
            "analyzed_utc": outcome.analyzed_utc or doc.get("analyzed_utc") or analysis_time_utc(),
            "acq_version": doc.get("acq_version"),
            "seconds": outcome.seconds, "verdict": doc.get("quality", {}).get("verdict"),
            "reasons_json": json.dumps(doc.get("quality", {}).get("reasons", [])), "error": outcome.error,
            "f_a_hz": doc.get("antiresonance_hz"), "f_r_hz": doc.get("resonance_hz"),
            "clock_offset_s": doc.get("clock", {}).get("offset_s"),
            "clock_drift_ppm": doc.get("clock", {}).get("drift_ppm"),
            "clock_residual_s": doc.get("clock", {}).get("residual_s"),
            "mean_coherence": doc.get("quality", {}).get("mean_coherence"),
            "truth_json": json.dumps(doc["simulated_truth"]) if "simulated_truth" in doc else None,
            "partial": int(bool(doc.get("partial"))),
            "excitation_json": json.dumps(doc["excitation"]) if "excitation" in doc else None,
        }
        for name, short in _PARAM_COLUMNS:
            lo, hi = doc.get("ci95", {}).get(name, (None, None))
            values |= {name: doc.get(name), f"{short}_lo": lo, f"{short}_hi": hi}
        try:
            return self._write_outcome(key, meta, values, keep_newer)
        except self._dialect.errors as e:  # e.g. "database or disk is full": the row is not there, say which catalogue
            raise self._write_error(e) from None

    def _write_outcome(self, key: str, meta: dict[str, Any], values: dict[str, Any], keep_newer: bool) -> str | None:
        columns = ", ".join(values)
        updates = ", ".join(f"{c} = excluded.{c}" for c in values if c not in ("session_key", "request_key"))
        path = values["file_path"]
        tags = meta.get("tags", {})
        monitor = str(tags[MONITOR_TAG]) if MONITOR_TAG in tags else None
        with self._transaction():
            self._execute(
                "INSERT INTO sessions (session_key, session_id, path, joint, created_utc, start_monotonic_ns, status,"
                " tags_json, monitor_id) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?) ON CONFLICT (session_key) DO NOTHING",
                (key, meta.get("session_id"), path, meta.get("joint"), meta.get("created_utc"),
                 meta.get("start_monotonic_ns"), meta.get("status"), json.dumps(tags), monitor))
            # one statement, so two writers cannot both pass a separate check (PostgreSQL's READ COMMITTED): the update
            # is skipped when a failure, or an analysis of only the readable part (--partial), of another file would
            # replace an analysis of a whole file
            # (a row filed before schema 5 has no file path: its file hash tells the same file; rowcount, not RETURNING:
            # SQLite before 3.35 has none — both back ends count 0 rows when the WHERE skips the update)
            # (ISO 8601 times, UTC, with microseconds or whole seconds: their order as bytes is their order in time)
            order = self._dialect.bytewise
            newer = f" AND analyses.analyzed_utc{order} <= excluded.analyzed_utc{order}" if keep_newer else ""
            stored = self._execute(
                f"INSERT INTO analyses ({columns}) VALUES ({', '.join('?' * len(values))})"
                f" ON CONFLICT (session_key, request_key) DO UPDATE SET {updates}"
                " WHERE (analyses.error IS NOT NULL OR analyses.file_path = excluded.file_path"
                " OR (analyses.file_path IS NULL AND analyses.sha256 = excluded.sha256)"
                f" OR (excluded.error IS NULL AND (excluded.partial = 0 OR analyses.partial = 1))){newer}",
                tuple(values.values())).rowcount
            if not stored:
                return str(self._execute("SELECT analyzed_utc FROM analyses WHERE session_key = ? AND request_key = ?",
                                         (key, values["request_key"])).fetchone()[0])
            # the session row follows the analysis that stands
            self._execute("UPDATE sessions SET path = ?, status = ?, tags_json = ?, monitor_id = ?"
                          " WHERE session_key = ?", (path, meta.get("status"), json.dumps(tags), monitor, key))
            return None

    def entries(self, joint: str | None = None, *, monitor: str | None = None,
                unowned: bool = False) -> list[Entry]:
        """Every session's analyses (one per request), oldest session first (all joints when ``joint`` is None).

        ``monitor``: only the windows of this monitor (:data:`MONITOR_TAG`), read by the column's index — and with
        ``unowned`` also the sessions of no monitor (windows filed before monitors had an identity). A session whose
        column is empty but whose tags name a monitor (filed by an acq of before schema 6 into a catalogue another
        one migrated, until a monitor's start fills the column: :meth:`fill_monitor_ids`) is read by its tag: readers
        (``acq trend``, ``acq fleet``) write nothing, and without it the latest windows of such a monitor were
        missing from its trend.
        """
        terms: list[str] = []
        params: list[Any] = []
        if monitor is not None:  # by the monitor_id index (both terms of the OR are index searches)
            terms.append("(s.monitor_id = ? OR (s.monitor_id IS NULL AND (? = 1 OR s.tags_json LIKE ?)))")
            params += [monitor, unowned, f'%"{MONITOR_TAG}"%']
        if joint is not None:
            # with a monitor the joint filters its windows, as an expression no index serves: SQLite (no statistics)
            # took the joint's index, which every robot's joint1 shares, and read all their windows (a "CAST(? AS
            # TEXT) IS NULL OR" form of these terms read every row of the catalogue)
            terms.append("s.joint = ?" if monitor is None else "s.joint || '' = ?")
            params.append(joint)
        where = "".join(f" {'AND' if i else 'WHERE'} {term}" for i, term in enumerate(terms))
        with self._reading():
            rows = self._execute(
                "SELECT s.*, a.*, COALESCE(a.file_path, s.path) AS analysed_path FROM sessions s JOIN analyses a"
                f" ON a.session_key = s.session_key{where}"
                " ORDER BY s.created_utc NULLS FIRST, s.start_monotonic_ns NULLS FIRST, s.path,"
                f" a.analyzed_utc{self._dialect.bytewise}, a.id",
                params).fetchall()
        if monitor is None:
            return [_entry(self.path, r) for r in rows]
        # a session without the column is whose its tag says
        entries = [(r["monitor_id"], _entry(self.path, r)) for r in rows]
        return [e for column, e in entries if column is not None or (
            str(e.tags[MONITOR_TAG]) == monitor if e.tags.get(MONITOR_TAG) is not None else unowned)]

    def fill_monitor_ids(self) -> int:
        """Fill the ``monitor_id`` column of the sessions whose tags name a monitor but whose column does not: the rows
        an acq of before schema 6 still running files into a catalogue another one migrated (its INSERT names the
        columns it knows). :meth:`entries` scopes by the column's index (such a session only by its tag, read outside
        the index) and :meth:`copy_windows` by the column alone: without this, such a monitor's windows were nobody's
        once it restarted upgraded. Returns the number of sessions filled (one transaction)."""
        try:
            with self._reading(), self._transaction():
                return self._fill_monitor_ids()
        except self._dialect.errors as e:
            raise self._write_error(e) from None

    def _fill_monitor_ids(self) -> int:
        """:meth:`fill_monitor_ids` inside the caller's transaction: the sessions without the column whose tags name
        the monitor tag (found by text; read by Python's JSON, which reads the NaN it writes)."""
        rows = self._execute("SELECT session_key, tags_json FROM sessions WHERE monitor_id IS NULL"
                             " AND tags_json LIKE ?", (f'%"{MONITOR_TAG}"%',)).fetchall()
        filled = [(str(tags[MONITOR_TAG]), key) for key, tags in ((r[0], _tags(r[1])) for r in rows)
                  if tags.get(MONITOR_TAG) is not None]
        if filled:
            self._db.cursor().executemany(self._dialect.sql("UPDATE sessions SET monitor_id = ? WHERE session_key = ?"),
                                          filled)
        return len(filled)

    def copy_windows(self, source: Catalogue, monitor: str, *, unowned: bool = False) -> int:
        """Copy the sessions of ``monitor`` with their analyses from ``source`` into this catalogue (one transaction;
        rows this catalogue already has are kept); with ``unowned`` also the sessions of no monitor, filed as
        ``monitor``'s (windows from before monitors had an identity). Returns the number of the monitor's sessions."""
        mine = "SELECT * FROM sessions WHERE monitor_id = ? OR (? = 1 AND monitor_id IS NULL)"
        with source._reading():
            sessions = list(source._execute(mine, (monitor, unowned)))
            analyses = list(source._execute(f"SELECT * FROM analyses WHERE session_key IN"
                                            f" ({mine.replace('*', 'session_key')}) ORDER BY id", (monitor, unowned)))
        try:
            with self._transaction():
                for r in sessions:
                    row = {name: r[name] for name in r.keys()}
                    tags = json_column(source.path, r, "tags_json", "{}")
                    row["tags_json"] = json.dumps({**tags, MONITOR_TAG: monitor})
                    row["monitor_id"] = monitor
                    self._insert("sessions", row, "session_key")
                for r in analyses:
                    self._insert("analyses", {name: r[name] for name in r.keys() if name != "id"},
                                 "session_key, request_key")
        except self._dialect.errors as e:
            raise self._write_error(e) from None
        return len(sessions)

    def _write_error(self, e: BaseException) -> StorageError:
        """The one-line error of a failed write into this catalogue: ``<cause>: <catalogue> (<its message>)``."""
        return StorageError(f"{cause_of(e) if 'full' not in str(e) else 'disk full'}: {self.path} ({one_line(e)})")

    def _insert(self, table: str, row: dict[str, Any], key: str) -> None:
        self._execute(f"INSERT INTO {table} ({', '.join(row)}) VALUES ({', '.join('?' * len(row))})"
                      f" ON CONFLICT ({key}) DO NOTHING", tuple(row.values()))

    def joints(self) -> list[str]:
        """The joints the catalogue knows."""
        with self._reading():
            return [r[0] for r in self._execute("SELECT DISTINCT joint FROM sessions WHERE joint IS NOT NULL")]


def _tags(text: str) -> dict[str, Any]:
    """A session's tags_json as a dict ({} when it is not a JSON object)."""
    try:
        tags = json.loads(text)
    except ValueError:
        return {}
    return tags if isinstance(tags, dict) else {}


def _entry(path: Path | str, r: Any) -> Entry:
    truth = json_column(path, r, "truth_json", "{}")
    return Entry(session_key=r["session_key"], session_id=r["session_id"], path=r["analysed_path"], joint=r["joint"],
                 created_utc=r["created_utc"], tags=json_column(path, r, "tags_json", "{}"), verdict=r["verdict"],
                 reasons=json_column(path, r, "reasons_json", "[]"), error=r["error"], K_Nm_per_rad=r["K_Nm_per_rad"],
                 K_ci95=(r["K_lo"], r["K_hi"]), f_a_hz=r["f_a_hz"], f_r_hz=r["f_r_hz"], request_key=r["request_key"],
                 analyzed_utc=r["analyzed_utc"], truth_K_Nm_per_rad=truth.get("K_Nm_per_rad"))
