"""Session paths: as given on the command line (one session file, or a batch: a folder or a glob), and the name of
a new session file.

Light on purpose (no numpy, h5py or analysis): the command line checks a path here before it loads
the libraries that read or analyse the file, so a mistyped path is one line at once.
"""

from __future__ import annotations

from pathlib import Path

from acqcore.errors import ConfigError

GLOB_CHARS = frozenset("*?[")
#: The first bytes of every SQLite database file (sqlite.org/fileformat.html, "The Database Header").
SQLITE_HEADER = b"SQLite format 3\0"


def is_catalogue_file(path: Path) -> bool:
    """True when ``path`` is a SQLite database (an acq catalogue: ``sessions/catalogue.sqlite``); False for any other
    file and for one that cannot be read (its reader says why)."""
    try:
        with path.open("rb") as f:
            return f.read(len(SQLITE_HEADER)) == SQLITE_HEADER
    except OSError:
        return False


def is_batch(spec: Path | str) -> bool:
    """True when ``spec`` names a folder or a glob pattern rather than one session file."""
    return Path(spec).is_dir() or bool(GLOB_CHARS & set(str(spec)))


def require_session_file(path: Path) -> None:
    """Raise :class:`ConfigError` naming ``path`` when it is missing, a folder, no regular file (a device such as
    /dev/zero, a pipe, a socket: it would read as "empty (0 bytes)") or a catalogue (given for a session, it read as
    "no HDF5 signature: another kind of file"; the line names the commands that read one). Of what it holds only the
    first 16 bytes are looked at."""
    if not path.exists():
        raise ConfigError(f"{path}: no such session file")
    if path.is_dir():
        raise ConfigError(f"{path}: is a folder, not a session file")
    if not path.is_file():
        raise ConfigError(f"{path}: not a regular file (a device, pipe or socket), not a session file")
    if is_catalogue_file(path):
        raise ConfigError(f"{path}: is a catalogue (SQLite) file, not a session file — read it with acq fleet "
                          f"--catalogue {path} (every joint's latest K) or acq trend --joint NAME --catalogue {path} "
                          "(one joint over time)")


def new_session_path(out_dir: Path, joint: str, created_utc: str) -> Path:
    """``<out_dir>/<UTC start>_<joint>.h5`` (file-system safe), ``_2``, ``_3`` … if taken."""
    stamp = created_utc.replace("+00:00", "").replace(":", "-")
    path = Path(out_dir) / f"{stamp}_{joint}.h5"
    if path.resolve().parent != Path(out_dir).resolve() or "/" in joint or "\0" in joint:
        raise ConfigError(f"joint {joint!r}: not usable in a file name (the session must stay in {out_dir})")
    n = 2
    while path.exists():
        path = Path(out_dir) / f"{stamp}_{joint}_{n}.h5"
        n += 1
    return path
