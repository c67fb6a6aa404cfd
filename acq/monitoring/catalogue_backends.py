"""The catalogue's two back ends, SQLite (a file, the default) and PostgreSQL (a ``postgresql://`` URL).

:class:`acq.monitoring.catalogue.Catalogue` writes one SQL for both; a dialect holds only what differs: how to
connect, the parameter placeholder, the column types of the migrations, where the schema version
lives and how migrations are serialised between processes.

* SQLite: the version is ``PRAGMA user_version``; ``BEGIN IMMEDIATE`` takes the database's write lock
  at once, so migrations and writes of several processes queue (WAL, busy timeout).
* PostgreSQL: the version is the one row of a ``schema_version`` table; a migration holds the
  transaction-level advisory lock :data:`MIGRATION_LOCK_KEY`, so hosts opening a fresh database at
  once migrate it one after the other; writes rely on ``INSERT … ON CONFLICT`` (atomic upserts) and
  need no lock of their own.
"""

from __future__ import annotations

import errno
import re
import sqlite3
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from acq.install import install_hint
from acq.recording.storage import make_folders, refused_write
from acqcore.errors import ConfigError, StorageError

#: Seconds a writer waits for another process's lock (SQLite's busy timeout, PostgreSQL's lock_timeout).
BUSY_TIMEOUT_S = 60.0
#: Key of PostgreSQL's advisory lock around migrations: any 64-bit number no other application on the
#: server uses (a signed 64-bit number); these are the bytes of "acqcatal".
MIGRATION_LOCK_KEY = 0x61637163_6174616C
#: The URL schemes of a PostgreSQL catalogue; anything else is a SQLite file's path.
URL_SCHEMES = ("postgresql://", "postgres://")


def is_url(location: Path | str) -> bool:
    """True when ``location`` is a PostgreSQL URL rather than a SQLite file."""
    return isinstance(location, str) and location.startswith(URL_SCHEMES)


def open_error(path: Path | str, e: BaseException, what: str) -> ConfigError | StorageError:
    """A full disk, or a folder acq may not write into (read-only, no permission), is a failed write (exit 1),
    anything else bad input naming the catalogue (exit 2)."""
    if "full" in str(e) or getattr(e, "errno", None) == errno.ENOSPC:
        return StorageError(f"disk full: {path} ({one_line(e)})")
    refused = None if is_url(path) else refused_write(Path(path).parent)
    if refused is not None:  # SQLite says only "unable to open database file"
        why = ("SQLite writes beside a catalogue, also to read it" if Path(path).exists()
               else "no catalogue can be made there")
        return StorageError(f"{refused}: {path} ({why})")
    return ConfigError(f"{path}: {what} ({one_line(e)})")


def folder_error(path: Path, *, given: bool = True) -> ConfigError:
    """A catalogue that is a folder: the error naming it and, where the user ``given`` it (``--catalogue``), the file
    it may have meant (the name a batch gives its catalogue, acq.monitoring.session_outcome.CATALOGUE_NAME, which
    imports this module)."""
    hint = f" — give the file, e.g. {path / 'catalogue.sqlite'}" if given else ""
    return ConfigError(f"{path}: is a folder, not a catalogue file{hint}")


def one_line(e: BaseException) -> str:
    """``e``'s message on one line: its first line, with a PostgreSQL error's DETAIL folded in. psycopg's message
    goes on with ``DETAIL:``/``HINT:``/``CONTEXT:`` lines, a failed connection's with libpq's hint ("Is the server
    running …?"): the first line says what failed, the DETAIL which row or value."""
    lines = [line.strip() for line in str(e).strip().splitlines() if line.strip()]
    first = lines[0] if lines else type(e).__name__
    detail = " ".join(str(getattr(getattr(e, "diag", None), "message_detail", None) or "").split())
    return f"{first}: {detail}" if detail and detail not in first else first


def redacted(url: str) -> str:
    """``url`` without its password (for messages)."""
    return re.sub(r"(://[^:/@]+):[^@]*@", r"\1:***@", url)


def without_masked_password(url: str) -> str:
    """``url`` as :func:`redacted` left it, without the masked password: libpq then reads the password from
    ``~/.pgpass`` or ``PGPASSWORD`` (the mask itself would be sent as the password)."""
    return re.sub(r"(://[^:/@]+):\*\*\*@", r"\1@", url)


class SQLiteDialect:
    """SQLite: a local file in WAL mode (never on a network share: its locking is unreliable there)."""

    name = "sqlite"
    errors: tuple[type[Exception], ...] = (sqlite3.Error,)
    begin = "BEGIN IMMEDIATE"
    #: What makes a text comparison compare bytes (stamps in time order): SQLite's default collation, BINARY.
    bytewise = ""

    def __init__(self) -> None:
        self.read_only = False  # set by connect: the file was opened read-only (its folder may not be written)

    def connect(self, path: Path, read_only: bool = False) -> sqlite3.Connection:
        """Open (create) the file; raises :class:`ConfigError` naming it when that fails. With ``read_only`` a file
        in a folder this process may not write into is opened read-only (:meth:`connect_read_only`)."""
        if path.is_dir():  # a folder in a catalogue's place (--catalogue is checked where it is parsed): SQLite
            raise folder_error(path, given=False)  # would say only "unable to open database file"
        if read_only and path.is_file() and refused_write(path.parent) is not None:
            return self.connect_read_only(path)
        try:
            make_folders(path.parent)
            db = sqlite3.connect(path, timeout=BUSY_TIMEOUT_S, isolation_level=None)
        except (OSError, sqlite3.Error) as e:
            raise open_error(path, e, "cannot open the catalogue") from None
        db.row_factory = sqlite3.Row
        try:
            _set_wal(db)
            db.execute("PRAGMA foreign_keys=ON")
        except sqlite3.DatabaseError as e:
            db.close()
            raise open_error(path, e, "not a usable catalogue") from None
        return db

    def connect_read_only(self, path: Path) -> sqlite3.Connection:
        """Open an existing catalogue in a folder this process may not write into (a read-only mount, an archive):
        ``mode=ro`` reads a WAL database whose ``-wal`` and ``-shm`` files are there (SQLite ≥ 3.22, "Read-Only
        Databases" of https://sqlite.org/wal.html); without them SQLite would have to create them, so the file is
        opened ``immutable=1`` — no locks, no WAL: nothing may write it meanwhile, which a folder no one may write
        into assures."""
        wal = all(path.with_name(path.name + suffix).is_file() for suffix in ("-wal", "-shm"))
        uri = f"{path.resolve().as_uri()}?{'mode=ro' if wal else 'immutable=1'}"
        try:
            db = sqlite3.connect(uri, uri=True, timeout=BUSY_TIMEOUT_S, isolation_level=None)
            db.execute("PRAGMA user_version").fetchone()  # SQLite opens lazily: the first read says if it can
        except sqlite3.Error as e:
            raise open_error(path, e, "cannot read the catalogue") from None
        db.row_factory = sqlite3.Row
        self.read_only = True
        return db

    def sql(self, text: str) -> str:
        """A statement with ``?`` placeholders in this dialect."""
        return text

    def ddl(self, text: str) -> str:
        """A migration statement in this dialect."""
        return text

    def lock_schema(self, db: Any) -> None:
        """Serialise migrations (``BEGIN IMMEDIATE`` already holds the write lock)."""

    def schema_version(self, db: Any) -> int:
        """The database's schema version."""
        return int(db.execute("PRAGMA user_version").fetchone()[0])

    def set_schema_version(self, db: Any, version: int) -> None:
        """Store the schema version (inside the migration's transaction)."""
        db.execute(f"PRAGMA user_version = {int(version)}")


def _set_wal(db: sqlite3.Connection) -> None:
    """Put the database in WAL mode (persistent). Switching a fresh file needs it to itself, and SQLite reports
    "database is locked" at once rather than waiting out the busy timeout when several processes open a new
    catalogue together: retry until the timeout."""
    deadline = time.monotonic() + BUSY_TIMEOUT_S
    while True:
        try:
            db.execute("PRAGMA journal_mode=WAL")
            return
        except sqlite3.OperationalError as e:
            if "locked" not in str(e) or time.monotonic() > deadline:
                raise
            time.sleep(0.02)


class PostgreSQLDialect:
    """PostgreSQL through psycopg 3, autocommit connection with explicit ``BEGIN``/``COMMIT``."""

    name = "postgresql"
    begin = "BEGIN"
    read_only = False  # a server: its own permissions decide
    #: A database's default collation may be ICU's, which orders '12:00:05+00:00' after '12:00:05.5+00:00' (it
    #: weighs the punctuation last); "C" compares bytes, as SQLite and Python do.
    bytewise = ' COLLATE "C"'
    #: SQLite's column types as PostgreSQL's: REAL is 4 bytes there, INTEGER too (ns timestamps need 8).
    _TYPES: Sequence[tuple[str, str]] = ((r"\bINTEGER PRIMARY KEY AUTOINCREMENT\b",
                                          "BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY"),
                                         (r"\bINTEGER\b", "BIGINT"), (r"\bREAL\b", "DOUBLE PRECISION"))

    def __init__(self) -> None:
        try:
            import psycopg
        except ImportError:
            raise ConfigError(f"--catalogue postgresql://…: needs psycopg 3 — {install_hint('fleet')}") from None
        self._psycopg = psycopg
        self.errors: tuple[type[Exception], ...] = (psycopg.Error,)

    def connect(self, url: str) -> Any:
        """Connect to the server; raises :class:`ConfigError` naming the URL (without its password)."""
        try:
            return self._psycopg.connect(url, autocommit=True, row_factory=_case_insensitive_rows, connect_timeout=10,
                                         options=f"-c lock_timeout={int(BUSY_TIMEOUT_S * 1000)}")
        except self._psycopg.Error as e:
            raise ConfigError(f"{redacted(url)}: cannot open the catalogue ({one_line(e)})") from None

    def sql(self, text: str) -> str:
        """``?`` placeholders as psycopg's ``%s`` (the catalogue's SQL has no literal ``?`` or ``%``)."""
        return text.replace("?", "%s")

    def ddl(self, text: str) -> str:
        """A migration written for SQLite with PostgreSQL's column types."""
        for pattern, replacement in self._TYPES:
            text = re.sub(pattern, replacement, text)
        return text

    def lock_schema(self, db: Any) -> None:
        """Hold the migration lock until the transaction ends; create the version table if missing."""
        db.execute("SELECT pg_advisory_xact_lock(%s)", (MIGRATION_LOCK_KEY,))
        db.execute("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)")

    def schema_version(self, db: Any) -> int:
        """The database's schema version (0 when it has none yet)."""
        exists = db.execute("SELECT to_regclass('schema_version') IS NOT NULL").fetchone()[0]
        row = db.execute("SELECT version FROM schema_version").fetchone() if exists else None
        return 0 if row is None else int(row[0])

    def set_schema_version(self, db: Any, version: int) -> None:
        """Store the schema version (inside the migration's transaction)."""
        db.execute("DELETE FROM schema_version")
        db.execute("INSERT INTO schema_version (version) VALUES (%s)", (version,))


Dialect = SQLiteDialect | PostgreSQLDialect


def open_catalogue_db(location: Path | str, read_only: bool = False) -> tuple[Dialect, Any, Path | str]:
    """The dialect, an open connection and the printable location (a Path, or the URL without its password);
    ``read_only``: a SQLite file in a folder this process may not write into is opened read-only
    (:meth:`SQLiteDialect.connect_read_only`)."""
    if is_url(location):
        pg = PostgreSQLDialect()
        return pg, pg.connect(str(location)), redacted(str(location))
    path = Path(location)
    sqlite = SQLiteDialect()
    return sqlite, sqlite.connect(path, read_only), path


class _Row:
    """A row readable by position or by column name in any case, as :class:`sqlite3.Row` (PostgreSQL folds
    unquoted names to lower case); with duplicate names the first column wins, as in SQLite."""

    __slots__ = ("_values", "_names")

    def __init__(self, values: Sequence[Any], names: dict[str, int]):
        self._values, self._names = values, names

    def __getitem__(self, key: int | str) -> Any:
        return self._values[key] if isinstance(key, int) else self._values[self._names[key.lower()]]

    def keys(self) -> list[str]:
        """The column names (lower case)."""
        return list(self._names)


def _case_insensitive_rows(cursor: Any) -> Callable[[Sequence[Any]], _Row]:
    """psycopg row factory making :class:`_Row`."""
    names: dict[str, int] = {}
    for i, column in enumerate(cursor.description or ()):
        names.setdefault(column.name.lower(), i)
    return lambda values: _Row(values, names)
