"""A throw-away PostgreSQL server for the tests and ``bench/batch.py``: Debian's ``postgresql`` package's
``initdb`` + ``pg_ctl`` in a temporary folder, listening on a free port of 127.0.0.1 and on a unix
socket in that folder. PostgreSQL refuses to run as root, so as root the server runs as ``nobody``.
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path


def server_binaries() -> Path | None:
    """The newest ``/usr/lib/postgresql/<major>/bin`` holding ``initdb`` and ``pg_ctl`` (None when absent)."""
    found = [Path(p).parent for p in glob.glob("/usr/lib/postgresql/*/bin/initdb")
             if Path(p).with_name("pg_ctl").exists()]
    return max(found, key=lambda p: int(p.parent.name) if p.parent.name.isdigit() else 0, default=None)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Server:
    """A running throw-away server: its URL (no database), and :meth:`stop` / :meth:`start` as an operator's
    ``pg_ctl stop -m fast`` and ``pg_ctl start`` (the same data, port and settings)."""

    url: str
    _run: Callable[..., None]
    _pg_ctl: list[str]
    _start: list[str]
    running: bool = True

    def stop(self) -> None:
        """``pg_ctl stop -m fast``: every connection is terminated ("terminating connection due to administrator
        command"), and the server is down until :meth:`start`."""
        self._run(*self._pg_ctl, "-m", "fast", "-w", "stop")
        self.running = False

    def start(self) -> None:
        """Start the stopped server again."""
        self._run(*self._pg_ctl, *self._start)
        self.running = True


@contextmanager
def throwaway_server(binaries: Path, durable: bool = False, password: str | None = None) -> Iterator[str]:
    """Start a server, yield its URL without a database (``postgresql://acq@127.0.0.1:PORT``), then remove it.
    (:func:`controllable_server` with its parameters.)"""
    with controllable_server(binaries, durable, password) as server:
        yield server.url


@contextmanager
def controllable_server(binaries: Path, durable: bool = False, password: str | None = None) -> Iterator[Server]:
    """Start a server, yield it (:class:`Server`: its URL, stop and start), then remove it.

    Parameters
    ----------
    binaries : Path
        The folder with ``initdb`` and ``pg_ctl`` (:func:`server_binaries`).
    durable : bool
        Keep ``fsync`` on (for benchmarks); the tests turn it off, as nothing must survive a crash.
    password : str or None
        The user's password, asked of every connection (scram-sha-256; the URL is then
        ``postgresql://acq:PASSWORD@127.0.0.1:PORT``); None: no password asked (trust).
    """
    root = Path(tempfile.mkdtemp(prefix="acq-pg-"))
    as_user: list[str] = []
    if os.geteuid() == 0:
        nobody = pwd.getpwnam("nobody")
        os.chown(root, nobody.pw_uid, nobody.pw_gid)
        as_user = ["runuser", "-u", "nobody", "--"]
    root.chmod(0o700)
    data = root / "data"
    env = {**os.environ, "LC_ALL": "C"}

    def run(*args: str) -> None:
        done = subprocess.run([*as_user, *args], cwd=root, env=env, capture_output=True, text=True, timeout=120)
        if done.returncode != 0:
            log = (root / "log").read_text() if (root / "log").exists() else ""
            raise RuntimeError(f"{' '.join(args[:2])} failed ({done.returncode}): {done.stderr.strip()} {log[-2000:]}")

    auth = ["-A", "trust"]
    if password is not None:
        (root / "pwfile").write_text(password + "\n")
        if as_user:
            os.chown(root / "pwfile", nobody.pw_uid, nobody.pw_gid)
        auth = ["-A", "scram-sha-256", f"--pwfile={root / 'pwfile'}"]
    try:
        run(str(binaries / "initdb"), "-D", str(data), "-U", "acq", *auth, "-E", "UTF8", "--no-sync")
        pg_ctl = [str(binaries / "pg_ctl"), "-D", str(data)]
        for attempt in range(5):
            # the port is free when asked, not held: another process (a second test worker's connections) may take
            # it before the server binds it — then another
            port = _free_port()
            settings = (f"-c listen_addresses=127.0.0.1 -p {port} -c unix_socket_directories={root} "
                        "-c max_connections=60" + ("" if durable else " -c fsync=off -c synchronous_commit=off"))
            start = ["-l", str(root / "log"), "-w", "-o", settings, "start"]
            (root / "log").unlink(missing_ok=True)
            try:
                run(*pg_ctl, *start)
                break
            except RuntimeError as e:
                if "Address already in use" not in str(e) or attempt == 4:
                    raise
        server = Server(f"postgresql://acq{'' if password is None else ':' + password}@127.0.0.1:{port}", run, pg_ctl,
                        start)
        try:
            yield server
        finally:
            if server.running:
                run(*pg_ctl, "-m", "immediate", "-w", "stop")
    finally:
        shutil.rmtree(root, ignore_errors=True)


def new_database(server_url: str) -> str:
    """Create an empty database on the server; return its URL."""
    import psycopg

    name = f"t_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(f"{server_url}/postgres", autocommit=True) as db:
        db.execute(f"CREATE DATABASE {name}")
    return f"{server_url}/{name}"
