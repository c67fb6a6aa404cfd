"""Shared fixtures. Tests import the installed package (``pip install -e ".[test]"``)."""

from __future__ import annotations

import importlib.util
import os
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.pg_server import new_database, server_binaries, throwaway_server



def pytest_configure(config: pytest.Config) -> None:
    """Ctrl-C in this process raises KeyboardInterrupt, as in a run started at a terminal, also where the run was
    started with SIGINT ignored (a shell's ``&`` without job control, some CI runners): Python then installs no
    handler, and the tests that send themselves a SIGINT (a Ctrl-C as click makes a context, as a monitor shuts a
    window down) saw it vanish — acq keeps an ignored signal ignored — and one then waited for ever on a window (seen:
    a run started with ``( pytest … & )`` hung in test_view). Children started by tests inherit the default from it."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


#: The password of ``postgres_server_with_password``'s user.
PG_PASSWORD = "s3cret"


def _server_binaries_or_skip() -> Path:
    """``initdb``/``pg_ctl``'s folder; skips when Debian's ``postgresql`` package or psycopg is missing — except in CI
    (``CI=true``), where the PostgreSQL tests must run: it fails."""
    binaries = server_binaries()
    missing = ("no PostgreSQL server: initdb/pg_ctl not under /usr/lib/postgresql/*/bin (apt-get install postgresql)"
               if binaries is None else None)
    if importlib.util.find_spec("psycopg") is None:
        missing = "no psycopg 3 (pip install 'acq[fleet]')"
    if missing:
        if os.environ.get("CI", "").lower() in ("true", "1"):
            pytest.fail(f"{missing} — CI must run the PostgreSQL tests", pytrace=False)
        pytest.skip(missing)
    assert binaries is not None
    return binaries


@pytest.fixture(scope="session")
def postgres_server() -> Iterator[str]:
    """A throw-away PostgreSQL server for the session (its URL, no database), asking no password."""
    with throwaway_server(_server_binaries_or_skip()) as url:
        yield url


@pytest.fixture(scope="session")
def postgres_server_with_password() -> Iterator[str]:
    """A throw-away PostgreSQL server asking every connection for the password :data:`PG_PASSWORD` (its URL, which
    carries it, no database)."""
    with throwaway_server(_server_binaries_or_skip(), password=PG_PASSWORD) as url:
        yield url


@pytest.fixture(params=["sqlite", "postgresql"])
def catalogue_location(request: pytest.FixtureRequest, tmp_path: Path) -> Path | str:
    """A fresh, empty catalogue on each back end: a SQLite file, or a new database on the test server."""
    if request.param == "sqlite":
        return tmp_path / "catalogue.sqlite"
    return new_database(request.getfixturevalue("postgres_server"))
