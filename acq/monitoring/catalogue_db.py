"""The catalogue's database (:class:`CatalogueDatabase`): opening it, its transactions, its reads, its schema.

The database is a SQLite file (the default) or, for several hosts sharing one history, a PostgreSQL server
(``--catalogue postgresql://user@host/db``); the few things that differ between the two are in
:mod:`acq.monitoring.catalogue_backends`. :data:`~acq.monitoring.catalogue_schema.MIGRATIONS` brings an older database
up to :data:`~acq.monitoring.catalogue_schema.SCHEMA_VERSION` step by step, each step in its own transaction,
serialised between processes (SQLite's write lock, PostgreSQL's advisory lock). A read of a SQLite file damaged on disk
raises one line naming it (:mod:`acq.monitoring.catalogue_damage`), a failed write one naming the catalogue. What is
written and read — sessions, analyses, entries — is :class:`acq.monitoring.catalogue.Catalogue`'s.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any, Self

from acq.monitoring.catalogue_backends import one_line, open_catalogue_db, open_error
from acq.monitoring.catalogue_damage import integrity_error, read_error
from acq.monitoring.catalogue_schema import MIGRATIONS, MONITOR_COLUMN_VERSION, SCHEMA_VERSION
from acq.monitoring.catalogue_text import to_db
from acq.recording.storage import cause_of
from acqcore.errors import ConfigError, StorageError

#: Session tag of a monitor's window: the identity of the monitor that captured it (also the column ``monitor_id``).
MONITOR_TAG = "monitor_id"


class CatalogueDatabase:
    """An open catalogue database, created and migrated on open (read-only: its schema only checked), a SQLite file's
    structure checked first (:func:`~acq.monitoring.catalogue_damage.integrity_error`); use as a context manager.
    Parameters as :class:`acq.monitoring.catalogue.Catalogue`'s.

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
            # a SQLite file is checked whether it is read or written (a monitor's restart, a batch): through a damaged
            # index a read misses rows and a write goes on into the damage — a restarted monitor filed its windows
            # into such a file (exit 0), or captured a window and then failed "database disk image is malformed"
            if self._dialect.name == "sqlite" and (damaged := integrity_error(self.path, self._db)):
                raise damaged
            if self._dialect.read_only:
                self._require_current_schema()
            else:
                self._migrate()
        except (*self._dialect.errors, UnicodeDecodeError) as e:
            damaged = self._damage(e)
            self._db.close()
            raise damaged or open_error(self.path, e, "not a usable catalogue") from None
        except BaseException:
            self._db.close()
            raise

    def __enter__(self) -> Self:
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
        values = tuple(int(p) if isinstance(p, bool) else to_db(p) for p in params)
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
                                          [(to_db(monitor), to_db(key)) for monitor, key in filled])
        return len(filled)

    def _write_error(self, e: BaseException) -> StorageError:
        """The one-line error of a failed write into this catalogue: ``<cause>: <catalogue> (<its message>)``."""
        return StorageError(f"{cause_of(e) if 'full' not in str(e) else 'disk full'}: {self.path} ({one_line(e)})")


def _tags(text: str) -> dict[str, Any]:
    """A session's tags_json as a dict ({} when it is not a JSON object)."""
    try:
        tags = json.loads(text)
    except ValueError:
        return {}
    return tags if isinstance(tags, dict) else {}
