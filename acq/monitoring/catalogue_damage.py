"""A SQLite catalogue damaged on disk (a flipped byte) named in one line: the file, the table, the row and the column.

SQLite reads a damaged page as "database disk image is malformed" (:class:`sqlite3.DatabaseError`) when its structure
is broken, but a byte flipped inside a text value reads back as another value: one that is no longer UTF-8 fails in
Python's ``sqlite3`` ("Could not decode to UTF-8 column 'options_json' with text '…'", an
:class:`sqlite3.OperationalError` naming the column, not the row), one that is no longer JSON fails where it is read
as JSON. :func:`read_error` turns these into :class:`ConfigError` (bad input: exit 2); errors of a working database
(locked, disk I/O, a PostgreSQL server gone) are left to their callers.
"""

from __future__ import annotations

import json
import re
import sqlite3
from pathlib import Path
from typing import Any

from acq.monitoring.catalogue_backends import one_line
from acq.recording.root_attrs import shown
from acqcore.errors import ConfigError

#: Python's sqlite3 message for a text value that is not UTF-8; names the column.
_NOT_UTF8 = re.compile(r"Could not decode to UTF-8 column '([^']*)'")
#: The heading integrity_check puts before a damaged page's finding ("*** in database main ***\nPage 4: …").
_DATABASE_HEADING = re.compile(r"\*\*\* in database \S+ \*\*\*")
#: The catalogue's tables, in the order a damaged column is looked for (:mod:`acq.monitoring.catalogue_schema`).
TABLES = ("sessions", "analyses")


def read_error(path: Path | str, db: Any, e: BaseException) -> ConfigError | None:
    """The one-line error of a read of the catalogue ``path`` (open as ``db``) that failed on damage, or None when
    ``e`` is no such failure."""
    if isinstance(e, sqlite3.OperationalError) and (found := _NOT_UTF8.search(str(e))):
        return ConfigError(f"{path}: damaged catalogue: {_where_not_utf8(db, found.group(1))}: not UTF-8 text")
    if isinstance(e, UnicodeDecodeError):  # a name in the schema (a column's, a table's) that is not UTF-8
        text = bytes(e.object).decode("utf-8", "surrogateescape")
        return ConfigError(f"{path}: damaged catalogue: a name in its schema is not UTF-8 text ({shown(text)})")
    if isinstance(e, sqlite3.DatabaseError) and not isinstance(e, sqlite3.OperationalError):
        return ConfigError(f"{path}: not a usable catalogue ({one_line(e)})")
    return None


def integrity_error(path: Path | str, db: sqlite3.Connection) -> ConfigError | None:
    """The one-line error of a SQLite catalogue whose structure SQLite finds damaged, or None when it is sound.

    A byte flipped in an index page reads without error, but a query through that index then misses rows (a
    baseline window gone from ``acq trend``: another baseline, every ΔK shifted, exit 0). ``PRAGMA quick_check``
    does not compare indexes with their tables, so it passes such a file; ``PRAGMA integrity_check`` does (stopped
    at its first finding). Its cost grows with the file: bench/catalogue_check.py measures it."""
    (first,) = db.execute("PRAGMA integrity_check(1)").fetchone()
    if first == "ok":
        return None
    finding = " ".join(_DATABASE_HEADING.sub("", first).split())
    return ConfigError(f"{path}: not a usable catalogue (database disk image is malformed: {finding})")


def _where_not_utf8(db: sqlite3.Connection, column: str) -> str:
    """``table row N, column C = 'value'``: the first row whose text in ``column`` is not UTF-8 (read as bytes), or
    the column alone when no table has it or none of its values fails now."""
    factory = db.text_factory
    db.text_factory = bytes
    try:
        for table in TABLES:
            if column not in {str(r[1], "utf-8", "replace") for r in db.execute(f"PRAGMA table_info({table})")}:
                continue
            for rowid, value in db.execute(f'SELECT rowid, "{column}" FROM {table} WHERE typeof("{column}") = \'text\''
                                           " ORDER BY rowid"):
                try:
                    value.decode("utf-8")
                except UnicodeDecodeError:
                    return f"{table} row {rowid}, column {column} = {shown(value.decode('utf-8', 'surrogateescape'))}"
    except sqlite3.Error:
        pass  # damaged further: the column is named all the same
    finally:
        db.text_factory = factory
    return f"column {column}"


def json_column(path: Path | str, r: Any, column: str, empty: str) -> Any:
    """Column ``column`` (``tags_json``: a JSON object; ``reasons_json`` a list, ``truth_json`` an object) of the row
    ``r`` of the catalogue at ``path`` read as JSON, ``empty`` when NULL or ""; a text that does not read as one is a
    :class:`ConfigError` naming the catalogue, the row (a session by its key, an analysis by its id) and the column."""
    text = r[column] or empty
    kind = dict if empty == "{}" else list
    try:
        value, at = json.loads(text), 0
    except json.JSONDecodeError as e:
        value, at = None, e.pos
    if isinstance(value, kind):
        return value
    row = f"sessions row of session_key {r['session_key']!r}" if column == "tags_json" else f"analyses row {r['id']}"
    what = "JSON object" if kind is dict else "JSON list"
    raise ConfigError(f"{path}: damaged catalogue: {row}, column {column} = {shown(text, at)}: not a {what}")
